// Patch mounts: patch coordinates <-> link frame, and checking a mount against the robot.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include "ruffini/error.h"
#include "ruffini/robot/kinematics.h"
#include "ruffini/robot/mount.h"

namespace ruffini::robot {
namespace {

using ::testing::HasSubstr;

constexpr double kDeg = std::numbers::pi / 180.0;

Eigen::Isometry3d Pose(const Eigen::Vector3d& t_m, const Eigen::AngleAxisd& r) {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.translate(t_m);
  X.rotate(r);
  return X;
}

// The mount mount.h uses as its example: 60 mm down srs7's forearm, R = 0 on the link's -y side.
PatchMount ForearmMount() {
  return {"forearm_link", Pose({0, 0, 0.060}, Eigen::AngleAxisd(90 * kDeg, Eigen::Vector3d::UnitX())), 37.4};
}

// An arbitrary tilted mount, for round trips.
PatchMount TiltedMount() {
  return {"upper_arm_link",
          Pose({0.01, -0.02, 0.1}, Eigen::AngleAxisd(0.7, Eigen::Vector3d(0.3, -1.0, 0.4).normalized())), 45.0};
}

TEST(Mount, KnownPointsInThePatchFrame) {
  const PatchMount m{"any", Eigen::Isometry3d::Identity(), 37.4};
  auto s = PatchToLink(m, {0.0, 0.0});
  EXPECT_TRUE(s.p_LS_m.isApprox(Eigen::Vector3d(0, 0, 0.0374), 1e-15));
  EXPECT_TRUE(s.n_L.isApprox(Eigen::Vector3d(0, 0, 1), 1e-15));
  s = PatchToLink(m, {150.0, 90.0});  // R grows right-handed about +y: from +z toward +x
  EXPECT_NEAR((s.p_LS_m - Eigen::Vector3d(0.0374, 0.150, 0)).norm(), 0, 1e-15);
  EXPECT_NEAR((s.n_L - Eigen::Vector3d(1, 0, 0)).norm(), 0, 1e-15);
  s = PatchToLink(m, {20.0, 180.0});
  EXPECT_NEAR((s.p_LS_m - Eigen::Vector3d(0, 0.020, -0.0374)).norm(), 0, 1e-15);
  // Arc length on the surface is radius x R: 145 deg on a 37.4 mm limb is 94.65 mm.
  EXPECT_NEAR(37.4 * 145 * kDeg, 94.65, 0.01);
}

TEST(Mount, KnownPointsOnTheForearm) {
  const PatchMount m = ForearmMount();
  const auto s = PatchToLink(m, {10.0, 0.0});
  EXPECT_NEAR((s.p_LS_m - Eigen::Vector3d(0, -0.0374, 0.070)).norm(), 0, 1e-15);
  EXPECT_NEAR((s.n_L - Eigen::Vector3d(0, -1, 0)).norm(), 0, 1e-15);
  // And in the base frame at q = 0 (forearm_link at 0.740 m, axes aligned with the base).
  const Model robot = Model::FromUrdfFile(RUFFINI_SOURCE_DIR "/config/robots/srs7.urdf");
  Data d;
  ASSERT_EQ(ForwardKinematics(robot, std::vector<double>(7, 0.0), d), FkStatus::kOk);
  const Eigen::Vector3d p_B = d.X_BL[ValidateMount(robot, m, "test")] * s.p_LS_m;
  EXPECT_NEAR((p_B - Eigen::Vector3d(0, -0.0374, 0.810)).norm(), 0, 1e-15);
}

TEST(Mount, NormalsAreUnitAndOutward) {
  for (const PatchMount& m : {ForearmMount(), TiltedMount()}) {
    for (double y = 0; y <= 150; y += 7.5) {
      for (double r = 0; r <= 145; r += 5) {
        const auto s = PatchToLink(m, {y, r});
        EXPECT_NEAR(s.n_L.norm(), 1.0, 1e-12);
        // Outward: along the line from the limb axis (patch y axis) to the point, and stepping along it
        // moves away from the axis.
        const Eigen::Vector3d on_axis = m.X_LP * Eigen::Vector3d(0, y * 1e-3, 0);
        const Eigen::Vector3d radial = s.p_LS_m - on_axis;
        EXPECT_NEAR((radial.normalized() - s.n_L).norm(), 0, 1e-12);
        EXPECT_NEAR(radial.norm(), m.surface_radius_mm * 1e-3, 1e-15);
        EXPECT_GT((s.p_LS_m + 1e-3 * s.n_L - on_axis).norm(), radial.norm());
      }
    }
  }
}

TEST(Mount, RoundTrip) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> y_mm(0, 150), r_deg(0, 145), h_mm(-20, 20);
  for (const PatchMount& m : {ForearmMount(), TiltedMount()}) {
    for (int i = 0; i < 2000; ++i) {
      const patch::SurfacePoint s{y_mm(rng), r_deg(rng)};
      const double h = h_mm(rng);
      const auto on = PatchToLink(m, s);
      // On the surface, and off it along the normal: the same (Y, R), the height recovered.
      for (const double height : {0.0, h}) {
        const auto back = LinkToPatch(m, on.p_LS_m + height * 1e-3 * on.n_L);
        ASSERT_TRUE(back.has_value());
        EXPECT_NEAR(back->point.y_mm, s.y_mm, 1e-9);
        EXPECT_NEAR(back->point.r_deg, s.r_deg, 1e-9);
        EXPECT_NEAR(back->height_mm, height, 1e-9);
      }
    }
  }
}

TEST(Mount, BackProjectionKeepsThePatchSpanContinuous) {
  const PatchMount m{"any", Eigen::Isometry3d::Identity(), 37.4};
  // R just below 0 stays negative; R past 180 stays past 180 (not -180).
  EXPECT_NEAR(LinkToPatch(m, PatchToLink(m, {5, -10}).p_LS_m)->point.r_deg, -10, 1e-9);
  EXPECT_NEAR(LinkToPatch(m, PatchToLink(m, {5, 200}).p_LS_m)->point.r_deg, 200, 1e-9);
}

TEST(Mount, BackProjectionRefusesTheAxisAndNaN) {
  const PatchMount m = TiltedMount();
  EXPECT_FALSE(LinkToPatch(m, m.X_LP * Eigen::Vector3d(0, 0.05, 0)).has_value());
  EXPECT_FALSE(LinkToPatch(m, Eigen::Vector3d(std::nan(""), 0, 0)).has_value());
  EXPECT_FALSE(LinkToPatch(m, Eigen::Vector3d(0, std::numeric_limits<double>::infinity(), 0)).has_value());
}

TEST(Mount, Validate) {
  const Model robot = Model::FromUrdfFile(RUFFINI_SOURCE_DIR "/config/robots/srs7.urdf");
  EXPECT_EQ(ValidateMount(robot, ForearmMount(), "scene"), *robot.FindLink("forearm_link"));

  PatchMount bad = ForearmMount();
  bad.link = "forarm_link";
  try {
    (void)ValidateMount(robot, bad, "arm.yaml: patches[0].mount");
    ADD_FAILURE();
  } catch (const InputError& e) {
    EXPECT_THAT(std::string(e.what()), HasSubstr("arm.yaml: patches[0].mount: link 'forarm_link' is not in "));
    EXPECT_THAT(std::string(e.what()), HasSubstr("srs7.urdf (links: base_link, shoulder_yaw_link,"));
  }
  bad = ForearmMount();
  bad.X_LP.linear() *= 1.01;
  EXPECT_THROW((void)ValidateMount(robot, bad, "m"), InputError);
  bad = ForearmMount();
  bad.X_LP.linear().col(0) *= -1;  // a reflection
  EXPECT_THROW((void)ValidateMount(robot, bad, "m"), InputError);
  bad = ForearmMount();
  bad.X_LP.translation().x() = std::nan("");
  EXPECT_THROW((void)ValidateMount(robot, bad, "m"), InputError);
  for (const double r : {0.0, -3.0, 2000.0, std::nan("")}) {
    bad = ForearmMount();
    bad.surface_radius_mm = r;
    EXPECT_THROW((void)ValidateMount(robot, bad, "m"), InputError) << r;
  }
}

}  // namespace
}  // namespace ruffini::robot
