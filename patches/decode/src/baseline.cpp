#include "ruffini/decode/baseline.h"

#include <cmath>
#include <limits>

namespace ruffini::decode {

void BaselineTracker::Reset() noexcept {
  state_ = State::kCapturing;
  baseline_nm_.fill(0.0);
  sum_nm_.fill(0.0);
  count_.fill(0);
  captured_ = 0;
  quiet_frames_ = 0;
}

void BaselineTracker::Seed(const Wavelengths& b) noexcept {
  baseline_nm_ = b;
  state_ = State::kTracking;
  quiet_frames_ = 0;
}

bool BaselineTracker::Update(const Wavelengths& wl, ShiftsPm& shift) noexcept {
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
  if (state_ == State::kCapturing) {
    bool quiet = true;
    for (std::size_t i = 0; i < kGratings; ++i) {
      if (std::isnan(wl[i]) || count_[i] == 0) continue;
      const double mean = sum_nm_[i] / count_[i];
      if (std::abs(wl[i] - mean) * 1e3 > config_.capture_tolerance_pm) quiet = false;
    }
    if (!quiet) {  // something moved during capture: start again from this frame
      sum_nm_.fill(0.0);
      count_.fill(0);
      captured_ = 0;
    }
    for (std::size_t i = 0; i < kGratings; ++i) {
      if (std::isnan(wl[i]) || std::isinf(wl[i])) continue;
      sum_nm_[i] += wl[i];
      ++count_[i];
    }
    shift.fill(kNaN);
    if (++captured_ < config_.capture_frames) return false;
    for (std::size_t i = 0; i < kGratings; ++i) {
      baseline_nm_[i] = count_[i] > 0 ? sum_nm_[i] / count_[i] : std::numeric_limits<double>::quiet_NaN();
    }
    state_ = State::kTracking;
    return false;
  }

  double max_abs = 0.0;
  for (std::size_t i = 0; i < kGratings; ++i) {
    if (!std::isfinite(wl[i]) || std::isnan(baseline_nm_[i])) {
      shift[i] = kNaN;
      continue;
    }
    shift[i] = static_cast<float>((wl[i] - baseline_nm_[i]) * 1e3);
    max_abs = std::max(max_abs, std::abs(static_cast<double>(shift[i])));
  }
  if (max_abs > config_.touch_on_pm) {
    state_ = State::kFrozen;
    quiet_frames_ = 0;
  } else if (state_ == State::kFrozen) {
    quiet_frames_ = max_abs < config_.touch_off_pm ? quiet_frames_ + 1 : 0;
    if (quiet_frames_ >= config_.release_frames) state_ = State::kTracking;
  }
  if (state_ == State::kTracking) {
    const double alpha = 1.0 / (config_.drift_tau_s * config_.sample_rate_hz);
    for (std::size_t i = 0; i < kGratings; ++i) {
      if (std::isfinite(wl[i]) && !std::isnan(baseline_nm_[i])) baseline_nm_[i] += alpha * (wl[i] - baseline_nm_[i]);
    }
  }
  return true;
}

}  // namespace ruffini::decode
