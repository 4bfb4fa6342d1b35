#include "ruffini/eval/prepared.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <set>

#include "ruffini/error.h"

namespace ruffini::eval {

decode::BaselineConfig BaselineConfigFor(const dataset::Dataset& data, const decode::BaselineConfig& config) {
  decode::BaselineConfig cfg = config;
  cfg.sample_rate_hz = data.info.sample_rate_hz;
  return cfg;
}

Prepared PrepareFrames(const dataset::Dataset& d, const decode::BaselineConfig& config) {
  Prepared p;
  const std::size_t n = d.size();
  p.shift_pm.resize(n);
  p.force_n = d.force_n;
  p.y_mm = d.y_mm;
  p.r_deg = d.r_deg;
  p.indentation = d.indentation;
  p.sample_rate_hz = d.info.sample_rate_hz;
  p.surface_radius_mm = d.info.surface_radius_mm;
  p.patch_name = d.info.patch_name;
  p.source = d.info.source;
  decode::BaselineTracker tracker(BaselineConfigFor(d, config));
  decode::Wavelengths wl;
  for (std::size_t k = 0; k < n; ++k) {
    for (std::size_t i = 0; i < decode::kGratings; ++i) wl[i] = d.wavelength_nm[k][i];
    tracker.Update(wl, p.shift_pm[k]);
  }
  std::map<std::int32_t, std::size_t> where;
  for (std::size_t k = 0; k < n; ++k) {
    const std::int32_t id = d.indentation[k];
    if (id < 0) continue;
    auto it = where.find(id);
    if (it == where.end()) {
      where[id] = p.ids.size();
      p.ids.push_back(id);
      p.ranges.emplace_back(k, k + 1);
    } else {
      auto& r = p.ranges[it->second];
      if (r.second != k) {
        throw InputError("dataset: indentation " + std::to_string(id) + " is not contiguous (frame " + std::to_string(k) + ")");
      }
      r.second = k + 1;
    }
  }
  return p;
}

Split MakeSplit(const Prepared& p, double test_fraction, int folds, std::uint64_t seed,
                const std::vector<std::int32_t>& forced_test) {
  Split s;
  s.folds = folds;
  std::vector<std::size_t> order(p.ids.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::mt19937_64 rng(seed);
  std::shuffle(order.begin(), order.end(), rng);
  if (!forced_test.empty()) {
    const std::set<std::int32_t> t(forced_test.begin(), forced_test.end());
    for (std::size_t i : order) (t.count(p.ids[i]) ? s.test : s.train).push_back(i);
  } else {
    const auto n_test = static_cast<std::size_t>(std::lround(test_fraction * static_cast<double>(order.size())));
    s.test.assign(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(n_test));
    s.train.assign(order.begin() + static_cast<std::ptrdiff_t>(n_test), order.end());
  }
  for (std::size_t k = 0; k < s.train.size(); ++k) s.fold.push_back(folds > 0 ? static_cast<int>(k % static_cast<std::size_t>(folds)) : 0);
  return s;
}

}  // namespace ruffini::eval
