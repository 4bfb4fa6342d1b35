#pragma once
// Contact mechanics of a probe pressed into the bonded silicone layer.
// Force-depth law: Dimitriadis et al. (2002), a sphere indenting a thin elastic layer bonded to a rigid
// substrate, F = 4E/(3(1-nu^2)) R^1/2 d^3/2 * P(chi), chi = sqrt(R d)/h, with the bonded-case polynomial
// P = 1 - 2a/pi chi + 4a^2/pi^2 chi^2 - 8/pi^3 (a^3 + 4 pi^2 b/15) chi^3 + 16a/pi^4 (a^3 + 3 pi^2 b/5) chi^4,
// a = -(1.2876 - 1.4678 nu + 1.3442 nu^2)/(1-nu), b = (0.6387 - 1.0277 nu + 1.5164 nu^2)/(1-nu).
// Contact radius a_c = sqrt(R d) (geometric), capped at the probe radius.
//
// Hard presses (beyond kLinearCompressionLimit of nominal compression d/h): the cover stiffens until it
// bottoms out on the limb. HardForceN(d) = ForceN(d) * B(d) / B(d_lin), B = the Yeoh material's nominal
// uniaxial stress at the stretch lambda = 1 - d/h over its small-strain (linear) value:
//   B(lambda) = 2 (lambda - lambda^-2) W1(I1) / (6 C1 (lambda - 1)),  W1 = C1 + 2 C2 (I1-3) + 3 C3 (I1-3)^2,
//   I1 = lambda^2 + 2/lambda  (incompressible uniaxial compression; Yeoh 1993, Rubber Chem. Technol. 66(5)).
// B -> 1 at small strain and grows without bound as lambda -> 0: the force needed to push the probe to the
// limb diverges (bottoming out). Below the linear limit nothing changes (ForceN, DepthMm are the paper's).
// The strain field of a hard press is that of the linear layer indented to the same depth
// (StrainForceN = ForceN(HardDepthMm(F))): the stiffening raises the force, the far field follows the
// displacement imposed.
#include <vector>

namespace ruffini::twin {

// The Yeoh constants of the cover (Pa): the hard-press law's stiffening.
struct Yeoh {
  double c1_pa = 36e3, c2_pa = 258.0, c3_pa = -0.56;
};

struct Probe {
  enum class Shape { kSphere, kPoint };
  Shape shape = Shape::kSphere;
  double radius_mm = 5.5;  // sphere radius, or the tip radius of a point-like probe (von Frey filament)
};

class ContactLaw {
 public:
  ContactLaw(double thickness_mm, double youngs_modulus_kpa, double poisson_ratio, double probe_radius_mm,
             Yeoh yeoh = {});

  [[nodiscard]] double ForceN(double depth_mm) const noexcept;  // Dimitriadis law
  // Inverse of ForceN (monotone); forces beyond the table's end return the deepest depth. noexcept, O(1).
  [[nodiscard]] double DepthMm(double force_n) const noexcept;
  [[nodiscard]] double ContactRadiusMm(double force_n) const noexcept;
  [[nodiscard]] double max_depth_mm() const noexcept { return max_depth_mm_; }
  // Beyond 30 % nominal compression (depth / thickness) linear elasticity no longer describes the layer:
  // the twin saturates the response at this force and flags the frame.
  static constexpr double kLinearCompressionLimit = 0.3;
  [[nodiscard]] double linear_limit_force_n() const noexcept { return f_lin_; }

  // Hard presses. Depth at which the twin stops: the cover is bottomed out (98 % nominal compression).
  static constexpr double kBottomCompression = 0.98;
  [[nodiscard]] double HardForceN(double depth_mm) const noexcept;       // = ForceN up to the linear limit
  // Inverse of HardForceN, monotone; = DepthMm up to the linear limit (bit for bit); beyond the bottomed-out
  // force, the bottom depth. noexcept, O(log n) at most.
  [[nodiscard]] double HardDepthMm(double force_n) const noexcept;
  // The linear-layer force whose strain field the twin uses for a press of force_n (= force_n up to the limit).
  [[nodiscard]] double StrainForceN(double force_n) const noexcept;
  [[nodiscard]] double bottom_depth_mm() const noexcept { return kBottomCompression * h_; }
  [[nodiscard]] double thickness_mm() const noexcept { return h_; }

 private:
  double h_, e_eff_mpa_, radius_, alpha_, beta_;
  double max_depth_mm_;
  double df_;                    // force step of the inverse table
  std::vector<double> depth_of_force_;
  [[nodiscard]] double Stiffening(double depth_mm) const noexcept;  // B(1 - d/h)
  Yeoh yeoh_;
  double f_lin_ = 0.0, b_lin_ = 1.0;
  double log_f_lin_ = 0.0, dlog_f_ = 0.0;  // the hard table: uniform in log force from f_lin_
  std::vector<double> hard_depth_;
};

}  // namespace ruffini::twin
