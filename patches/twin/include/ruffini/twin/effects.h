#pragma once
// The effects a scene may ask the twin to model. Each is optional: absent means not built, not simulated.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace ruffini::twin {

// Interrogator read noise, Gaussian, per grating per frame.
struct NoiseEffect {
  double sigma_pm = 0.3;
};

// Per-grating sensitivity spread from fabrication (drawn from the skin sample seed).
struct GainSpreadEffect {
  double sigma = 0.07;  // relative, 1-sigma
};

// A response lobe of a grating: where (relative to the grating centre, in its own frame: along the fibre
// and across it, mm) and how strongly (relative gain) the grating picks up strain.
struct Lobe {
  double along_mm = 0.0;
  double across_mm = 0.0;
  double gain = 1.0;
};
// Gratings whose receptive field is not one clean spot (the paper's 2, 12, 13: two areas; 6: clustered
// sub-regions). Their lobes replace the single lobe {0, 0, 1}.
struct IrregularGrating {
  int grating = 0;  // 1-based, as the paper numbers them
  std::vector<Lobe> lobes;
};
struct IrregularEffect {
  std::vector<IrregularGrating> gratings;
};

// Hyperelastic stiffening (Yeoh) of the silicone under the probe at high force.
struct StiffeningEffect {};

// Temperature: dT(t) = offset_c + amplitude_c sin(2 pi t / period_s) + ramp_c_per_s t, shifting every
// grating by coefficient_pm_per_c * (1 + spread * n_i) per degree, n_i ~ N(0,1) per grating.
struct TemperatureEffect {
  double offset_c = 0.0;
  double amplitude_c = 0.0;
  double period_s = 600.0;
  double ramp_c_per_s = 0.0;
  double coefficient_pm_per_c = 10.0;
  double spread = 0.03;
};

// A grating whose peak is lost (dead) or weak (dimmed: more noise, the peak dropping out at times).
struct FaultEffect {
  enum class Kind { kDead, kDimmed };
  int grating = 0;  // 1-based
  Kind kind = Kind::kDead;
  double dropout = 0.0;       // dimmed: probability a frame misses the peak
  double noise_factor = 1.0;  // dimmed: noise multiplier
};

// One cast of the design: grating positions moved by up to position_mm, layer thickness by thickness_sigma
// (relative, 1-sigma, clipped at 3 sigma), reference wavelengths by up to wavelength_nm.
struct SkinSampleEffect {
  std::uint64_t seed = 0;
  double position_mm = 1.0;
  double thickness_sigma = 0.03;
  double wavelength_nm = 0.05;
};

struct TwinEffects {
  std::optional<NoiseEffect> noise;
  std::optional<GainSpreadEffect> gain_spread;
  std::optional<IrregularEffect> irregular;
  std::optional<StiffeningEffect> stiffening;
  std::optional<TemperatureEffect> temperature;
  std::vector<FaultEffect> faults;
  std::optional<SkinSampleEffect> skin_sample;

  // The seed for everything fabrication draws (gains, temperature spread, positions).
  [[nodiscard]] std::uint64_t fabrication_seed() const { return skin_sample ? skin_sample->seed : 0; }
  // One line naming the effects that are on, for dataset provenance.
  [[nodiscard]] std::string Summary() const;
};

}  // namespace ruffini::twin
