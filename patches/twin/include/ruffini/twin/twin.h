#pragma once
// The skin twin: a forward model from contacts on a patch to the 16 Bragg wavelength shifts.
//
//   contact (Y, R, force, probe) --Dimitriadis--> contact radius --bonded-layer elasticity--> in-plane strain
//   at the fibre depth --average along each 8 mm grating, axial component--> silicone strain over the grating
//   --x strain_transfer (shear lag into the glass, calibrated)--> fibre strain --x 1.2 pm/ue--> shift.
//
// Everything that does not depend on the contact is precomputed at construction: for a ladder of contact
// radii, a table K_a(u, v) of the grating-averaged axial strain per newton as a function of the contact's
// offset from the grating (u along the fibre, v across it). All gratings share the tables (same length,
// same layer); a frame costs a few bilinear look-ups per grating.
//
// SkinTwin is the immutable Model; InterrogatorSim holds the per-stream Data (random state).
#include <array>
#include <cstdint>
#include <memory>
#include <random>
#include <span>
#include <vector>

#include "ruffini/frame.h"
#include "ruffini/patch/geometry.h"
#include "ruffini/patch/spec.h"
#include "ruffini/twin/contact.h"
#include "ruffini/twin/effects.h"

namespace ruffini::twin {

using Shifts = std::array<double, patch::kGratings>;

// Largest probe radius the kernel tables cover (they stop at a 6 mm contact radius).
inline constexpr double kMaxProbeRadiusMm = 6.0;

struct Contact {
  patch::SurfacePoint at;
  double force_n = 0.0;
  Probe probe;
};

// Flags a frame can carry (same bits as dataset::FrameFlags).
using enum ::ruffini::FrameFlags;  // kFlagSaturated, kFlagOffPatch, kFlagPeakMissing, kFlagBadContact (ruffini/frame.h)

class KernelTables;  // grating-averaged strain tables, one per contact radius

class SkinTwin {
 public:
  // sphere_probe_radii_mm: the spherical probes this twin will be asked about (a contact law is built for
  // each); a sphere contact of another radius is rejected with kFlagBadContact.
  // Throws InputError when an effect names a grating that does not exist.
  SkinTwin(const patch::PatchSpec& spec, const TwinEffects& effects,
           std::vector<double> sphere_probe_radii_mm = {5.5});
  ~SkinTwin();
  SkinTwin(SkinTwin&&) noexcept;

  // Noise-free strain shifts (pm) of the 16 gratings for a set of simultaneous contacts; contributions
  // superpose. A contact outside the patch contributes nothing and sets kFlagOffPatch; a non-finite or
  // negative force contributes nothing and sets kFlagBadContact. A sphere's force beyond the layer's linear
  // range (indentation > 30 % of the thickness: about 4 N for the 11 mm sphere) sets kFlagSaturated and
  // follows the hard-press law (the cover stiffens until it bottoms out; ContactLaw::HardForceN); a press
  // compressing the cover beyond hard_press.microbend_compression pinches the fibre: the gratings from the
  // pinch on along the fibre come out NaN (kFlagPeakMissing). A point-like probe saturates at the 11 mm
  // sphere's linear limit (flagged). InterrogatorSim reports out-of-band peaks where they are (flagged).
  // Real-time safe: no allocation, no lock, no throw.
  void StrainShiftsPm(std::span<const Contact> contacts, Shifts& shift_pm, std::uint32_t& flags) const noexcept;
  [[nodiscard]] Shifts StrainShiftsPm(const Contact& c) const noexcept;

  [[nodiscard]] const patch::PatchSpec& spec() const noexcept { return spec_; }
  [[nodiscard]] const TwinEffects& effects() const noexcept { return effects_; }
  [[nodiscard]] const patch::Geometry& geometry() const noexcept { return geometry_; }
  // The cast's unloaded peak positions (nominal + skin-sample offsets).
  [[nodiscard]] const std::array<double, patch::kGratings>& reference_wavelength_nm() const noexcept {
    return reference_nm_;
  }
  [[nodiscard]] const std::array<double, patch::kGratings>& gain() const noexcept { return gain_; }
  [[nodiscard]] const std::array<double, patch::kGratings>& temperature_pm_per_c() const noexcept {
    return temp_coeff_;
  }
  // Grating centres as cast (after skin-sample displacement).
  [[nodiscard]] const std::array<patch::SurfacePoint, patch::kGratings>& grating_centres() const noexcept {
    return centres_;
  }
  [[nodiscard]] double layer_thickness_mm() const noexcept { return thickness_mm_; }
  // The force-depth law for a sphere probe, or nullptr for a radius the twin was not built for.
  [[nodiscard]] const ContactLaw* contact_law(const Probe& p) const noexcept;

 private:
  struct LobeGeo {
    double y_mm, r_rad;      // lobe centre
    double cos_d, sin_d;     // fibre direction in the unrolled (Y, arc at fibre depth) plane
    double scale;            // gain * transfer * pm/strain
  };
  [[nodiscard]] double StiffeningFactor(double depth_mm) const noexcept;
  struct Source {
    double y_mm = 0.0, r_deg = 0.0, weight = 0.0;
  };
  // The contact and its edge images (effects.edges); returns how many of out are set.
  std::size_t Sources(const patch::SurfacePoint& at, std::array<Source, 4>& out) const noexcept;
  // The share of the footprint on the cover (free edges only), at least 1/4.
  [[nodiscard]] double CoverFraction(const patch::SurfacePoint& at, double contact_radius_mm) const noexcept;
  // Lowers pinched_from_s_mm to the fibre path length where a hard press at `at` pinches the fibre, if it does.
  void Pinch(const patch::SurfacePoint& at, double contact_radius_mm, double& pinched_from_s_mm) const noexcept;

  patch::PatchSpec spec_;
  TwinEffects effects_;
  patch::Geometry geometry_;
  double thickness_mm_;
  double depth_radius_mm_;  // radius of the cylinder the fibre lies on
  std::array<double, patch::kGratings> reference_nm_{}, gain_{}, temp_coeff_{};
  std::array<patch::SurfacePoint, patch::kGratings> centres_{};
  std::array<std::vector<LobeGeo>, patch::kGratings> lobes_;
  std::shared_ptr<const KernelTables> tables_;  // shared between twins with the same layer (cache)
  std::vector<double> law_radii_mm_;
  std::vector<ContactLaw> laws_;                // one per sphere radius
  double point_force_limit_n_ = 0.0;            // saturation force for point-like probes
  std::vector<double> path_y_mm_, path_arc_mm_, path_s_mm_;  // fibre path at the fibre's depth, unrolled
  std::array<double, patch::kGratings> grating_s_mm_{};       // each grating's centre along the path
};

// Per-stream interrogator state (holds a reference: the SkinTwin must outlive it and not be moved): turns strain shifts into the peak wavelengths an interrogator reports
// (reference + strain + temperature, clipped to the band, noise, faults). Real-time safe Read().
class InterrogatorSim {
 public:
  InterrogatorSim(const SkinTwin& twin, std::uint64_t seed);
  void Read(double t_s, const Shifts& strain_shift_pm, std::array<double, patch::kGratings>& wavelength_nm,
            std::uint32_t& flags) noexcept;
  [[nodiscard]] double TemperatureC(double t_s) const noexcept;

 private:
  const SkinTwin& twin_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
  std::uniform_real_distribution<double> uniform_{0.0, 1.0};
  std::array<double, patch::kGratings> noise_pm_{};
  std::array<double, patch::kGratings> dropout_{};
  std::array<bool, patch::kGratings> dead_{};
  std::array<double, patch::kGratings> field_c_{};  // the temperature field at each grating, full strength, C
};

// Splits one user seed into independent streams (SplitMix64), so adding a stream never shifts another.
std::uint64_t DeriveSeed(std::uint64_t seed, std::uint64_t stream) noexcept;

}  // namespace ruffini::twin
