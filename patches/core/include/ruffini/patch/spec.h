#pragma once
// PatchSpec: the immutable description of one skin patch (one fibre, 16 gratings).
// Loaded and validated once (spec_loader.h); everything downstream takes it by const reference.
#include <array>
#include <cstddef>
#include <string>
#include <vector>

#include "ruffini/frame.h"

namespace ruffini::patch {

using ::ruffini::kGratings;  // ruffini/frame.h

// Silicone constants (Dragon Skin 10 in the paper).
struct Material {
  double youngs_modulus_kpa = 152.0;
  double poisson_ratio = 0.49;
  double density_kg_m3 = 1070.0;
  double yeoh_c1_kpa = 36.0;
  double yeoh_c2_pa = 258.0;
  double yeoh_c3_pa = -0.56;
};

// The soft layer bonded to the rigid limb, with the fibre embedded at fibre_depth_mm below the surface.
struct Layer {
  double thickness_mm = 8.0;
  double fibre_depth_mm = 4.0;
  Material material;
};

// A point of the patch in patch coordinates: Y along the limb from the elbow edge, R around it.
struct SurfacePoint {
  double y_mm = 0.0;
  double r_deg = 0.0;
};

struct Grating {
  SurfacePoint centre;
  // Direction of the fibre through the grating in the unrolled surface: 0 deg = toward +Y (wrist),
  // 90 deg = toward +R.
  double direction_deg = 0.0;
  double length_mm = 8.0;
  double wavelength_nm = 1530.0;  // nominal Bragg wavelength, unloaded
};

// Axis-aligned region of the patch in (Y, R).
struct Region {
  double y_min_mm = 0.0, y_max_mm = 0.0;
  double r_min_deg = 0.0, r_max_deg = 0.0;
  [[nodiscard]] bool Contains(const SurfacePoint& p, double tol = 1e-9) const {
    return p.y_mm >= y_min_mm - tol && p.y_mm <= y_max_mm + tol && p.r_deg >= r_min_deg - tol &&
           p.r_deg <= r_max_deg + tol;
  }
};

struct Fibre {
  std::vector<SurfacePoint> path;             // polyline through every grating, U-turns included
  double strain_optic_pm_per_microstrain = 1.2;
  double strain_transfer = 5e-4;              // silicone-to-glass strain attenuation (calibrated)
  double band_half_width_nm = 1.1;            // largest |shift| the twin lets a peak move (then clipped)
};

struct Interrogator {
  double window_min_nm = 1510.0;
  double window_max_nm = 1590.0;
  double noise_pm = 0.3;  // 1-sigma precision
};

struct PatchSpec {
  std::string name;
  std::string source;  // file it was loaded from, for messages
  double surface_radius_mm = 37.4;
  double extent_y_mm = 150.0;
  double extent_r_deg = 145.0;
  Region indented_area;
  Layer layer;
  Fibre fibre;
  Interrogator interrogator;
  std::array<Grating, kGratings> gratings{};

  [[nodiscard]] Region Extent() const { return {0.0, extent_y_mm, 0.0, extent_r_deg}; }
  // A stable hash (hex) of every physical field, for models trained on this spec.
  [[nodiscard]] std::string Fingerprint() const;
};

}  // namespace ruffini::patch
