#include "ruffini/hypothesis.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

namespace ruffini::stats {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

void CheckSameSize(std::span<const double> a, std::span<const double> b, const char* what) {
  if (a.size() != b.size()) {
    throw std::invalid_argument(std::string(what) + ": paired samples differ in size (" + std::to_string(a.size()) +
                                " vs " + std::to_string(b.size()) + ")");
  }
}

// Two-sided exact p for W+ = w (no ties, 1 <= n <= 50): 2 * P(W <= min(w, n(n+1)/2 - w)), capped at 1.
// counts[s] = number of subsets of {1..n} whose sum is s; all counts are <= 2^50 < 2^53, so every value and
// partial sum is an exact integer in a double, and dividing by 2^n (ldexp) is exact too.
double ExactSignedRankP(std::size_t n, double w_plus) {
  const std::size_t total = n * (n + 1) / 2;
  std::vector<double> counts(total + 1, 0.0);
  counts[0] = 1.0;
  std::size_t reach = 0;
  for (std::size_t k = 1; k <= n; ++k) {
    reach += k;
    for (std::size_t s = reach; s >= k; --s) counts[s] += counts[s - k];
  }
  // Without ties W+ is an integer.
  const auto w = static_cast<std::size_t>(std::llround(w_plus));
  const std::size_t lo = std::min(w, total - w);
  double tail = 0.0;
  for (std::size_t s = 0; s <= lo; ++s) tail += counts[s];
  return std::min(1.0, std::ldexp(2.0 * tail, -static_cast<int>(n)));
}

struct MeanVar {
  std::size_t n = 0;
  long double mean = 0, m2 = 0;  // m2 = sum of squared deviations from the mean
};

// Two-pass mean / sum of squared deviations, NaNs skipped.
template <typename Get>
MeanVar Moments(std::size_t size, Get get) {
  MeanVar r;
  long double sum = 0;
  for (std::size_t i = 0; i < size; ++i) {
    const double x = get(i);
    if (std::isnan(x)) continue;
    sum += x;
    ++r.n;
  }
  if (r.n == 0) return r;
  r.mean = sum / static_cast<long double>(r.n);
  for (std::size_t i = 0; i < size; ++i) {
    const double x = get(i);
    if (std::isnan(x)) continue;
    const long double dev = x - r.mean;
    r.m2 += dev * dev;
  }
  return r;
}

}  // namespace

WilcoxonResult WilcoxonSignedRank(std::span<const double> a, std::span<const double> b) {
  CheckSameSize(a, b, "WilcoxonSignedRank");
  WilcoxonResult r;
  std::vector<double> d;
  d.reserve(a.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    const double di = a[i] - b[i];  // NaN if a[i] or b[i] is NaN (or inf - inf)
    if (std::isnan(di)) {
      ++r.dropped;
    } else if (di == 0.0) {
      ++r.zeros;
    } else {
      d.push_back(di);
    }
  }
  r.n = d.size();
  const std::size_t n = r.n;
  if (n == 0) {
    r.p_two_sided = 1.0;
    r.exact = true;
    return r;
  }

  std::sort(d.begin(), d.end(), [](double x, double y) { return std::fabs(x) < std::fabs(y); });
  // Ranks are multiples of 0.5 and W+ <= n(n+1)/2, so the sums are exact in double for any realistic n.
  double w_plus = 0.0;
  long double tie_term = 0.0L;  // sum over tie groups of t^3 - t
  bool ties = false;
  for (std::size_t i = 0; i < n;) {
    std::size_t j = i + 1;
    while (j < n && std::fabs(d[j]) == std::fabs(d[i])) ++j;
    const std::size_t t = j - i;
    // Ranks i+1 .. j (1-based) averaged.
    const double avg_rank = 0.5 * (static_cast<double>(i + 1) + static_cast<double>(j));
    for (std::size_t k = i; k < j; ++k) {
      if (d[k] > 0) w_plus += avg_rank;
    }
    if (t > 1) {
      ties = true;
      const auto tl = static_cast<long double>(t);
      tie_term += tl * tl * tl - tl;
    }
    i = j;
  }
  const double nd = static_cast<double>(n);
  const double total = nd * (nd + 1.0) / 2.0;
  r.w_plus = w_plus;
  r.w_minus = total - w_plus;
  r.statistic = std::min(r.w_plus, r.w_minus);

  if (n <= kWilcoxonExactMaxN && !ties) {
    r.exact = true;
    r.p_two_sided = ExactSignedRankP(n, w_plus);
    return r;
  }

  const auto nl = static_cast<long double>(n);
  const long double mean = nl * (nl + 1.0L) / 4.0L;
  // Always > 0 for n >= 1: even with all |d| tied it is n(n+1)(3n+3)/48.
  const long double var = nl * (nl + 1.0L) * (2.0L * nl + 1.0L) / 24.0L - tie_term / 48.0L;
  const long double diff = static_cast<long double>(w_plus) - mean;
  // Continuity correction: move 0.5 toward the mean, but never past it (|diff| can be 0.25 with ties).
  const long double corrected = std::copysign(std::max(0.0L, std::fabs(diff) - 0.5L), diff);
  r.z = static_cast<double>(corrected / std::sqrt(var));
  // 2 * (1 - Phi(|z|)) == erfc(|z| / sqrt 2), without cancellation; underflows to 0 for huge |z|.
  const double p = std::erfc(std::fabs(r.z) / std::numbers::sqrt2);
  r.p_two_sided = std::clamp(p, 0.0, 1.0);
  return r;
}

double CohensDPaired(std::span<const double> a, std::span<const double> b) {
  CheckSameSize(a, b, "CohensDPaired");
  const MeanVar m = Moments(a.size(), [&](std::size_t i) { return a[i] - b[i]; });
  if (m.n < 2) return kNaN;
  const long double sd = std::sqrt(m.m2 / static_cast<long double>(m.n - 1));
  return static_cast<double>(m.mean / sd);
}

double CohensDIndependent(std::span<const double> a, std::span<const double> b) {
  const MeanVar ma = Moments(a.size(), [&](std::size_t i) { return a[i]; });
  const MeanVar mb = Moments(b.size(), [&](std::size_t i) { return b[i]; });
  if (ma.n == 0 || mb.n == 0 || ma.n + mb.n < 3) return kNaN;
  const long double pooled = std::sqrt((ma.m2 + mb.m2) / static_cast<long double>(ma.n + mb.n - 2));
  return static_cast<double>((ma.mean - mb.mean) / pooled);
}

}  // namespace ruffini::stats
