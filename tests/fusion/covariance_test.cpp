// Covariance intersection and the gate: properties on random pairs, the exact cases (identical, nested,
// zero, huge, singular), refusals, and a Monte-Carlo check that the fused covariance is consistent.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>

#include "ruffini/fusion/covariance.h"

namespace ruffini::fusion {
namespace {

// A random SPD matrix with eigenvalues (sd) between lo and hi metres.
Eigen::Matrix3d RandomCov(std::mt19937& rng, double lo_sd, double hi_sd) {
  std::normal_distribution<double> g;
  std::uniform_real_distribution<double> u(std::log(lo_sd), std::log(hi_sd));
  Eigen::Matrix3d M;
  for (int i = 0; i < 9; ++i) M(i) = g(rng);
  const Eigen::Matrix3d Q = Eigen::HouseholderQR<Eigen::Matrix3d>(M).householderQ();
  Eigen::Vector3d l;
  for (int i = 0; i < 3; ++i) l[i] = std::pow(std::exp(u(rng)), 2);
  return Q * l.asDiagonal() * Q.transpose();
}

Eigen::Vector3d RandomVec(std::mt19937& rng, double sd) {
  std::normal_distribution<double> g(0, sd);
  return {g(rng), g(rng), g(rng)};
}

double MinEig(const Eigen::Matrix3d& P) { return Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(P).eigenvalues()[0]; }

double TraceAt(const Estimate& a, const Estimate& b, double w) {
  return (w * a.P.inverse() + (1 - w) * b.P.inverse()).inverse().trace();
}

TEST(CovarianceIntersection, PropertiesOnRandomPairs) {
  std::mt19937 rng(1);
  int interior = 0;
  for (int i = 0; i < 2000; ++i) {
    const Estimate a{RandomVec(rng, 0.01), RandomCov(rng, 1e-4, 1e-2)};
    const Estimate b{RandomVec(rng, 0.01), RandomCov(rng, 1e-4, 1e-2)};
    Estimate f;
    double w = -1;
    ASSERT_EQ(CovarianceIntersection(a, b, f, &w), CovarianceStatus::kOk);
    ASSERT_TRUE(f.x.allFinite() && f.P.allFinite());
    EXPECT_GE(w, 0.0);
    EXPECT_LE(w, 1.0);
    EXPECT_EQ(f.P, f.P.transpose());
    EXPECT_GT(MinEig(f.P), 0.0);                                                   // PD
    EXPECT_LE(f.P.trace(), std::min(a.P.trace(), b.P.trace()) * (1 + 1e-12));  // no worse than either
    // The minimum: no w on a fine grid does better (beyond the search's tolerance).
    double best = std::numeric_limits<double>::infinity();
    for (int k = 0; k <= 1000; ++k) best = std::min(best, TraceAt(a, b, k / 1000.0));
    EXPECT_LE(f.P.trace(), best * (1 + 1e-9));
    if (w > 0 && w < 1) {
      ++interior;
      // The formula, with that w.
      const Eigen::Matrix3d info = w * a.P.inverse() + (1 - w) * b.P.inverse();
      const Eigen::Vector3d x = info.inverse() * (w * a.P.inverse() * a.x + (1 - w) * b.P.inverse() * b.x);
      EXPECT_LT((x - f.x).norm(), 1e-9);
      EXPECT_LT((info.inverse() - f.P).cwiseAbs().maxCoeff(), 1e-12);
    }
  }
  EXPECT_GT(interior, 1000);  // the search ran, not just the ends
}

TEST(CovarianceIntersection, IdenticalEstimatesGiveThemselves) {
  std::mt19937 rng(2);
  for (int i = 0; i < 200; ++i) {
    Estimate a{RandomVec(rng, 1.0), RandomCov(rng, 1e-5, 1e-1)};
    a.P = 0.5 * (a.P + a.P.transpose());
    Estimate f;
    ASSERT_EQ(CovarianceIntersection(a, a, f), CovarianceStatus::kOk);
    EXPECT_LT((f.x - a.x).norm(), 1e-15);
    EXPECT_LT((f.P - a.P).cwiseAbs().maxCoeff(), 1e-15 + 1e-12 * a.P.cwiseAbs().maxCoeff());
    // Nearly identical (a copy through a rounding): the same to rounding, whatever w the search picks.
    Estimate b = a;
    b.P = a.P * (1 + 1e-15);
    b.x = a.x * (1 + 1e-15);
    ASSERT_EQ(CovarianceIntersection(a, b, f), CovarianceStatus::kOk);
    // (condition numbers up to 1e8 here: relative rounding up to about 1e-8 in P)
    EXPECT_LT((f.x - a.x).norm(), 1e-14);
    EXPECT_LT((f.P - a.P).cwiseAbs().maxCoeff(), 1e-7 * a.P.cwiseAbs().maxCoeff());
  }
}

TEST(CovarianceIntersection, NestedEstimatesPutWAtTheEndsExactly) {
  const Estimate a{{0.1, 0.2, 0.3}, 1e-6 * Eigen::Matrix3d::Identity()};
  const Estimate b{{0.11, 0.19, 0.3}, Eigen::Vector3d(4e-6, 9e-6, 2e-6).asDiagonal()};
  Estimate f;
  double w = -1;
  ASSERT_EQ(CovarianceIntersection(a, b, f, &w), CovarianceStatus::kOk);
  EXPECT_EQ(w, 1.0);
  EXPECT_EQ(f.x, a.x);
  EXPECT_EQ(f.P, a.P);
  ASSERT_EQ(CovarianceIntersection(b, a, f, &w), CovarianceStatus::kOk);
  EXPECT_EQ(w, 0.0);
  EXPECT_EQ(f.x, a.x);
  EXPECT_EQ(f.P, a.P);
}

// Equal covariances, different means: tr P(w) is the same for every w; w = 1/2 treats both alike (the mean).
TEST(CovarianceIntersection, EqualCovariancesGiveTheMidpoint) {
  std::mt19937 rng(6);
  const Estimate a{{0.1, 0.2, 0.3}, RandomCov(rng, 1e-3, 1e-2)};
  const Estimate b{{0.104, 0.2, 0.29}, a.P};
  Estimate f;
  double w = -1;
  ASSERT_EQ(CovarianceIntersection(a, b, f, &w), CovarianceStatus::kOk);
  EXPECT_EQ(w, 0.5);
  EXPECT_LT((f.x - 0.5 * (a.x + b.x)).norm(), 1e-15);
  Eigen::Matrix3d Pa = a.P;
  ASSERT_EQ(Regularize(Pa), CovarianceStatus::kOk);
  EXPECT_LT((f.P - Pa).cwiseAbs().maxCoeff(), 1e-15);
}

TEST(CovarianceIntersection, ZeroHugeSingularAndNearSingular) {
  const Estimate normal{{0.5, 0.5, 0.5}, 1e-6 * Eigen::Matrix3d::Identity()};
  Estimate f;
  double w = -1;
  // Zero: floored to (10 um)^2; that estimate wins, exactly.
  const Estimate zero{{0.5, 0.501, 0.5}, Eigen::Matrix3d::Zero()};
  ASSERT_EQ(CovarianceIntersection(normal, zero, f, &w), CovarianceStatus::kOk);
  EXPECT_EQ(w, 0.0);
  EXPECT_EQ(f.x, zero.x);
  EXPECT_NEAR(f.P(0, 0), kMinVariance_m2, 1e-20);
  // Huge: capped at 1 m^2; the other wins, exactly.
  const Estimate huge{{9.0, -9.0, 9.0}, 1e30 * Eigen::Matrix3d::Identity()};
  ASSERT_EQ(CovarianceIntersection(huge, normal, f, &w), CovarianceStatus::kOk);
  EXPECT_EQ(w, 0.0);
  EXPECT_EQ(f.x, normal.x);
  EXPECT_EQ(f.P, normal.P);
  // Singular in different directions: a knows z exactly, b knows x exactly. The fusion knows both well.
  const Estimate sa{{0.0, 0.0, 0.1}, Eigen::Vector3d(1e-4, 1e-4, 0.0).asDiagonal()};
  const Estimate sb{{0.1, 0.0, 0.0}, Eigen::Vector3d(0.0, 1e-4, 1e-4).asDiagonal()};
  ASSERT_EQ(CovarianceIntersection(sa, sb, f, &w), CovarianceStatus::kOk);
  EXPECT_GT(w, 0.0);
  EXPECT_LT(w, 1.0);
  EXPECT_TRUE(f.x.allFinite());
  EXPECT_GT(MinEig(f.P), 0.0);
  EXPECT_LT(f.P(0, 0), 1e-8);
  EXPECT_LT(f.P(2, 2), 1e-8);
  EXPECT_NEAR(f.x.x(), 0.1, 1e-3);  // x from b
  EXPECT_NEAR(f.x.z(), 0.1, 1e-3);  // z from a
  // Near-singular (eigenvalues down to 1e-30) and very anisotropic: finite, PD, never worse than the inputs.
  std::mt19937 rng(3);
  for (int i = 0; i < 500; ++i) {
    const Estimate a{RandomVec(rng, 0.1), RandomCov(rng, 1e-15, 10.0)};
    const Estimate b{RandomVec(rng, 0.1), RandomCov(rng, 1e-15, 10.0)};
    ASSERT_EQ(CovarianceIntersection(a, b, f, &w), CovarianceStatus::kOk);
    ASSERT_TRUE(f.x.allFinite() && f.P.allFinite());
    EXPECT_GT(MinEig(f.P), 0.0);
    Eigen::Matrix3d ra = a.P, rb = b.P;
    ASSERT_EQ(Regularize(ra), CovarianceStatus::kOk);
    ASSERT_EQ(Regularize(rb), CovarianceStatus::kOk);
    EXPECT_LE(f.P.trace(), std::min(ra.trace(), rb.trace()) * (1 + 1e-9));
  }
}

TEST(CovarianceIntersection, RefusesNonFiniteAndNonCovarianceLeavingTheOutputAlone) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const Estimate good{{0, 0, 0}, 1e-6 * Eigen::Matrix3d::Identity()};
  const Estimate sentinel{{7, 7, 7}, 7 * Eigen::Matrix3d::Identity()};
  auto expect = [&](const Estimate& a, const Estimate& b, CovarianceStatus s) {
    Estimate f = sentinel;
    EXPECT_EQ(CovarianceIntersection(a, b, f), s) << ToString(s);
    EXPECT_EQ(f.x, sentinel.x);
    EXPECT_EQ(f.P, sentinel.P);
  };
  Estimate bad = good;
  bad.x.y() = nan;
  expect(good, bad, CovarianceStatus::kNotFinite);
  expect(bad, good, CovarianceStatus::kNotFinite);
  bad = good;
  bad.P(1, 2) = nan;
  expect(good, bad, CovarianceStatus::kNotFinite);
  bad = good;
  bad.P(2, 2) = std::numeric_limits<double>::infinity();
  expect(bad, good, CovarianceStatus::kNotFinite);
  bad = good;
  bad.P(2, 2) = -1e-6;
  expect(good, bad, CovarianceStatus::kNotCovariance);
  bad.P = -Eigen::Matrix3d::Identity();
  expect(bad, good, CovarianceStatus::kNotCovariance);
  // A rounding-sized negative eigenvalue is not a refusal: clamped to the floor.
  bad = good;
  bad.P(2, 2) = -1e-18;
  Estimate f;
  EXPECT_EQ(CovarianceIntersection(good, bad, f), CovarianceStatus::kOk);
  EXPECT_TRUE(f.P.allFinite());
}

// Two noisy observations of one true point; the fused error's mean squared Mahalanobis distance under the
// fused covariance is at most 3 (3 dof) when CI is consistent: with independent errors (CI is then
// conservative, well below 3) and with fully correlated ones (where a Kalman-style fusion would be
// overconfident).
TEST(CovarianceIntersection, MonteCarloConsistency) {
  std::mt19937 rng(4);
  std::normal_distribution<double> g;
  const Eigen::Vector3d truth(0.3, -0.2, 0.5);
  std::array<double, 2> worst{0, 0};
  for (const bool correlated : {false, true}) {
    for (int pair = 0; pair < 20; ++pair) {
      const Eigen::Matrix3d Pa = RandomCov(rng, 1e-3, 2e-2);
      const Eigen::Matrix3d Pb = RandomCov(rng, 1e-3, 2e-2);
      const Eigen::Matrix3d La = Eigen::LLT<Eigen::Matrix3d>(Pa).matrixL();
      const Eigen::Matrix3d Lb = Eigen::LLT<Eigen::Matrix3d>(Pb).matrixL();
      double nees = 0, naive = 0;
      const int n = 4000;
      for (int i = 0; i < n; ++i) {
        const Eigen::Vector3d za(g(rng), g(rng), g(rng));
        const Eigen::Vector3d zb = correlated ? za : Eigen::Vector3d(g(rng), g(rng), g(rng));
        const Estimate a{truth + La * za, Pa};
        const Estimate b{truth + Lb * zb, Pb};
        Estimate f;
        ASSERT_EQ(CovarianceIntersection(a, b, f), CovarianceStatus::kOk);
        const Eigen::Vector3d e = f.x - truth;
        nees += e.dot(f.P.ldlt().solve(e));
        // The independent-errors (Kalman) fusion, for contrast.
        const Eigen::Matrix3d Pk = (Pa.inverse() + Pb.inverse()).inverse();
        const Eigen::Vector3d xk = Pk * (Pa.inverse() * a.x + Pb.inverse() * b.x);
        naive += (xk - truth).dot(Pk.ldlt().solve(xk - truth));
      }
      nees /= n;
      naive /= n;
      worst[correlated] = std::max(worst[correlated], nees);
      // Sampling sd of the mean of a chi-square(3) over 4000 draws is about 0.04.
      EXPECT_LE(nees, 3.15) << (correlated ? "correlated" : "independent") << " pair " << pair;
      if (!correlated) {
        EXPECT_NEAR(naive, 3.0, 0.2);  // the check itself is calibrated
      }
    }
  }
  std::printf("mean squared Mahalanobis error of CI, worst of 20 pairs: independent %.3f, correlated %.3f (3 dof)\n",
              worst[0], worst[1]);
}

TEST(Gate, TangentMahalanobis) {
  const Eigen::Vector3d n = Eigen::Vector3d::UnitZ();
  const Eigen::Matrix3d P = 1e-6 * Eigen::Matrix3d::Identity();  // 1 mm sd each
  const Estimate a{{0, 0, 0}, P};
  // 3 mm apart along x: S = 2 mm^2, d2 = 9 / 2.
  EXPECT_NEAR(TangentMahalanobis2(a, {{0.003, 0, 0}, P}, n), 4.5, 1e-9);
  EXPECT_LE(TangentMahalanobis2(a, {{0.003, 0, 0}, P}, n), kChi2_2dof_95);
  EXPECT_GT(TangentMahalanobis2(a, {{0.004, 0, 0}, P}, n), kChi2_2dof_95);  // 8
  // Along the normal: ignored, however far.
  EXPECT_NEAR(TangentMahalanobis2(a, {{0, 0, 0.005}, P}, n), 0.0, 1e-12);
  // Any tangent basis: the same value for a tilted normal direction (rotation invariance).
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const Estimate ra{R * a.x, R * P * R.transpose()};
  const Estimate rb{R * Eigen::Vector3d(0.002, 0.001, 0.004), R * Eigen::Vector3d(4e-6, 1e-6, 1e-6).asDiagonal() * R.transpose()};
  const Estimate b{{0.002, 0.001, 0.004}, Eigen::Vector3d(4e-6, 1e-6, 1e-6).asDiagonal()};
  EXPECT_NEAR(TangentMahalanobis2(ra, rb, R * n), TangentMahalanobis2(a, b, n), 1e-9);
  EXPECT_NEAR(TangentMahalanobis2(a, b, n), 4.0 / 5.0 + 1.0 / 2.0, 1e-9);
  // Not finite, zero normal, singular projected covariance: +inf (never accepted).
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(TangentMahalanobis2(a, {{nan, 0, 0}, P}, n), std::numeric_limits<double>::infinity());
  EXPECT_EQ(TangentMahalanobis2(a, a, Eigen::Vector3d::Zero()), std::numeric_limits<double>::infinity());
  EXPECT_EQ(TangentMahalanobis2({{0, 0, 0}, Eigen::Matrix3d::Zero()}, {{0, 0, 0}, Eigen::Matrix3d::Zero()}, n),
            std::numeric_limits<double>::infinity());
}

}  // namespace
}  // namespace ruffini::fusion
