#include "ruffini/decode/baseline.h"

#include <algorithm>
#include <cmath>
#include <limits>

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
}

void BaselineTracker::Seed(const Wavelengths& b) noexcept {
  baseline_nm_ = b;
  captured_nm_ = b;
  state_ = State::kTracking;
  quiet_frames_ = 0;
  frozen_frames_ = 0;
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

void BaselineTracker::Advance(const Wavelengths& wl, const ShiftsPm& shift, Gate gate) noexcept {
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
}

}  // namespace ruffini::decode
