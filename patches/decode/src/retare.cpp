#include "ruffini/decode/retare.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "ruffini/decode/touches.h"
#include "ruffini/error.h"

namespace ruffini::decode {

std::string_view RetareOutcomeName(RetareOutcome o) noexcept {
  switch (o) {
    case RetareOutcome::kAccepted: return "accepted";
    case RetareOutcome::kPressing: return "pressing";
    case RetareOutcome::kMoving: return "moving";
    case RetareOutcome::kInvalidFrames: return "invalid_frames";
    case RetareOutcome::kNoBaseline: return "no_baseline";
    case RetareOutcome::kNoMap: return "no_map";
    case RetareOutcome::kBusy: return "busy";
    case RetareOutcome::kInterrupted: return "interrupted";
  }
  return "unknown";
}

void RetareConfig::SeparateField(const patch::PatchSpec& spec) noexcept {
  separate_field = true;
  for (std::size_t i = 0; i < kGratings; ++i) {
    grating_y_mm[i] = spec.gratings[i].centre.y_mm;
    grating_r_deg[i] = spec.gratings[i].centre.r_deg;
  }
}

namespace {

using Basis = Eigen::Matrix<double, static_cast<int>(kGratings), 4>;

// The field's least-squares part of v over the present gratings (rows of B zeroed where absent): B (B'B)^-1 B' v.
// false when B'B is singular (the present gratings cannot carry the field).
bool FieldPart(const Basis& b, const Eigen::LDLT<Eigen::Matrix4d>& btb, const Eigen::Matrix<double, 16, 1>& v,
               Eigen::Matrix<double, 16, 1>& out) noexcept {
  const Eigen::Vector4d c = btb.solve(b.transpose() * v);
  if (!c.allFinite()) return false;
  out = b * c;
  return true;
}

// B'B of the present rows, factored; false when it is not positive definite enough to trust.
bool Factor(const Basis& b, Eigen::LDLT<Eigen::Matrix4d>& out) noexcept {
  const Eigen::Matrix4d btb = b.transpose() * b;
  out.compute(btb);
  if (out.info() != Eigen::Success || !out.isPositive()) return false;
  // A zero pivot is not a failure for LDLT: ask for every pivot to be a real share of the largest.
  const auto d = out.vectorD();
  return d.minCoeff() > 1e-9 * std::max(1.0, d.maxCoeff());
}

}  // namespace

RetareJudge::RetareJudge(const v1::ResponseMap& map, RetareConfig config) : model_(FromProto(map)), config_(config) {
  if (!(config_.min_force_n > 0) || !std::isfinite(config_.min_force_n)) {
    throw InputError("re-tare: min_force_n must be a positive number of newtons");
  }
  if (!(config_.min_shift_pm >= 0) || !std::isfinite(config_.min_shift_pm)) {
    throw InputError("re-tare: min_shift_pm must be a non-negative number of picometres");
  }
  if (!config_.separate_field) return;
  Basis b;
  for (std::size_t i = 0; i < kGratings; ++i) {
    const double r = config_.grating_r_deg[i] * std::numbers::pi / 180.0;
    basis_[i] = {1.0, config_.grating_y_mm[i] / 100.0, std::cos(r), std::sin(r)};
    if (!std::isfinite(basis_[i][1]) || !std::isfinite(basis_[i][2])) {
      throw InputError("re-tare: the gratings' centres must be finite to separate a field");
    }
    for (int c = 0; c < 4; ++c) b(static_cast<int>(i), c) = basis_[i][static_cast<std::size_t>(c)];
  }
  Eigen::LDLT<Eigen::Matrix4d> btb;
  if (!Factor(b, btb)) throw InputError("re-tare: the gratings' centres cannot carry a field (they lie on one line)");
  own_g_.resize(model_.g.size());
  own_gg_.resize(model_.g.size());
  for (std::size_t node = 0; node < model_.g.size(); ++node) {
    Eigen::Matrix<double, 16, 1> g, part;
    for (std::size_t i = 0; i < kGratings; ++i) g(static_cast<int>(i)) = model_.g[node][i];
    if (!FieldPart(b, btb, g, part)) part.setZero();
    const Eigen::Matrix<double, 16, 1> own = g - part;
    for (std::size_t i = 0; i < kGratings; ++i) own_g_[node][i] = static_cast<float>(own(static_cast<int>(i)));
    own_gg_[node] = own.squaredNorm();
  }
  field_ready_ = true;
}

double RetareJudge::Force(double amplitude) const noexcept {
  // amplitude = F (1 + c F), as in TouchCheck
  const double c = model_.stiffening;
  if (std::abs(c) < 1e-9) return amplitude;
  const double disc = 1.0 + 4.0 * c * amplitude;
  return disc > 0 ? (std::sqrt(disc) - 1.0) / (2.0 * c) : amplitude;
}

RetareResult RetareJudge::Judge(const ShiftsPm& s) const noexcept {
  RetareResult r;
  r.y_mm = r.r_deg = std::numeric_limits<double>::quiet_NaN();
  // The field's part of the shifts, over the present gratings (separate_field). With every grating present the
  // nodes' field-free responses are the precomputed ones; with some missing they are computed here.
  bool field = false, all_present = true;
  int present = 0;
  Basis b = Basis::Zero();
  Eigen::Matrix<double, 16, 1> sv = Eigen::Matrix<double, 16, 1>::Zero(), s_own = sv;
  Eigen::LDLT<Eigen::Matrix4d> btb;
  if (field_ready_) {
    for (std::size_t i = 0; i < kGratings; ++i) {
      if (!std::isfinite(s[i])) {
        all_present = false;
        continue;
      }
      ++present;
      sv(static_cast<int>(i)) = s[i];
      for (int c = 0; c < 4; ++c) b(static_cast<int>(i), c) = basis_[i][static_cast<std::size_t>(c)];
    }
    Eigen::Matrix<double, 16, 1> part;
    field = present >= kMinPeaksForField && Factor(b, btb) && FieldPart(b, btb, sv, part);
    if (field) s_own = sv - part;
  }
  double ss = 0;  // the shifts' energy
  for (std::size_t i = 0; i < kGratings; ++i) {
    if (std::isfinite(s[i])) ss += static_cast<double>(s[i]) * s[i];
  }
  double best = 0.0;
  int best_node = -1;
  for (std::size_t node = 0; node < model_.g.size(); ++node) {
    const auto& g = model_.g[node];
    double sg = 0, gg = 0;
    for (std::size_t i = 0; i < kGratings; ++i) {
      if (!std::isfinite(s[i])) continue;
      sg += static_cast<double>(s[i]) * g[i];
      gg += static_cast<double>(g[i]) * g[i];
    }
    if (!(gg > 0)) continue;
    double a = sg / gg;  // the touch takes every shift
    if (field) {
      // The plain reading stands where this touch alone explains the shifts (a touch-shaped pattern: a press
      // with no field under it keeps its plain reading at the places that explain it).
      const double unexplained = ss > 0 ? 1.0 - (sg * sg) / (gg * ss) : 1.0;
      const double plain = unexplained <= kTouchLikeMisfit ? a : 0.0;
      // One touch plus a field: the touch's amplitude is the projection of the shifts' field-free part on the
      // response's field-free part (least squares over both). Trusted only where the response keeps a real share
      // of its energy outside the field's span.
      double own_sg = 0, own_gg = 0;
      if (all_present) {
        const auto& og = own_g_[node];
        for (std::size_t i = 0; i < kGratings; ++i) own_sg += s_own(static_cast<int>(i)) * og[i];
        own_gg = own_gg_[node];
      } else {
        Eigen::Matrix<double, 16, 1> gv = Eigen::Matrix<double, 16, 1>::Zero(), part;
        for (std::size_t i = 0; i < kGratings; ++i) {
          if (std::isfinite(s[i])) gv(static_cast<int>(i)) = g[i];
        }
        if (FieldPart(b, btb, gv, part)) {
          const Eigen::Matrix<double, 16, 1> own = gv - part;
          own_sg = s_own.dot(own);
          own_gg = own.squaredNorm();
        }
      }
      if (own_gg >= kMinOwnShare * gg) a = std::max(own_sg / own_gg, plain);
    }
    if (!(a > 0)) continue;  // a press pushes: a negative amplitude explains nothing
    double peak = 0;  // the touch's largest shift on one grating
    for (std::size_t i = 0; i < kGratings; ++i) {
      if (std::isfinite(s[i])) peak = std::max(peak, a * std::abs(static_cast<double>(g[i])));
    }
    if (peak < config_.min_shift_pm) continue;  // moves no grating by what the decoder calls a contact
    const double f = Force(a);
    if (f > best) {
      best = f;
      best_node = static_cast<int>(node);
    }
  }
  r.force_n = best;
  if (best_node >= 0) {
    r.y_mm = model_.y0_mm + (best_node / model_.nr) * model_.dy_mm;
    r.r_deg = model_.r0_deg + (best_node % model_.nr) * model_.dr_deg;
  }
  r.outcome = best >= config_.min_force_n ? RetareOutcome::kPressing : RetareOutcome::kAccepted;
  return r;
}

Retare::Retare(const v1::ResponseMap* map, const BaselineConfig& baseline, RetareConfig config)
    : baseline_(baseline), config_(config) {
  if (!(config_.min_force_n > 0) || !std::isfinite(config_.min_force_n)) {
    throw InputError("re-tare: min_force_n must be a positive number of newtons");
  }
  if (!(config_.min_shift_pm >= 0) || !std::isfinite(config_.min_shift_pm)) {
    throw InputError("re-tare: min_shift_pm must be a non-negative number of picometres");
  }
  if (map != nullptr) judge_.emplace(*map, config);
}

bool Retare::Start() noexcept {
  if (active_) return false;
  active_ = true;
  frames_ = 0;
  motion_pm_ = 0.0;
  sum_nm_.fill(0.0);
  count_.fill(0);
  shift_sum_pm_.fill(0.0);
  shift_count_.fill(0);
  head_sum_pm_.fill(0.0);
  head_count_.fill(0);
  tail_pm_.fill(std::numeric_limits<float>::quiet_NaN());
  return true;
}

std::optional<RetareResult> Retare::End(RetareOutcome o) noexcept {
  active_ = false;
  RetareResult r;
  r.outcome = o;
  r.y_mm = r.r_deg = std::numeric_limits<double>::quiet_NaN();
  r.motion_pm = motion_pm_;
  r.frames = frames_;
  return r;
}

std::optional<RetareResult> Retare::Interrupt() noexcept {
  if (!active_) return std::nullopt;
  return End(RetareOutcome::kInterrupted);
}

std::optional<RetareResult> Retare::Feed(const Wavelengths& wl, const PipelineOutput& out,
                                         const BaselineTracker& tracker) noexcept {
  if (!active_) return std::nullopt;
  if (!judge_) return End(RetareOutcome::kNoMap);
  if (tracker.state() == BaselineTracker::State::kCapturing) return End(RetareOutcome::kNoBaseline);
  ++frames_;
  if (out.over_range) {
    auto r = End(RetareOutcome::kPressing);
    r->force_n = out.force_n;
    return r;
  }
  switch (out.reason) {
    case Reason::kSaturated:
    case Reason::kNoSignal:
    case Reason::kOutOfBand:
    case Reason::kTooManyMissing:
    case Reason::kOutOfRange:
    case Reason::kCapturing:
      return End(RetareOutcome::kInvalidFrames);
    default: break;  // valid, stale, or a decoded frame the networks could not judge: the peaks are readable
  }
  // The start-up capture's rule: every present peak within the tolerance of its running mean.
  for (std::size_t i = 0; i < kGratings; ++i) {
    if (!std::isfinite(wl[i]) || count_[i] == 0) continue;
    const double d = std::abs(wl[i] - sum_nm_[i] / count_[i]) * 1e3;
    motion_pm_ = std::max(motion_pm_, d);
  }
  if (motion_pm_ > baseline_.capture_tolerance_pm) return End(RetareOutcome::kMoving);
  // The shift against the old baseline, common mode removed as the tracker removes it.
  const Wavelengths& b = tracker.baseline_nm();
  ShiftsPm s;
  for (std::size_t i = 0; i < kGratings; ++i) {
    s[i] = std::isfinite(wl[i]) && std::isfinite(b[i]) ? static_cast<float>((wl[i] - b[i]) * 1e3)
                                                        : std::numeric_limits<float>::quiet_NaN();
  }
  if (baseline_.common_mode) {
    const float cm = MedianOfPresent(s, baseline_.min_common_mode_gratings);
    if (std::isfinite(cm)) {
      for (std::size_t i = 0; i < kGratings; ++i) s[i] -= baseline_.thermal_ratio[i] * cm;
    }
  }
  const int tenth = std::max(1, baseline_.capture_frames / 10);
  const float alpha = 1.0f / static_cast<float>(tenth);
  for (std::size_t i = 0; i < kGratings; ++i) {
    if (std::isfinite(wl[i])) {
      sum_nm_[i] += wl[i];
      ++count_[i];
    }
    if (std::isfinite(s[i])) {
      shift_sum_pm_[i] += s[i];
      ++shift_count_[i];
      if (frames_ <= tenth) {
        head_sum_pm_[i] += s[i];
        ++head_count_[i];
      }
      tail_pm_[i] = std::isfinite(tail_pm_[i]) ? tail_pm_[i] + alpha * (s[i] - tail_pm_[i]) : s[i];
    }
  }
  if (frames_ < baseline_.capture_frames) return std::nullopt;
  ShiftsPm mean;
  for (std::size_t i = 0; i < kGratings; ++i) {
    // A grating missing in most of the window is left out of the judgement and keeps no new baseline of its
    // own (NaN, as the start-up capture leaves a grating it never saw).
    const bool enough = 2 * count_[i] >= frames_;
    mean_nm_[i] = enough ? sum_nm_[i] / count_[i] : std::numeric_limits<double>::quiet_NaN();
    mean[i] = 2 * shift_count_[i] >= frames_ ? static_cast<float>(shift_sum_pm_[i] / shift_count_[i])
                                             : std::numeric_limits<float>::quiet_NaN();
  }
  ShiftsPm head;
  for (std::size_t i = 0; i < kGratings; ++i) {
    head[i] = head_count_[i] > 0 ? static_cast<float>(head_sum_pm_[i] / head_count_[i]) : std::numeric_limits<float>::quiet_NaN();
  }
  // The largest force of the three judgements (the window, its start, its end).
  RetareResult r = judge_->Judge(mean);
  for (const ShiftsPm* part : {&head, &tail_pm_}) {
    const RetareResult p = judge_->Judge(*part);
    if (p.force_n > r.force_n) r = p;
  }
  active_ = false;
  r.motion_pm = motion_pm_;
  r.frames = frames_;
  return r;
}

}  // namespace ruffini::decode
