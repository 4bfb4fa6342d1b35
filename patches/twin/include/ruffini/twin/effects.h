#pragma once
// The effects a scene may ask the twin to model. Each is optional: absent means not built, not simulated.
#include <array>
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

// Temperature: dT(t) = offset_c + amplitude_c sin(2 pi t / period_s) + ramp_c_per_s t
//                     + triangle(t) + knots(t),
// shifting every grating by coefficient_pm_per_c * (1 + spread * n_i) per degree, n_i ~ N(0,1) per grating.
//   triangle(t): zero-mean triangle wave rising at triangle_rate_c_per_h for the first quarter period, falling
//     for half a period, rising again: a "+-10 C/h" ramp up and down, amplitude rate * period / 4.
//   knots(t): piecewise-linear through the knots (strictly increasing t_s), held at the first / last value
//     outside them; a step is two knots a short time apart. No knots: 0.
// FBG thermal sensitivity: d lambda / dT = (alpha + xi) lambda ~ 10 pm/C at 1550 nm (Kersey et al., "Fiber
// grating sensors", J. Lightwave Technol. 15(8), 1997, for the physics; Cosme et al., "Accurate determination
// of the temperature sensitivity of UV-induced fiber Bragg gratings", PMC12846186: (alpha + xi) = 5.2e-6 to
// 6.7e-6 /K at 20 C in Ge-doped fibres, i.e. 8.0 to 10.4 pm/K at 1550 nm).
struct TemperatureKnot {
  double t_s = 0.0;
  double c = 0.0;
};
struct TemperatureEffect {
  double offset_c = 0.0;
  double amplitude_c = 0.0;
  double period_s = 600.0;
  double ramp_c_per_s = 0.0;
  double coefficient_pm_per_c = 10.0;
  double spread = 0.03;
  double triangle_rate_c_per_h = 0.0;
  double triangle_period_s = 3600.0;
  std::vector<TemperatureKnot> knots;
  // A field across the patch on top of dT(t) (docs/twin.md, "Temperature fields"): grating i at (Y_i, R_i) sees
  //   dT_i(t) = dT(t) + s(t) [gradient_along_c (1/2 - Y_i / extent_y) + gradient_around_c / 2 cos(R_i - R_warm)]
  // with s(t) = 1 - exp(-t / gradient_tau_s) (0 s: s = 1 from the start): the elbow end warmer than the wrist
  // end by gradient_along_c (a warm joint motor), and one side warmer than the other by gradient_around_c
  // (sunlight, a lamp), both building up with the time constant.
  double gradient_along_c = 0.0;
  double gradient_around_c = 0.0;
  double gradient_around_r_deg = 0.0;  // R_warm: where around the limb it is warmest
  double gradient_tau_s = 0.0;
  // Thermal strain: the cover's expansion carried into the fibre, pm/C added to the bare grating's
  // coefficient_pm_per_c (0: a bare grating's response; a grating embedded in silicone measures several times it).
  double strain_pm_per_c = 0.0;

  // dT at time t (the uniform part). Real-time safe: no allocation, no lock, no throw.
  [[nodiscard]] double AtC(double t_s) const noexcept;
  // The field's build-up s(t) in [0, 1]. Real-time safe.
  [[nodiscard]] double GradientScale(double t_s) const noexcept;
  // The field's part at (y_frac = Y / extent_y, r_deg) at full strength (s = 1), C.
  [[nodiscard]] double FieldC(double y_frac, double r_deg) const noexcept;
};

// Viscoelastic silicone: creep under a held load, a different unloading path, and a residual after release
// that fades. The strain the gratings see follows an effective force
//   F_eff(t) = F(t) + sum_k g_k x_k(t),   dx_k/dt = (F(t) - x_k) / tau_k,
// i.e. a creep compliance J(t) = J0 [1 + sum_k g_k (1 - exp(-t / tau_k))] (a Prony series, Boltzmann
// superposition). Under a held load the response creeps up by sum g_k; after release it decays to zero with
// the tau_k (a "phantom contact"); loading and unloading differ at the same force (hysteresis).
// Source (silicones of the Dragon Skin / Ecoflex family): see ViscoelasticFilter (viscoelastic.h) and
// docs/twin.md, "Field effects".
struct PronyTerm {
  double g = 0.0;      // relative creep amplitude of the term
  double tau_s = 1.0;  // retardation time
};
struct ViscoelasticEffect {
  std::vector<PronyTerm> terms = {{0.05, 1.0}, {0.04, 10.0}, {0.03, 100.0}};
  [[nodiscard]] double total_creep() const noexcept {
    double s = 0.0;
    for (const auto& t : terms) s += t.g;
    return s;
  }
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

// Hard presses (always modelled; a scene's `hard_press:` only changes the parameters). Beyond the layer's
// linear range the contact law stiffens until the cover bottoms out (ContactLaw::HardForceN). Once the cover
// under a sphere is compressed beyond microbend_compression (depth / thickness), the fibre where it passes
// under the probe (within the contact radius + pinch_margin_mm of its centre, at the fibre's depth) is pinched
// against the limb: microbending loss there, in both directions of the reflected light, darkens every grating
// from that point on along the fibre, and a grating under the probe is split by the transverse load (its
// peak is lost). See docs/twin.md, "Hard presses".
struct HardPressParams {
  double microbend_compression = 0.6;
  double pinch_margin_mm = 1.0;
};

// The cover ends at the patch's edges (docs/twin.md, "Edges"). Each edge (Y = 0, Y = extent, R = 0,
// R = extent) is `continued` (the layer goes on: a seam with a neighbouring cover; the old behaviour),
// `free` (the cover ends: traction-free face) or `bonded` (the cover's end face is glued to a rigid rim).
// Within zone_mm of a free or bonded edge a contact gets an image mirrored across the edge (Hetenyi's
// method for the elastic quarter-space, its first term) of gain free_image_gain (a traction-free face) or
// bonded_image_gain (a clamped face), tapered linearly to 0 from zone_mm / 2 to zone_mm; and at a free edge
// the part of the probe's footprint still on the cover carries the whole force (it is indented as deep as
// the whole footprint would be by F / fraction). Contacts farther than zone_mm from every such edge are
// computed exactly as without edges.
struct EdgeEffect {
  enum class Kind { kContinued, kFree, kBonded };
  std::array<Kind, 4> kind{Kind::kFree, Kind::kFree, Kind::kFree, Kind::kFree};  // y_min, y_max, r_min, r_max
  double free_image_gain = 1.0;
  double bonded_image_gain = -1.0;
  double zone_mm = 12.0;
};

struct TwinEffects {
  std::optional<NoiseEffect> noise;
  std::optional<GainSpreadEffect> gain_spread;
  std::optional<IrregularEffect> irregular;
  std::optional<StiffeningEffect> stiffening;
  std::optional<TemperatureEffect> temperature;
  std::optional<ViscoelasticEffect> viscoelastic;
  std::vector<FaultEffect> faults;
  std::optional<SkinSampleEffect> skin_sample;
  HardPressParams hard_press;  // always on (defaults); not in Summary() unless named
  std::optional<EdgeEffect> edges;
  bool hard_press_named = false;

  // The seed for everything fabrication draws (gains, temperature spread, positions).
  [[nodiscard]] std::uint64_t fabrication_seed() const { return skin_sample ? skin_sample->seed : 0; }
  // One line naming the effects that are on, for dataset provenance.
  [[nodiscard]] std::string Summary() const;
};

}  // namespace ruffini::twin
