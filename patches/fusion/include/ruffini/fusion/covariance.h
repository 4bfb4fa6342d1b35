#pragma once
// Covariance tools for fusing body-frame contact estimates: regularising a 3x3 covariance, covariance
// intersection (Julier and Uhlmann 1997) and the association gate. The math, the choices and their reasons
// are in docs/fusion.md.
//
// Units: positions in metres, covariances in m^2 (the frame is the caller's; the fuser uses the base frame B).
// Everything here is pure and real-time safe: no allocation, no lock, no throw. No function returns a NaN:
// a non-finite or non-covariance input is refused with a status and the output is left untouched.
#include <Eigen/Core>
#include <cstdint>

namespace ruffini::fusion {

// Every covariance the library fuses has its eigenvalues clamped into [kMinVariance_m2, kMaxVariance_m2]:
// 10 um sd (far below any skin's resolution; keeps a zero covariance invertible) up to 1 m sd (an estimate
// that only says "somewhere on the robot"). The ratio bounds the condition number at 1e10, so every
// inverse below keeps about six significant digits in its worst direction.
inline constexpr double kMinVariance_m2 = 1e-10;
inline constexpr double kMaxVariance_m2 = 1.0;

// A position estimate: mean x and covariance P.
struct Estimate {
  Eigen::Vector3d x = Eigen::Vector3d::Zero();
  Eigen::Matrix3d P = Eigen::Matrix3d::Identity();
};

enum class CovarianceStatus : std::uint8_t {
  kOk,
  kNotFinite,      // a NaN or infinite entry (mean or covariance)
  kNotCovariance,  // an eigenvalue clearly below 0 (below -1e-9 x the largest magnitude, or -kMinVariance_m2)
};
[[nodiscard]] const char* ToString(CovarianceStatus s) noexcept;

// Symmetrises P ((P + P^T) / 2) and clamps its eigenvalues into [min_var, max_var] (0 < min_var <= max_var).
// Small negative eigenvalues (rounding) are clamped too; a clearly negative one is kNotCovariance. On any
// status but kOk, P is unchanged.
[[nodiscard]] CovarianceStatus Regularize(Eigen::Matrix3d& P, double min_var = kMinVariance_m2,
                                          double max_var = kMaxVariance_m2) noexcept;

// Covariance intersection of two estimates of one quantity whose cross-correlation is unknown:
//   P^-1 = w Pa^-1 + (1 - w) Pb^-1,   x = P (w Pa^-1 a + (1 - w) Pb^-1 b),
// with w in [0, 1] minimising trace P. Both covariances are first regularised (Regularize, library bounds).
// tr P(w) is convex in w (matrix inversion is operator convex on positive-definite matrices and the
// argument is affine in w), so a fixed golden-section search (kCiIterations, bracket below 1e-10) finds the
// minimum. The ends are compared with it: when no interior w is better by more than 1e-12 (relative), the
// better end is taken and returns that input exactly (w = 1: a, w = 0: b); when the two ends tie too, tr P
// is flat on [0, 1] and w = 1/2 (equal covariances give the midpoint). Identical inputs return that
// estimate exactly (w = 1/2). The mean is computed as a + (1 - w) P Pb^-1 (b - a), algebraically the formula
// above but without its cancellation when a and b are close. *w_out (optional) receives w, the weight on a.
// The result is consistent whatever the correlation of a and b, its P is symmetric positive definite and
// tr P <= min(tr Pa, tr Pb) (of the regularised inputs).
inline constexpr int kCiIterations = 50;
[[nodiscard]] CovarianceStatus CovarianceIntersection(const Estimate& a, const Estimate& b, Estimate& out,
                                                      double* w_out = nullptr) noexcept;

// The association gate's statistic: the squared Mahalanobis distance of a.x - b.x in the plane orthogonal to
// the unit normal n, with covariance Pa + Pb projected onto that plane (2 degrees of freedom). The component
// along n is left out on purpose: it is not measured (the lift gives it a modelling variance only), and two
// patches' surfaces differ along it by mounting and thickness tolerances. +infinity when an input is not
// finite or the projected covariance is not positive definite.
[[nodiscard]] double TangentMahalanobis2(const Estimate& a, const Estimate& b, const Eigen::Vector3d& n) noexcept;

// Chi-square quantiles at 95 % used as gates.
inline constexpr double kChi2_2dof_95 = 5.991;
inline constexpr double kChi2_3dof_95 = 7.815;

}  // namespace ruffini::fusion
