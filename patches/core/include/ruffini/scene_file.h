#pragma once
// The scene's root reader (DESIGN.md, "Conventions"): a scene (`config/scenes/*.yaml`) names the robot, the
// patches and where each is mounted, the effects the twin must model, and the safety zones. This reader
// knows the file's shape and nothing of what the sections mean; each part parses its own section:
//
//   key                        read by                           what
//   name                       here                              the scene's name
//   robot                      robot::LoadRobotScene             the URDF (ruffini/robot/scene.h)
//   patches[i].name            here                              unique patch id
//   patches[i].spec            here (the path), the parts        the patch spec (must exist)
//   patches[i].model           here (the path), the decoder      the decoder model (optional; must exist)
//   patches[i].mount           robot::LoadRobotScene             where it is bonded (needs `robot`)
//   patches[i].region          safety::ConfigFromScene           its body region (needs `safety`)
//   patches[i].silence_deadline_ms  safety::ConfigFromScene      per-patch override (needs `safety`)
//   twin                       twin::LoadScene                   probe, load cell, effects
//   safety                     safety::ConfigFromScene           regions, thresholds, deadlines
//
// Presence rules checked here, so every part sees a consistent scene: any other key is an error; a scene
// with `robot` mounts every patch and one without mounts none; a scene with `safety` gives every patch a
// region and one without gives none. Errors read "<file>:<line>:<col>: '<key path>' (<value>) <what>".
// Loading is not real-time (it reads files and allocates).
#include <optional>
#include <string>
#include <vector>

#include "ruffini/yaml_reader.h"

namespace ruffini {

struct SceneFilePatch {
  std::string name;
  std::string spec_path;   // relative to the scene's folder, normalised; the file exists
  std::string model_path;  // same; empty when the scene names none
  // The patch's own mapping, for the parts to read their keys from (`mount`, `region`, ...) and to place
  // their messages ('patches[2].region'). Finish() on it is this reader's job, not theirs.
  YamlReader entry;
};

struct SceneFile {
  std::string source;  // the file, as given
  std::string name;
  std::vector<SceneFilePatch> patches;  // at least one, names unique
  // The sections, unread (nullopt when absent). A part reads its copy and calls Finish() on it.
  std::optional<YamlReader> robot;
  std::optional<YamlReader> twin;
  std::optional<YamlReader> safety;

  // A path written in the scene, resolved against the scene's folder and normalised.
  [[nodiscard]] std::string Resolve(const std::string& written) const;
  // The patch named `name`, or nullptr.
  [[nodiscard]] const SceneFilePatch* FindPatch(const std::string& name) const;
};

// Reads the file and checks its shape (above). Throws InputError.
SceneFile LoadSceneFile(const std::string& path);

}  // namespace ruffini
