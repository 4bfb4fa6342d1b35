// Loading srs7.urdf and refusing bad robot descriptions with messages that name the file and the fault.
#include <console_bridge/console.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <string>
#include <vector>

#include "ruffini/error.h"
#include "ruffini/robot/kinematics.h"
#include "ruffini/robot/model.h"

namespace ruffini::robot {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;

constexpr const char* kSrs7 = RUFFINI_SOURCE_DIR "/config/robots/srs7.urdf";
constexpr double kDeg = std::numbers::pi / 180.0;

// The message of the InputError that f throws ("" and a test failure if it throws none).
template <typename F>
std::string ErrorOf(F&& f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  ADD_FAILURE() << "no InputError";
  return "";
}

std::string Parse(const std::string& xml) {
  return ErrorOf([&] { (void)Model::FromUrdfString(xml, "test.urdf"); });
}

std::string Robot(const std::string& body) { return "<?xml version=\"1.0\"?>\n<robot name=\"r\">\n" + body + "</robot>\n"; }

constexpr const char* kTwoLinks = R"(<link name="a"/><link name="b"/>)";

TEST(Model, LoadsSrs7) {
  const Model m = Model::FromUrdfFile(kSrs7);
  EXPECT_EQ(m.name(), "srs7");
  EXPECT_EQ(m.source(), kSrs7);
  ASSERT_EQ(m.num_links(), 9u);
  ASSERT_EQ(m.num_dof(), 7u);
  const std::vector<std::string> links = {"base_link",  "shoulder_yaw_link", "shoulder_pitch_link",
                                          "upper_arm_link", "elbow_link",   "forearm_link",
                                          "wrist_link", "flange_link",       "tool0"};
  for (std::size_t k = 0; k < links.size(); ++k) {
    EXPECT_EQ(m.link(k).name, links[k]);
    EXPECT_EQ(m.FindLink(links[k]), k);
    EXPECT_EQ(m.link(k).parent, k == 0 ? kNoIndex : k - 1);
  }
  EXPECT_EQ(m.FindLink("nope"), std::nullopt);
  const double limit_deg[] = {170, 120, 170, 120, 170, 120, 175};
  const double velocity_deg_s[] = {98, 98, 100, 130, 140, 180, 180};
  const double effort_nm[] = {176, 176, 110, 110, 110, 40, 40};
  for (std::size_t i = 0; i < 7; ++i) {
    const Joint& j = m.dof_joint(i);
    EXPECT_EQ(j.name, "joint_" + std::to_string(i + 1));
    EXPECT_EQ(j.type, JointType::kRevolute);
    EXPECT_EQ(j.q_index, i);
    EXPECT_EQ(j.child_link, i + 1);
    EXPECT_NEAR(j.limits.upper, limit_deg[i] * kDeg, 1e-15);
    EXPECT_NEAR(j.limits.lower, -limit_deg[i] * kDeg, 1e-15);
    EXPECT_NEAR(j.limits.velocity, velocity_deg_s[i] * kDeg, 1e-15);
    EXPECT_EQ(j.limits.effort, effort_nm[i]);
    EXPECT_EQ(m.FindJoint(j.name), i + 1);
  }
  EXPECT_EQ(m.joint(8).type, JointType::kFixed);
  EXPECT_EQ(m.joint(8).q_index, kNoIndex);
}

// The frames docs/robot.md and mount.h promise: at q = 0 the arm stands up along base +z.
TEST(Model, Srs7FramesAtZero) {
  const Model m = Model::FromUrdfFile(kSrs7);
  Data d;
  const std::vector<double> q(7, 0.0);
  ASSERT_EQ(ForwardKinematics(m, q, d), FkStatus::kOk);
  auto at = [&](const char* link) { return d.X_BL[*m.FindLink(link)]; };
  EXPECT_TRUE(at("upper_arm_link").translation().isApprox(Eigen::Vector3d(0, 0, 0.340), 1e-15));
  EXPECT_TRUE(at("upper_arm_link").linear().isIdentity(1e-15));
  EXPECT_TRUE(at("forearm_link").translation().isApprox(Eigen::Vector3d(0, 0, 0.740), 1e-15));
  EXPECT_TRUE(at("forearm_link").linear().isIdentity(1e-15));
  EXPECT_TRUE(at("wrist_link").translation().isApprox(Eigen::Vector3d(0, 0, 1.140), 1e-15));
  EXPECT_TRUE(at("tool0").translation().isApprox(Eigen::Vector3d(0, 0, 1.266), 1e-15));
  // The elbow bends the forearm: +90 deg on J4 swings the wrist off the vertical by 0.400 m.
  std::vector<double> bent(7, 0.0);
  bent[3] = 90 * kDeg;
  ASSERT_EQ(ForwardKinematics(m, bent, d), FkStatus::kOk);
  const Eigen::Vector3d wrist = at("wrist_link").translation();
  EXPECT_NEAR(wrist.z(), 0.740, 1e-12);
  EXPECT_NEAR(std::hypot(wrist.x(), wrist.y()), 0.400, 1e-12);
}

TEST(ModelErrors, MissingFile) {
  const std::string path = RUFFINI_SOURCE_DIR "/config/robots/no-such-robot.urdf";
  EXPECT_EQ(ErrorOf([&] { (void)Model::FromUrdfFile(path); }),
            path + ": cannot open the robot description (URDF) file");
}

TEST(ModelErrors, EmptyFile) {
  const auto path = std::filesystem::path(::testing::TempDir()) / "robot_empty.urdf";
  { std::ofstream(path) << ""; }
  EXPECT_EQ(ErrorOf([&] { (void)Model::FromUrdfFile(path); }), path.string() + ": the URDF file is empty");
  std::filesystem::remove(path);
}

TEST(ModelErrors, MalformedXml) {
  // TinyXML's words, passed on by urdfdom (Debian's urdfdom 3.0.1).
  EXPECT_EQ(Parse("<robot name=\"r\"><link name=\"a\"></robot>"), "test.urdf: not a valid URDF: Error reading end tag.");
  EXPECT_EQ(Parse("not xml at all"), "test.urdf: not a valid URDF: Error document empty.");
}

TEST(ModelErrors, NotARobot) {
  EXPECT_EQ(Parse("<?xml version=\"1.0\"?><model/>"),
            "test.urdf: not a valid URDF: Could not find the 'robot' element in the xml file");
}

TEST(ModelErrors, UnknownLink) {
  const std::string e = Parse(Robot(std::string(kTwoLinks) + R"(
    <joint name="j" type="fixed"><parent link="a"/><child link="nope"/></joint>)"));
  EXPECT_EQ(e, "test.urdf: not a valid URDF: Failed to build tree: child link [nope] of joint [j] not found");
}

TEST(ModelErrors, TwoRoots) {
  EXPECT_EQ(Parse(Robot(kTwoLinks)),
            "test.urdf: not a valid URDF: Failed to find root link: Two root links found: [a] and [b]");
}

TEST(ModelErrors, RevoluteWithoutLimit) {
  const std::string e = Parse(Robot(std::string(kTwoLinks) + R"(
    <joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/></joint>)"));
  EXPECT_THAT(e, AllOf(HasSubstr("test.urdf: not a valid URDF: "),
                       HasSubstr("Joint [j] is of type REVOLUTE but it does not specify limits")));
}

TEST(ModelErrors, LowerAboveUpper) {
  EXPECT_EQ(Parse(Robot(std::string(kTwoLinks) + R"(
    <joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
      <limit lower="1" upper="-1" velocity="1" effort="1"/></joint>)")),
            "test.urdf: joint 'j': <limit> lower (1) and upper (-1) must be finite with lower <= upper");
}

TEST(ModelErrors, ZeroAxis) {
  const std::string e = Parse(Robot(std::string(kTwoLinks) + R"(
    <joint name="j" type="continuous"><parent link="a"/><child link="b"/><axis xyz="0 0 0"/></joint>)"));
  EXPECT_EQ(e, "test.urdf: joint 'j': <axis> has zero length");
}

// urdfdom refuses a non-number; several of its messages are joined.
TEST(ModelErrors, BadNumber) {
  EXPECT_THAT(Parse(Robot(std::string(kTwoLinks) + R"(
    <joint name="j" type="continuous"><parent link="a"/><child link="b"/><origin xyz="nan 0 0"/></joint>)")),
              AllOf(HasSubstr("test.urdf: not a valid URDF: Unable to parse component [nan] to a double"),
                    HasSubstr("; Malformed parent origin element for joint [j]")));
}

TEST(ModelErrors, FloatingJoint) {
  EXPECT_EQ(Parse(Robot(std::string(kTwoLinks) + R"(
    <joint name="free" type="floating"><parent link="a"/><child link="b"/></joint>)")),
            "test.urdf: joint 'free': type 'floating' is not supported (fixed, revolute, continuous, prismatic are)");
}

TEST(ModelErrors, MimicJoint) {
  EXPECT_EQ(Parse(Robot(R"(<link name="a"/><link name="b"/><link name="c"/>
    <joint name="j1" type="continuous"><parent link="a"/><child link="b"/></joint>
    <joint name="j2" type="continuous"><parent link="b"/><child link="c"/><mimic joint="j1"/></joint>)")),
            "test.urdf: joint 'j2': mimic joints are not supported");
}

TEST(ModelErrors, TooManyLinks) {
  std::string body = "<link name=\"l0\"/>";
  for (std::size_t i = 1; i <= kMaxLinks; ++i) {
    body += "<link name=\"l" + std::to_string(i) + "\"/><joint name=\"j" + std::to_string(i) +
            "\" type=\"fixed\"><parent link=\"l" + std::to_string(i - 1) + "\"/><child link=\"l" +
            std::to_string(i) + "\"/></joint>";
  }
  EXPECT_EQ(Parse(Robot(body)), "test.urdf: has 33 links; at most 32 are supported");
}

TEST(ModelErrors, TooManyDof) {
  std::string body = "<link name=\"l0\"/>";
  for (std::size_t i = 1; i <= kMaxDof + 1; ++i) {
    body += "<link name=\"l" + std::to_string(i) + "\"/><joint name=\"j" + std::to_string(100 + i) +
            "\" type=\"continuous\"><parent link=\"l" + std::to_string(i - 1) + "\"/><child link=\"l" +
            std::to_string(i) + "\"/></joint>";
  }
  EXPECT_EQ(Parse(Robot(body)), "test.urdf: more than 16 moving joints are not supported");
}

// urdfdom's console output is captured during a parse and the previous handler is back afterwards.
TEST(ModelErrors, RestoresConsoleHandler) {
  console_bridge::OutputHandler* before = console_bridge::getOutputHandler();
  (void)Parse("not xml at all");
  EXPECT_EQ(console_bridge::getOutputHandler(), before);
}

TEST(Kinematics, RefusesBadJointStates) {
  const Model m = Model::FromUrdfFile(kSrs7);
  Data d;
  std::vector<double> q = {0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7};
  ASSERT_EQ(ForwardKinematics(m, q, d), FkStatus::kOk);
  const Data good = d;
  auto unchanged = [&] {
    for (std::size_t k = 0; k < m.num_links(); ++k) {
      if (!d.X_BL[k].isApprox(good.X_BL[k], 0.0)) return false;
    }
    return true;
  };
  const std::vector<double> six(6, 0.0), eight(8, 0.0);
  EXPECT_EQ(ForwardKinematics(m, six, d), FkStatus::kWrongJointCount);
  EXPECT_EQ(ForwardKinematics(m, eight, d), FkStatus::kWrongJointCount);
  EXPECT_EQ(ForwardKinematics(m, {}, d), FkStatus::kWrongJointCount);
  EXPECT_TRUE(unchanged());
  for (const double bad : {std::nan(""), std::numeric_limits<double>::infinity(),
                           -std::numeric_limits<double>::infinity()}) {
    auto q_bad = q;
    q_bad[4] = bad;
    EXPECT_EQ(ForwardKinematics(m, q_bad, d), FkStatus::kNotFinite);
    EXPECT_TRUE(unchanged());
  }
  auto q_far = q;
  q_far[0] = 2 * kMaxAbsJointValue;
  EXPECT_EQ(ForwardKinematics(m, q_far, d), FkStatus::kOutOfRange);
  EXPECT_TRUE(unchanged());
  EXPECT_STREQ(ToString(FkStatus::kNotFinite), "a joint value is not finite");
}

TEST(Kinematics, WithinLimits) {
  const Model m = Model::FromUrdfFile(kSrs7);
  std::vector<double> q(7, 0.0);
  EXPECT_TRUE(WithinLimits(m, q));
  q[1] = 120 * kDeg;
  EXPECT_TRUE(WithinLimits(m, q));
  q[1] = 121 * kDeg;
  EXPECT_FALSE(WithinLimits(m, q));
  EXPECT_TRUE(WithinLimits(m, q, 2 * kDeg));
  q[1] = std::nan("");
  EXPECT_FALSE(WithinLimits(m, q, 1e9));
  EXPECT_FALSE(WithinLimits(m, std::vector<double>(6, 0.0)));
}

// Continuous joints have no position limits; a prismatic joint moves along its axis.
TEST(Kinematics, ContinuousAndPrismatic) {
  const Model m = Model::FromUrdfString(Robot(R"(<link name="a"/><link name="b"/><link name="c"/>
    <joint name="spin" type="continuous"><parent link="a"/><child link="b"/><axis xyz="0 0 2"/></joint>
    <joint name="slide" type="prismatic"><parent link="b"/><child link="c"/><origin xyz="1 0 0"/>
      <axis xyz="1 0 0"/><limit lower="0" upper="0.5" velocity="1" effort="10"/></joint>)"),
                                        "inline");
  ASSERT_EQ(m.num_dof(), 2u);
  EXPECT_EQ(m.dof_joint(0).limits.upper, std::numeric_limits<double>::infinity());
  EXPECT_TRUE(m.dof_joint(0).axis_J.isApprox(Eigen::Vector3d::UnitZ()));  // normalised
  Data d;
  const std::vector<double> q = {std::numbers::pi / 2, 0.25};
  ASSERT_EQ(ForwardKinematics(m, q, d), FkStatus::kOk);
  EXPECT_TRUE(d.X_BL[2].translation().isApprox(Eigen::Vector3d(0, 1.25, 0), 1e-15));
  EXPECT_TRUE(WithinLimits(m, std::vector<double>{100.0, 0.5}));
}

}  // namespace
}  // namespace ruffini::robot
