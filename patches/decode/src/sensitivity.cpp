#include "ruffini/decode/sensitivity.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include "ruffini/error.h"

namespace ruffini::decode {
namespace {

template <typename Seq>
bool Ascending(const Seq& v) {
  for (int i = 0; i < v.size(); ++i) {
    if (!std::isfinite(v[i]) || (i > 0 && !(v[i] > v[i - 1]))) return false;
  }
  return true;
}

}  // namespace

void ValidateSensitivity(const v1::SensitivityMap& m, const std::string& where) {
  const auto fail = [&](const std::string& what) { throw InputError(where + ": sensitivity map " + what); };
  if (!(std::isfinite(m.level_n()) && m.level_n() > 0)) fail("level_n " + std::to_string(m.level_n()) + " must be finite and > 0");
  if (!(m.reliability() > 0 && m.reliability() <= 1)) fail("reliability must be in (0, 1]");
  if (m.y_mm_size() < 1 || m.r_deg_size() < 1 || !Ascending(m.y_mm()) || !Ascending(m.r_deg())) {
    fail("grid must be non-empty, finite and ascending in Y and R");
  }
  if (m.forces_n_size() < 1 || !Ascending(m.forces_n()) || !(m.forces_n(0) > 0)) fail("force ladder must be positive and ascending");
  const int n = m.y_mm_size() * m.r_deg_size();
  if (m.min_force_n_size() != n || m.location_error_mm_size() != n) {
    fail("has " + std::to_string(m.min_force_n_size()) + " forces and " + std::to_string(m.location_error_mm_size()) +
         " location errors for " + std::to_string(n) + " grid points");
  }
  for (int i = 0; i < n; ++i) {
    const float f = m.min_force_n(i), e = m.location_error_mm(i);
    if (std::isnan(f) || !(f > 0)) fail("point " + std::to_string(i) + " has min_force_n " + std::to_string(f) + " (> 0 or +infinity)");
    if (!std::isnan(e) && !(std::isfinite(e) && e >= 0)) fail("point " + std::to_string(i) + " has a location error " + std::to_string(e));
  }
  if (m.presses() < 1) fail("names no presses per point");
}

const v1::SensitivityMap* MapForThreshold(const google::protobuf::RepeatedPtrField<v1::SensitivityMap>& maps,
                                          double threshold_n) {
  const v1::SensitivityMap* best = nullptr;
  for (const auto& m : maps) {
    if (m.level_n() >= threshold_n && (best == nullptr || m.level_n() < best->level_n())) best = &m;
  }
  return best;
}

double EdgeReachMm(const v1::SensitivityMap& map, const std::function<double(double, double)>& distance_mm,
                   double near_mm, double quantile) {
  std::vector<double> reach;
  const int nr = map.r_deg_size();
  for (int iy = 0; iy < map.y_mm_size(); ++iy) {
    for (int ir = 0; ir < nr; ++ir) {
      const int k = iy * nr + ir;
      if (k >= map.location_error_mm_size()) continue;
      const double d = distance_mm(map.y_mm(iy), map.r_deg(ir));
      const double e = map.location_error_mm(k);
      if (d <= near_mm && std::isfinite(e)) reach.push_back(std::max(0.0, d) + e);
    }
  }
  if (reach.empty()) return 0.0;
  std::sort(reach.begin(), reach.end());
  const double q = std::clamp(quantile, 0.0, 1.0) * static_cast<double>(reach.size() - 1);
  const auto lo = static_cast<std::size_t>(q);
  const std::size_t hi = std::min(lo + 1, reach.size() - 1);
  return reach[lo] + (q - static_cast<double>(lo)) * (reach[hi] - reach[lo]);
}

namespace {

// The strips between each edge of p and m's outermost grid lines that are wider than kMaxMapEdgeGapMm and hold
// some point outside every accepted band of the patch (sampled every 0.25 mm and 0.25 deg, edges included).
void UnmeasuredStrips(const CoveragePatch& p, const v1::SensitivityMap& m, const std::vector<UncoveredBand>& bands,
                      const std::vector<std::size_t>& mine, std::vector<std::string>& out) {
  if (m.y_mm_size() == 0 || m.r_deg_size() == 0) {
    out.push_back("patch " + p.id + ": its map has no grid");
    return;
  }
  const auto [ylo, yhi] = std::minmax_element(m.y_mm().begin(), m.y_mm().end());
  const auto [rlo, rhi] = std::minmax_element(m.r_deg().begin(), m.r_deg().end());
  const double deg_mm = p.mm_per_deg > 0 ? p.mm_per_deg : 0.0;  // 0: the R strips' gaps are 0, never judged
  struct Strip {
    const char* edge;
    double gap_mm, y0, y1, r0, r1;
  };
  const Strip strips[] = {
      {"Y 0", *ylo, 0.0, *ylo, 0.0, p.extent_r_deg},
      {"Y end", p.extent_y_mm - *yhi, *yhi, p.extent_y_mm, 0.0, p.extent_r_deg},
      {"R 0", *rlo * deg_mm, 0.0, p.extent_y_mm, 0.0, *rlo},
      {"R end", (p.extent_r_deg - *rhi) * deg_mm, 0.0, p.extent_y_mm, *rhi, p.extent_r_deg},
  };
  for (const Strip& s : strips) {
    if (!(s.gap_mm > kMaxMapEdgeGapMm)) continue;  // NaN extents count as unmeasured
    bool covered = false;
    const int ny = static_cast<int>(std::ceil((s.y1 - s.y0) / 0.25)), nr = static_cast<int>(std::ceil((s.r1 - s.r0) / 0.25));
    for (int iy = 0; iy <= ny && !covered; ++iy) {
      const double y = std::min(s.y1, s.y0 + 0.25 * iy);
      for (int ir = 0; ir <= nr && !covered; ++ir) {
        const double r = std::min(s.r1, s.r0 + 0.25 * ir);
        bool in_band = false;
        for (std::size_t b : mine) in_band = in_band || bands[b].Contains(y, r);
        covered = !in_band;
      }
    }
    if (!covered) continue;
    char buf[256];
    std::snprintf(buf, sizeof buf,
                  "patch %s: its map's grid stops %.1f mm from the %s edge (more than %.1f mm), and that strip is not "
                  "in an accepted band: never measured",
                  p.id.c_str(), s.gap_mm, s.edge, kMaxMapEdgeGapMm);
    out.emplace_back(buf);
  }
}

}  // namespace

RegionGuarantee GuaranteeRegion(const std::vector<CoveragePatch>& patches, const std::vector<UncoveredBand>& bands,
                                double threshold_n, double press_factor, double judge_margin_n) {
  RegionGuarantee g;
  g.threshold_n = threshold_n;
  g.press_factor = press_factor;
  // The bands on any of the region's patches, in the scene's order; band_index maps a band to its entry.
  std::vector<int> band_index(bands.size(), -1);
  for (std::size_t b = 0; b < bands.size(); ++b) {
    for (const CoveragePatch& p : patches) {
      if (band_index[b] < 0 && bands[b].On(p.id)) {
        band_index[b] = static_cast<int>(g.bands.size());
        g.bands.push_back({bands[b].name, 0, 0});
      }
    }
  }
  double level = 0.0, stop = 0.0;
  bool any_map = false;
  for (const CoveragePatch& p : patches) {
    std::vector<std::size_t> mine;  // the bands on this patch
    for (std::size_t b = 0; b < bands.size(); ++b) {
      if (bands[b].On(p.id)) mine.push_back(b);
    }
    const v1::SensitivityMap* m = p.maps ? MapForThreshold(*p.maps, threshold_n + std::max(0.0, judge_margin_n)) : nullptr;
    if (m == nullptr) {
      bool whole = false;
      for (std::size_t b : mine) {
        whole = whole || (bands[b].Contains(0, 0) && bands[b].Contains(p.extent_y_mm, p.extent_r_deg));
      }
      if (!whole) g.unmapped.push_back(p.id);
      continue;
    }
    any_map = true;
    level = std::max(level, static_cast<double>(m->level_n()));
    UnmeasuredStrips(p, *m, bands, mine, g.unmeasured);
    for (int iy = 0; iy < m->y_mm_size(); ++iy) {
      for (int ir = 0; ir < m->r_deg_size(); ++ir) {
        const double y = m->y_mm(iy), r = m->r_deg(ir);
        const float f = m->min_force_n(iy * m->r_deg_size() + ir);
        const bool weak = !(f <= press_factor * threshold_n);
        ++g.points;
        bool accepted = false;
        for (std::size_t k = 0; k < mine.size(); ++k) {
          if (!bands[mine[k]].Contains(y, r)) continue;
          accepted = true;
          BandCount& count = g.bands[static_cast<std::size_t>(band_index[mine[k]])];
          ++count.points;
          count.uncovered_points += weak ? 1u : 0u;
        }
        if (accepted) continue;
        ++g.covered_points;
        stop = std::max(stop, static_cast<double>(f));  // +inf propagates
        if (weak) g.uncovered.push_back({p.id, y, r, f});
      }
    }
  }
  if (any_map) {
    g.map_level_n = level;
    if (!g.unmeasured.empty()) stop = std::numeric_limits<double>::infinity();
    g.stop_force_n = stop;
    g.guaranteed_threshold_n = stop / press_factor;
  } else if (g.unmapped.empty()) {
    // Every patch accepted whole: nothing is covered and nothing is promised.
    g.map_level_n = std::numeric_limits<double>::quiet_NaN();
    g.stop_force_n = 0.0;
    g.guaranteed_threshold_n = 0.0;
  }
  return g;
}

}  // namespace ruffini::decode
