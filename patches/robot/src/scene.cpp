#include "ruffini/robot/scene.h"

#include <filesystem>
#include <numbers>

#include "ruffini/error.h"
#include "ruffini/patch/spec_loader.h"

namespace ruffini::robot {
namespace {

constexpr double kMaxOffsetM = 10.0;  // no link of a cobot is 10 m long: a bigger offset is a unit slip
constexpr double kTwoPi = 2.0 * std::numbers::pi;

Eigen::Vector3d Triple(YamlReader& r, const std::string& key, double limit, const char* what) {
  const std::vector<double> v = r.Numbers(key, -limit, limit);
  if (v.size() != 3) r.Fail(key, std::string("must be 3 numbers: ") + what);
  return {v[0], v[1], v[2]};
}

// A URDF <origin>: translation, then R = Rz(yaw) Ry(pitch) Rx(roll) about fixed axes.
Eigen::Isometry3d FromXyzRpy(const Eigen::Vector3d& xyz_m, const Eigen::Vector3d& rpy_rad) {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.translation() = xyz_m;
  X.linear() = (Eigen::AngleAxisd(rpy_rad.z(), Eigen::Vector3d::UnitZ()) *
                Eigen::AngleAxisd(rpy_rad.y(), Eigen::Vector3d::UnitY()) *
                Eigen::AngleAxisd(rpy_rad.x(), Eigen::Vector3d::UnitX()))
                   .toRotationMatrix();
  return X;
}

}  // namespace

const MountedPatch* RobotScene::FindPatch(std::string_view patch_name) const {
  for (const auto& p : patches) {
    if (p.name == patch_name) return &p;
  }
  return nullptr;
}

RobotScene LoadRobotScene(const SceneFile& scene) {
  if (!scene.robot) {
    throw InputError(scene.source + ": 'robot' is missing (a mapping {urdf: <file>} expected): the scene names no robot");
  }
  YamlReader r = *scene.robot;
  RobotScene out;
  out.source = scene.source;
  const std::string written = r.String("urdf");
  out.urdf_path = scene.Resolve(written);
  if (!std::filesystem::exists(out.urdf_path)) r.Fail("urdf", "names a file that does not exist (" + out.urdf_path + ")");
  try {
    out.model = Model::FromUrdfFile(out.urdf_path);
  } catch (const InputError& e) {
    r.Fail("urdf", std::string("is not a robot Ruffini can use: ") + e.what());
  }
  r.Finish();

  for (const SceneFilePatch& p : scene.patches) {
    YamlReader entry = p.entry;
    YamlReader m = entry.Map("mount");  // the root reader made sure it is there
    MountedPatch mp;
    mp.name = p.name;
    mp.mount.link = m.String("link");
    const Eigen::Vector3d xyz_m = Triple(m, "xyz_m", kMaxOffsetM, "[x, y, z] in metres");
    const Eigen::Vector3d rpy_rad = Triple(m, "rpy_rad", kTwoPi, "[roll, pitch, yaw] in radians");
    m.Finish();
    mp.mount.X_LP = FromXyzRpy(xyz_m, rpy_rad);
    const patch::PatchSpec spec = patch::LoadPatchSpec(p.spec_path);
    mp.mount.surface_radius_mm = spec.surface_radius_mm;
    mp.extent_y_mm = spec.extent_y_mm;
    mp.extent_r_deg = spec.extent_r_deg;
    mp.link_index = ValidateMount(out.model, mp.mount, m.Where("link") + ": '" + m.path() + "'");
    out.patches.push_back(std::move(mp));
  }
  return out;
}

RobotScene LoadRobotScene(const std::string& scene_path) { return LoadRobotScene(LoadSceneFile(scene_path)); }

}  // namespace ruffini::robot
