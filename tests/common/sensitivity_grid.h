#pragma once
// Synthetic sensitivity maps on `ruffini sensitivity`'s grid, for tests of the scene guarantee (docs/coverage.md):
// the guarantee judges a map's cells, so a test map has the real grid's spacing, not a handful of points.
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "ruffini/v1/model.pb.h"

namespace ruffini::testing {

inline constexpr double kForearmMmPerDeg = 37.4 * 3.14159265358979 / 180.0;  // the forearm sleeve's radius

// `ruffini sensitivity`'s axis (services/ruffini/cmd_coverage.cpp): `edge` from each end, then every `step` at
// least 1 mm clear of the ends.
inline std::vector<double> SensitivityAxis(double length, double step = 5.0, double edge = 2.0) {
  std::vector<double> v{edge};
  for (double x = step; x < length - edge - 1.0 + 1e-9; x += step) {
    if (x > edge + 1.0 - 1e-9) v.push_back(x);
  }
  v.push_back(length - edge);
  return v;
}

// The Y rows (mm) and R columns (deg) of a 150 mm x 145 deg forearm patch's map: 31 x 20 points.
inline std::vector<double> ForearmYs() { return SensitivityAxis(150.0); }
inline std::vector<double> ForearmRs() {
  std::vector<double> r;
  for (double arc : SensitivityAxis(145.0 * kForearmMmPerDeg)) r.push_back(arc / kForearmMmPerDeg);
  return r;
}

// A map of level `level` on the grid ys x rs: every point reliable at `base` N, except (weak_y, weak_r) (a grid
// point, matched within 1e-6) at `weak` N. Location errors 2.5 mm, NaN where the force is infinite.
inline v1::SensitivityMap GridMap(float level, float base, double weak_y, double weak_r, float weak,
                                  const std::vector<double>& ys, const std::vector<double>& rs,
                                  const std::string& source = "test") {
  v1::SensitivityMap m;
  m.set_level_n(level);
  m.set_reliability(0.95f);
  for (double y : ys) m.add_y_mm(y);
  for (double r : rs) m.add_r_deg(r);
  for (double y : ys) {
    for (double r : rs) {
      const float f = std::abs(y - weak_y) < 1e-6 && std::abs(r - weak_r) < 1e-6 ? weak : base;
      m.add_min_force_n(f);
      m.add_location_error_mm(std::isinf(f) ? std::numeric_limits<float>::quiet_NaN() : 2.5f);
    }
  }
  for (float f : {1.0f, 2.0f, 5.0f, 200.0f}) m.add_forces_n(f);
  m.set_presses(20);
  m.set_probe_radius_mm(5.5);
  m.set_source(source);
  return m;
}

}  // namespace ruffini::testing
