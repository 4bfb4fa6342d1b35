#include "ruffini/stats.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace ruffini::stats {
namespace {
void DropNaN(std::vector<double>& v) {
  v.erase(std::remove_if(v.begin(), v.end(), [](double x) { return std::isnan(x); }), v.end());
}
double SortedQuantile(const std::vector<double>& v, double q) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  const double h = (static_cast<double>(v.size()) - 1.0) * q;
  const auto lo = static_cast<std::size_t>(std::floor(h));
  const std::size_t hi = std::min(lo + 1, v.size() - 1);
  return v[lo] + (h - static_cast<double>(lo)) * (v[hi] - v[lo]);
}
}  // namespace

double Quantile(std::vector<double> v, double q) {
  DropNaN(v);
  std::sort(v.begin(), v.end());
  return SortedQuantile(v, q);
}

double Median(std::vector<double> v) { return Quantile(std::move(v), 0.5); }

Summary Summarize(std::vector<double> v) {
  DropNaN(v);
  std::sort(v.begin(), v.end());
  return {SortedQuantile(v, 0.5), SortedQuantile(v, 0.25), SortedQuantile(v, 0.75)};
}

}  // namespace ruffini::stats
