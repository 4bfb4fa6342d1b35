#include "ruffini/fusion/fuser.h"

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
    ++counters.accepted;
  }

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
