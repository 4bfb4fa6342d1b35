// Forward kinematics against Orocos KDL, two ways:
//  1. a KDL tree built here, by this test's own code, from urdfdom's reading of the same URDF (the way
//     kdl_parser does it, without kdl_parser): every link pose of srs7 and of a branching test robot with
//     prismatic, continuous and fixed joints, tilted origins and unnormalised axes;
//  2. a KDL chain built from the standard DH table (FACTS, "Kinematics") with KDL::Frame::DH, which checks
//     that srs7.urdf is the published arm and not only that we read it the way KDL does.
// 1000+ seeded random configurations each; positions to 1e-9 m, orientations to 1e-9 rad.
#include <gtest/gtest.h>
#include <kdl/chain.hpp>
#include <kdl/chainfksolverpos_recursive.hpp>
#include <kdl/frames.hpp>
#include <kdl/jntarray.hpp>
#include <kdl/tree.hpp>
#include <kdl/treefksolverpos_recursive.hpp>
#include <urdf_parser/urdf_parser.h>

#include <cmath>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <numbers>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "ruffini/robot/kinematics.h"
#include "ruffini/robot/model.h"

namespace ruffini::robot {
namespace {

constexpr const char* kSrs7 = RUFFINI_SOURCE_DIR "/config/robots/srs7.urdf";
constexpr double kTolM = 1e-9;
constexpr double kTolRad = 1e-9;
constexpr int kConfigurations = 1000;

std::string ReadFile(const char* path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

KDL::Frame ToKdl(const urdf::Pose& p) {
  return {KDL::Rotation::Quaternion(p.rotation.x, p.rotation.y, p.rotation.z, p.rotation.w),
          KDL::Vector(p.position.x, p.position.y, p.position.z)};
}

// Adds link's subtree under segment `parent` of the KDL tree; records each moving joint's name.
void AddChildren(const urdf::Link& link, KDL::Tree& tree) {
  for (const auto& child : link.child_links) {
    const urdf::Joint& j = *child->parent_joint;
    const KDL::Frame origin = ToKdl(j.parent_to_joint_origin_transform);
    KDL::Vector axis(j.axis.x, j.axis.y, j.axis.z);
    KDL::Joint joint(j.name, KDL::Joint::Fixed);
    if (j.type != urdf::Joint::FIXED) {
      axis.Normalize();
      const auto type = j.type == urdf::Joint::PRISMATIC ? KDL::Joint::TransAxis : KDL::Joint::RotAxis;
      joint = KDL::Joint(j.name, origin.p, origin.M * axis, type);
    }
    ASSERT_TRUE(tree.addSegment(KDL::Segment(child->name, joint, origin), link.name));
    AddChildren(*child, tree);
  }
}

struct KdlTree {
  KDL::Tree tree;
  std::map<std::string, unsigned> q_nr;  // moving joint name -> index in KDL's JntArray
};

KdlTree BuildKdlTree(const std::string& xml) {
  const auto urdf = urdf::parseURDF(xml);
  EXPECT_TRUE(urdf);
  KdlTree k{KDL::Tree(urdf->getRoot()->name), {}};
  AddChildren(*urdf->getRoot(), k.tree);
  for (const auto& [name, element] : k.tree.getSegments()) {
    const KDL::Segment& s = GetTreeElementSegment(element);
    if (s.getJoint().getType() != KDL::Joint::Fixed) k.q_nr[s.getJoint().getName()] = GetTreeElementQNr(element);
  }
  return k;
}

struct Errors {
  double position_m = 0.0;
  double rotation_rad = 0.0;
};

Errors Compare(const Eigen::Isometry3d& X, const KDL::Frame& F) {
  Eigen::Matrix3d R;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) R(r, c) = F.M(static_cast<unsigned>(r), static_cast<unsigned>(c));
  }
  const Eigen::Vector3d p(F.p.x(), F.p.y(), F.p.z());
  return {(X.translation() - p).norm(), Eigen::AngleAxisd(X.linear().transpose() * R).angle()};
}

// Random configurations: mostly inside the limits, some well outside them (FK does not clamp), and for
// unbounded joints anywhere in +-2 turns.
std::vector<std::vector<double>> RandomConfigurations(const Model& m, int n, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::vector<std::vector<double>> out;
  for (int c = 0; c < n; ++c) {
    std::vector<double> q(m.num_dof());
    const bool wide = c % 10 == 9;
    for (std::size_t i = 0; i < q.size(); ++i) {
      const JointLimits& l = m.dof_joint(i).limits;
      const double lo = std::isfinite(l.lower) ? l.lower : -4 * std::numbers::pi;
      const double hi = std::isfinite(l.upper) ? l.upper : 4 * std::numbers::pi;
      const double margin = wide ? 0.5 * (hi - lo) : 0.0;
      q[i] = std::uniform_real_distribution<double>(lo - margin, hi + margin)(rng);
    }
    out.push_back(std::move(q));
  }
  return out;
}

// Every link of the model against the KDL tree for n configurations; returns the worst errors.
Errors WorstAgainstTree(const std::string& xml, const Model& m, int n, unsigned seed) {
  const KdlTree k = BuildKdlTree(xml);
  EXPECT_EQ(k.q_nr.size(), m.num_dof());
  EXPECT_EQ(k.tree.getNrOfSegments() + 1, m.num_links());
  KDL::TreeFkSolverPos_recursive solver(k.tree);
  Data data;
  Errors worst;
  KDL::JntArray q_kdl(k.tree.getNrOfJoints());
  for (const auto& q : RandomConfigurations(m, n, seed)) {
    EXPECT_EQ(ForwardKinematics(m, q, data), FkStatus::kOk);
    for (std::size_t i = 0; i < q.size(); ++i) q_kdl(k.q_nr.at(m.dof_joint(i).name)) = q[i];
    for (std::size_t link = 1; link < m.num_links(); ++link) {
      KDL::Frame F;
      EXPECT_GE(solver.JntToCart(q_kdl, F, m.link(link).name), 0);
      const Errors e = Compare(data.X_BL[link], F);
      worst.position_m = std::max(worst.position_m, e.position_m);
      worst.rotation_rad = std::max(worst.rotation_rad, e.rotation_rad);
    }
  }
  return worst;
}

TEST(FkVersusKdl, Srs7EveryLinkAgainstKdlTree) {
  const std::string xml = ReadFile(kSrs7);
  const Model m = Model::FromUrdfFile(kSrs7);
  const Errors worst = WorstAgainstTree(xml, m, kConfigurations, 7);
  EXPECT_LT(worst.position_m, kTolM);
  EXPECT_LT(worst.rotation_rad, kTolRad);
  std::ostringstream report;
  report << std::scientific << std::setprecision(2) << "worst over " << kConfigurations
         << " configurations x 8 links: " << worst.position_m << " m, " << worst.rotation_rad << " rad";
  RecordProperty("worst", report.str());
  std::cout << report.str() << "\n";
}

// A tree (two branches off the base), every joint type we support, tilted origins, unnormalised axes.
constexpr const char* kBranchy = R"(<?xml version="1.0"?>
<robot name="branchy">
  <link name="base"/>
  <link name="torso"/> <link name="left"/> <link name="left_tip"/> <link name="right"/> <link name="right_slide"/>
  <link name="right_tip"/> <link name="camera"/>
  <joint name="waist" type="continuous"><parent link="base"/><child link="torso"/>
    <origin xyz="0.1 -0.2 0.3" rpy="0.1 0.2 0.3"/><axis xyz="0.3 -0.4 1.2"/></joint>
  <joint name="left_shoulder" type="revolute"><parent link="torso"/><child link="left"/>
    <origin xyz="0 0.25 0.5" rpy="-1.2 0.4 2.9"/><axis xyz="1 1 0"/>
    <limit lower="-2" upper="1.5" velocity="1" effort="5"/></joint>
  <joint name="left_wrist" type="revolute"><parent link="left"/><child link="left_tip"/>
    <origin xyz="0.4 0 -0.05" rpy="3.0 -1.5 0.7"/><axis xyz="0 -1 0"/>
    <limit lower="-3" upper="3" velocity="1" effort="5"/></joint>
  <joint name="right_shoulder" type="revolute"><parent link="torso"/><child link="right"/>
    <origin xyz="0 -0.25 0.5" rpy="1.2 -0.4 -2.9"/><axis xyz="0 0 -1"/>
    <limit lower="-1" upper="2" velocity="1" effort="5"/></joint>
  <joint name="right_extend" type="prismatic"><parent link="right"/><child link="right_slide"/>
    <origin xyz="0.2 0.1 0" rpy="0 1.5707963267948966 0"/><axis xyz="2 0 1"/>
    <limit lower="-0.1" upper="0.3" velocity="0.5" effort="50"/></joint>
  <joint name="right_tool" type="fixed"><parent link="right_slide"/><child link="right_tip"/>
    <origin xyz="0 0 0.12" rpy="0.5 0.5 0.5"/></joint>
  <joint name="camera_mount" type="fixed"><parent link="base"/><child link="camera"/>
    <origin xyz="1 2 3" rpy="-0.3 0.2 -0.1"/></joint>
</robot>
)";

TEST(FkVersusKdl, BranchingTreeAllJointTypes) {
  const Model m = Model::FromUrdfString(kBranchy, "branchy");
  ASSERT_EQ(m.num_links(), 8u);
  ASSERT_EQ(m.num_dof(), 5u);
  const Errors worst = WorstAgainstTree(kBranchy, m, kConfigurations, 11);
  EXPECT_LT(worst.position_m, kTolM);
  EXPECT_LT(worst.rotation_rad, kTolRad);
}

// srs7.urdf is the published arm: KDL's standard-DH frames from FACTS' table. Link i+1 of the URDF is DH
// frame i turned by q_{i+1}; tool0 is DH frame 7.
TEST(FkVersusKdl, Srs7IsTheDhArm) {
  constexpr double kD[7] = {0.340, 0, 0.400, 0, 0.400, 0, 0.126};
  constexpr double kAlphaDeg[7] = {-90, 90, -90, 90, -90, 90, 0};
  KDL::Chain chain;
  for (int i = 0; i < 7; ++i) {
    chain.addSegment(KDL::Segment(KDL::Joint(KDL::Joint::RotZ),
                                  KDL::Frame::DH(0.0, kAlphaDeg[i] * std::numbers::pi / 180.0, kD[i], 0.0)));
  }
  KDL::ChainFkSolverPos_recursive solver(chain);
  const Model m = Model::FromUrdfFile(kSrs7);
  const std::size_t tool0 = *m.FindLink("tool0");
  Data data;
  Errors worst;
  KDL::JntArray q_kdl(7);
  for (const auto& q : RandomConfigurations(m, kConfigurations, 3)) {
    ASSERT_EQ(ForwardKinematics(m, q, data), FkStatus::kOk);
    for (unsigned i = 0; i < 7; ++i) q_kdl(i) = q[i];
    for (int frame = 1; frame <= 7; ++frame) {
      KDL::Frame F;
      ASSERT_GE(solver.JntToCart(q_kdl, F, frame), 0);
      const Errors e = frame == 7 ? Compare(data.X_BL[tool0], F)
                                  : Compare(data.X_BL[static_cast<std::size_t>(frame) + 1],
                                            F * KDL::Frame(KDL::Rotation::RotZ(q[static_cast<std::size_t>(frame)])));
      worst.position_m = std::max(worst.position_m, e.position_m);
      worst.rotation_rad = std::max(worst.rotation_rad, e.rotation_rad);
    }
  }
  EXPECT_LT(worst.position_m, kTolM);
  EXPECT_LT(worst.rotation_rad, kTolRad);
}

// The comparison itself can fail: a 1e-6 rad nudge of one joint is seen.
TEST(FkVersusKdl, ComparisonDetectsSmallErrors) {
  const Model m = Model::FromUrdfFile(kSrs7);
  Data a, b;
  std::vector<double> q = {0.1, -0.5, 0.7, 1.1, -0.3, 0.9, 0.2};
  ASSERT_EQ(ForwardKinematics(m, q, a), FkStatus::kOk);
  q[1] += 1e-6;
  ASSERT_EQ(ForwardKinematics(m, q, b), FkStatus::kOk);
  const KDL::Frame F(KDL::Rotation(b.X_BL[8](0, 0), b.X_BL[8](0, 1), b.X_BL[8](0, 2), b.X_BL[8](1, 0),
                                   b.X_BL[8](1, 1), b.X_BL[8](1, 2), b.X_BL[8](2, 0), b.X_BL[8](2, 1),
                                   b.X_BL[8](2, 2)),
                     KDL::Vector(b.X_BL[8](0, 3), b.X_BL[8](1, 3), b.X_BL[8](2, 3)));
  const Errors e = Compare(a.X_BL[8], F);
  EXPECT_GT(e.position_m, 1e-7);
  EXPECT_NEAR(e.rotation_rad, 1e-6, 1e-9);
}

}  // namespace
}  // namespace ruffini::robot
