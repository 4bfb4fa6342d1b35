#pragma once
// Hypothesis-test statistics for evaluation reports: Wilcoxon signed-rank test and Cohen's d.
//
// Hand-written on purpose: among the C++ packages the project allows (Debian's set), there is no
// maintained statistics library with a Wilcoxon signed-rank test (Boost.Math has distributions but no
// signed-rank test; GSL has no rank tests either). The test is small and checked against R's wilcox.test values in
// tests/core/hypothesis_test.cpp.
#include <cstddef>
#include <limits>
#include <span>

namespace ruffini::stats {

struct WilcoxonResult {
  // Pairs with a non-zero difference a[i] - b[i]. Zero differences are dropped before ranking
  // (Wilcoxon's original method, as R's wilcox.test and SciPy's zero_method="wilcox"), not split
  // between W+ and W- (Pratt's method).
  std::size_t n = 0;
  std::size_t zeros = 0;    // pairs dropped because a[i] - b[i] == 0
  std::size_t dropped = 0;  // pairs dropped because a[i], b[i] or a[i] - b[i] is NaN
  double w_plus = 0;        // sum of the (average) ranks of |d| where d > 0
  double w_minus = 0;       // same for d < 0; w_plus + w_minus == n (n + 1) / 2
  double statistic = 0;     // min(W+, W-)
  // Normal approximation of W+ with tie and continuity correction, signed: z > 0 means a tends to be
  // larger than b. NaN when the exact distribution was used.
  double z = std::numeric_limits<double>::quiet_NaN();
  double p_two_sided = std::numeric_limits<double>::quiet_NaN();  // in [0, 1]; never NaN
  // True when the exact null distribution of W+ was used: n <= kWilcoxonExactMaxN and no tied |d|
  // (n = 0 counts as exact, with p = 1). Otherwise the normal approximation.
  bool exact = false;
};

inline constexpr std::size_t kWilcoxonExactMaxN = 50;

// Two-sided Wilcoxon signed-rank test on the paired differences d[i] = a[i] - b[i].
// Ties in |d| (exact floating-point equality) get average ranks. O(n log n) time, one n-sized buffer.
// Throws std::invalid_argument if a and b have different sizes.
WilcoxonResult WilcoxonSignedRank(std::span<const double> a, std::span<const double> b);

// Cohen's d for paired samples ("d_z"): mean(a - b) / sd(a - b), sample sd with n - 1.
// This is what SPSS reports as the paired-samples Cohen's d (standardizer = sd of the differences).
// Use THIS one in the paper-style report: it compares absolute errors of the model and of a random guess
// on the same test samples, i.e. paired data, and the report pairs it with the signed-rank test above.
// NaN pairs are dropped. Returns NaN with fewer than 2 pairs; +-inf (or NaN for 0/0) if all differences
// are equal. Throws std::invalid_argument if a and b have different sizes.
double CohensDPaired(std::span<const double> a, std::span<const double> b);

// Cohen's d for independent samples: (mean a - mean b) / pooled sd, where
// pooled sd = sqrt(((na - 1) sa^2 + (nb - 1) sb^2) / (na + nb - 2)). NaNs are dropped per sample.
// Sizes may differ. Returns NaN if either sample is empty or na + nb < 3. Not for the paired report: it
// ignores the pairing, so it is usually much smaller than the paired d on the same data.
double CohensDIndependent(std::span<const double> a, std::span<const double> b);

}  // namespace ruffini::stats
