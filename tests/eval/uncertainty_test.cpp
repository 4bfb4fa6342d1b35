// The uncertainty fit (eval::FitUncertaintyRows) on synthetic rows whose errors have heavy tails: the fitted
// force sd and position covariance must hold both coverage levels (issue 17: 68 +- 5 % within 1 sigma, 95 +- 3 %
// within 2) on a fresh draw of the same errors, where a fit of the 1-sigma level alone leaves the 2-sigma share
// well short of its band.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "ruffini/error.h"
#include "ruffini/eval/calibrate.h"
#include "ruffini/stats.h"

namespace ruffini::eval {
namespace {

constexpr double kChi2Sigma1 = 2.2957, kChi2Sigma2 = 6.1801;

// Force: 90 % of frames err N(0, 30 mN), 10 % N(0, 120 mN), at predicted forces 0.2..3 N (the spread grows
// with the force). Position: the NIP's raw covariance is an ellipse of random size (sd 0.3-3 mm) and
// orientation; 80 % of frames err as it says (variance x 4), 20 % twice as far (variance x 16).
UncertaintyRows Draw(std::uint64_t seed, std::size_t n) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::normal_distribution<double> z(0.0, 1.0);
  UncertaintyRows rows;
  for (std::size_t i = 0; i < n; ++i) {
    const double pred = 0.2 + 2.8 * u01(rng);
    const double sd = (u01(rng) < 0.10 ? 0.12 : 0.03) * (0.5 + 0.5 * pred);
    rows.force.push_back({pred, std::abs(sd * z(rng))});
    const double s1 = 0.3 + 2.7 * u01(rng), s2 = 0.3 + 2.7 * u01(rng), th = 3.14159 * u01(rng);
    const double c = std::cos(th), s = std::sin(th);
    const double cyy = c * c * s1 * s1 + s * s * s2 * s2, caa = s * s * s1 * s1 + c * c * s2 * s2, cya = c * s * (s1 * s1 - s2 * s2);
    const double g = u01(rng) < 0.8 ? 2.0 : 4.0;
    const double a = g * s1 * z(rng), b = g * s2 * z(rng);  // along the ellipse's axes
    const double dy = c * a - s * b, da = s * a + c * b;
    rows.position.push_back({pred, dy, da, cyy, cya, caa});
  }
  return rows;
}

// The fitted functions applied as the pipeline applies them (piecewise linear in the predicted force, clamped).
double Interp(const v1::Uncertainty& u, const google::protobuf::RepeatedField<float>& ys, double x) {
  const int n = u.force_knots_n_size();
  if (x <= u.force_knots_n(0) || n == 1) return ys.Get(0);
  if (x >= u.force_knots_n(n - 1)) return ys.Get(n - 1);
  int k = 1;
  while (u.force_knots_n(k) < x) ++k;
  const double t = (x - u.force_knots_n(k - 1)) / (u.force_knots_n(k) - u.force_knots_n(k - 1));
  return ys.Get(k - 1) + t * (ys.Get(k) - ys.Get(k - 1));
}

struct Coverage {
  double f1 = 0, f2 = 0, p1 = 0, p2 = 0;
};

Coverage Score(const v1::Uncertainty& u, const UncertaintyRows& rows) {
  Coverage c;
  for (const auto& r : rows.force) {
    const double sd = Interp(u, u.force_sd_n(), r.pred);
    c.f1 += r.err <= sd;
    c.f2 += r.err <= 2 * sd;
  }
  for (const auto& r : rows.position) {
    const double k = Interp(u, u.position_scale(), r.pred), fl = u.position_floor_mm2();
    const double yy = k * r.cyy + fl, ya = k * r.cya, aa = k * r.caa + fl;
    const double d2 = (aa * r.dy * r.dy - 2 * ya * r.dy * r.da + yy * r.da * r.da) / (yy * aa - ya * ya);
    c.p1 += d2 <= kChi2Sigma1;
    c.p2 += d2 <= kChi2Sigma2;
  }
  const auto nf = static_cast<double>(rows.force.size()), np = static_cast<double>(rows.position.size());
  return {c.f1 / nf, c.f2 / nf, c.p1 / np, c.p2 / np};
}

TEST(FitUncertaintyTest, HeavyTailsMeetBothCoverageLevels) {
  const UncertaintyRows fit = Draw(1, 60000), check = Draw(2, 60000);
  const v1::Uncertainty u = FitUncertaintyRows(fit);
  ASSERT_GE(u.force_knots_n_size(), 3);
  const Coverage c = Score(u, check);
  EXPECT_NEAR(c.f1, 0.6827, 0.05);
  EXPECT_NEAR(c.f2, 0.9545, 0.03);
  EXPECT_NEAR(c.p1, 0.6827, 0.05);
  EXPECT_NEAR(c.p2, 0.9545, 0.03);
  // The data are a real test: the 1-sigma fit alone (the 68.27 % quantile as sd; the scale that puts 68.27 %
  // within chi-square 2.30 at the smallest floor) leaves the 2-sigma share outside its band.
  v1::Uncertainty one = u;
  std::vector<double> errs;
  for (const auto& r : fit.force) errs.push_back(r.err / (0.5 + 0.5 * r.pred));
  one.clear_force_knots_n();
  one.clear_force_sd_n();
  one.clear_position_scale();
  one.add_force_knots_n(1.0f);
  one.add_force_sd_n(static_cast<float>(stats::Quantile(errs, 0.6827)));
  one.set_position_floor_mm2(0.25f);
  double lo = 1e-3, hi = 1e3;
  for (int it = 0; it < 50; ++it) {
    one.clear_position_scale();
    one.add_position_scale(static_cast<float>(std::sqrt(lo * hi)));
    (Score(one, fit).p1 < 0.6827 ? lo : hi) = std::sqrt(lo * hi);
  }
  // (the force sd of `one` is for the force-normalised errors: score it on rows normalised the same way)
  UncertaintyRows norm = check;
  for (auto& r : norm.force) r.err /= 0.5 + 0.5 * r.pred;
  const Coverage o = Score(one, norm);
  EXPECT_LT(o.f2, 0.92);
  EXPECT_LT(o.p2, 0.92);
}

TEST(FitUncertaintyTest, NormalErrorsKeepTheOneSigmaFit) {
  // Errors exactly as the covariance says (times 3): both levels met at once, the floor stays at its least.
  std::mt19937_64 rng(5);
  std::normal_distribution<double> z(0.0, 1.0);
  UncertaintyRows rows;
  for (int i = 0; i < 40000; ++i) {
    rows.force.push_back({1.0, std::abs(0.05 * z(rng))});
    rows.position.push_back({1.0, std::sqrt(3.0) * 2.0 * z(rng), std::sqrt(3.0) * 2.0 * z(rng), 4.0, 0.0, 4.0});
  }
  const v1::Uncertainty u = FitUncertaintyRows(rows);
  ASSERT_EQ(u.force_knots_n_size(), 1);
  EXPECT_NEAR(u.force_sd_n(0), 0.05, 0.002);
  EXPECT_NEAR(u.position_floor_mm2(), 0.25, 1e-6);
  EXPECT_NEAR(u.position_scale(0) * 4.0 + 0.25, 12.0, 0.5);
}

TEST(FitUncertaintyTest, TooFewRowsIsAnError) {
  UncertaintyRows rows;
  for (int i = 0; i < 150; ++i) {
    rows.force.push_back({1.0, 0.1});
    rows.position.push_back({1.0, 1.0, 1.0, 1.0, 0.0, 1.0});
  }
  EXPECT_THROW(FitUncertaintyRows(rows), InputError);
}

}  // namespace
}  // namespace ruffini::eval
