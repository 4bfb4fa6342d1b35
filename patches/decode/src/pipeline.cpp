#include "ruffini/decode/pipeline.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <span>

#include "ruffini/decode/model_io.h"
#include "ruffini/error.h"

namespace ruffini::decode {

std::string_view ReasonName(Reason r) noexcept {
  switch (r) {
    case Reason::kOk: return "ok";
    case Reason::kCapturing: return "capturing";
    case Reason::kSaturated: return "saturated";
    case Reason::kNoSignal: return "no_signal";
    case Reason::kOutOfBand: return "out_of_band";
    case Reason::kTooManyMissing: return "too_many_missing";
    case Reason::kBaselineStale: return "baseline_stale";
    case Reason::kOutOfRange: return "out_of_range";
    case Reason::kNonFinite: return "non_finite";
  }
  return "unknown";
}

BaselineConfig BaselineFor(const v1::DecoderModel& model, double sample_rate_hz) {
  BaselineConfig c;
  // The frame counts are the 100 Hz defaults; keep their durations at any rate (1 s capture, 0.2 s release).
  const double scale = sample_rate_hz / 100.0;
  c.capture_frames = std::max(1, static_cast<int>(std::lround(c.capture_frames * scale)));
  c.release_frames = std::max(1, static_cast<int>(std::lround(c.release_frames * scale)));
  c.sample_rate_hz = sample_rate_hz;
  c.common_mode = model.preprocessing().common_mode_removed();
  c.thermal_field = model.preprocessing().thermal_field();
  if (model.preprocessing().thermal_ratio_size() == static_cast<int>(kGratings)) {
    for (std::size_t i = 0; i < kGratings; ++i) c.thermal_ratio[i] = model.preprocessing().thermal_ratio(static_cast<int>(i));
  }
  return c;
}

template <typename Scalar>
Pipeline<Scalar>::Pipeline(const v1::DecoderModel& m, const patch::PatchSpec& spec, PipelineConfig config,
                           DecoderOptions options)
    : decoder_((CheckModelMatchesPatch(m, spec, "pipeline"), m), [&] {
        options.max_missing = config.max_missing;
        options.sample_rate_hz = config.baseline.sample_rate_hz;
        return std::move(options);
      }()),
      config_(config) {
  if (!(config_.baseline.sample_rate_hz > 0)) throw InputError("pipeline: sample_rate_hz must be > 0");
  if (config_.baseline.common_mode != m.preprocessing().common_mode_removed()) {
    throw InputError(std::string("pipeline: the model was trained with common_mode_removed = ") +
                     (m.preprocessing().common_mode_removed() ? "true" : "false") +
                     " but the baseline is configured otherwise (use BaselineFor(model, rate))");
  }
  for (std::size_t i = 0; i < kGratings; ++i) {
    const double c = spec.gratings[i].wavelength_nm, half = spec.fibre.band_half_width_nm + config_.band_margin_nm;
    band_lo_nm_[i] = std::max(c - half, spec.interrogator.window_min_nm);
    band_hi_nm_[i] = std::min(c + half, spec.interrogator.window_max_nm);
    mean_pm_[i] = m.force().input().mean(static_cast<int>(i));
    std_pm_[i] = m.force().input().std(static_cast<int>(i));
  }
  if (m.has_input_range()) {
    has_range_ = true;
    const auto& r = m.input_range();
    for (std::size_t i = 0; i < kGratings; ++i) {
      range_lo_pm_[i] = r.min_shift_pm(static_cast<int>(i)) - r.margin_pm();
      range_hi_pm_[i] = r.max_shift_pm(static_cast<int>(i)) + r.margin_pm();
    }
  }
  if (m.has_uncertainty()) {
    const auto& u = m.uncertainty();
    force_knots_.assign(u.force_knots_n().begin(), u.force_knots_n().end());
    force_sd_.assign(u.force_sd_n().begin(), u.force_sd_n().end());
    position_scale_.assign(u.position_scale().begin(), u.position_scale().end());
    position_floor_mm2_ = u.position_floor_mm2();
  }
  mm_per_deg_ = m.surface_radius_mm() * std::numbers::pi / 180.0;
  if (!(config_.multi_rel > 0 && config_.multi_rel <= 1 && config_.multi_floor_pm >= 0 &&
        config_.multi_link_mm >= 0 && config_.multi_margin_mm >= 0 && config_.multi_link_mm < 1e4 &&
        config_.multi_margin_mm < 1e4)) {
    throw InputError("pipeline: multi_rel must be in (0, 1], multi_floor_pm, multi_link_mm and multi_margin_mm >= 0");
  }
  if (!(config_.multi_window_nodes >= 0 && config_.multi_window_nodes <= 20)) {
    throw InputError("pipeline: multi_window_nodes must be 0..20 (the two-touch check's window, +- nodes)");
  }
  if (m.has_response()) {
    touches_.emplace(m.response());
    // The map must lie on the patch (1 mm and 1 deg of slack): a map elsewhere would flag every frame and place
    // it off the patch.
    const ResponseModel& r = touches_->model();
    const double y1 = r.y0_mm + (r.ny - 1) * r.dy_mm, r1 = r.r0_deg + (r.nr - 1) * r.dr_deg;
    if (!(r.y0_mm >= -1.0 && y1 <= spec.extent_y_mm + 1.0 && r.r0_deg >= -1.0 && r1 <= spec.extent_r_deg + 1.0)) {
      throw InputError("pipeline: the model's response map (Y " + std::to_string(r.y0_mm) + ".." + std::to_string(y1) +
                       " mm, R " + std::to_string(r.r0_deg) + ".." + std::to_string(r1) + " deg) does not lie on the patch (Y 0.." +
                       std::to_string(spec.extent_y_mm) + " mm, R 0.." + std::to_string(spec.extent_r_deg) + " deg)");
    }
  }
  if (!(config_.multi_refit_s >= 0 && config_.multi_refit_s <= 1)) throw InputError("pipeline: multi_refit_s must be 0..1 s");
  refit_frames_ = static_cast<int>(std::lround(config_.multi_refit_s * config_.baseline.sample_rate_hz));
  half_y_mm_ = 0.5 * spec.extent_y_mm;
  half_a_mm_ = 0.5 * spec.extent_r_deg * mm_per_deg_;
  for (std::size_t i = 0; i < kGratings; ++i) {
    grating_y_mm_[i] = spec.gratings[i].centre.y_mm;
    grating_a_mm_[i] = spec.gratings[i].centre.r_deg * mm_per_deg_;
    config_.baseline.grating_y_mm[i] = static_cast<float>(grating_y_mm_[i]);
    config_.baseline.grating_arc_mm[i] = static_cast<float>(grating_a_mm_[i]);
  }
  if (!(config_.baseline.field_tau_s > 0 && config_.baseline.field_tau_s < 1e6 && config_.baseline.field_far_tau_s > 0 &&
        config_.baseline.field_far_tau_s < 1e6 && config_.baseline.field_trim >= 0 &&
        config_.baseline.field_trim < static_cast<int>(kGratings) && config_.baseline.field_exclude_mm >= 0 &&
        config_.baseline.field_min_gratings >= 3 && config_.baseline.field_min_gratings <= static_cast<int>(kGratings) &&
        config_.baseline.field_max_rate_pm_s >= 0 && config_.baseline.field_max_rate_pm_s < 1e6)) {
    throw InputError("pipeline: thermal field: field_tau_s and field_far_tau_s must be > 0, field_trim 0..15, field_exclude_mm >= 0, "
                     "field_min_gratings 3..16, field_max_rate_pm_s >= 0");
  }
  for (std::size_t i = 0; i < kGratings; ++i) {
    for (std::size_t j = 0; j < kGratings; ++j) {
      const double d = std::hypot(grating_y_mm_[i] - grating_y_mm_[j], grating_a_mm_[i] - grating_a_mm_[j]);
      if (d <= config_.multi_link_mm) linked_[i] = static_cast<std::uint16_t>(linked_[i] | (1u << j));
    }
  }
  if (!(config_.contact_confirm_s >= 0 && config_.contact_confirm_s <= 1.0)) {
    throw InputError("pipeline: contact_confirm_s must be 0..1 s");
  }
  confirm_frames_ = static_cast<int>(std::lround(config_.contact_confirm_s * config_.baseline.sample_rate_hz));
  peak_decay_ = static_cast<float>(std::exp(-1.0 / (0.5 * config_.baseline.sample_rate_hz)));
  if (!(config_.over_range_force_n > 0 && config_.over_range_force_n < 1e6) || config_.over_range_missing < 1) {
    throw InputError("pipeline: over_range_force_n must be > 0 and over_range_missing >= 1");
  }
  if (!(config_.multi_force_k >= 0 && config_.multi_force_k <= 100 && config_.multi_force_min_gain >= 0 &&
        std::isfinite(config_.multi_force_min_gain))) {
    throw InputError("pipeline: multi_force_k must be 0..100 and multi_force_min_gain >= 0");
  }
  if (!(config_.quiet_release_pm >= 0 && config_.quiet_release_drop >= 0)) {
    throw InputError("pipeline: quiet_release_pm and quiet_release_drop must be >= 0");
  }
  if (!config_.faint_refuse.has_value()) {
    const float below = m.preprocessing().faint_refuse_below_n();
    config_.faint_refuse = below > 0.0f;
    if (below > 0.0f) config_.faint_max_n = below;
  }
  if (!(config_.faint_pm >= 0 && config_.faint_pm < 1e3 && config_.faint_max_n >= 0 && config_.faint_max_n < 1e6 &&
        config_.faint_smooth_s >= 0 && config_.faint_smooth_s <= 10)) {
    throw InputError("pipeline: faint_pm must be 0..1000 pm, faint_max_n >= 0, faint_smooth_s 0..10 s");
  }
  // The refusal after a release stays inside the faint refusal's force, which the hello declares.
  if (!(config_.release_refuse_n >= 0 && config_.release_peak_n >= 0 && std::isfinite(config_.release_peak_n) &&
        config_.release_tau_s > 0 && config_.release_tau_s <= 3600)) {
    throw InputError("pipeline: release_refuse_n and release_peak_n must be >= 0, release_tau_s 0..3600 s");
  }
  if (*config_.faint_refuse && config_.release_refuse_n > config_.faint_max_n) {
    throw InputError("pipeline: release_refuse_n " + std::to_string(config_.release_refuse_n) +
                     " N is above the faint refusal's " + std::to_string(config_.faint_max_n) +
                     " N (the force the hello declares refused)");
  }
  force_decay_ = static_cast<float>(std::exp(-1.0 / (config_.release_tau_s * config_.baseline.sample_rate_hz)));
  const double smooth_frames = config_.faint_smooth_s * config_.baseline.sample_rate_hz;
  smooth_alpha_ = smooth_frames > 1.0 ? static_cast<float>(1.0 - std::exp(-1.0 / smooth_frames)) : 1.0f;
}

template <typename Scalar>
Pipeline<Scalar>::Data::Data(const Pipeline& p) : tracker_(p.config_.baseline), net_(p.decoder_) {}

template <typename Scalar>
Reason Pipeline<Scalar>::CheckRaw(const Wavelengths& wl, std::uint32_t flags) const noexcept {
  if (flags & kSourceSaturated) return Reason::kSaturated;
  int missing = 0, dark = 0;
  for (std::size_t i = 0; i < kGratings; ++i) {
    if (!std::isfinite(wl[i])) {
      ++missing;
    } else if (wl[i] <= 0.0) {
      ++dark;
    }
  }
  if (missing + dark == static_cast<int>(kGratings)) return Reason::kNoSignal;
  for (std::size_t i = 0; i < kGratings; ++i) {
    if (std::isfinite(wl[i]) && (wl[i] < band_lo_nm_[i] || wl[i] > band_hi_nm_[i])) return Reason::kOutOfBand;
  }
  if (missing > config_.max_missing) return Reason::kTooManyMissing;
  return Reason::kOk;
}

// A capture just made, against the patch's rest (BaselineConfig::rest_nm; review 11): the difference, common mode
// removed as the tracker removes it, decoded by the networks as one frame held for the whole window. If that
// reads a contact (the force gate opens) or lies outside the calibrated range, the capture holds a press the
// restart did not see: refused, capture again. The tracker's own 6 pm check comes first; this one sees what the
// decoder sees (a 2.25 N press far from every grating moves none by 6 pm, review 11 finding 1).
template <typename Scalar>
void Pipeline<Scalar>::RestCheck(Data& d) const noexcept {
  ShiftsPm shift{};
  bool refuse = !BaselineTracker::RestDifferencePm(d.tracker_.baseline_nm(), *config_.baseline.rest_nm,
                                                   config_.baseline, shift) ||
                !InRange(shift);
  if (!refuse) {
    decoder_.Reset(d.net_, &shift);
    const DecodeOutput o = decoder_.Decode(shift, d.net_);
    refuse = !o.valid || o.in_contact;
  }
  d.primed_ = false;  // the window starts afresh from the first tracked frame
  if (refuse) {
    d.tracker_.RefuseCapture(BaselineTracker::RestResidualPm(d.tracker_.baseline_nm(), *config_.baseline.rest_nm,
                                                             config_.baseline));
  }
}

template <typename Scalar>
bool Pipeline<Scalar>::InRange(const ShiftsPm& s) const noexcept {
  for (std::size_t i = 0; i < kGratings; ++i) {
    if (!std::isfinite(s[i])) continue;  // missing: counted by CheckRaw
    if (has_range_) {
      if (s[i] < range_lo_pm_[i] || s[i] > range_hi_pm_[i]) return false;
    } else if (std::abs(s[i] - mean_pm_[i]) > config_.z_limit * std_pm_[i]) {
      return false;
    }
  }
  return true;
}

template <typename Scalar>
float Pipeline<Scalar>::Interp(const std::vector<float>& ys, float x) const noexcept {
  const std::size_t n = force_knots_.size();
  if (x <= force_knots_.front() || n == 1) return ys.front();
  if (x >= force_knots_.back()) return ys.back();
  const auto it = std::upper_bound(force_knots_.begin(), force_knots_.end(), x);
  const auto k = static_cast<std::size_t>(it - force_knots_.begin());
  const float t = (x - force_knots_[k - 1]) / (force_knots_[k] - force_knots_[k - 1]);
  return ys[k - 1] + t * (ys[k] - ys[k - 1]);
}

namespace {

// Widens out's covariance (Y, arc mm) so that every place of `places` (Y mm, arc mm) lies within 1 sigma of
// (cy, ca): the sum of their offsets' outer products bounds each one's; plus margin_mm in every direction.
void WidenToHold(PipelineOutput& out, std::span<const std::array<double, 2>> places, double cy, double ca,
                 double margin_mm) noexcept {
  const double m2 = margin_mm * margin_mm;
  double yy = m2, ya = 0, aa = m2;
  for (const auto& p : places) {
    const double dy = p[0] - cy, da = p[1] - ca;
    yy += dy * dy;
    ya += dy * da;
    aa += da * da;
  }
  out.cov_yy_mm2 += static_cast<float>(yy);
  out.cov_yr_mm2 += static_cast<float>(ya);
  out.cov_rr_mm2 += static_cast<float>(aa);
}

}  // namespace

template <typename Scalar>
void Pipeline<Scalar>::RaiseForPair(const TouchVerdict& v, PipelineOutput& out) const noexcept {
  using MF = PipelineConfig::MultiForce;
  if (config_.multi_force == MF::kNetworks) return;
  double bound[2] = {0.0, 0.0}, sd[2] = {0.0, 0.0};
  for (int k = 0; k < 2; ++k) {
    const Touch& t = v.touch[static_cast<std::size_t>(k)];
    if (!(t.gain_pm_per_n >= config_.multi_force_min_gain) || !std::isfinite(t.force_sd_n) || !std::isfinite(t.force_n)) continue;
    bound[k] = std::max(0.0, t.force_n - config_.multi_force_k * t.force_sd_n);
    sd[k] = t.force_sd_n;
  }
  const bool total = config_.multi_force == MF::kTotal;
  const double force = total ? bound[0] + bound[1] : std::max(bound[0], bound[1]);
  if (!(force > out.force_n) || !std::isfinite(force)) return;
  out.force_n = static_cast<float>(force);
  // The sd of what is now reported (a sum: both touches' in quadrature), never below the networks'.
  const double s = total ? std::hypot(sd[0], sd[1]) : (bound[0] >= bound[1] ? sd[0] : sd[1]);
  if (std::isfinite(out.force_sd_n)) out.force_sd_n = std::max(out.force_sd_n, static_cast<float>(s));
}

template <typename Scalar>
bool Pipeline<Scalar>::Faint(const ShiftsPm& shift, Data& d) const noexcept {
  if (!(config_.faint_pm > 0)) return false;
  float peak = 0.0f;
  for (std::size_t i = 0; i < kGratings; ++i) {
    float& m = d.smooth_[i];
    if (!std::isfinite(shift[i])) continue;  // missing: its smoothed value is kept (and still counts)
    m = d.smooth_primed_ && std::isfinite(m) ? m + smooth_alpha_ * (shift[i] - m) : shift[i];
  }
  d.smooth_primed_ = true;
  for (float m : d.smooth_) {
    if (std::isfinite(m)) peak = std::max(peak, std::abs(m));
  }
  return peak < static_cast<float>(config_.faint_pm);
}

template <typename Scalar>
int Pipeline<Scalar>::Touches(const ShiftsPm& shift, PipelineOutput& out, Data& d) const noexcept {
  static_assert(kGratings <= 16, "linked_ holds one bit per grating");
  float peak = 0.0f;
  for (float v : shift) {
    if (std::isfinite(v)) peak = std::max(peak, std::abs(v));
  }
  const float level = std::max(static_cast<float>(config_.multi_rel) * peak, static_cast<float>(config_.multi_floor_pm));
  std::uint32_t moved = 0;
  for (std::size_t i = 0; i < kGratings; ++i) {
    if (std::isfinite(shift[i]) && std::abs(shift[i]) >= level) moved |= 1u << i;
  }
  // A map whose limit is 0 checks nothing (it is there for the re-tare): the gratings' groups below, as without one.
  if (touches_ && touches_->limit() > 0 && out.located) {
    // The model's one-touch response: is this one touch? If not, the two-touch fit's places and total force.
    const bool refit = d.pair_age_ >= refit_frames_;
    TouchVerdict v = touches_->Check(shift, out.y_mm, out.r_deg, refit, config_.multi_confirm_anywhere,
                                     config_.multi_window_nodes);
    if (!v.multiple) {
      d.pair_age_ = 1 << 30;
      return 1;
    }
    if (refit) {
      d.pair_ = v;
      d.pair_age_ = 0;
    } else {
      ++d.pair_age_;
      v.found = d.pair_.found;
      v.touch = d.pair_.touch;
      touches_->Amplitudes(shift, v);  // the cached places, this frame's forces
    }
    out.multiple = true;
    const bool cal = std::isfinite(out.cov_yy_mm2);
    if (v.found == 2) {
      RaiseForPair(v, out);
      // One place, the pair's centre of pressure, with the covariance holding both places.
      const double total = v.touch[0].force_n + v.touch[1].force_n;
      const double w0 = total > 0 ? v.touch[0].force_n / total : 0.5;
      const double cy = w0 * v.touch[0].y_mm + (1 - w0) * v.touch[1].y_mm;
      const double cr = w0 * v.touch[0].r_deg + (1 - w0) * v.touch[1].r_deg;
      out.y_mm = static_cast<float>(cy);
      out.r_deg = static_cast<float>(cr);
      if (cal) {
        const std::array<std::array<double, 2>, 2> places{{{v.touch[0].y_mm, v.touch[0].r_deg * mm_per_deg_},
                                                           {v.touch[1].y_mm, v.touch[1].r_deg * mm_per_deg_}}};
        WidenToHold(out, places, cy, cr * mm_per_deg_, config_.multi_margin_mm);
      }
      return 2;
    }
    // Not one touch, and no pair explains it either: somewhere on the patch.
    if (cal) {
      out.cov_yy_mm2 += static_cast<float>(half_y_mm_ * half_y_mm_);
      out.cov_rr_mm2 += static_cast<float>(half_a_mm_ * half_a_mm_);
    }
    return 0;
  }
  if (moved == 0 || config_.multi_link_mm <= 0) return moved == 0 ? 0 : 1;
  // Single linkage over at most 16 gratings: grow each group from its first member through linked_.
  struct Group {
    double w = 0, y = 0, a = 0;
  };
  std::array<Group, kGratings> groups{};
  std::array<std::array<double, 2>, kGratings> centres{};
  int n = 0;
  std::uint32_t left = moved;
  while (left != 0) {
    std::uint32_t group = left & (~left + 1u);  // the lowest grating left
    std::uint32_t grown = 0;
    while (grown != group) {
      grown = group;
      for (std::size_t i = 0; i < kGratings; ++i) {
        if (grown & (1u << i)) group |= linked_[i] & moved;
      }
    }
    left &= ~group;
    Group& g = groups[static_cast<std::size_t>(n++)];
    for (std::size_t i = 0; i < kGratings; ++i) {
      if (!(group & (1u << i))) continue;
      const double w = std::abs(shift[i]);
      g.w += w;
      g.y += w * grating_y_mm_[i];
      g.a += w * grating_a_mm_[i];
    }
  }
  if (n < 2 || !out.located) return n;
  out.multiple = true;
  if (!std::isfinite(out.cov_yy_mm2)) return n;  // no calibrated uncertainty: the flag says it
  // Widen so that every group's centre is within 1 sigma of the reported place, plus the margin.
  for (int k = 0; k < n; ++k) {
    const Group& g = groups[static_cast<std::size_t>(k)];
    centres[static_cast<std::size_t>(k)] = {g.y / g.w, g.a / g.w};
  }
  WidenToHold(out, std::span<const std::array<double, 2>>(centres.data(), static_cast<std::size_t>(n)), out.y_mm,
              out.r_deg * mm_per_deg_, config_.multi_margin_mm);
  return n;
}

template <typename Scalar>
PipelineOutput Pipeline<Scalar>::Process(const Wavelengths& wl, std::uint32_t flags, Data& d) const noexcept {
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
  PipelineOutput out;
  ++d.counters_.frames;
  d.recent_force_n_ *= force_decay_;  // every frame, valid or not: the peak fades with time
  auto invalid = [&](Reason r) {
    out.reason = r;
    out.force_sd_n = kNaN;
    out.cov_yy_mm2 = out.cov_yr_mm2 = out.cov_rr_mm2 = kNaN;
    out.y_mm = out.r_deg = kNaN;
    ++d.counters_.invalid[static_cast<std::size_t>(r)];
    ++d.invalid_run_;
    d.pair_age_ = 1 << 30;  // the two-touch fit's places end with the located frames (a gap: fit afresh)
    // A gap longer than the window: the networks start afresh from the next valid frame.
    if (d.invalid_run_ > decoder_.window()) d.primed_ = false;
    return out;
  };
  // Over range: the frame is not decoded (invalid, counted under its reason, the baseline and the window
  // untouched) but reported as a contact of at least over_range_force_n. The gate stays open, so the
  // baseline stays frozen until the decoder sees the release.
  auto over_range = [&](Reason r) {
    invalid(r);
    out.over_range = true;
    out.in_contact = true;
    out.force_n = static_cast<float>(config_.over_range_force_n);
    d.recent_force_n_ = std::max(d.recent_force_n_, out.force_n);
    if (!d.contact_) ++d.counters_.onsets;
    ++d.counters_.over_range;
    d.contact_ = true;
    d.over_range_ = true;
    d.gate_ = true;
    return out;
  };
  const bool have_baseline = d.tracker_.state() != BaselineTracker::State::kCapturing;
  const bool loaded = d.contact_ || d.over_range_;
  int lost = 0;
  for (double v : wl) lost += std::isfinite(v) ? 0 : 1;
  // Frames that cannot be peaks of this fibre never reach the baseline (they would move it).
  const Reason raw = CheckRaw(wl, flags);
  if (raw != Reason::kOk) {
    if (have_baseline && (raw == Reason::kSaturated || raw == Reason::kOutOfBand)) return over_range(raw);
    if (have_baseline && loaded && (raw == Reason::kTooManyMissing || raw == Reason::kNoSignal)) return over_range(raw);
    d.over_range_ = false;
    return invalid(raw);
  }
  if (have_baseline && loaded && lost >= config_.over_range_missing) return over_range(Reason::kTooManyMissing);

  ShiftsPm shift;
  using Gate = BaselineTracker::Gate;
  const Gate gate = !config_.freeze_on_gate ? Gate::kNone : (d.gate_ ? Gate::kOpen : Gate::kClosed);
  if (d.tracker_.state() == BaselineTracker::State::kCapturing) {
    d.tracker_.Update(wl, shift, gate);
    if (d.tracker_.state() != BaselineTracker::State::kCapturing && config_.baseline.rest_nm) RestCheck(d);
    return invalid(Reason::kCapturing);
  }
  d.tracker_.Measure(wl, shift);
  out.common_mode_pm = d.tracker_.common_mode_pm();
  // Out of range: refused before it can move the baseline.
  if (!InRange(shift)) return over_range(Reason::kOutOfRange);
  d.over_range_ = false;
  d.tracker_.Advance(wl, shift, gate, d.place_y_mm_, d.place_a_mm_);

  if (!d.primed_) {
    decoder_.Reset(d.net_, &shift);  // as if this frame had been there for the whole window
    d.primed_ = true;
    d.smooth_primed_ = false;
  }
  const DecodeOutput o = decoder_.Decode(shift, d.net_);
  out.missing = o.missing;
  if (!o.valid) return invalid(Reason::kNonFinite);
  d.place_y_mm_ = o.located ? o.y_mm : BaselineTracker::kNoPlace;
  d.place_a_mm_ = o.located ? static_cast<float>(o.r_deg * mm_per_deg_) : BaselineTracker::kNoPlace;
  // A baseline frozen too long is reported (a fault upstream), yet the stream goes on being decoded: the
  // gate keeps driving the baseline, so the fault clears itself once the gate lets go.
  if (d.tracker_.stale()) {
    d.gate_ = o.in_contact;
    d.open_run_ = 0;
    d.contact_ = false;
    return invalid(Reason::kBaselineStale);
  }
  d.invalid_run_ = 0;
  out.valid = true;
  out.reason = Reason::kOk;
  out.force_n = o.force_n;
  d.gate_ = o.in_contact;
  d.open_run_ = o.in_contact ? d.open_run_ + 1 : 0;
  // Shifts a baseline error gives as well: flagged. With faint_refuse, below faint_max_n no contact; the gate
  // stays open, so the baseline stays frozen and its stale clock runs. Letting the baseline track instead ate
  // a held 0.9 N press (raised to 2.25 N it read 1.2 N); pausing the clock let a -0.8 pm error hide a 2.25 N
  // press with no FAULT for good (review 7). Both are tested (tests/eval/field_test.cpp, faint_review_test.cpp).
  bool refused = false;
  if (Faint(shift, d) && o.in_contact) {
    out.faint = true;
    ++d.counters_.faint;
    if (*config_.faint_refuse && o.force_n < config_.faint_max_n) {
      refused = true;
      d.open_run_ = 0;
    }
  }
  // After a release (PipelineConfig::release_*): the cover's fading strain and the window's lag, below
  // release_refuse_n, are no contact while a press of release_peak_n or more is recent. Same treatment as a
  // refused faint frame: the gate stays open (the baseline frozen, its stale clock running).
  if (std::isfinite(o.force_n)) d.recent_force_n_ = std::max(d.recent_force_n_, o.force_n);
  if (!refused && *config_.faint_refuse && config_.release_refuse_n > 0 && o.in_contact &&
      o.force_n < config_.release_refuse_n && d.recent_force_n_ >= config_.release_peak_n) {
    refused = true;
    d.open_run_ = 0;
    ++d.counters_.release_refused;
  }
  bool quiet = false;
  if (config_.quiet_release_pm > 0) {
    float peak = 0.0f;
    for (float v : shift) {
      if (std::isfinite(v)) peak = std::max(peak, std::abs(v));
    }
    const float before = d.recent_peak_pm_;
    d.recent_peak_pm_ = std::max(peak, before * peak_decay_);
    quiet = peak < static_cast<float>(config_.quiet_release_pm) &&
            (config_.quiet_release_drop <= 0 ||
             before >= static_cast<float>(config_.quiet_release_drop * config_.quiet_release_pm));
  }
  const bool contact = o.in_contact && d.open_run_ > confirm_frames_ && !quiet && !refused;
  if (quiet || refused) out.force_n = 0.0f;
  if (contact && !d.contact_) ++d.counters_.onsets;
  d.contact_ = contact;
  out.in_contact = contact;
  ++d.counters_.valid;
  const bool cal = !force_knots_.empty();
  out.force_sd_n = cal ? Interp(force_sd_, o.force_n) : kNaN;
  out.located = o.located && contact;
  if (!out.located) {
    d.pair_age_ = 1 << 30;  // a later flagged frame fits afresh
    out.y_mm = out.r_deg = kNaN;
    out.cov_yy_mm2 = out.cov_yr_mm2 = out.cov_rr_mm2 = kNaN;
    return out;
  }
  ++d.counters_.located;
  out.y_mm = o.y_mm;
  out.r_deg = o.r_deg;
  out.confidence = o.confidence;
  if (cal) {
    const float k = Interp(position_scale_, o.force_n);
    out.cov_yy_mm2 = k * o.cov_yy_mm2 + position_floor_mm2_;
    out.cov_yr_mm2 = k * o.cov_ya_mm2;
    out.cov_rr_mm2 = k * o.cov_aa_mm2 + position_floor_mm2_;
  } else {
    out.cov_yy_mm2 = out.cov_yr_mm2 = out.cov_rr_mm2 = kNaN;
  }
  out.touch_groups = static_cast<std::uint8_t>(Touches(shift, out, d));
  if (out.multiple) ++d.counters_.multiple;
  return out;
}

template class Pipeline<float>;
template class Pipeline<double>;

}  // namespace ruffini::decode
