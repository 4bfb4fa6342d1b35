#include "ruffini/decode/baseline.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Dense>

namespace ruffini::decode {

float MedianOfPresent(const ShiftsPm& s, int min_count) noexcept {
  std::array<float, kGratings> v;
  std::size_t n = 0;
  for (float x : s) {
    if (std::isfinite(x)) v[n++] = x;
  }
  if (n == 0 || static_cast<int>(n) < min_count) return std::numeric_limits<float>::quiet_NaN();
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(n / 2);
  std::nth_element(v.begin(), mid, v.begin() + static_cast<std::ptrdiff_t>(n));
  if (n % 2 == 1) return *mid;
  const float upper = *mid;
  const float lower = *std::max_element(v.begin(), mid);
  return 0.5f * (lower + upper);
}

void BaselineTracker::Reset() noexcept {
  state_ = State::kCapturing;
  baseline_nm_.fill(0.0);
  captured_nm_.fill(0.0);
  sum_nm_.fill(0.0);
  count_.fill(0);
  captured_ = 0;
  quiet_frames_ = 0;
  frozen_frames_ = 0;
  common_mode_pm_ = 0.0f;
  field_slope_y_ = field_slope_arc_ = 0.0f;
  moved_pm_.fill(0.0);
}

void BaselineTracker::Seed(const Wavelengths& b) noexcept {
  moved_pm_.fill(0.0);
  baseline_nm_ = b;
  captured_nm_ = b;
  state_ = State::kTracking;
  quiet_frames_ = 0;
  frozen_frames_ = 0;
}

bool BaselineTracker::RestDifferencePm(const Wavelengths& b, const Wavelengths& rest, const BaselineConfig& config,
                                       ShiftsPm& out) noexcept {
  for (std::size_t i = 0; i < kGratings; ++i) out[i] = static_cast<float>((b[i] - rest[i]) * 1e3);  // NaN stays NaN
  const float cm = MedianOfPresent(out, std::max(1, config.min_common_mode_gratings));
  if (!std::isfinite(cm)) return false;
  for (std::size_t i = 0; i < kGratings; ++i) out[i] -= config.thermal_ratio[i] * cm;
  return true;
}

float BaselineTracker::RestResidualPm(const Wavelengths& b, const Wavelengths& rest, const BaselineConfig& config) noexcept {
  ShiftsPm d;
  if (!RestDifferencePm(b, rest, config, d)) return std::numeric_limits<float>::quiet_NaN();
  float worst = 0.0f;
  for (float v : d) {
    if (std::isfinite(v)) worst = std::max(worst, std::abs(v));
  }
  return worst;
}

void BaselineTracker::RefuseCapture(float residual_pm) noexcept {
  const std::uint64_t refused = captures_refused_ + 1;
  Reset();
  captures_refused_ = refused;
  refused_residual_pm_ = residual_pm;
}

double BaselineTracker::drift_pm() const noexcept {
  if (state_ == State::kCapturing) return 0.0;
  double sum = 0;
  int n = 0;
  for (std::size_t i = 0; i < kGratings; ++i) {
    if (std::isfinite(baseline_nm_[i]) && std::isfinite(captured_nm_[i])) {
      sum += (baseline_nm_[i] - captured_nm_[i]) * 1e3;
      ++n;
    }
  }
  return n > 0 ? sum / n : 0.0;
}

bool BaselineTracker::Update(const Wavelengths& wl, ShiftsPm& shift, Gate gate) noexcept {
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
  if (state_ == State::kCapturing) {
    bool quiet = true;
    for (std::size_t i = 0; i < kGratings; ++i) {
      if (!std::isfinite(wl[i]) || count_[i] == 0) continue;
      const double mean = sum_nm_[i] / count_[i];
      if (std::abs(wl[i] - mean) * 1e3 > config_.capture_tolerance_pm) quiet = false;
    }
    if (!quiet) {  // something moved during capture: start again from this frame
      sum_nm_.fill(0.0);
      count_.fill(0);
      captured_ = 0;
    }
    for (std::size_t i = 0; i < kGratings; ++i) {
      if (!std::isfinite(wl[i])) continue;
      sum_nm_[i] += wl[i];
      ++count_[i];
    }
    shift.fill(kNaN);
    if (++captured_ < config_.capture_frames) return false;
    for (std::size_t i = 0; i < kGratings; ++i) {
      baseline_nm_[i] = count_[i] > 0 ? sum_nm_[i] / count_[i] : std::numeric_limits<double>::quiet_NaN();
    }
    if (config_.rest_nm) {
      // Not the rest this patch last had (a press held through a restart): refused, capture again. A
      // residual that cannot be computed (too few gratings) is refused as well.
      const float residual = RestResidualPm(baseline_nm_, *config_.rest_nm, config_);
      if (!(residual <= config_.rest_tolerance_pm)) {
        ++captures_refused_;
        refused_residual_pm_ = residual;
        sum_nm_.fill(0.0);
        count_.fill(0);
        captured_ = 0;
        return false;
      }
    }
    captured_nm_ = baseline_nm_;
    state_ = State::kTracking;
    frozen_frames_ = 0;
    return false;
  }

  Measure(wl, shift);
  Advance(wl, shift, gate);
  return true;
}

bool BaselineTracker::Measure(const Wavelengths& wl, ShiftsPm& shift) noexcept {
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
  if (state_ == State::kCapturing) {
    shift.fill(kNaN);
    return false;
  }
  for (std::size_t i = 0; i < kGratings; ++i) {
    shift[i] = std::isfinite(wl[i]) && std::isfinite(baseline_nm_[i]) ? static_cast<float>((wl[i] - baseline_nm_[i]) * 1e3)
                                                                        : kNaN;
  }
  common_mode_pm_ = 0.0f;
  if (config_.common_mode) {
    const float cm = MedianOfPresent(shift, config_.min_common_mode_gratings);
    if (std::isfinite(cm)) {
      common_mode_pm_ = cm;
      for (std::size_t i = 0; i < kGratings; ++i) shift[i] -= config_.thermal_ratio[i] * cm;  // NaN stays NaN
    }
  }
  return true;
}

namespace {

constexpr double kScaleMm = 50.0;  // the places are centred and scaled so the 3x3 normal equations stay well conditioned

struct Places {
  std::array<double, kGratings> y{}, x{};  // centred, scaled
};

Places PlacesOf(const BaselineConfig& c) noexcept {
  double yc = 0, xc = 0;
  for (std::size_t i = 0; i < kGratings; ++i) {
    yc += c.grating_y_mm[i];
    xc += c.grating_arc_mm[i];
  }
  yc /= kGratings;
  xc /= kGratings;
  Places p;
  for (std::size_t i = 0; i < kGratings; ++i) {
    p.y[i] = (c.grating_y_mm[i] - yc) / kScaleMm;
    p.x[i] = (c.grating_arc_mm[i] - xc) / kScaleMm;
  }
  return p;
}

// The field's shape: a plane, a + b y + c x. Tried on validation data: a quadratic surface (plus y^2, x y,
// x^2) fits a lamp's cosine around the limb better, but it also fits more of a touch, and it missed more
// presses (docs/decoders.md "Thermal fields").
using Basis = Eigen::Vector3d;

Basis BasisAt(const Places& pl, std::size_t i) noexcept { return {1.0, pl.y[i], pl.x[i]}; }

// Least squares plane through value[i] over the gratings in use, then again without the trim gratings
// furthest from it. False when the gratings in use cannot pin a plane (fewer than min_count, all in one row).
// Allocation-free.
bool FitField(const Places& pl, std::array<bool, kGratings> use, const std::array<double, kGratings>& value, int trim,
              int min_count, Basis& p) noexcept {
  auto count = [&] {
    int n = 0;
    for (bool u : use) n += u ? 1 : 0;
    return n;
  };
  auto fit = [&] {
    Eigen::Matrix3d a = Eigen::Matrix3d::Zero();
    Basis b = Basis::Zero();
    for (std::size_t i = 0; i < kGratings; ++i) {
      if (!use[i]) continue;
      const Basis r = BasisAt(pl, i);
      a.noalias() += r * r.transpose();
      b.noalias() += r * value[i];
    }
    // Both slopes need places spread along and around (sd of 5 mm each): LDLT alone would quietly give a
    // row of gratings a plane with a made-up slope across it (its zero pivot is not a failure).
    const double n_used = a(0, 0), min_var = (5.0 / kScaleMm) * (5.0 / kScaleMm);
    if (!(n_used > 0)) return false;
    const double var_y = a(1, 1) / n_used - (a(0, 1) / n_used) * (a(0, 1) / n_used);
    const double var_x = a(2, 2) / n_used - (a(0, 2) / n_used) * (a(0, 2) / n_used);
    if (!(var_y >= min_var && var_x >= min_var)) return false;
    const Eigen::LDLT<Eigen::Matrix3d> ldlt(a);
    if (ldlt.info() != Eigen::Success || !(ldlt.rcond() > 1e-3)) return false;
    p = ldlt.solve(b);
    return p.allFinite();
  };
  const int n = count();
  if (n < min_count || !fit()) return false;
  trim = std::min(trim, n - min_count);
  for (int k = 0; k < trim; ++k) {
    std::size_t worst = kGratings;
    double worst_r = -1;
    for (std::size_t i = 0; i < kGratings; ++i) {
      if (!use[i]) continue;
      const double r = std::abs(value[i] - BasisAt(pl, i).dot(p));
      if (r > worst_r) {
        worst_r = r;
        worst = i;
      }
    }
    if (worst < kGratings) use[worst] = false;
  }
  return trim <= 0 || fit();
}

}  // namespace

void BaselineTracker::FollowField(const ShiftsPm& s, float touch_y_mm, float touch_arc_mm) noexcept {
  field_slope_y_ = field_slope_arc_ = 0.0f;
  const Places pl = PlacesOf(config_);
  const double rate = config_.sample_rate_hz;
  const double max_step_pm = config_.field_max_rate_pm_s / rate;
  const bool placed = std::isfinite(touch_y_mm) && std::isfinite(touch_arc_mm);
  // Far from the touch: more than field_exclude_mm from where the networks placed it (all, when unplaced).
  std::array<bool, kGratings> far{};
  for (std::size_t i = 0; i < kGratings; ++i) {
    far[i] = std::isfinite(s[i]) && std::isfinite(baseline_nm_[i]);
    if (far[i] && placed) {
      far[i] = std::hypot(config_.grating_y_mm[i] - touch_y_mm, config_.grating_arc_mm[i] - touch_arc_mm) > config_.field_exclude_mm;
    }
  }
  Basis p;
  if (state_ != State::kFrozen || !placed) {
    // Untouched, or touched where the networks do not place it: the baseline follows the plane through the
    // shifts with field_tau_s (the slow filter is too slow for a field building over minutes), robust to a
    // touch the gate has not seen or not placed (trim).
    std::array<double, kGratings> v{};
    for (std::size_t i = 0; i < kGratings; ++i) v[i] = far[i] ? static_cast<double>(s[i]) : 0.0;
    if (!FitField(pl, far, v, config_.field_trim, config_.field_min_gratings, p)) return;
    field_slope_y_ = static_cast<float>(p[1] / kScaleMm);
    field_slope_arc_ = static_cast<float>(p[2] / kScaleMm);
    const double beta = std::min(1.0, 1.0 / (config_.field_tau_s * rate));
    for (std::size_t i = 0; i < kGratings; ++i) {
      if (!std::isfinite(baseline_nm_[i])) continue;
      const double field_pm = BasisAt(pl, i).dot(p) - p[0];  // the mean stays with the common mode
      baseline_nm_[i] += std::clamp(beta * field_pm, -max_step_pm, max_step_pm) * 1e-3;
    }
    return;
  }
  // Touched and placed (frozen): a grating away from the touch that moves by no more than touch_off_pm (no
  // second touch on it) follows its own shift with field_far_tau_s; what those baselines moved since the
  // freeze began (beyond the common mode) is fitted by a plane, and the gratings near the touch move with
  // that plane, never faster than field_max_rate_pm_s.
  for (std::size_t i = 0; i < kGratings; ++i) {
    if (far[i] && std::abs(s[i]) > config_.touch_off_pm) far[i] = false;
  }
  const double beta = std::min(1.0, 1.0 / (config_.field_far_tau_s * rate));
  for (std::size_t i = 0; i < kGratings; ++i) {
    if (!far[i]) continue;
    const double step = std::clamp(beta * static_cast<double>(s[i]), -max_step_pm, max_step_pm);
    baseline_nm_[i] += step * 1e-3;
    moved_pm_[i] += step;
  }
  if (!FitField(pl, far, moved_pm_, config_.field_trim, config_.field_min_gratings, p)) return;
  field_slope_y_ = static_cast<float>(p[1] / kScaleMm);
  field_slope_arc_ = static_cast<float>(p[2] / kScaleMm);
  for (std::size_t i = 0; i < kGratings; ++i) {
    if (far[i] || !std::isfinite(baseline_nm_[i])) continue;
    const double target = BasisAt(pl, i).dot(p);
    const double step = std::clamp(target - moved_pm_[i], -max_step_pm, max_step_pm);
    baseline_nm_[i] += step * 1e-3;
    moved_pm_[i] += step;
  }
}

void BaselineTracker::Advance(const Wavelengths& wl, const ShiftsPm& shift, Gate gate, float touch_y_mm,
                              float touch_arc_mm) noexcept {
  const bool was_frozen = state_ == State::kFrozen;
  if (gate == Gate::kNone) {
    double max_abs = 0.0;
    for (float v : shift) {
      if (std::isfinite(v)) max_abs = std::max(max_abs, static_cast<double>(std::abs(v)));
    }
    if (max_abs > config_.touch_on_pm) {
      state_ = State::kFrozen;
      quiet_frames_ = 0;
    } else if (state_ == State::kFrozen) {
      quiet_frames_ = max_abs < config_.touch_off_pm ? quiet_frames_ + 1 : 0;
      if (quiet_frames_ >= config_.release_frames) state_ = State::kTracking;
    }
  } else if (gate == Gate::kOpen) {
    state_ = State::kFrozen;
    quiet_frames_ = 0;
  } else if (state_ == State::kFrozen && ++quiet_frames_ >= config_.release_frames) {
    state_ = State::kTracking;
  }
  if (state_ == State::kTracking) {
    frozen_frames_ = 0;
    const double alpha = 1.0 / (config_.drift_tau_s * config_.sample_rate_hz);
    for (std::size_t i = 0; i < kGratings; ++i) {
      if (std::isfinite(wl[i]) && std::isfinite(baseline_nm_[i])) baseline_nm_[i] += alpha * (wl[i] - baseline_nm_[i]);
    }
  } else {
    ++frozen_frames_;
    if (common_mode_pm_ != 0.0f) {  // follow the uniform drift under the touch
      const double beta = std::min(1.0, 1.0 / (config_.common_mode_tau_s * config_.sample_rate_hz));
      for (std::size_t i = 0; i < kGratings; ++i) {
        if (std::isfinite(baseline_nm_[i])) baseline_nm_[i] += beta * config_.thermal_ratio[i] * common_mode_pm_ * 1e-3;
      }
    }
  }
  if (state_ == State::kFrozen && !was_frozen) moved_pm_.fill(0.0);
  if (config_.thermal_field) FollowField(shift, touch_y_mm, touch_arc_mm);
}

}  // namespace ruffini::decode
