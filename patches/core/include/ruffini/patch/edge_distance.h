#pragma once
// How far a point lies from the nearest edge of its patch, on the surface.
#include <algorithm>
#include <numbers>

#include "ruffini/patch/spec.h"

namespace ruffini::patch {

// Distance (mm on the surface) from p to the nearest of the patch's four edges: Y = 0 and Y = extent
// directly, R = 0 and R = extent as arc length on the surface radius; negative outside the patch.
inline double EdgeDistanceMm(const PatchSpec& spec, const SurfacePoint& p) {
  const double mm_per_deg = spec.surface_radius_mm * std::numbers::pi / 180.0;
  const double dy = std::min(p.y_mm, spec.extent_y_mm - p.y_mm);
  const double dr = std::min(p.r_deg, spec.extent_r_deg - p.r_deg) * mm_per_deg;
  return std::min(dy, dr);
}

}  // namespace ruffini::patch
