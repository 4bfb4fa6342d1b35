// The lift: hand-computed points, normals and covariances on a simple mount; the unlocated representation;
// the covariance floors and caps; every bad input refused with its reason and nothing written.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <cmath>
#include <limits>
#include <random>

#include "fixture.h"
#include "ruffini/error.h"
#include "ruffini/fusion/lift.h"

namespace ruffini::fusion {
namespace {

using testing::kDeg;

// The fore patch: elbow edge 60 mm up the link, radius 40 mm; the link sits at (1, 2, 3) turned 90 deg about z.
struct ForeMount {
  FusionPatch patch = testing::Patch("fore", "fore", 0.060, 40.0);
  Eigen::Isometry3d X_BL = Eigen::Translation3d(1, 2, 3) * Eigen::AngleAxisd(90 * kDeg, Eigen::Vector3d::UnitZ());
  LiftConfig config;
};

void ExpectNear(const Eigen::Vector3d& a, const Eigen::Vector3d& b, double tol) {
  EXPECT_LT((a - b).cwiseAbs().maxCoeff(), tol) << a.transpose() << " vs " << b.transpose();
}

TEST(Lift, PointNormalAndCovarianceByHand) {
  ForeMount s;
  // Y = 50, R = 0: p_P = (0, 0.05, 0.04); Rx(90): p_L = (0, -0.04, 0.11); Rz(90) then + (1, 2, 3): (1.04, 2, 3.11).
  // Tangents: +Y -> L +z -> B +z; +arc at R = 0 is P +x -> L +x -> B +y; normal P +z -> L -y -> B +x.
  SurfaceContact c = testing::Located(50, 0, 2.5);
  c.cov_yy_mm2 = 4;
  c.cov_ss_mm2 = 9;
  c.cov_ys_mm2 = 2;
  c.force_sd_n = 0.1;
  LiftedContact out;
  ASSERT_EQ(Lift(s.patch, s.X_BL, c, s.config, out), Rejection::kNone);
  ExpectNear(out.p_BC_m, {1.04, 2.0, 3.11}, 1e-12);
  ExpectNear(out.n_B, {1, 0, 0}, 1e-12);
  Eigen::Matrix3d expected = Eigen::Matrix3d::Zero();
  expected(0, 0) = 0.25e-6;  // (0.5 mm)^2 along the normal
  expected(1, 1) = 9e-6;     // arc
  expected(2, 2) = 4e-6;     // Y
  expected(1, 2) = expected(2, 1) = 2e-6;
  EXPECT_LT((out.cov_p_BC_m2 - expected).cwiseAbs().maxCoeff(), 1e-15) << out.cov_p_BC_m2;
  EXPECT_DOUBLE_EQ(out.force_n, 2.5);
  EXPECT_NEAR(out.force_var_n2, 0.01, 1e-15);
  EXPECT_TRUE(out.located);
  EXPECT_TRUE(out.uncertainty_calibrated);

  // R = 90: p_P = (0.04, 0.05, 0) -> p_L = (0.04, 0, 0.11) -> p_B = (1, 2.04, 3.11); normal B +y; arc B -x.
  c.r_deg = 90;
  c.cov_ys_mm2 = 0;
  ASSERT_EQ(Lift(s.patch, s.X_BL, c, s.config, out), Rejection::kNone);
  ExpectNear(out.p_BC_m, {1.0, 2.04, 3.11}, 1e-12);
  ExpectNear(out.n_B, {0, 1, 0}, 1e-12);
  expected.setZero();
  expected(0, 0) = 9e-6;
  expected(1, 1) = 0.25e-6;
  expected(2, 2) = 4e-6;
  EXPECT_LT((out.cov_p_BC_m2 - expected).cwiseAbs().maxCoeff(), 1e-15) << out.cov_p_BC_m2;
}

TEST(Lift, AgreesWithPatchToLinkEverywhere) {
  ForeMount s;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> y(0, 150), r(0, 145);
  for (int i = 0; i < 500; ++i) {
    const SurfaceContact c = testing::Located(y(rng), r(rng));
    LiftedContact out;
    ASSERT_EQ(Lift(s.patch, s.X_BL, c, s.config, out), Rejection::kNone);
    const auto in_link = robot::PatchToLink(s.patch.mount, {c.y_mm, c.r_deg});
    ExpectNear(out.p_BC_m, s.X_BL * in_link.p_LS_m, 1e-12);
    ExpectNear(out.n_B, s.X_BL.linear() * in_link.n_L, 1e-12);
    // The covariance's smallest eigenvector is the normal; the surface part is isotropic (2 mm sd).
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(out.cov_p_BC_m2);
    EXPECT_NEAR(eig.eigenvalues()[0], 0.25e-6, 1e-15);
    EXPECT_NEAR(std::abs(eig.eigenvectors().col(0).dot(out.n_B)), 1.0, 1e-9);
    EXPECT_NEAR(eig.eigenvalues()[1], 4e-6, 1e-15);
    EXPECT_NEAR(eig.eigenvalues()[2], 4e-6, 1e-15);
  }
}

TEST(Lift, UncalibratedZeroAndHugeCovariances) {
  ForeMount s;
  LiftedContact out;
  // Uncalibrated: 12.5 mm sd on both surface axes, whatever the fields say; no force variance.
  SurfaceContact c = testing::Located(50, 0);
  c.uncertainty_calibrated = false;
  c.cov_yy_mm2 = c.cov_ss_mm2 = 0;
  c.force_sd_n = 0;
  ASSERT_EQ(Lift(s.patch, s.X_BL, c, s.config, out), Rejection::kNone);
  EXPECT_NEAR(out.cov_p_BC_m2(1, 1), 156.25e-6, 1e-15);
  EXPECT_NEAR(out.cov_p_BC_m2(2, 2), 156.25e-6, 1e-15);
  EXPECT_EQ(out.force_var_n2, 0.0);
  EXPECT_FALSE(out.uncertainty_calibrated);
  // Calibrated but zero (or singular): floored at (0.5 mm)^2.
  c = testing::Located(50, 0);
  c.cov_yy_mm2 = 0;
  c.cov_ss_mm2 = 0;
  ASSERT_EQ(Lift(s.patch, s.X_BL, c, s.config, out), Rejection::kNone);
  EXPECT_NEAR(out.cov_p_BC_m2(1, 1), 0.25e-6, 1e-15);
  EXPECT_NEAR(out.cov_p_BC_m2(2, 2), 0.25e-6, 1e-15);
  c.cov_yy_mm2 = 4;
  c.cov_ss_mm2 = 9;
  c.cov_ys_mm2 = 6;  // exactly singular (correlation 1)
  ASSERT_EQ(Lift(s.patch, s.X_BL, c, s.config, out), Rejection::kNone);
  EXPECT_GT(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(out.cov_p_BC_m2).eigenvalues().minCoeff(), 0.2e-6);
  // Huge: capped at (1000 mm)^2 = 1 m^2.
  c.cov_yy_mm2 = 1e30;
  c.cov_ss_mm2 = 1e30;
  c.cov_ys_mm2 = 0;
  ASSERT_EQ(Lift(s.patch, s.X_BL, c, s.config, out), Rejection::kNone);
  EXPECT_NEAR(out.cov_p_BC_m2(1, 1), 1.0, 1e-12);
  EXPECT_NEAR(out.cov_p_BC_m2(2, 2), 1.0, 1e-12);
  EXPECT_TRUE(out.cov_p_BC_m2.allFinite());
}

TEST(Lift, UnlocatedIsThePatchCentreWithACoveringCovariance) {
  ForeMount s;
  LiftedContact out;
  SurfaceContact c = testing::ForceOnly(3.0);
  c.y_mm = 1e3;  // ignored (not located), so not "outside the patch"
  ASSERT_EQ(Lift(s.patch, s.X_BL, c, s.config, out), Rejection::kNone);
  EXPECT_FALSE(out.located);
  const auto centre = robot::PatchToLink(s.patch.mount, {75.0, 72.5});
  ExpectNear(out.p_BC_m, s.X_BL * centre.p_LS_m, 1e-12);
  ExpectNear(out.n_B, s.X_BL.linear() * centre.n_L, 1e-12);

  // The covering moment is the second moment about the centre of points uniform over the curved patch:
  // check it against 400k samples.
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> y(0, 150), r(0, 145);
  Eigen::Matrix3d m = Eigen::Matrix3d::Zero();
  const int n = 400000;
  const Eigen::Vector3d c_L = centre.p_LS_m;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d d = robot::PatchToLink(s.patch.mount, {y(rng), r(rng)}).p_LS_m - c_L;
    m += d * d.transpose();
  }
  m /= n;
  const Eigen::Matrix3d R_LP = s.patch.mount.X_LP.linear();
  const Eigen::Matrix3d formula = R_LP * PatchCoveringMoment_P(s.patch) * R_LP.transpose();
  EXPECT_LT((m - formula).cwiseAbs().maxCoeff(), 0.01 * formula.cwiseAbs().maxCoeff()) << m << "\n\n" << formula;
  // Along Y: 150^2 / 12 mm^2; plus the normal allowance along n in the lifted one.
  EXPECT_NEAR(formula.trace(), m.trace(), 0.005 * m.trace());
  const Eigen::Matrix3d R_BL = s.X_BL.linear();
  const Eigen::Matrix3d lifted = R_BL * (formula + 0.25e-6 * centre.n_L * centre.n_L.transpose()) * R_BL.transpose();
  EXPECT_LT((out.cov_p_BC_m2 - lifted).cwiseAbs().maxCoeff(), 1e-15);
}

TEST(Lift, BadInputsAreRefusedWithTheirReasonAndWriteNothing) {
  ForeMount s;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  LiftedContact sentinel;
  sentinel.force_n = -42;
  auto refuse = [&](SurfaceContact c, Rejection why, const Eigen::Isometry3d* pose = nullptr) {
    LiftedContact out = sentinel;
    EXPECT_EQ(Lift(s.patch, pose ? *pose : s.X_BL, c, s.config, out), why) << ToString(why);
    EXPECT_EQ(out.force_n, -42);
  };
  const SurfaceContact good = testing::Located(50, 30);
  for (double bad : {nan, inf, -inf}) {
    auto c = good;
    c.force_n = bad;
    refuse(c, Rejection::kNotFinite);
    c = good;
    c.force_sd_n = bad;
    refuse(c, Rejection::kNotFinite);
    c = good;
    c.y_mm = bad;
    refuse(c, Rejection::kNotFinite);
    c = good;
    c.r_deg = bad;
    refuse(c, Rejection::kNotFinite);
    c = good;
    c.cov_yy_mm2 = bad;
    refuse(c, Rejection::kNotFinite);
    c = good;
    c.cov_ys_mm2 = bad;
    refuse(c, Rejection::kNotFinite);
    c = good;
    c.cov_ss_mm2 = bad;
    refuse(c, Rejection::kNotFinite);
    c = testing::ForceOnly(1.0);
    c.r_deg = bad;  // even in a field an unlocated contact ignores: a NaN means a broken decoder
    refuse(c, Rejection::kNotFinite);
  }
  auto c = good;
  c.force_n = -0.1;
  refuse(c, Rejection::kNegativeForce);
  c = good;
  c.force_sd_n = -0.1;
  refuse(c, Rejection::kBadUncertainty);
  c = good;
  c.cov_yy_mm2 = -1;
  refuse(c, Rejection::kBadUncertainty);
  c = good;
  c.cov_ys_mm2 = 4.1;  // > sqrt(4 x 4)
  refuse(c, Rejection::kBadUncertainty);
  c = good;
  c.y_mm = 160.5;
  refuse(c, Rejection::kOutsidePatch);
  c = good;
  c.r_deg = -10.5;
  refuse(c, Rejection::kOutsidePatch);
  c = good;
  c.y_mm = 1e300;
  refuse(c, Rejection::kOutsidePatch);
  Eigen::Isometry3d pose = s.X_BL;
  pose.translation().x() = nan;
  refuse(good, Rejection::kBadPose, &pose);
  pose = s.X_BL;
  pose.linear()(0, 1) = inf;
  refuse(good, Rejection::kBadPose, &pose);

  // Uncalibrated contacts' zero sd and covariance are not checked (they mean nothing), but a negative
  // force still is.
  c = good;
  c.uncertainty_calibrated = false;
  c.cov_yy_mm2 = -5;
  LiftedContact out;
  EXPECT_EQ(Lift(s.patch, s.X_BL, c, s.config, out), Rejection::kNone);
  EXPECT_TRUE(out.cov_p_BC_m2.allFinite());
}

TEST(Lift, ConfigAndPatchValidationNameTheField) {
  LiftConfig c;
  c.normal_sd_mm = 0;
  try {
    ValidateLiftConfig(c, "fusion.lift");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "fusion.lift.normal_sd_mm (0) must lie in (0, 100]");
  }
  c = {};
  c.uncalibrated_sd_mm = 0.1;
  EXPECT_THROW(ValidateLiftConfig(c, "x"), InputError);
  FusionPatch p = testing::Patch("a", "fore", 0);
  p.extent_r_deg = 400;
  try {
    ValidatePatchShape(p, "fusion.patches[0]");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "fusion.patches[0].extent_r_deg (400) must lie in (0, 360]");
  }
}

}  // namespace
}  // namespace ruffini::fusion
