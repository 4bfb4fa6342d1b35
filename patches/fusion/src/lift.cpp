#include "ruffini/fusion/lift.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <sstream>

#include "ruffini/error.h"
#include "ruffini/fusion/covariance.h"
#include "ruffini/patch/geometry.h"

namespace ruffini::fusion {

const char* ToString(Rejection r) noexcept {
  switch (r) {
    case Rejection::kNone: return "none";
    case Rejection::kUnknownPatch: return "unknown_patch";
    case Rejection::kDuplicatePatch: return "duplicate_patch";
    case Rejection::kNotFinite: return "not_finite";
    case Rejection::kNegativeForce: return "negative_force";
    case Rejection::kBadUncertainty: return "bad_uncertainty";
    case Rejection::kOutsidePatch: return "outside_patch";
    case Rejection::kBadPose: return "bad_pose";
  }
  return "unknown";
}

namespace {

void Require(bool ok, std::string_view where, std::string_view field, double value, std::string_view expected) {
  if (ok) return;
  std::ostringstream s;
  s << where << "." << field << " (" << value << ") must " << expected;
  throw InputError(s.str());
}

bool Finite(double v) noexcept { return std::isfinite(v); }

}  // namespace

void ValidateLiftConfig(const LiftConfig& c, std::string_view where) {
  Require(Finite(c.normal_sd_mm) && c.normal_sd_mm > 0 && c.normal_sd_mm <= 100, where, "normal_sd_mm",
          c.normal_sd_mm, "lie in (0, 100]");
  Require(Finite(c.min_surface_sd_mm) && c.min_surface_sd_mm > 0 && c.min_surface_sd_mm <= 100, where,
          "min_surface_sd_mm", c.min_surface_sd_mm, "lie in (0, 100]");
  Require(Finite(c.max_surface_sd_mm) && c.max_surface_sd_mm >= c.min_surface_sd_mm && c.max_surface_sd_mm <= 1000,
          where, "max_surface_sd_mm", c.max_surface_sd_mm, "lie in [min_surface_sd_mm, 1000]");
  Require(Finite(c.uncalibrated_sd_mm) && c.uncalibrated_sd_mm >= c.min_surface_sd_mm &&
              c.uncalibrated_sd_mm <= c.max_surface_sd_mm,
          where, "uncalibrated_sd_mm", c.uncalibrated_sd_mm, "lie in [min_surface_sd_mm, max_surface_sd_mm]");
  Require(Finite(c.outside_margin_mm) && c.outside_margin_mm >= 0 && c.outside_margin_mm <= 1000, where,
          "outside_margin_mm", c.outside_margin_mm, "lie in [0, 1000]");
  Require(Finite(c.outside_margin_deg) && c.outside_margin_deg >= 0 && c.outside_margin_deg <= 180, where,
          "outside_margin_deg", c.outside_margin_deg, "lie in [0, 180]");
}

void ValidatePatchShape(const FusionPatch& p, std::string_view where) {
  if (p.id.empty()) throw InputError(std::string(where) + ".id must not be empty");
  Require(Finite(p.extent_y_mm) && p.extent_y_mm > 0 && p.extent_y_mm <= 10000, where, "extent_y_mm",
          p.extent_y_mm, "lie in (0, 10000]");
  Require(Finite(p.extent_r_deg) && p.extent_r_deg > 0 && p.extent_r_deg <= 360, where, "extent_r_deg",
          p.extent_r_deg, "lie in (0, 360]");
  Require(Finite(p.mount.surface_radius_mm) && p.mount.surface_radius_mm > 0 && p.mount.surface_radius_mm <= 1000,
          where, "mount.surface_radius_mm", p.mount.surface_radius_mm, "lie in (0, 1000]");
}

Eigen::Matrix3d PatchCoveringMoment_P(const FusionPatch& patch) noexcept {
  const double rho_m = patch.mount.surface_radius_mm * 1e-3;
  const double c = 0.5 * patch.extent_r_deg * patch::kDegToRad;  // centre angle
  const double h = c;                                              // half-width, rad
  const double L_m = patch.extent_y_mm * 1e-3;
  // theta = R - c uniform on [-h, h]; offsets from the centre point: tangential rho sin(theta), normal
  // rho (cos(theta) - 1); along the limb uniform on [-L/2, L/2]. The cross moments vanish by symmetry.
  const double s2h = std::sin(2.0 * h) / (4.0 * h);
  const double sh = std::sin(h) / h;
  const double m_yy = L_m * L_m / 12.0;
  const double m_tt = std::max(0.0, rho_m * rho_m * (0.5 - s2h));
  const double m_nn = std::max(0.0, rho_m * rho_m * (1.5 + s2h - 2.0 * sh));
  const Eigen::Vector3d e_y = Eigen::Vector3d::UnitY();
  const Eigen::Vector3d e_t(std::cos(c), 0.0, -std::sin(c));
  const Eigen::Vector3d e_n(std::sin(c), 0.0, std::cos(c));
  return m_yy * e_y * e_y.transpose() + m_tt * e_t * e_t.transpose() + m_nn * e_n * e_n.transpose();
}

Rejection Lift(const FusionPatch& patch, const Eigen::Isometry3d& X_BL, const SurfaceContact& c,
               const LiftConfig& config, LiftedContact& out, const Eigen::Matrix2d* surface_cov_mm2) noexcept {
  if (!Finite(c.force_n) || !Finite(c.force_sd_n) || !Finite(c.y_mm) || !Finite(c.r_deg) || !Finite(c.cov_yy_mm2) ||
      !Finite(c.cov_ys_mm2) || !Finite(c.cov_ss_mm2)) {
    return Rejection::kNotFinite;
  }
  if (c.force_n < 0) return Rejection::kNegativeForce;
  if (c.uncertainty_calibrated) {
    if (c.force_sd_n < 0) return Rejection::kBadUncertainty;
    if (c.located && (c.cov_yy_mm2 < 0 || c.cov_ss_mm2 < 0 ||
                      c.cov_ys_mm2 * c.cov_ys_mm2 > c.cov_yy_mm2 * c.cov_ss_mm2 * (1.0 + 1e-6) + 1e-12)) {
      return Rejection::kBadUncertainty;
    }
  }
  if (c.located && (c.y_mm < -config.outside_margin_mm || c.y_mm > patch.extent_y_mm + config.outside_margin_mm ||
                    c.r_deg < -config.outside_margin_deg || c.r_deg > patch.extent_r_deg + config.outside_margin_deg)) {
    return Rejection::kOutsidePatch;
  }
  if (!X_BL.matrix().allFinite()) return Rejection::kBadPose;

  const Eigen::Isometry3d X_BP = X_BL * patch.mount.X_LP;
  const Eigen::Matrix3d R_BP = X_BP.linear();
  const double sigma_n_m = config.normal_sd_mm * 1e-3;
  const patch::Geometry geometry(patch.mount.surface_radius_mm);
  LiftedContact r;
  r.force_n = c.force_n;
  r.uncertainty_calibrated = c.uncertainty_calibrated;
  r.force_var_n2 = c.uncertainty_calibrated ? c.force_sd_n * c.force_sd_n : 0.0;
  r.located = c.located;
  if (c.located) {
    const patch::SurfacePoint s{c.y_mm, c.r_deg};
    r.p_BC_m = X_BP * geometry.PointM(s);
    r.n_B = R_BP * geometry.NormalAt(s);
    Eigen::Matrix2d C;  // mm^2 on (Y, arc)
    if (surface_cov_mm2 != nullptr) {
      C = *surface_cov_mm2;
    } else if (c.uncertainty_calibrated) {
      C << c.cov_yy_mm2, c.cov_ys_mm2, c.cov_ys_mm2, c.cov_ss_mm2;
    } else {
      C = config.uncalibrated_sd_mm * config.uncalibrated_sd_mm * Eigen::Matrix2d::Identity();
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig;
    eig.computeDirect(C);
    Eigen::Vector2d lambda = eig.eigenvalues();
    const double lo = config.min_surface_sd_mm * config.min_surface_sd_mm;
    const double hi = config.max_surface_sd_mm * config.max_surface_sd_mm;
    for (int i = 0; i < 2; ++i) lambda[i] = std::clamp(Finite(lambda[i]) ? lambda[i] : hi, lo, hi);
    C = eig.eigenvectors() * lambda.asDiagonal() * eig.eigenvectors().transpose();
    const double a = c.r_deg * patch::kDegToRad;
    Eigen::Matrix<double, 3, 2> J;  // m per mm
    J.col(0) = R_BP * Eigen::Vector3d::UnitY() * 1e-3;
    J.col(1) = R_BP * Eigen::Vector3d(std::cos(a), 0.0, -std::sin(a)) * 1e-3;
    r.cov_p_BC_m2 = J * C * J.transpose() + sigma_n_m * sigma_n_m * r.n_B * r.n_B.transpose();
  } else {
    const patch::SurfacePoint centre{0.5 * patch.extent_y_mm, 0.5 * patch.extent_r_deg};
    r.p_BC_m = X_BP * geometry.PointM(centre);
    r.n_B = R_BP * geometry.NormalAt(centre);
    r.cov_p_BC_m2 = R_BP * PatchCoveringMoment_P(patch) * R_BP.transpose() +
                    sigma_n_m * sigma_n_m * r.n_B * r.n_B.transpose();
  }
  r.n_B.normalize();
  if (Regularize(r.cov_p_BC_m2) != CovarianceStatus::kOk || !r.p_BC_m.allFinite() || !r.n_B.allFinite()) {
    return Rejection::kBadPose;  // only a degenerate pose (finite but huge) gets here
  }
  out = r;
  return Rejection::kNone;
}

}  // namespace ruffini::fusion
