#include "ruffini/scene_file.h"

#include <filesystem>

#include "ruffini/error.h"

namespace ruffini {

std::string SceneFile::Resolve(const std::string& written) const {
  return (std::filesystem::path(source).parent_path() / written).lexically_normal().string();
}

const SceneFilePatch* SceneFile::FindPatch(const std::string& patch_name) const {
  for (const auto& p : patches) {
    if (p.name == patch_name) return &p;
  }
  return nullptr;
}

SceneFile LoadSceneFile(const std::string& path) {
  YamlReader root = YamlReader::LoadFile(path);
  SceneFile s{.source = path, .name = root.String("name"), .patches = {}, .robot = {}, .twin = {}, .safety = {}};
  s.robot = root.MapOr("robot");
  s.safety = root.MapOr("safety");
  for (YamlReader& p : root.Sequence("patches")) {
    const std::string patch_name = p.String("name");
    const std::string spec_path = s.Resolve(p.String("spec"));
    if (!std::filesystem::exists(spec_path)) p.Fail("spec", "names a file that does not exist (" + spec_path + ")");
    std::string model_path;
    if (p.Has("model")) {
      model_path = s.Resolve(p.String("model"));
      if (!std::filesystem::exists(model_path)) p.Fail("model", "names a file that does not exist (" + model_path + ")");
    }
    // The parts' keys: present exactly when their section is.
    if (s.robot && !p.Has("mount")) p.Fail("mount", "is missing: the scene names a robot, so every patch needs a mount");
    if (!s.robot && p.Has("mount")) p.Fail("mount", "needs a robot: the scene has no 'robot' section");
    if (s.safety && !p.Has("region")) {
      p.Fail("region", "is missing: the scene has a safety section, so every patch needs a body region");
    }
    for (const char* key : {"region", "silence_deadline_ms"}) {
      if (!s.safety && p.Has(key)) p.Fail(key, "needs a safety section: the scene has no 'safety' section");
    }
    p.Allow({"mount", "region", "silence_deadline_ms"});
    p.Finish();
    if (s.FindPatch(patch_name) != nullptr) p.Fail("name", "is used by two patches; patch names must be unique");
    SceneFilePatch sp{.name = patch_name, .spec_path = spec_path, .model_path = model_path, .entry = p};
    s.patches.push_back(std::move(sp));
  }
  if (s.patches.empty()) root.Fail("patches", "must list at least one patch");
  s.twin = root.MapOr("twin");
  root.Finish();
  return s;
}

}  // namespace ruffini
