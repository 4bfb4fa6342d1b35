#pragma once
// Fusion across patches: the aggregator's patch contacts of one instant -> body-frame contacts.
//
//   fusion::Fuser fuser(model, config);           // validates; throws InputError naming the field
//   fusion::FusionData data;                      // fixed-size; one per thread
//   robot::ForwardKinematics(model, q, fk);       // link poses X_BL
//   fuser.Update(inputs, fk.X_BL, data);          // data.contacts() now holds the fused contacts
//
// Shape (Pinocchio's Model/Data, like robot::ForwardKinematics): the const Fuser holds what the scene fixes
// (patches, mounts, which links are adjacent, the gate); a FusionData holds the scratch, the output and the
// counters. FusionData is fixed-size (at most kMaxPatches contacts in and out), so neither making one nor
// Update allocates.
//
// One Update:
//  1. every input is checked and lifted into B (lift.h); a refused one is counted by reason and dropped;
//  2. the lifted contacts are visited in ascending patch index (so the result does not depend on the order
//     of `inputs`); each joins the existing body contact it is nearest to under the gate, or starts a new one.
//     A contact may join a body contact when (a) no contribution from its patch is in it yet, (b) its link is
//     the same as or adjacent to every contributor's link, (c) at least one of the two is located (two
//     force-only contacts carry no evidence of a shared place and are never merged), (d) when both are
//     located, their normals are within max_normal_angle_deg, and (e) the squared Mahalanobis distance of
//     the two positions on the tangent plane (2 dof, covariance.h) is at most gate_chi2 (5.991: 95 %);
//  3. joining fuses pairwise, in that deterministic order: positions by covariance intersection (the
//     patches' errors are correlated in unknown ways: both come from one indenter, one joint state, one
//     calibration rig), forces and force variances SUMMED (a contact on a seam loads both patches, each
//     reports its part), normals averaged over the located contributors and renormalised.
// Why 2 dof on the tangent plane rather than 3 dof in space: docs/fusion.md (short: the normal component is
// not measured, and neighbouring patches' surfaces legitimately differ along it by millimetres).
#include <Eigen/Geometry>
#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "ruffini/fusion/covariance.h"
#include "ruffini/fusion/lift.h"
#include "ruffini/robot/model.h"

namespace ruffini::fusion {

inline constexpr std::size_t kMaxPatches = 64;  // patches per robot (one bit each in BodyContact::patches)

struct FusionConfig {
  std::vector<FusionPatch> patches;  // 1..kMaxPatches, ids unique; a patch's index is its place here
  // Links whose contacts may be fused, besides two patches on the same link: the model's parent-child pairs
  // (when adjacent_from_model), plus these pairs of URDF link names.
  bool adjacent_from_model = true;
  std::vector<std::pair<std::string, std::string>> adjacent_links;
  double gate_chi2 = kChi2_2dof_95;     // (0, 1e6]
  double max_normal_angle_deg = 45.0;   // (0, 180]
  bool fuse_unlocated = true;           // false: a force-only contact is never merged with anything
  LiftConfig lift;
  // Seams (robot::FindSeams over the patches' mounts, indices into `patches`) with their bands: how far from
  // the seam each side's decoder may place a touch that is on the seam (band_a_mm for patch a, mm on the
  // surface; 0: no seam rule). See "Seams" in docs/fusion.md.
  struct SeamBand {
    robot::Seam seam;
    double band_a_mm = 0.0, band_b_mm = 0.0;
  };
  std::vector<SeamBand> seams;  // at most kMaxSeams
  // Two contacts are one touch on their seam only if they agree along it: the distance between their places on
  // the seam within the 95 % gate (1 dof) of their along-seam variances plus this floor's, per side (mm): the
  // probe's footprint, and the edge decoders' along-seam sd being overconfident near a seam (docs/fusion.md).
  double seam_along_floor_mm = 5.0;
};

inline constexpr std::size_t kMaxSeams = 4 * 64;  // four edges per patch, kMaxPatches patches
inline constexpr double kChi2_1dof_95 = 3.841;

// Both contacts may lie on their seam (docs/fusion.md, "Seams"): both located, each within its side's band of
// the seam plus 2 sd of its own across it, and the seam has both bands. pa/ca are seam.a's, pb/cb seam.b's.
// Real-time safe.
[[nodiscard]] bool MayBeOnSeam(const FusionConfig::SeamBand& sb, const FusionPatch& pa, const SurfaceContact& ca,
                               const FusionPatch& pb, const SurfaceContact& cb, const LiftConfig& lift) noexcept;

// One side's contact may lie on the seam: located, within that side's band plus 2 sd of its own across it.
[[nodiscard]] bool SideMayBeOnSeam(const FusionConfig::SeamBand& sb, bool side_a, const FusionPatch& p,
                                   const SurfaceContact& c, const LiftConfig& lift) noexcept;
// The squared gate distance (1 dof) between the two contacts' places along their seam, each moved onto it:
// the distance between them over their along-seam variances plus 2 along_floor_mm^2. +inf for NaN.
[[nodiscard]] double AlongSeamD2(const FusionConfig::SeamBand& sb, const FusionPatch& pa, const SurfaceContact& ca,
                                 const FusionPatch& pb, const SurfaceContact& cb, const LiftConfig& lift,
                                 double along_floor_mm) noexcept;
// One probe across the seam may explain both contacts: MayBeOnSeam, and they agree along the seam
// (AlongSeamD2 <= kChi2_1dof_95 with config.seam_along_floor_mm). ca is seam.a's, cb seam.b's. Real-time safe.
[[nodiscard]] bool OneTouchOnSeam(const FusionConfig& config, const FusionConfig::SeamBand& sb, const SurfaceContact& ca,
                                  const SurfaceContact& cb) noexcept;

// One patch's contact at this instant. `patch` indexes FusionConfig::patches (Fuser::FindPatch).
struct PatchInput {
  std::size_t patch = 0;
  SurfaceContact contact;
};

// A fused contact on the robot's body, base frame B.
struct BodyContact {
  std::size_t link = 0;  // model link index: the link of the contributor with the largest force (the first on ties)
  Eigen::Vector3d p_BC_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d n_B = Eigen::Vector3d::UnitZ();            // outward unit normal
  Eigen::Matrix3d cov_p_BC_m2 = Eigen::Matrix3d::Identity();  // symmetric positive definite, m^2
  double force_n = 0.0;        // the sum of the contributors' forces
  double force_var_n2 = 0.0;   // the sum of their variances (those without calibration add 0)
  bool located = false;        // some contributor was located (false: p_BC_m is a patch's centre)
  bool uncertainty_calibrated = false;  // every contributor had calibrated uncertainty
  std::uint64_t patches = 0;   // bit i: patch i contributed
  std::size_t num_patches = 0;
  [[nodiscard]] bool HasPatch(std::size_t i) const noexcept { return i < kMaxPatches && ((patches >> i) & 1u); }
};

// Plain counters (cumulative over the Data's life); a service copies them into its metrics.
struct FusionCounters {
  std::uint64_t updates = 0;
  std::uint64_t inputs = 0;
  std::uint64_t accepted = 0;
  std::uint64_t merges = 0;  // pairwise fusions performed
  std::uint64_t seam_pairs = 0;     // pairs of contacts placed on their seam (FusionConfig::seams)
  std::uint64_t seam_mixtures = 0;  // of them, two places along the seam made one covering contact
  std::array<std::uint64_t, kRejectionCount> rejected{};  // by Rejection value (kNone unused)
  [[nodiscard]] std::uint64_t rejected_total() const noexcept;
};

class Fuser;

// Per-thread state of a Fuser: scratch, the latest result and counters. Fixed-size: making one allocates
// nothing; it holds no reference to its Fuser.
struct FusionData {
  [[nodiscard]] std::span<const BodyContact> contacts() const noexcept { return {contacts_.data(), num_contacts_}; }
  FusionCounters counters;
  Rejection last_rejection = Rejection::kNone;  // the newest refused input's reason (kNone: none yet)

 private:
  friend class Fuser;
  struct Cluster {
    Estimate estimate;
    Eigen::Vector3d normal_sum = Eigen::Vector3d::Zero();  // sum of located contributors' normals
    double max_force_n = -1.0;
    std::uint32_t links = 0;  // bit per model link of the contributors
  };
  std::array<BodyContact, kMaxPatches> contacts_{};
  std::size_t num_contacts_ = 0;
  std::array<LiftedContact, kMaxPatches> lifted_{};
  std::array<SurfaceContact, kMaxPatches> input_{};
  std::array<bool, kMaxPatches> have_{};
  std::array<Cluster, kMaxPatches> clusters_{};
};

class Fuser {
 public:
  // Validates config against the model (every mount via robot::ValidateMount, every adjacent link name);
  // throws InputError whose message names the field, e.g. "fusion.patches[1].id ('forearm') is a duplicate".
  Fuser(const robot::Model& model, FusionConfig config);

  [[nodiscard]] const FusionConfig& config() const noexcept { return config_; }
  [[nodiscard]] std::size_t num_patches() const noexcept { return config_.patches.size(); }
  [[nodiscard]] const std::string& patch_id(std::size_t i) const noexcept { return config_.patches[i].id; }
  [[nodiscard]] std::size_t patch_link(std::size_t i) const noexcept { return patch_link_[i]; }
  // Configure-time lookup (string compares): resolve once, keep the index.
  [[nodiscard]] std::optional<std::size_t> FindPatch(std::string_view id) const noexcept;
  // Contacts on links a and b may be fused (a == b, or adjacent by the config).
  [[nodiscard]] bool Adjacent(std::size_t link_a, std::size_t link_b) const noexcept;

  // Replaces data's contacts with the fusion of `inputs` (at most one per patch; later duplicates refused),
  // placed with the link poses X_BL (robot::Data::X_BL: X_BL[k] is link k in B). Refused inputs are counted
  // in data.counters.rejected and never reach the output; no output field is ever NaN. Returns the number
  // of body contacts. Real-time safe: no allocation, no lock, no throw.
  std::size_t Update(std::span<const PatchInput> inputs, std::span<const Eigen::Isometry3d> X_BL,
                     FusionData& data) const noexcept;

 private:
  void PlaceOnSeams(std::span<const Eigen::Isometry3d> X_BL, FusionData& data) const noexcept;

  FusionConfig config_;
  std::vector<std::size_t> patch_link_;
  std::array<std::uint32_t, robot::kMaxLinks> neighbours_{};  // bit j of neighbours_[i]: links i, j adjacent
  double cos_max_normal_angle_ = 0.0;
};

}  // namespace ruffini::fusion
