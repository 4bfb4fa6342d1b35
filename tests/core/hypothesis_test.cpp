#include "ruffini/hypothesis.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <vector>

namespace ruffini::stats {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Paired samples from differences, b = 0.
WilcoxonResult FromDiffs(const std::vector<double>& d) {
  const std::vector<double> zero(d.size(), 0.0);
  return WilcoxonSignedRank(d, zero);
}

TEST(WilcoxonTest, ExactSmallSampleMatchesR) {
  // R's ?wilcox.test example: wilcox.test(x, y, paired = TRUE) -> V = 40, p-value = 0.03906.
  const std::vector<double> x = {1.83, 0.50, 1.62, 2.48, 1.68, 1.88, 1.55, 3.06, 1.30};
  const std::vector<double> y = {0.878, 0.647, 0.598, 2.05, 1.06, 1.29, 1.06, 3.14, 1.29};
  const WilcoxonResult r = WilcoxonSignedRank(x, y);
  EXPECT_TRUE(r.exact);
  EXPECT_EQ(r.n, 9u);
  EXPECT_EQ(r.w_plus, 40.0);
  EXPECT_EQ(r.w_minus, 5.0);
  EXPECT_EQ(r.statistic, 5.0);
  // 2 * #{subsets of 1..9 with sum <= 5} / 2^9 = 2 * 10 / 512.
  EXPECT_EQ(r.p_two_sided, 0.0390625);
  EXPECT_TRUE(std::isnan(r.z));
}

TEST(WilcoxonTest, ExactMatchesCriticalValueTable) {
  // n = 10, W- = 1 + 3 + 4 = 8: tables give P(W <= 8) = 0.0244 (25 of the 1024 subsets of 1..10).
  const WilcoxonResult r = FromDiffs({-1, 2, -3, -4, 5, 6, 7, 8, 9, 10});
  EXPECT_TRUE(r.exact);
  EXPECT_EQ(r.w_plus, 47.0);
  EXPECT_EQ(r.statistic, 8.0);
  EXPECT_EQ(r.p_two_sided, 50.0 / 1024.0);
  // Near the middle of the distribution (mean 27.5): large p, never above 1.
  const WilcoxonResult mid = FromDiffs({1, 2, 3, 4, 5, 6, -7, -8, -9, 10});  // W+ = 31, W- = 24
  EXPECT_EQ(mid.statistic, 24.0);
  EXPECT_GT(mid.p_two_sided, 0.5);
  EXPECT_LE(mid.p_two_sided, 1.0);
}

TEST(WilcoxonTest, ExactAtFiftyNormalAboveFifty) {
  std::vector<double> d;
  for (int i = 1; i <= 50; ++i) d.push_back(i);
  const WilcoxonResult r50 = FromDiffs(d);
  EXPECT_TRUE(r50.exact);
  EXPECT_EQ(r50.w_plus, 1275.0);
  EXPECT_EQ(r50.p_two_sided, std::ldexp(1.0, -49));  // 2 * 1 / 2^50, exact in doubles
  d.push_back(51);
  const WilcoxonResult r51 = FromDiffs(d);
  EXPECT_FALSE(r51.exact);
  EXPECT_GT(r51.z, 6.0);
  EXPECT_GT(r51.p_two_sided, 0.0);
  EXPECT_LT(r51.p_two_sided, 1e-9);
}

TEST(WilcoxonTest, NormalApproximationWithTies) {
  // d = {1, -1, 2, 2, -2, 3, 4, -4, 5, 6, 7, 8}, n = 12.
  // |d| sorted: 1 1 | 2 2 2 | 3 | 4 4 | 5 | 6 | 7 | 8
  // average ranks: 1.5 1.5 | 4 4 4 | 6 | 7.5 7.5 | 9 | 10 | 11 | 12
  // W+ = 1.5 + 4 + 4 + 6 + 7.5 + 9 + 10 + 11 + 12 = 65;  W- = 1.5 + 4 + 7.5 = 13;  65 + 13 = 78 = 12 * 13 / 2.
  // mean = 12 * 13 / 4 = 39
  // var  = 12 * 13 * 25 / 24 - [(2^3 - 2) + (3^3 - 3) + (2^3 - 2)] / 48 = 162.5 - 36 / 48 = 161.75
  // z    = (65 - 39 - 0.5) / sqrt(161.75) = 25.5 / 12.71810... = 2.0050168916...
  // p    = 2 (1 - Phi(z)) = erfc(z / sqrt 2) = 0.0449612412...   (R: wilcox.test(d, exact = FALSE))
  const WilcoxonResult r = FromDiffs({1, -1, 2, 2, -2, 3, 4, -4, 5, 6, 7, 8});
  EXPECT_FALSE(r.exact);  // ties force the normal approximation even for n <= 50
  EXPECT_EQ(r.n, 12u);
  EXPECT_EQ(r.w_plus, 65.0);
  EXPECT_EQ(r.w_minus, 13.0);
  EXPECT_EQ(r.statistic, 13.0);
  EXPECT_NEAR(r.z, 25.5 / std::sqrt(161.75), 1e-12);
  EXPECT_NEAR(r.z, 2.005016891625416, 1e-12);
  EXPECT_NEAR(r.p_two_sided, 0.04496124124811452, 1e-9);
}

TEST(WilcoxonTest, SwappingSamplesSwapsRankSums) {
  const std::vector<double> x = {1.83, 0.50, 1.62, 2.48, 1.68, 1.88, 1.55, 3.06, 1.30};
  const std::vector<double> y = {0.878, 0.647, 0.598, 2.05, 1.06, 1.29, 1.06, 3.14, 1.29};
  const WilcoxonResult xy = WilcoxonSignedRank(x, y);
  const WilcoxonResult yx = WilcoxonSignedRank(y, x);
  EXPECT_EQ(yx.w_plus, xy.w_minus);
  EXPECT_EQ(yx.w_minus, xy.w_plus);
  EXPECT_EQ(yx.statistic, xy.statistic);
  EXPECT_EQ(yx.p_two_sided, xy.p_two_sided);

  const std::vector<double> d = {1, -1, 2, 2, -2, 3, 4, -4, 5, 6, 7, 8};
  std::vector<double> neg;
  for (double v : d) neg.push_back(-v);
  const WilcoxonResult p = FromDiffs(d);
  const WilcoxonResult m = FromDiffs(neg);
  EXPECT_EQ(m.w_plus, p.w_minus);
  EXPECT_EQ(m.w_minus, p.w_plus);
  EXPECT_EQ(m.z, -p.z);
  EXPECT_EQ(m.p_two_sided, p.p_two_sided);
}

TEST(WilcoxonTest, ZerosAndNaNsDropped) {
  // The R example's differences with zero and NaN pairs mixed in: same result as without them.
  const std::vector<double> x = {1.83, 0.50, 5.0, 1.62, 2.48, kNaN, 1.68, 1.88, 1.55, 3.06, 1.30, 7.0, 2.0};
  const std::vector<double> y = {0.878, 0.647, 5.0, 0.598, 2.05, 1.0, 1.06, 1.29, 1.06, 3.14, 1.29, kNaN, 2.0};
  const WilcoxonResult r = WilcoxonSignedRank(x, y);
  EXPECT_EQ(r.n, 9u);
  EXPECT_EQ(r.zeros, 2u);
  EXPECT_EQ(r.dropped, 2u);
  EXPECT_EQ(r.w_plus, 40.0);
  EXPECT_EQ(r.p_two_sided, 0.0390625);

  const WilcoxonResult none = FromDiffs({0, 0, 0, 0});
  EXPECT_EQ(none.n, 0u);
  EXPECT_EQ(none.zeros, 4u);
  EXPECT_EQ(none.statistic, 0.0);
  EXPECT_EQ(none.p_two_sided, 1.0);

  const WilcoxonResult empty = FromDiffs({});
  EXPECT_EQ(empty.n, 0u);
  EXPECT_EQ(empty.p_two_sided, 1.0);
}

TEST(WilcoxonTest, AllTiedContinuityCorrectionDoesNotOvershoot) {
  // d = {1, -1, 1}: all |d| tied, ranks 2 each. W+ = 4, mean = 3, |W+ - mean| = 1 -> corrected 0.5.
  // var = 3 * 4 * 7 / 24 - (27 - 3) / 48 = 3.5 - 0.5 = 3 -> z = 0.5 / sqrt 3.
  const WilcoxonResult r = FromDiffs({1, -1, 1});
  EXPECT_FALSE(r.exact);
  EXPECT_EQ(r.w_plus, 4.0);
  EXPECT_NEAR(r.z, 0.5 / std::sqrt(3.0), 1e-12);
  // d = {1, 1, -1, -1}: W+ = W- = 5 = mean -> z = 0, p = 1.
  const WilcoxonResult mid = FromDiffs({1, 1, -1, -1});
  EXPECT_EQ(mid.z, 0.0);
  EXPECT_EQ(mid.p_two_sided, 1.0);
}

TEST(WilcoxonTest, SizeMismatchThrows) {
  const std::vector<double> a = {1, 2, 3};
  const std::vector<double> b = {1, 2};
  EXPECT_THROW(WilcoxonSignedRank(a, b), std::invalid_argument);
  EXPECT_THROW(CohensDPaired(a, b), std::invalid_argument);
  EXPECT_NO_THROW(CohensDIndependent(a, b));
}

TEST(WilcoxonTest, LargeSampleShiftedAndNull) {
  constexpr std::size_t kN = 1'000'000;
  std::mt19937_64 rng(20240611);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::vector<double> b(kN), shifted(kN), null(kN);
  for (std::size_t i = 0; i < kN; ++i) {
    b[i] = normal(rng);
    shifted[i] = b[i] + 0.01 * normal(rng) + 0.001;  // shift = 0.1 sd of the noise
    null[i] = b[i] + 0.01 * normal(rng);
  }
  const WilcoxonResult s = WilcoxonSignedRank(shifted, b);
  EXPECT_FALSE(s.exact);
  EXPECT_EQ(s.n + s.zeros, kN);
  EXPECT_GT(s.z, 50.0);  // ~ 0.1 * sqrt(3/pi) * sqrt(n) ~ 98
  EXPECT_TRUE(std::isfinite(s.p_two_sided));
  EXPECT_LT(s.p_two_sided, 1e-10);
  EXPECT_GE(s.p_two_sided, 0.0);

  const WilcoxonResult n0 = WilcoxonSignedRank(null, b);
  EXPECT_FALSE(n0.exact);
  EXPECT_TRUE(std::isfinite(n0.z));
  EXPECT_GT(n0.p_two_sided, 1e-4);
  EXPECT_LE(n0.p_two_sided, 1.0);
  EXPECT_DOUBLE_EQ(n0.w_plus + n0.w_minus, 0.5 * static_cast<double>(n0.n) * static_cast<double>(n0.n + 1));
}

TEST(CohensDTest, Paired) {
  // Differences {1, 2, 3}: mean 2, sample sd 1 -> d = 2.
  const std::vector<double> a = {3, 5, 10};
  const std::vector<double> b = {2, 3, 7};
  EXPECT_NEAR(CohensDPaired(a, b), 2.0, 1e-12);
  EXPECT_NEAR(CohensDPaired(b, a), -2.0, 1e-12);
  // A NaN pair is dropped.
  const std::vector<double> an = {3, 5, kNaN, 10};
  const std::vector<double> bn = {2, 3, 1, 7};
  EXPECT_NEAR(CohensDPaired(an, bn), 2.0, 1e-12);
  const std::vector<double> one = {1};
  EXPECT_TRUE(std::isnan(CohensDPaired(one, one)));
}

TEST(CohensDTest, Independent) {
  // a: mean 3, var 2.5; b: mean 5, var 2.5 -> pooled sd sqrt(2.5), d = -2 / sqrt(2.5) = -1.2649...
  const std::vector<double> a = {1, 2, 3, 4, 5};
  const std::vector<double> b = {3, 4, 5, 6, 7};
  EXPECT_NEAR(CohensDIndependent(a, b), -2.0 / std::sqrt(2.5), 1e-12);
  EXPECT_NEAR(CohensDIndependent(a, b), -1.2649110640673518, 1e-12);
  // Unequal sizes: c = {2, 4, 6} (mean 4, SS 8), e = {1, 1, 1, 1, 6} (mean 2, SS 20, with a NaN dropped)
  // pooled sd = sqrt((8 + 20) / (3 + 5 - 2)) = sqrt(28 / 6) -> d = 2 / sqrt(4.6667) = 0.92582...
  const std::vector<double> c = {2, 4, 6};
  const std::vector<double> e = {1, 1, kNaN, 1, 1, 6};
  EXPECT_NEAR(CohensDIndependent(c, e), 2.0 / std::sqrt(28.0 / 6.0), 1e-12);
  // The paired example above, ignoring the pairing: means 6 and 4, SS 26 and 14, pooled sd sqrt(40 / 4)
  // -> d = 2 / sqrt(10) = 0.632, vs paired d = 2.
  const std::vector<double> p = {3, 5, 10};
  const std::vector<double> q = {2, 3, 7};
  EXPECT_NEAR(CohensDIndependent(p, q), 2.0 / std::sqrt(10.0), 1e-12);
  const std::vector<double> empty;
  EXPECT_TRUE(std::isnan(CohensDIndependent(empty, a)));
}

}  // namespace
}  // namespace ruffini::stats
