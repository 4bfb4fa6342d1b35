#include "ruffini/fusion/fuser.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <sstream>

#include "ruffini/error.h"

namespace ruffini::fusion {

std::uint64_t FusionCounters::rejected_total() const noexcept {
  std::uint64_t n = 0;
  for (const auto v : rejected) n += v;
  return n;
}

namespace {

std::string Field(std::string_view name, std::size_t i) {
  return "fusion." + std::string(name) + "[" + std::to_string(i) + "]";
}

}  // namespace

Fuser::Fuser(const robot::Model& model, FusionConfig config) : config_(std::move(config)) {
  if (config_.patches.empty() || config_.patches.size() > kMaxPatches) {
    throw InputError("fusion.patches: " + std::to_string(config_.patches.size()) + " patches; expected 1 to " +
                     std::to_string(kMaxPatches));
  }
  ValidateLiftConfig(config_.lift, "fusion.lift");
  if (!(std::isfinite(config_.gate_chi2) && config_.gate_chi2 > 0 && config_.gate_chi2 <= 1e6)) {
    std::ostringstream s;
    s << "fusion.gate_chi2 (" << config_.gate_chi2 << ") must lie in (0, 1e6]";
    throw InputError(s.str());
  }
  if (!(std::isfinite(config_.max_normal_angle_deg) && config_.max_normal_angle_deg > 0 &&
        config_.max_normal_angle_deg <= 180)) {
    std::ostringstream s;
    s << "fusion.max_normal_angle_deg (" << config_.max_normal_angle_deg << ") must lie in (0, 180]";
    throw InputError(s.str());
  }
  cos_max_normal_angle_ = std::cos(config_.max_normal_angle_deg * std::numbers::pi / 180.0);

  patch_link_.reserve(config_.patches.size());
  for (std::size_t i = 0; i < config_.patches.size(); ++i) {
    const auto& p = config_.patches[i];
    const std::string where = Field("patches", i);
    ValidatePatchShape(p, where);
    for (std::size_t j = 0; j < i; ++j) {
      if (config_.patches[j].id == p.id) throw InputError(where + ".id ('" + p.id + "') is a duplicate");
    }
    patch_link_.push_back(robot::ValidateMount(model, p.mount, where + ".mount"));
  }

  if (config_.seams.size() > kMaxSeams) {
    throw InputError("fusion.seams: " + std::to_string(config_.seams.size()) + " seams; at most " + std::to_string(kMaxSeams));
  }
  if (!(std::isfinite(config_.seam_along_floor_mm) && config_.seam_along_floor_mm >= 0 && config_.seam_along_floor_mm <= 1000)) {
    std::ostringstream m;
    m << "fusion.seam_along_floor_mm (" << config_.seam_along_floor_mm << ") must lie in [0, 1000]";
    throw InputError(m.str());
  }
  for (std::size_t i = 0; i < config_.seams.size(); ++i) {
    const FusionConfig::SeamBand& sb = config_.seams[i];
    const std::string where = Field("seams", i);
    if (sb.seam.a >= config_.patches.size() || sb.seam.b >= config_.patches.size() || sb.seam.a == sb.seam.b) {
      throw InputError(where + ": patches " + std::to_string(sb.seam.a) + " and " + std::to_string(sb.seam.b) +
                       " must be two of the " + std::to_string(config_.patches.size()) + " patches");
    }
    for (const double band : {sb.band_a_mm, sb.band_b_mm}) {
      if (!(std::isfinite(band) && band >= 0 && band <= 1000)) {
        std::ostringstream m;
        m << where << ": a band (" << band << " mm) must lie in [0, 1000]";
        throw InputError(m.str());
      }
    }
  }

  for (std::size_t k = 0; k < model.num_links(); ++k) neighbours_[k] |= 1u << k;
  if (config_.adjacent_from_model) {
    for (std::size_t k = 1; k < model.num_links(); ++k) {
      const std::size_t p = model.link(k).parent;
      if (p == robot::kNoIndex) continue;
      neighbours_[k] |= 1u << p;
      neighbours_[p] |= 1u << k;
    }
  }
  for (std::size_t i = 0; i < config_.adjacent_links.size(); ++i) {
    const auto& [a, b] = config_.adjacent_links[i];
    const auto la = model.FindLink(a);
    const auto lb = model.FindLink(b);
    if (!la) throw InputError(Field("adjacent_links", i) + ".first: link '" + a + "' is not in " + model.source());
    if (!lb) throw InputError(Field("adjacent_links", i) + ".second: link '" + b + "' is not in " + model.source());
    neighbours_[*la] |= 1u << *lb;
    neighbours_[*lb] |= 1u << *la;
  }
}

std::optional<std::size_t> Fuser::FindPatch(std::string_view id) const noexcept {
  for (std::size_t i = 0; i < config_.patches.size(); ++i) {
    if (config_.patches[i].id == id) return i;
  }
  return std::nullopt;
}

bool Fuser::Adjacent(std::size_t link_a, std::size_t link_b) const noexcept {
  if (link_a >= robot::kMaxLinks || link_b >= robot::kMaxLinks) return false;
  return ((neighbours_[link_a] >> link_b) & 1u) != 0;
}

namespace {

robot::MountedSurface SurfaceOf(const FusionPatch& p) noexcept {
  return robot::MountedSurface{p.mount, p.extent_y_mm, p.extent_r_deg};
}

// The contact moved onto its patch's edge (the seam), keeping its place along the edge.
SurfaceContact OntoEdge(const FusionPatch& p, robot::PatchEdge edge, SurfaceContact c) noexcept {
  switch (edge) {
    case robot::PatchEdge::kYMin: c.y_mm = 0.0; break;
    case robot::PatchEdge::kYMax: c.y_mm = p.extent_y_mm; break;
    case robot::PatchEdge::kRMin: c.r_deg = 0.0; break;
    case robot::PatchEdge::kRMax: c.r_deg = p.extent_r_deg; break;
  }
  return c;
}

// The variance along the edge: the contact's own (Y for an R edge, arc for a Y edge), or the uncalibrated sd.
double AlongEdgeVariance(const SurfaceContact& c, robot::PatchEdge edge, const LiftConfig& lift) noexcept {
  if (!c.uncertainty_calibrated) return lift.uncalibrated_sd_mm * lift.uncalibrated_sd_mm;
  const bool r_edge = edge == robot::PatchEdge::kRMin || edge == robot::PatchEdge::kRMax;
  return std::max(0.0, r_edge ? c.cov_yy_mm2 : c.cov_ss_mm2);
}

// The variance across the edge (arc for an R edge, Y for a Y edge), or the uncalibrated sd's.
double AcrossEdgeVariance(const SurfaceContact& c, robot::PatchEdge edge, const LiftConfig& lift) noexcept {
  if (!c.uncertainty_calibrated) return lift.uncalibrated_sd_mm * lift.uncalibrated_sd_mm;
  const bool r_edge = edge == robot::PatchEdge::kRMin || edge == robot::PatchEdge::kRMax;
  return std::max(0.0, r_edge ? c.cov_ss_mm2 : c.cov_yy_mm2);
}

}  // namespace

bool MayBeOnSeam(const FusionConfig::SeamBand& sb, const FusionPatch& pa, const SurfaceContact& ca,
                 const FusionPatch& pb, const SurfaceContact& cb, const LiftConfig& lift) noexcept {
  if (!(sb.band_a_mm > 0 && sb.band_b_mm > 0) || !ca.located || !cb.located) return false;
  const double da = robot::DistanceToEdgeMm(SurfaceOf(pa), sb.seam.edge_a, {ca.y_mm, ca.r_deg});
  const double db = robot::DistanceToEdgeMm(SurfaceOf(pb), sb.seam.edge_b, {cb.y_mm, cb.r_deg});
  // NaN anywhere compares false: not on the seam.
  return da - 2.0 * std::sqrt(AcrossEdgeVariance(ca, sb.seam.edge_a, lift)) <= sb.band_a_mm &&
         db - 2.0 * std::sqrt(AcrossEdgeVariance(cb, sb.seam.edge_b, lift)) <= sb.band_b_mm;
}

bool SideMayBeOnSeam(const FusionConfig::SeamBand& sb, bool side_a, const FusionPatch& p, const SurfaceContact& c,
                     const LiftConfig& lift) noexcept {
  const double band = side_a ? sb.band_a_mm : sb.band_b_mm;
  const robot::PatchEdge edge = side_a ? sb.seam.edge_a : sb.seam.edge_b;
  if (!(sb.band_a_mm > 0 && sb.band_b_mm > 0) || !c.located) return false;
  const double d = robot::DistanceToEdgeMm(SurfaceOf(p), edge, {c.y_mm, c.r_deg});
  return d - 2.0 * std::sqrt(AcrossEdgeVariance(c, edge, lift)) <= band;  // NaN: false
}

double AlongSeamD2(const FusionConfig::SeamBand& sb, const FusionPatch& pa, const SurfaceContact& ca,
                   const FusionPatch& pb, const SurfaceContact& cb, const LiftConfig& lift,
                   double along_floor_mm) noexcept {
  // Both contacts moved onto the seam, in their (common) link's frame: what separates them is along the seam.
  const SurfaceContact oa = OntoEdge(pa, sb.seam.edge_a, ca), ob = OntoEdge(pb, sb.seam.edge_b, cb);
  const Eigen::Vector3d p_a = robot::PatchToLink(pa.mount, {oa.y_mm, oa.r_deg}).p_LS_m;
  const Eigen::Vector3d p_b = robot::PatchToLink(pb.mount, {ob.y_mm, ob.r_deg}).p_LS_m;
  const double d_mm = (p_a - p_b).norm() * 1e3;
  const double var = AlongEdgeVariance(ca, sb.seam.edge_a, lift) + AlongEdgeVariance(cb, sb.seam.edge_b, lift) +
                     2.0 * along_floor_mm * along_floor_mm;
  const double d2 = d_mm * d_mm / var;
  return std::isfinite(d2) ? d2 : std::numeric_limits<double>::infinity();
}

bool OneTouchOnSeam(const FusionConfig& config, const FusionConfig::SeamBand& sb, const SurfaceContact& ca,
                    const SurfaceContact& cb) noexcept {
  const FusionPatch& pa = config.patches[sb.seam.a];
  const FusionPatch& pb = config.patches[sb.seam.b];
  return MayBeOnSeam(sb, pa, ca, pb, cb, config.lift) &&
         AlongSeamD2(sb, pa, ca, pb, cb, config.lift, config.seam_along_floor_mm) <= kChi2_1dof_95;
}

// Seams (docs/fusion.md, "Seams"). A decoder trained on its patch's interior places a touch on the seam well
// inside its own patch (edge locations are pulled inward), so the two patches' contacts of one probe across a
// seam lie tens of mm apart, often with covariances that do not cover the gap, and the gate keeps them apart.
// A contact may be on the seam when the seam lies within its band (how far from the seam its decoder places a
// touch on it, from its sensitivity map) plus 2 sd of its own across the seam. When both contacts may be, each
// is moved onto the seam: along it, it keeps its place and variance; across it, it gets a sd of half of the
// larger of (band + 2 own sd) over the two sides (so each contact's own place lies within 2 sd, and never less
// than its own sd). If the two then pass the gate they are fused as usual (covariance intersection); if not
// (two places along the seam), both are replaced by their 50/50 mixture (the mean, and the mean covariance plus
// the spread), one contact whose covariance holds both places, as for two touches on one patch. A patch on
// several seams is placed on at most one: the candidate pairs are taken in ascending gate distance.
void Fuser::PlaceOnSeams(std::span<const Eigen::Isometry3d> X_BL, FusionData& data) const noexcept {
  // Both contacts of seam k moved onto it (false: one could not be lifted).
  auto place = [&](std::size_t k, LiftedContact& la, LiftedContact& lb) {
    const FusionConfig::SeamBand& sb = config_.seams[k];
    const std::size_t a = sb.seam.a, b = sb.seam.b;
    const SurfaceContact& ca = data.input_[a];
    const SurfaceContact& cb = data.input_[b];
    const double sd_a = std::sqrt(AcrossEdgeVariance(ca, sb.seam.edge_a, config_.lift));
    const double sd_b = std::sqrt(AcrossEdgeVariance(cb, sb.seam.edge_b, config_.lift));
    const double across_sd_mm = 0.5 * std::max(sb.band_a_mm + 2.0 * sd_a, sb.band_b_mm + 2.0 * sd_b);
    auto lift_onto_seam = [&](std::size_t i, robot::PatchEdge edge, const SurfaceContact& c, LiftedContact& out) {
      const FusionPatch& p = config_.patches[i];
      const double along = AlongEdgeVariance(c, edge, config_.lift);
      const double across = across_sd_mm * across_sd_mm;
      const bool r_edge = edge == robot::PatchEdge::kRMin || edge == robot::PatchEdge::kRMax;
      Eigen::Matrix2d C = Eigen::Matrix2d::Zero();  // (Y, arc)
      C(0, 0) = r_edge ? along : across;
      C(1, 1) = r_edge ? across : along;
      return Lift(p, X_BL[patch_link_[i]], OntoEdge(p, edge, c), config_.lift, out, &C);
    };
    return lift_onto_seam(a, sb.seam.edge_a, ca, la) == Rejection::kNone &&
           lift_onto_seam(b, sb.seam.edge_b, cb, lb) == Rejection::kNone &&
           la.n_B.dot(lb.n_B) >= cos_max_normal_angle_;
  };
  // The candidates: seams whose two contacts may lie on them, ranked by how well they agree along the seam
  // (those passing the gate first, then by the distance between their places on the seam, mm): a vague
  // partner's wide covariance must not win over one that is where this contact is.
  struct Candidate {
    std::size_t seam = 0;
    bool gated = false;
    double distance_mm = 0.0;
  };
  std::array<Candidate, kMaxSeams> candidates;
  std::size_t n = 0;
  for (std::size_t k = 0; k < config_.seams.size() && n < kMaxSeams; ++k) {
    const FusionConfig::SeamBand& sb = config_.seams[k];
    const std::size_t a = sb.seam.a, b = sb.seam.b;
    if (!data.have_[a] || !data.have_[b]) continue;
    if (!MayBeOnSeam(sb, config_.patches[a], data.input_[a], config_.patches[b], data.input_[b], config_.lift)) continue;
    LiftedContact la, lb;
    if (!place(k, la, lb)) continue;
    const double d2 = TangentMahalanobis2({la.p_BC_m, la.cov_p_BC_m2}, {lb.p_BC_m, lb.cov_p_BC_m2}, la.n_B + lb.n_B);
    const double dist = (la.p_BC_m - lb.p_BC_m).norm() * 1e3;
    candidates[n++] = Candidate{k, d2 <= config_.gate_chi2, std::isfinite(dist) ? dist : std::numeric_limits<double>::infinity()};
  }
  auto before = [](const Candidate& x, const Candidate& y) {
    return x.gated != y.gated ? x.gated : x.distance_mm < y.distance_mm;
  };
  for (std::size_t i = 1; i < n; ++i) {  // insertion sort: few candidates, no allocation
    for (std::size_t j = i; j > 0 && before(candidates[j], candidates[j - 1]); --j) std::swap(candidates[j], candidates[j - 1]);
  }
  std::array<bool, kMaxPatches> placed{};
  for (std::size_t i = 0; i < n; ++i) {
    const Candidate& c = candidates[i];
    const FusionConfig::SeamBand& sb = config_.seams[c.seam];
    if (placed[sb.seam.a] || placed[sb.seam.b]) continue;
    LiftedContact la, lb;
    if (!place(c.seam, la, lb)) continue;
    if (!c.gated) {
      // Two places along the seam: one contact covering both (the main loop fuses identical estimates exactly).
      const Eigen::Vector3d mean = 0.5 * (la.p_BC_m + lb.p_BC_m);
      const Eigen::Vector3d half = 0.5 * (la.p_BC_m - lb.p_BC_m);
      Eigen::Matrix3d P = 0.5 * (la.cov_p_BC_m2 + lb.cov_p_BC_m2) + half * half.transpose();
      if (Regularize(P) != CovarianceStatus::kOk) continue;
      la.p_BC_m = lb.p_BC_m = mean;
      la.cov_p_BC_m2 = lb.cov_p_BC_m2 = P;
      ++data.counters.seam_mixtures;
    }
    data.lifted_[sb.seam.a] = la;
    data.lifted_[sb.seam.b] = lb;
    placed[sb.seam.a] = placed[sb.seam.b] = true;
    ++data.counters.seam_pairs;
  }
}

std::size_t Fuser::Update(std::span<const PatchInput> inputs, std::span<const Eigen::Isometry3d> X_BL,
                          FusionData& data) const noexcept {
  auto& counters = data.counters;
  ++counters.updates;
  const std::size_t n_patches = config_.patches.size();
  data.have_.fill(false);
  data.num_contacts_ = 0;

  auto reject = [&](Rejection r) {
    ++counters.rejected[static_cast<std::size_t>(r)];
    data.last_rejection = r;
  };

  // 1. Check and lift; one slot per patch.
  for (const PatchInput& in : inputs) {
    ++counters.inputs;
    if (in.patch >= n_patches) {
      reject(Rejection::kUnknownPatch);
      continue;
    }
    if (data.have_[in.patch]) {
      reject(Rejection::kDuplicatePatch);
      continue;
    }
    const std::size_t link = patch_link_[in.patch];
    if (link >= X_BL.size()) {
      reject(Rejection::kBadPose);
      continue;
    }
    const Rejection r = Lift(config_.patches[in.patch], X_BL[link], in.contact, config_.lift, data.lifted_[in.patch]);
    if (r != Rejection::kNone) {
      reject(r);
      continue;
    }
    data.have_[in.patch] = true;
    data.input_[in.patch] = in.contact;
    ++counters.accepted;
  }
  PlaceOnSeams(X_BL, data);

  // 2. and 3. Associate and fuse, in ascending patch index.
  for (std::size_t i = 0; i < n_patches; ++i) {
    if (!data.have_[i]) continue;
    const LiftedContact& c = data.lifted_[i];
    const std::size_t link = patch_link_[i];
    const Estimate e{c.p_BC_m, c.cov_p_BC_m2};

    std::size_t best = kMaxPatches;
    double best_d2 = std::numeric_limits<double>::infinity();
    for (std::size_t k = 0; k < data.num_contacts_; ++k) {
      const BodyContact& b = data.contacts_[k];
      const auto& cl = data.clusters_[k];
      if ((cl.links & ~neighbours_[link]) != 0) continue;  // some contributor's link is not adjacent
      if (!c.located && !b.located) continue;
      if (!config_.fuse_unlocated && (!c.located || !b.located)) continue;
      Eigen::Vector3d n_gate;
      if (c.located && b.located) {
        if (c.n_B.dot(b.n_B) < cos_max_normal_angle_) continue;
        n_gate = c.n_B + b.n_B;
      } else {
        n_gate = c.located ? c.n_B : b.n_B;
      }
      const double d2 = TangentMahalanobis2(e, cl.estimate, n_gate);
      if (d2 <= config_.gate_chi2 && d2 < best_d2) {
        best_d2 = d2;
        best = k;
      }
    }

    if (best < kMaxPatches) {
      BodyContact& b = data.contacts_[best];
      auto& cl = data.clusters_[best];
      if (b.HasPatch(i)) continue;  // unreachable: one slot per patch
      Estimate fused;
      if (CovarianceIntersection(cl.estimate, e, fused) == CovarianceStatus::kOk) {
        ++counters.merges;
        cl.estimate = fused;
        b.p_BC_m = fused.x;
        b.cov_p_BC_m2 = fused.P;
        if (c.located) {
          if (!b.located) cl.normal_sum.setZero();  // the centre's normal gives way to a measured one
          cl.normal_sum += c.n_B;
          const double norm = cl.normal_sum.norm();
          if (norm > 1e-9) b.n_B = cl.normal_sum / norm;  // the normal gate keeps the sum well away from 0
        }
        b.force_n += c.force_n;
        b.force_var_n2 += c.force_var_n2;
        b.located = b.located || c.located;
        b.uncertainty_calibrated = b.uncertainty_calibrated && c.uncertainty_calibrated;
        b.patches |= std::uint64_t{1} << i;
        ++b.num_patches;
        cl.links |= 1u << link;
        if (c.force_n > cl.max_force_n) {
          cl.max_force_n = c.force_n;
          b.link = link;
        }
        continue;
      }
      // CI refused (cannot happen for lifted contacts): keep the contact on its own below.
    }

    const std::size_t k = data.num_contacts_++;
    BodyContact& b = data.contacts_[k];
    b.link = link;
    b.p_BC_m = c.p_BC_m;
    b.n_B = c.n_B;
    b.cov_p_BC_m2 = c.cov_p_BC_m2;
    b.force_n = c.force_n;
    b.force_var_n2 = c.force_var_n2;
    b.located = c.located;
    b.uncertainty_calibrated = c.uncertainty_calibrated;
    b.patches = std::uint64_t{1} << i;
    b.num_patches = 1;
    auto& cl = data.clusters_[k];
    cl.estimate = e;
    cl.normal_sum = c.located ? c.n_B : Eigen::Vector3d::Zero();
    cl.max_force_n = c.force_n;
    cl.links = 1u << link;
  }
  return data.num_contacts_;
}

}  // namespace ruffini::fusion
