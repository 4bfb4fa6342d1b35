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

// Whether the closed rectangle [y0, y1] x [r0, r1] holds a point outside every band of `mine`. Exact, not sampled
// (review 11 found a 0.2 mm gap between two bands stepped over by 0.25 mm samples): the rectangle is cut at every
// band edge inside it, and each piece's centre is tested. No band edge crosses a piece, so a closed band holding a
// piece's centre holds the whole piece (and its closure); the pieces' closures make up the rectangle.
bool HoldsCoveredSurface(double y0, double y1, double r0, double r1, const std::vector<UncoveredBand>& bands,
                         const std::vector<std::size_t>& mine) {
  std::vector<double> ys{y0, y1}, rs{r0, r1};
  for (std::size_t b : mine) {
    for (double v : {bands[b].y_min_mm, bands[b].y_max_mm}) {
      if (v > y0 && v < y1) ys.push_back(v);
    }
    for (double v : {bands[b].r_min_deg, bands[b].r_max_deg}) {
      if (v > r0 && v < r1) rs.push_back(v);
    }
  }
  std::sort(ys.begin(), ys.end());
  std::sort(rs.begin(), rs.end());
  for (std::size_t i = 0; i + 1 < ys.size(); ++i) {
    if (!(ys[i + 1] > ys[i])) continue;
    const double y = 0.5 * (ys[i] + ys[i + 1]);
    for (std::size_t j = 0; j + 1 < rs.size(); ++j) {
      if (!(rs[j + 1] > rs[j])) continue;
      const double r = 0.5 * (rs[j] + rs[j + 1]);
      bool in_band = false;
      for (std::size_t b : mine) in_band = in_band || bands[b].Contains(y, r);
      if (!in_band) return true;
    }
  }
  return false;
}

std::string Fmt(const char* fmt, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, fmt, v);
  return buf;
}

// One axis of a map's cells: the lines 0, the grid's values, the extent; cell i lies between lines i and i + 1.
// Its grid corners are grid values i - 1 and i where they exist (an edge cell has one). What is wrong with the axis
// (a value outside the patch, an edge cell or an inner cell too wide) is named per cell in `problem`.
struct Axis {
  std::vector<double> lines;
  std::vector<std::string> problem;
};

Axis CellAxis(const google::protobuf::RepeatedField<double>& grid, double extent, double mm_per_unit, const char* name,
              const char* unit) {
  Axis a;
  a.lines.push_back(0.0);
  for (double v : grid) a.lines.push_back(v);
  a.lines.push_back(extent);
  const std::size_t n = a.lines.size() - 1;
  a.problem.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double lo = a.lines[i], hi = a.lines[i + 1];
    const double width_mm = (hi - lo) * mm_per_unit;  // mm_per_unit 0: this axis's widths are not judged
    const bool edge = i == 0 || i + 1 == n;
    if (!(hi >= lo)) {  // a grid value beyond the patch (or NaN extent)
      a.problem[i] = std::string("its grid lies outside the patch (") + name + " 0.." + Fmt("%g", extent) + " " + unit + ")";
    } else if (edge && width_mm > kMaxMapEdgeGapMm) {
      a.problem[i] = std::string("its grid stops ") + Fmt("%.1f mm", width_mm) + " from the " + name +
                     (i == 0 ? " 0" : " end") + " edge (more than " + Fmt("%.1f mm", kMaxMapEdgeGapMm) + ")";
    } else if (!edge && width_mm > kMaxMapCellMm) {
      a.problem[i] = std::string("its grid lines ") + name + " " + Fmt("%g", lo) + " and " + Fmt("%g", hi) + " " + unit +
                     " are " + Fmt("%.1f mm", width_mm) + " apart (more than " + Fmt("%.1f mm", kMaxMapCellMm) + ")";
    }
  }
  return a;
}

}  // namespace

RegionGuarantee GuaranteeRegion(const std::vector<CoveragePatch>& patches, const std::vector<UncoveredBand>& bands,
                                double threshold_n, double press_factor, double judge_margin_n) {
  RegionGuarantee g;
  g.threshold_n = threshold_n;
  g.press_factor = press_factor;
  g.patches = static_cast<std::uint32_t>(patches.size());
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
    const int ny = m->y_mm_size(), nr = m->r_deg_size();
    if (ny == 0 || nr == 0) {
      g.unmeasured.push_back("patch " + p.id + ": its map has no grid");
      continue;
    }
    // The cells: the patch cut by the map's grid lines, with the edges. A cell that holds any covered surface
    // (a point outside the accepted bands) is judged by its grid corners: the map says nothing between its points,
    // so the weakest corner stands for the cell (the measured mid-cell check, docs/coverage.md, is what supports
    // that). A covered cell without the corners to judge it (an edge strip wider than kMaxMapEdgeGapMm, an inner
    // cell wider than kMaxMapCellMm, a grid beyond the patch) was never measured: review 10 finding 3, review 11.
    const Axis ay = CellAxis(m->y_mm(), p.extent_y_mm, 1.0, "Y", "mm");
    const Axis ar = CellAxis(m->r_deg(), p.extent_r_deg, p.mm_per_deg > 0 ? p.mm_per_deg : 0.0, "R", "deg");
    std::vector<char> judged(static_cast<std::size_t>(ny) * static_cast<std::size_t>(nr), 0);
    std::vector<std::string> problems;
    for (std::size_t i = 0; i + 1 < ay.lines.size(); ++i) {
      for (std::size_t j = 0; j + 1 < ar.lines.size(); ++j) {
        // A grid value beyond the patch leaves a cell whose lines run backwards: refused whatever the bands say.
        const bool beyond = !(ay.lines[i + 1] >= ay.lines[i]) || !(ar.lines[j + 1] >= ar.lines[j]);
        if (!beyond) {
          const double y0 = std::max(0.0, ay.lines[i]), y1 = std::min(p.extent_y_mm, ay.lines[i + 1]);
          const double r0 = std::max(0.0, ar.lines[j]), r1 = std::min(p.extent_r_deg, ar.lines[j + 1]);
          if (!(y1 > y0) || !(r1 > r0)) continue;  // no area: part of its neighbours' closures
          if (!HoldsCoveredSurface(y0, y1, r0, r1, bands, mine)) continue;
        }
        const std::string& why = !ay.problem[i].empty() ? ay.problem[i] : ar.problem[j];
        if (!why.empty()) {
          const std::string text = "patch " + p.id + ": " + why + (beyond ? "" : ", and covered surface lies there") +
                                   ": never measured";
          if (std::find(problems.begin(), problems.end(), text) == problems.end()) problems.push_back(text);
          continue;
        }
        for (std::size_t ci : {i, i + 1}) {  // grid value k is line k + 1
          if (ci < 1 || ci > static_cast<std::size_t>(ny)) continue;
          for (std::size_t cj : {j, j + 1}) {
            if (cj < 1 || cj > static_cast<std::size_t>(nr)) continue;
            judged[(ci - 1) * static_cast<std::size_t>(nr) + (cj - 1)] = 1;
          }
        }
      }
    }
    g.unmeasured.insert(g.unmeasured.end(), problems.begin(), problems.end());
    for (int iy = 0; iy < ny; ++iy) {
      for (int ir = 0; ir < nr; ++ir) {
        const double y = m->y_mm(iy), r = m->r_deg(ir);
        const int k = iy * nr + ir;
        const float f = m->min_force_n(k);
        const bool weak = !(f <= press_factor * threshold_n);
        ++g.points;
        for (std::size_t b : mine) {
          if (!bands[b].Contains(y, r)) continue;
          BandCount& count = g.bands[static_cast<std::size_t>(band_index[b])];
          ++count.points;
          count.uncovered_points += weak ? 1u : 0u;
        }
        if (!judged[static_cast<std::size_t>(k)]) continue;
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
