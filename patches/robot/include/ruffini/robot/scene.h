#pragma once
// The robot part of a scene: the scene's `robot:` section (the URDF) and every patch's `mount:`, read into a
// Model and one PatchMount per patch, each checked with ValidateMount. The file's shape (which keys exist,
// which patches) is the root reader's (ruffini/scene_file.h); the scene format is in docs/robot.md, "Scenes".
//
//   robot: {urdf: ../robots/srs7.urdf}            # relative to the scene file
//   patches:
//     - name: forearm_a
//       spec: ../patches/forearm.yaml             # its surface_radius_mm is the mount's
//       mount: {link: forearm_link, xyz_m: [0, 0, 0.06], rpy_rad: [1.5707963267948966, 0, 0]}
//
// `xyz_m` and `rpy_rad` are X_LP, the pose of the patch frame P (mount.h) in the link frame L, as a URDF
// <origin> writes one: translation in metres, then fixed-axis roll, pitch, yaw in radians
// (R = Rz(yaw) Ry(pitch) Rx(roll)). The surface radius always comes from the patch spec: the decoder gives R
// in degrees on the spec's cylinder, so a limb of another radius needs a spec (and a cast) of its own.
//
// Loading is not real-time: it reads files and throws InputError "<scene>:<line>:<col>: '<key>' ... <what>".
#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include "ruffini/robot/model.h"
#include "ruffini/robot/mount.h"
#include "ruffini/scene_file.h"

namespace ruffini::robot {

struct MountedPatch {
  std::string name;           // the scene's patch id
  PatchMount mount;           // link, X_LP, surface_radius_mm (from the spec)
  std::size_t link_index = 0;  // model.FindLink(mount.link), resolved once
  double extent_y_mm = 0.0;   // the spec's extent: the patch covers Y 0..extent_y_mm, R 0..extent_r_deg
  double extent_r_deg = 0.0;
};

struct RobotScene {
  std::string source;     // the scene file
  std::string urdf_path;  // resolved against the scene's folder
  Model model;
  std::vector<MountedPatch> patches;  // in the scene's order

  // The patch named `name`, or nullptr.
  [[nodiscard]] const MountedPatch* FindPatch(std::string_view name) const;
};

// Reads the scene's robot section and mounts. Throws InputError when the scene names no robot, the URDF is
// missing or invalid, or a mount is wrong (an unknown link, a pose that is not 3 finite numbers each).
[[nodiscard]] RobotScene LoadRobotScene(const SceneFile& scene);
[[nodiscard]] RobotScene LoadRobotScene(const std::string& scene_path);

}  // namespace ruffini::robot
