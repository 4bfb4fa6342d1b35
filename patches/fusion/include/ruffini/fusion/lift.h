#pragma once
// Lifting one patch contact into the robot's base frame B: patch coordinates (Y mm, R deg, a 2x2 surface
// covariance in mm^2) -> a point, an outward normal and a 3x3 position covariance in B (m, m^2).
//
// The surface covariance is on the axes (Y mm, arc length mm = surface radius x R in rad), as
// ruffini.v1.PatchContact carries it. At the contact point the surface has two unit tangents, t_Y (along the
// limb, +Y) and t_s (around it, +R); the covariance maps through J = [t_Y t_s] (in B, x 1e-3 m/mm):
//     cov_p_BC = J C J^T + sigma_n^2 n n^T,
// the second term a small stated variance along the normal (LiftConfig::normal_sd_mm) so the 3x3 is
// positive definite. An unlocated contact (force only) sits at the patch's centre with the second moments of
// a point uniform over the whole curved patch about that centre (docs/fusion.md derives them).
//
// Pure and real-time safe: no allocation, no lock, no throw (ValidateLiftConfig excepted).
#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "ruffini/robot/mount.h"

namespace ruffini::fusion {

// A patch as fusion sees it: its id, where it is mounted and how far it extends.
struct FusionPatch {
  std::string id;                // the scene's patch id
  robot::PatchMount mount;       // link, X_LP, surface_radius_mm
  double extent_y_mm = 150.0;    // the patch spans Y in [0, extent_y_mm] (PatchSpec::extent_y_mm)
  double extent_r_deg = 145.0;   // and R in [0, extent_r_deg] (PatchSpec::extent_r_deg), <= 360
};

// One decoded contact in patch coordinates (ruffini.v1.PatchContact without the protobuf).
struct SurfaceContact {
  double force_n = 0.0;      // >= 0
  double force_sd_n = 0.0;   // 1-sigma of force_n; meaningful when uncertainty_calibrated
  bool located = false;      // false: force only; y_mm, r_deg and the covariance are ignored
  double y_mm = 0.0;
  double r_deg = 0.0;
  double cov_yy_mm2 = 0.0;   // variance of Y
  double cov_ys_mm2 = 0.0;   // covariance of Y and arc length
  double cov_ss_mm2 = 0.0;   // variance of arc length
  bool uncertainty_calibrated = false;  // false: force_sd_n and the covariance are 0 and mean nothing
};

struct LiftConfig {
  // Standard deviation along the surface normal, mm: not measured, a modelling allowance (skin compression,
  // mount tolerance) that also makes the 3x3 covariance positive definite.
  double normal_sd_mm = 0.5;
  // The surface covariance's eigenvalues are clamped into [min_surface_sd_mm^2, max_surface_sd_mm^2]: no
  // decoder is better than about half a millimetre (an ideal one reaches 0.6 mm, FACTS), and none is worse
  // than the patch itself.
  double min_surface_sd_mm = 0.5;
  double max_surface_sd_mm = 1000.0;
  // A located contact without calibrated uncertainty gets this sd on both surface axes, mm: about the
  // 5-fold CV error of the coarsest single grid (12.5 mm), 3 to 4 times the paper's 3.2-3.6 mm median.
  double uncalibrated_sd_mm = 12.5;
  // A located contact further than this outside the patch's extent is refused (kOutsidePatch), mm and deg.
  double outside_margin_mm = 10.0;
  double outside_margin_deg = 10.0;
};
// Throws InputError naming the field and value, prefixed by `where` (e.g. "fusion.lift").
void ValidateLiftConfig(const LiftConfig& c, std::string_view where);
// Throws InputError if the patch's id is empty, its extents are not finite and positive (extent_r_deg <=
// 360) or the radius is not finite and positive. The mount's link is checked by robot::ValidateMount.
void ValidatePatchShape(const FusionPatch& p, std::string_view where);

// Why an input contact was refused. Counted by the fuser, one counter per reason.
enum class Rejection : std::uint8_t {
  kNone = 0,
  kUnknownPatch,     // a patch index the fuser does not have
  kDuplicatePatch,   // a second contact from the same patch in one update (the first one is kept)
  kNotFinite,        // a NaN or infinite field (force, sd, position, covariance)
  kNegativeForce,    // force_n < 0
  kBadUncertainty,   // force_sd_n < 0, a negative variance, or |cov_ys| > sqrt(cov_yy cov_ss) (not a covariance)
  kOutsidePatch,     // a located position further than the margins outside the patch
  kBadPose,          // X_BL not finite, or no pose for the patch's link
};
inline constexpr std::size_t kRejectionCount = 8;
[[nodiscard]] const char* ToString(Rejection r) noexcept;

// A contact in the base frame B.
struct LiftedContact {
  Eigen::Vector3d p_BC_m = Eigen::Vector3d::Zero();  // the contact point C (unlocated: the patch's centre)
  Eigen::Vector3d n_B = Eigen::Vector3d::UnitZ();    // outward unit normal at C
  Eigen::Matrix3d cov_p_BC_m2 = Eigen::Matrix3d::Identity();  // covariance of p_BC_m, m^2, symmetric PD
  double force_n = 0.0;
  double force_var_n2 = 0.0;   // variance of force_n, N^2 (0 when not calibrated)
  bool located = false;
  bool uncertainty_calibrated = false;
};

// Lifts c (a contact on `patch`) into B, given the pose of the patch's link in B (X_BL, from robot FK).
// Returns kNone and fills out, or the reason it refused c (out untouched). Never produces a NaN.
// Real-time safe: no allocation, no lock, no throw.
// surface_cov_mm2 (located contacts only): the surface covariance to use instead of the contact's own (or the
// uncalibrated default); clamped like any other.
[[nodiscard]] Rejection Lift(const FusionPatch& patch, const Eigen::Isometry3d& X_BL, const SurfaceContact& c,
                             const LiftConfig& config, LiftedContact& out,
                             const Eigen::Matrix2d* surface_cov_mm2 = nullptr) noexcept;

// The 3x3 second-moment matrix, in the patch frame P (m^2), of a point uniform over the patch's surface about
// its centre (Y = extent_y/2, R = extent_r/2), without the normal allowance. Used for unlocated contacts.
[[nodiscard]] Eigen::Matrix3d PatchCoveringMoment_P(const FusionPatch& patch) noexcept;

}  // namespace ruffini::fusion
