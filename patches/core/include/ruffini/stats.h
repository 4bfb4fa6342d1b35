#pragma once
// Order statistics used by reports. Quantiles use linear interpolation between order statistics
// (Hyndman-Fan type 7, the default of R, NumPy and MATLAB's prctile-like tools), NaNs dropped.
#include <vector>

namespace ruffini::stats {

// q in [0, 1]. Returns NaN for an empty (or all-NaN) sample. Takes a copy: it sorts.
double Quantile(std::vector<double> values, double q);
double Median(std::vector<double> values);
struct Summary {
  double median, q1, q3;
  [[nodiscard]] double iqr() const { return q3 - q1; }
};
Summary Summarize(std::vector<double> values);

}  // namespace ruffini::stats
