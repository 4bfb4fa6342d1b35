#pragma once
// A small robot and patch mounts for the fusion tests.
//
// base_link -j1-> upper -j2-> fore -j3-> hand, every joint about z; at q = 0 every link frame is the base
// frame moved up z: upper at 0, fore at 0.3 m, hand at 0.6 m. Patches are mounted with their Y axis along
// the link's +z (X_LP = translation * Rx(+90 deg): P's +y -> L's +z, P's +z -> L's -y).
#include <Eigen/Geometry>
#include <array>
#include <numbers>
#include <string>

#include "ruffini/fusion/fuser.h"
#include "ruffini/robot/kinematics.h"
#include "ruffini/robot/model.h"

namespace ruffini::fusion::testing {

inline constexpr const char* kUrdf = R"(<?xml version="1.0"?>
<robot name="three">
  <link name="base_link"/>
  <link name="upper"/>
  <link name="fore"/>
  <link name="hand"/>
  <joint name="j1" type="revolute">
    <parent link="base_link"/><child link="upper"/><origin xyz="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" velocity="1" effort="1"/>
  </joint>
  <joint name="j2" type="revolute">
    <parent link="upper"/><child link="fore"/><origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" velocity="1" effort="1"/>
  </joint>
  <joint name="j3" type="revolute">
    <parent link="fore"/><child link="hand"/><origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" velocity="1" effort="1"/>
  </joint>
</robot>
)";

inline robot::Model TestModel() { return robot::Model::FromUrdfString(kUrdf, "three.urdf"); }

inline constexpr double kDeg = std::numbers::pi / 180.0;

// A patch on `link` whose elbow edge is z_m up the link, R = 0 on the link's -y side, R turned by r0_deg
// about the link's z axis.
inline FusionPatch Patch(std::string id, std::string link, double z_m, double radius_mm = 40.0, double r0_deg = 0.0) {
  FusionPatch p;
  p.id = std::move(id);
  p.mount.link = std::move(link);
  p.mount.X_LP = Eigen::Translation3d(0, 0, z_m) * Eigen::AngleAxisd(r0_deg * kDeg, Eigen::Vector3d::UnitZ()) *
                 Eigen::AngleAxisd(90.0 * kDeg, Eigen::Vector3d::UnitX());
  p.mount.surface_radius_mm = radius_mm;
  return p;
}

inline SurfaceContact Located(double y_mm, double r_deg, double force_n = 1.0, double sd_mm = 2.0) {
  SurfaceContact c;
  c.force_n = force_n;
  c.force_sd_n = 0.05;
  c.located = true;
  c.y_mm = y_mm;
  c.r_deg = r_deg;
  c.cov_yy_mm2 = sd_mm * sd_mm;
  c.cov_ss_mm2 = sd_mm * sd_mm;
  c.uncertainty_calibrated = true;
  return c;
}

inline SurfaceContact ForceOnly(double force_n) {
  SurfaceContact c;
  c.force_n = force_n;
  return c;
}

// Link poses at q = 0.
inline robot::Data PosesAtZero(const robot::Model& model) {
  robot::Data d;
  const std::array<double, 3> q{0, 0, 0};
  (void)robot::ForwardKinematics(model, q, d);
  return d;
}

}  // namespace ruffini::fusion::testing
