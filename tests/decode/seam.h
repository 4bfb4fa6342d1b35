#pragma once
// One probe across a seam (issue 16, docs/fusion.md "Seams"), through both patches' whole decode paths and the
// aggregator's fusion: the probe's load is shared between the patches by sim::ProbeLoads (as ruffini-sim does),
// each patch's share is pressed on its own HardPressRig (its twin, the Hyperion bytes, link::Monitor over the
// scene's model), and at each hold frame the two patches' contacts go through fusion::Fuser with the robot at
// q = 0. Shared by the test (seam_test.cpp) and the measurement (seam_eval.cpp).
#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
#include <optional>
#include <vector>

#include "hard_press.h"
#include "ruffini/decode/sensitivity.h"
#include "ruffini/fusion/fuser.h"
#include "ruffini/robot/kinematics.h"

namespace ruffini::testing {

// Whether aggregate::Core::JudgeOnSeam sums the two sides' forces (its rule, for in-process rigs): both located
// and one touch on the seam may explain both, or one side unplaced (force only) and the located side may be on
// the seam. ca is seam.a's contact, cb seam.b's.
inline bool SeamSumApplies(const fusion::FusionConfig& fc, const fusion::FusionConfig::SeamBand& sb,
                           const fusion::SurfaceContact& ca, const fusion::SurfaceContact& cb) {
  if (ca.located && cb.located) return fusion::OneTouchOnSeam(fc, sb, ca, cb);
  if (ca.located) return fusion::SideMayBeOnSeam(sb, true, fc.patches[sb.seam.a], ca, fc.lift);
  if (cb.located) return fusion::SideMayBeOnSeam(sb, false, fc.patches[sb.seam.b], cb, fc.lift);
  return false;
}

// What the aggregator's fusion made of one hold frame of a seam probe.
struct SeamFrame {
  int patches_in_contact = 0;  // 0, 1 or 2 of the seam's patches reported a contact
  bool fused = false;          // one body contact holds both patches' contacts
  bool located = false;        // the body contact nearest the probe was located
  double error_mm = NAN;       // distance from the probe to the nearest located body contact, mm
  double force_n = 0.0;        // that body contact's force
  // The same frame through the plain gate (no seam rule), as before seams had bands.
  bool plain_fused = false;
  double plain_error_mm = NAN;
  // What the aggregator's stop judges: the larger of the patches' own forces, and with the seam rule the sum
  // of both sides' forces when one touch on the seam may explain both (aggregate::Core::JudgeOnSeam).
  double own_max_n = 0.0;
  double judged_n = 0.0;
};

class SeamRig {
 public:
  // The scene's first seam (robot::FindSeams over its mounts). band_mm < 0: each side's band from its model's
  // map at `threshold_n` (decode::EdgeReachMm with near_mm and quantile); otherwise that band on both sides
  // (0: the plain gate, no seam rule).
  SeamRig(const twin::Scene& scene, double threshold_n, double band_mm = -1.0, double near_mm = 5.0,
          double quantile = 0.9)
      : scene_(scene), mounts_(sim::LoadMounts(scene)) {
    if (!mounts_) throw std::runtime_error(scene.source + ": no robot, so no seams");
    const robot::RobotScene& rs = mounts_->robot;
    fusion::FusionConfig fc;
    std::vector<robot::MountedSurface> surfaces;
    for (const robot::MountedPatch& p : rs.patches) {
      fusion::FusionPatch fp;
      fp.id = p.name;
      fp.mount = p.mount;
      fp.extent_y_mm = p.extent_y_mm;
      fp.extent_r_deg = p.extent_r_deg;
      fc.patches.push_back(fp);
      surfaces.push_back({p.mount, p.extent_y_mm, p.extent_r_deg});
    }
    const std::vector<robot::Seam> seams = robot::FindSeams(surfaces);
    if (seams.empty()) throw std::runtime_error(scene.source + ": no seam between its patches");
    seam_ = seams.front();
    for (const std::size_t i : {seam_.a, seam_.b}) {
      models_[i == seam_.a ? 0 : 1] = decode::LoadModel(scene.patches[i].model_path);
    }
    for (int side = 0; side < 2; ++side) {
      const std::size_t i = side == 0 ? seam_.a : seam_.b;
      const robot::PatchEdge edge = side == 0 ? seam_.edge_a : seam_.edge_b;
      double band = band_mm;
      if (band < 0) {
        band = 0;
        const v1::SensitivityMap* map = decode::MapForThreshold(models_[side].sensitivity(), threshold_n);
        if (map != nullptr) {
          band = decode::EdgeReachMm(*map, [&](double y, double r) { return robot::DistanceToEdgeMm(surfaces[i], edge, {y, r}); },
                                     near_mm, quantile);
        }
      }
      bands_[side] = band;
      rigs_[side] = std::make_unique<HardPressRig>(scene, i, models_[side]);
    }
    if (bands_[0] > 0 && bands_[1] > 0) fc.seams.push_back({seam_, bands_[0], bands_[1]});
    fuser_.emplace(rs.model, fc);
    fc.seams.clear();
    plain_.emplace(rs.model, fc);
    std::vector<double> q(rs.model.num_dof(), 0.0);
    if (robot::ForwardKinematics(rs.model, q, fk_) != robot::FkStatus::kOk) throw std::runtime_error("FK at q = 0");
    surfaces_ = surfaces;
  }

  [[nodiscard]] const robot::Seam& seam() const noexcept { return seam_; }
  [[nodiscard]] double band_mm(int side) const noexcept { return bands_[side]; }
  [[nodiscard]] const robot::MountedSurface& surface(std::size_t patch) const { return surfaces_.at(patch); }
  [[nodiscard]] const HardPressRig& rig(int side) const noexcept { return *rigs_[side]; }
  // For probes (review 3): the fuser with the seam rule, the link poses at q = 0, the mounted scene.
  [[nodiscard]] const fusion::Fuser& fuser() const noexcept { return *fuser_; }
  [[nodiscard]] const robot::Data& fk() const noexcept { return fk_; }
  [[nodiscard]] const sim::MountedScene& mounts() const noexcept { return *mounts_; }

  // The probe at (y_mm, r_deg) on patch seam().a's cylinder (r_deg may pass its edge) with force_n; nullopt
  // when its footprint does not load both patches. Otherwise one SeamFrame per hold frame.
  [[nodiscard]] std::optional<std::vector<SeamFrame>> Press(double y_mm, double r_deg, double force_n, double threshold_n,
                                                            std::uint64_t seed) const {
    const twin::ContactLaw* law = rigs_[0]->twin().contact_law(scene_.probe);
    const double a = law != nullptr ? law->ContactRadiusMm(std::min(force_n, law->linear_limit_force_n())) : scene_.probe.radius_mm;
    const std::vector<sim::PatchLoad> loads = sim::ProbeLoads(scene_, mounts_.get(), seam_.a, y_mm, r_deg, a);
    const sim::PatchLoad* on[2] = {nullptr, nullptr};
    for (const sim::PatchLoad& l : loads) {
      if (l.patch == seam_.a) on[0] = &l;
      if (l.patch == seam_.b) on[1] = &l;
    }
    if (on[0] == nullptr || on[1] == nullptr || loads.size() != 2) return std::nullopt;
    PressOutcome out[2];
    for (int side = 0; side < 2; ++side) {
      const ProbeAt p{on[side]->y_mm, on[side]->r_deg, force_n * on[side]->share};
      out[side] = rigs_[side]->Press(std::span<const ProbeAt>(&p, 1), threshold_n, twin::DeriveSeed(seed, static_cast<std::uint64_t>(side)));
    }
    // The probe's true place, in B.
    const robot::MountedPatch& home = mounts_->robot.patches[seam_.a];
    const Eigen::Vector3d truth = fk_.X_BL[home.link_index] * robot::PatchToLink(home.mount, {y_mm, r_deg}).p_LS_m;
    // Align the two hold streams by frame time (one clock).
    std::vector<SeamFrame> frames;
    std::size_t j = 0;
    fusion::FusionData data;
    for (std::size_t i = 0; i < out[0].hold.size(); ++i) {
      const std::int64_t t = out[0].hold_t_ns[i];
      while (j < out[1].hold.size() && out[1].hold_t_ns[j] < t) ++j;
      std::vector<fusion::PatchInput> in;
      in.push_back({seam_.a, Surface(out[0].hold[i])});
      if (j < out[1].hold.size() && out[1].hold_t_ns[j] == t) in.push_back({seam_.b, Surface(out[1].hold[j])});
      frames.push_back(Judge(in, truth, data));
    }
    // Hold frames where only patch b reported.
    for (std::size_t k = 0; k < out[1].hold.size(); ++k) {
      const std::int64_t t = out[1].hold_t_ns[k];
      if (std::find(out[0].hold_t_ns.begin(), out[0].hold_t_ns.end(), t) != out[0].hold_t_ns.end()) continue;
      std::vector<fusion::PatchInput> in{{seam_.b, Surface(out[1].hold[k])}};
      frames.push_back(Judge(in, truth, data));
    }
    return frames;
  }

 public:
  static fusion::SurfaceContact Surface(const link::Contact& c) {
    fusion::SurfaceContact s;
    s.force_n = c.force_n;
    s.force_sd_n = c.uncertainty ? c.force_sd_n : 0.0f;
    s.located = c.located;
    s.y_mm = c.y_mm;
    s.r_deg = c.r_deg;
    s.cov_yy_mm2 = c.cov_yy_mm2;
    s.cov_ys_mm2 = c.cov_yr_mm2;
    s.cov_ss_mm2 = c.cov_rr_mm2;
    s.uncertainty_calibrated = c.uncertainty;
    return s;
  }

 private:
  SeamFrame Judge(const std::vector<fusion::PatchInput>& in, const Eigen::Vector3d& truth, fusion::FusionData& data) const {
    SeamFrame f;
    f.patches_in_contact = static_cast<int>(in.size());
    double sum = 0.0;
    for (const fusion::PatchInput& x : in) {
      f.own_max_n = std::max(f.own_max_n, x.contact.force_n);
      sum += x.contact.force_n;
    }
    f.judged_n = f.own_max_n;
    const fusion::FusionConfig& fc = fuser_->config();
    if (in.size() == 2 && !fc.seams.empty() &&
        SeamSumApplies(fc, fc.seams[0], in.front().contact, in.back().contact)) {
      f.judged_n = std::max(f.judged_n, sum);
    }
    fuser_->Update(in, fk_.X_BL, data);
    for (const fusion::BodyContact& b : data.contacts()) {
      if (b.num_patches == 2) f.fused = true;
      if (!b.located) continue;
      const double e = (b.p_BC_m - truth).norm() * 1e3;
      if (!(e >= f.error_mm)) {  // NaN at first
        f.error_mm = e;
        f.located = true;
        f.force_n = b.force_n;
      }
    }
    plain_->Update(in, fk_.X_BL, data);
    for (const fusion::BodyContact& b : data.contacts()) {
      if (b.num_patches == 2) f.plain_fused = true;
      if (!b.located) continue;
      const double e = (b.p_BC_m - truth).norm() * 1e3;
      if (!(e >= f.plain_error_mm)) f.plain_error_mm = e;
    }
    return f;
  }

 public:
  // One press on patch seam().a alone, well inside: the located hold frames' errors, mm (the interior
  // reference the seam is compared with).
  [[nodiscard]] std::vector<double> InteriorErrors(double y_mm, double r_deg, double force_n, double threshold_n,
                                                   std::uint64_t seed) const {
    const ProbeAt p{y_mm, r_deg, force_n};
    const PressOutcome o = rigs_[0]->Press(std::span<const ProbeAt>(&p, 1), threshold_n, seed);
    const robot::MountedPatch& home = mounts_->robot.patches[seam_.a];
    const Eigen::Vector3d truth = fk_.X_BL[home.link_index] * robot::PatchToLink(home.mount, {y_mm, r_deg}).p_LS_m;
    std::vector<double> errors;
    fusion::FusionData data;
    for (const link::Contact& c : o.hold) {
      const std::vector<fusion::PatchInput> in{{seam_.a, Surface(c)}};
      const SeamFrame f = Judge(in, truth, data);
      if (f.located) errors.push_back(f.error_mm);
    }
    return errors;
  }

 private:

  const twin::Scene& scene_;
  std::unique_ptr<sim::MountedScene> mounts_;
  robot::Seam seam_;
  std::array<v1::DecoderModel, 2> models_;
  std::array<double, 2> bands_{};
  std::array<std::unique_ptr<HardPressRig>, 2> rigs_;
  std::optional<fusion::Fuser> fuser_, plain_;
  robot::Data fk_;
  std::vector<robot::MountedSurface> surfaces_;
};

}  // namespace ruffini::testing
