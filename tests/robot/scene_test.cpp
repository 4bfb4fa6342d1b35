// The robot part of a scene: config/scenes/cobot.yaml's robot and mounts, the forearm seam, and every bad
// robot or mount key with its message.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>
#include <unistd.h>

#include "ruffini/error.h"
#include "ruffini/robot/kinematics.h"
#include "ruffini/robot/scene.h"

namespace ruffini::robot {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::MatchesRegex;

constexpr double kDeg = std::numbers::pi / 180.0;
const std::string kCobot = RUFFINI_SOURCE_DIR "/config/scenes/cobot.yaml";
const std::string kSpec = RUFFINI_SOURCE_DIR "/config/patches/forearm.yaml";
const std::string kUrdf = RUFFINI_SOURCE_DIR "/config/robots/srs7.urdf";

const RobotScene& Cobot() {
  static const RobotScene s = LoadRobotScene(kCobot);
  return s;
}

// Distance on the surface (mm) between two points of one patch: arc length = radius x R in radians.
double SurfaceDistanceMm(const MountedPatch& p, const patch::SurfacePoint& a, const patch::SurfacePoint& b) {
  return std::hypot(a.y_mm - b.y_mm, p.mount.surface_radius_mm * (a.r_deg - b.r_deg) * kDeg);
}

// The largest distance from `a`'s edge R = r_a (sampled every mm of Y) to `b`'s edge R = r_b, on b's surface.
double EdgeGapMm(const MountedPatch& a, double r_a, const MountedPatch& b, double r_b) {
  double worst = 0.0;
  for (double y = 0.0; y <= a.extent_y_mm; y += 1.0) {
    const SurfaceInLink s = PatchToLink(a.mount, {y, r_a});
    const auto q = LinkToPatch(b.mount, s.p_LS_m);
    if (!q) return INFINITY;
    const double d = std::hypot(SurfaceDistanceMm(b, q->point, {q->point.y_mm, r_b}), q->height_mm);
    const bool within_b = q->point.y_mm >= -1.0 && q->point.y_mm <= b.extent_y_mm + 1.0;
    worst = std::max(worst, within_b ? d : INFINITY);
  }
  return worst;
}

TEST(CobotScene, LoadsTheRobotAndFourMounts) {
  const RobotScene& s = Cobot();
  EXPECT_EQ(s.model.name(), "srs7");
  EXPECT_EQ(s.model.num_dof(), 7u);
  EXPECT_EQ(fs::path(s.urdf_path).lexically_normal(), fs::path(kUrdf).lexically_normal());
  ASSERT_EQ(s.patches.size(), 4u);
  const char* names[] = {"forearm_a", "forearm_b", "upper_arm_a", "upper_arm_b"};
  const char* links[] = {"forearm_link", "forearm_link", "upper_arm_link", "upper_arm_link"};
  for (std::size_t i = 0; i < 4; ++i) {
    const MountedPatch& p = s.patches[i];
    EXPECT_EQ(p.name, names[i]);
    EXPECT_EQ(p.mount.link, links[i]);
    // Every mount's link exists, and the index is the one the model gives.
    const auto link = s.model.FindLink(p.mount.link);
    ASSERT_TRUE(link.has_value()) << p.mount.link;
    EXPECT_EQ(p.link_index, *link);
    // The radius and extent are the spec's.
    EXPECT_EQ(p.mount.surface_radius_mm, 37.4);
    EXPECT_EQ(p.extent_y_mm, 150.0);
    EXPECT_EQ(p.extent_r_deg, 145.0);
    EXPECT_EQ(s.FindPatch(names[i]), &p);
  }
  EXPECT_EQ(s.FindPatch("nope"), nullptr);
}

TEST(CobotScene, RpyIsTheUrdfConvention) {
  // forearm_a: 125 mm down the forearm, roll +90 deg (mount.h's example shape); forearm_b: the same turned by
  // yaw 145 deg about the link's +z, the limb axis (URDF: R = Rz(yaw) Ry(pitch) Rx(roll)).
  const Eigen::Isometry3d a = Eigen::Translation3d(0, 0, 0.125) * Eigen::AngleAxisd(90 * kDeg, Eigen::Vector3d::UnitX());
  const Eigen::Isometry3d b = Eigen::Translation3d(0, 0, 0.125) * Eigen::AngleAxisd(145 * kDeg, Eigen::Vector3d::UnitZ()) *
                              Eigen::AngleAxisd(90 * kDeg, Eigen::Vector3d::UnitX());
  EXPECT_TRUE(Cobot().FindPatch("forearm_a")->mount.X_LP.isApprox(a, 1e-12));
  EXPECT_TRUE(Cobot().FindPatch("forearm_b")->mount.X_LP.isApprox(b, 1e-12));
  // R = 0 of forearm_a is on the link's -y side, R = 90 deg on +x.
  const auto& m = Cobot().FindPatch("forearm_a")->mount;
  EXPECT_TRUE(PatchToLink(m, {0, 0}).n_L.isApprox(-Eigen::Vector3d::UnitY(), 1e-12));
  EXPECT_TRUE(PatchToLink(m, {0, 90}).n_L.isApprox(Eigen::Vector3d::UnitX(), 1e-12));
}

TEST(CobotScene, TheForearmPatchesShareASeam) {
  const MountedPatch& a = *Cobot().FindPatch("forearm_a");
  const MountedPatch& b = *Cobot().FindPatch("forearm_b");
  ASSERT_EQ(a.mount.link, b.mount.link);
  // Every point of forearm_a's R = 145 edge lands, through both mounts, within 1 mm of forearm_b's R = 0
  // edge (on the surface, and on it: height ~ 0), and the other way round.
  EXPECT_LT(EdgeGapMm(a, a.extent_r_deg, b, 0.0), 1.0);
  EXPECT_LT(EdgeGapMm(b, 0.0, a, a.extent_r_deg), 1.0);
  // Point for point too: the same Y on both edges is the same place, with the same outward normal.
  for (double y : {0.0, 75.0, 150.0}) {
    const SurfaceInLink pa = PatchToLink(a.mount, {y, a.extent_r_deg});
    const SurfaceInLink pb = PatchToLink(b.mount, {y, 0.0});
    EXPECT_LT((pa.p_LS_m - pb.p_LS_m).norm() * 1e3, 1.0) << "Y " << y;
    EXPECT_TRUE(pa.n_L.isApprox(pb.n_L, 1e-9)) << "Y " << y;
  }
  // And the seam is the only one: forearm_b's far edge does not meet forearm_a's R = 0 edge (70 deg bare).
  EXPECT_GT(EdgeGapMm(b, b.extent_r_deg, a, 0.0), 40.0);
}

TEST(CobotScene, FindSeamsFindsTheForearmSeamAndNothingElse) {
  const RobotScene& s = Cobot();
  std::vector<MountedSurface> surfaces;
  for (const MountedPatch& p : s.patches) surfaces.push_back({p.mount, p.extent_y_mm, p.extent_r_deg});
  const std::vector<Seam> seams = FindSeams(surfaces);
  ASSERT_EQ(seams.size(), 1u);
  EXPECT_EQ(s.patches[seams[0].a].name, "forearm_a");
  EXPECT_EQ(s.patches[seams[0].b].name, "forearm_b");
  EXPECT_EQ(seams[0].edge_a, PatchEdge::kRMax);
  EXPECT_EQ(seams[0].edge_b, PatchEdge::kRMin);
  // The distance to an edge is measured on the surface: arc length for R edges.
  EXPECT_NEAR(DistanceToEdgeMm(surfaces[seams[0].a], PatchEdge::kRMax, {75.0, 135.0}), 37.4 * 10 * kDeg, 1e-9);
  EXPECT_NEAR(DistanceToEdgeMm(surfaces[seams[0].b], PatchEdge::kRMin, {75.0, -2.0}), -37.4 * 2 * kDeg, 1e-9);
  EXPECT_DOUBLE_EQ(DistanceToEdgeMm(surfaces[0], PatchEdge::kYMax, {140.0, 50.0}), surfaces[0].extent_y_mm - 140.0);
  // Moved 3 mm apart around the limb, the covers no longer meet: no seam.
  for (std::size_t i = 0; i < surfaces.size(); ++i) {
    if (s.patches[i].name == "forearm_b") surfaces[i].mount.X_LP = surfaces[i].mount.X_LP * Eigen::AngleAxisd(-3.0 / 37.4, Eigen::Vector3d::UnitY());
  }
  EXPECT_TRUE(FindSeams(surfaces).empty());
}

TEST(CobotScene, TheUpperArmPatchesDoNotTouch) {
  // The check above is not vacuous: two patches 35 deg apart (about 23 mm of arc) are far from 1 mm.
  const MountedPatch& a = *Cobot().FindPatch("upper_arm_a");
  const MountedPatch& b = *Cobot().FindPatch("upper_arm_b");
  EXPECT_NEAR(EdgeGapMm(a, a.extent_r_deg, b, 0.0), 37.4 * 35 * kDeg, 0.01);
  EXPECT_NEAR(EdgeGapMm(b, b.extent_r_deg, a, 0.0), 37.4 * 35 * kDeg, 0.01);
}

TEST(CobotScene, TheSeamHoldsInTheBaseFrameAtAnyPose) {
  const RobotScene& s = Cobot();
  const MountedPatch& a = *s.FindPatch("forearm_a");
  const MountedPatch& b = *s.FindPatch("forearm_b");
  Data data;
  const double q[] = {0.3, -0.7, 1.1, 1.2, -2.0, 0.4, 0.9};
  ASSERT_EQ(ForwardKinematics(s.model, q, data), FkStatus::kOk);
  const Eigen::Vector3d pa = data.X_BL[a.link_index] * PatchToLink(a.mount, {40, 145}).p_LS_m;
  const Eigen::Vector3d pb = data.X_BL[b.link_index] * PatchToLink(b.mount, {40, 0}).p_LS_m;
  EXPECT_LT((pa - pb).norm() * 1e3, 1.0);
}

// --- Bad scenes ------------------------------------------------------------------------------------------------

class BadRobotScene : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::path(::testing::TempDir()) / (std::to_string(::getpid()) + "_ruffini_robot_" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  // A one-patch scene: the robot section on line 2, the patch's mount on line 6 (its mapping at column 12).
  std::string Write(const std::string& mount, const std::string& robot = "{urdf: " + kUrdf + "}") const {
    const std::string path = (dir_ / "s.yaml").string();
    std::ofstream(path) << "name: t\n"
                        << "robot: " << robot << "\n"
                        << "patches:\n"
                        << "  - name: p\n"
                        << "    spec: " << kSpec << "\n"
                        << "    mount: " << mount << "\n";
    return path;
  }
  static std::string Message(const std::string& path) {
    try {
      (void)LoadRobotScene(path);
    } catch (const InputError& e) {
      return e.what();
    }
    return "(no error)";
  }
  fs::path dir_;
};

TEST_F(BadRobotScene, AGoodOneLoads) {
  const RobotScene s = LoadRobotScene(Write("{link: forearm_link, xyz_m: [0, 0, 0.06], rpy_rad: [0, 0, 0]}"));
  ASSERT_EQ(s.patches.size(), 1u);
  EXPECT_TRUE(s.patches[0].mount.X_LP.isApprox(Eigen::Isometry3d(Eigen::Translation3d(0, 0, 0.06))));
}

TEST_F(BadRobotScene, UnknownLink) {
  const std::string p = Write("{link: hand_link, xyz_m: [0, 0, 0], rpy_rad: [0, 0, 0]}");
  EXPECT_EQ(Message(p), p + ":6:13: 'patches[0].mount': link 'hand_link' is not in " + kUrdf +
                            " (links: base_link, shoulder_yaw_link, shoulder_pitch_link, upper_arm_link, elbow_link, "
                            "forearm_link, wrist_link, flange_link, tool0)");
}

TEST_F(BadRobotScene, NaNPose) {
  const std::string p = Write("{link: forearm_link, xyz_m: [0, .nan, 0], rpy_rad: [0, 0, 0]}");
  EXPECT_EQ(Message(p), p + ":6:44: 'patches[0].mount.xyz_m[1]' (.nan) must be a number inside -10..10");
  const std::string q = Write("{link: forearm_link, xyz_m: [0, 0, 0], rpy_rad: [0, 0, .inf]}");
  EXPECT_THAT(Message(q), MatchesRegex(".*s\\.yaml:6:[0-9]+: 'patches\\[0\\]\\.mount\\.rpy_rad\\[2\\]' \\(\\.inf\\) "
                                       "must be a number inside -6\\.28.*"));
}

TEST_F(BadRobotScene, PoseOfTheWrongShape) {
  const std::string p = Write("{link: forearm_link, xyz_m: [0, 0], rpy_rad: [0, 0, 0]}");
  EXPECT_EQ(Message(p), p + ":6:33: 'patches[0].mount.xyz_m' must be 3 numbers: [x, y, z] in metres");
  const std::string q = Write("{link: forearm_link, xyz_m: [0, 0, 0]}");
  EXPECT_EQ(Message(q), q + ":6:12: 'patches[0].mount.rpy_rad' is missing (a sequence of numbers expected)");
  const std::string r = Write("{link: forearm_link, xyz_m: [0, 0, 20], rpy_rad: [0, 0, 0]}");
  EXPECT_THAT(Message(r), HasSubstr("'patches[0].mount.xyz_m[2]' (20) must be a number inside -10..10"));
}

TEST_F(BadRobotScene, UnknownMountKey) {
  const std::string p = Write("{link: forearm_link, xyz_m: [0, 0, 0], rpy_rad: [0, 0, 0], radius_mm: 40}");
  EXPECT_EQ(Message(p), p + ":6:71: 'patches[0].mount.radius_mm' is not a known key here");
}

TEST_F(BadRobotScene, MissingAndBrokenUrdf) {
  const std::string mount = "{link: forearm_link, xyz_m: [0, 0, 0], rpy_rad: [0, 0, 0]}";
  const std::string p = Write(mount, "{urdf: nope.urdf}");
  EXPECT_EQ(Message(p), p + ":2:9: 'robot.urdf' (nope.urdf) names a file that does not exist (" +
                            (dir_ / "nope.urdf").string() + ")");
  std::ofstream((dir_ / "bad.urdf").string()) << "<robot name='x'><link name='a'/><joint name='j' type='fixed'>"
                                                 "<parent link='a'/><child link='b'/></joint></robot>";
  const std::string q = Write(mount, "{urdf: bad.urdf}");
  EXPECT_THAT(Message(q), HasSubstr(q + ":2:9: 'robot.urdf' (bad.urdf) is not a robot Ruffini can use: " +
                                    (dir_ / "bad.urdf").string() + ": not a valid URDF"));
  const std::string r = Write(mount, "{urdf: " + kUrdf + ", base: world}");
  EXPECT_EQ(Message(r), r + ":2:" + std::to_string(17 + kUrdf.size()) + ": 'robot.base' is not a known key here");
}

TEST_F(BadRobotScene, MountAndRobotGoTogether) {
  // The root reader's presence rules: no mount without a robot, no robot without every mount.
  const std::string path = (dir_ / "s.yaml").string();
  std::ofstream(path) << "name: t\npatches:\n  - name: p\n    spec: " << kSpec
                      << "\n    mount: {link: forearm_link, xyz_m: [0, 0, 0], rpy_rad: [0, 0, 0]}\n";
  EXPECT_EQ(Message(path), path + ":5:5: 'patches[0].mount' needs a robot: the scene has no 'robot' section");
  std::ofstream(path) << "name: t\nrobot: {urdf: " << kUrdf << "}\npatches:\n  - name: p\n    spec: " << kSpec << "\n";
  EXPECT_EQ(Message(path),
            path + ":4:5: 'patches[0].mount' is missing: the scene names a robot, so every patch needs a mount");
}

TEST(RobotScene, ASceneWithoutARobotHasNoRobotPart) {
  const std::string forearm = RUFFINI_SOURCE_DIR "/config/scenes/forearm.yaml";
  try {
    (void)LoadRobotScene(forearm);
    FAIL() << "forearm.yaml names no robot";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()),
              forearm + ": 'robot' is missing (a mapping {urdf: <file>} expected): the scene names no robot");
  }
}

}  // namespace
}  // namespace ruffini::robot
