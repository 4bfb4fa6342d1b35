#pragma once
// Baseline per grating: the unloaded peak wavelength that shifts are measured against.
//
// Start-up: the first capture_frames frames in which every present peak stays within capture_tolerance_pm of
// its running mean are averaged (a touch during capture restarts it). Then the baseline follows slow drift
// (temperature) with a first-order filter of time constant drift_tau_s, but only while untouched: any
// |shift| above touch_on_pm freezes it until every shift has stayed below touch_off_pm for release_frames
// frames, so a long press is never eaten. A missing peak (NaN) leaves its baseline alone. The filter lags a
// drift by rate x drift_tau_s: drift faster than touch_on_pm / drift_tau_s (0.1 pm/s by default, about
// 0.01 C/s) reads as a touch and freezes the baseline until it settles.
// Real-time safe: no allocation, no lock, no throw.
#include <array>
#include <cstdint>

namespace ruffini::decode {

inline constexpr std::size_t kGratings = 16;
using Wavelengths = std::array<double, kGratings>;
using ShiftsPm = std::array<float, kGratings>;

struct BaselineConfig {
  double sample_rate_hz = 100.0;
  int capture_frames = 100;
  double capture_tolerance_pm = 3.0;
  double drift_tau_s = 30.0;
  double touch_on_pm = 3.0;
  double touch_off_pm = 1.5;
  int release_frames = 20;
};

class BaselineTracker {
 public:
  explicit BaselineTracker(const BaselineConfig& config = {}) noexcept : config_(config) {}

  enum class State : std::uint8_t { kCapturing, kTracking, kFrozen };

  // Feeds one frame; writes shifts (pm, NaN where the peak is missing or no baseline yet). Returns true when
  // the shifts are usable (a baseline exists for every present peak).
  bool Update(const Wavelengths& wavelength_nm, ShiftsPm& shift_pm) noexcept;

  [[nodiscard]] State state() const noexcept { return state_; }
  [[nodiscard]] const Wavelengths& baseline_nm() const noexcept { return baseline_nm_; }
  // Sets a known baseline (e.g. a dataset's reference) and starts tracking.
  void Seed(const Wavelengths& baseline_nm) noexcept;
  void Reset() noexcept;

 private:
  BaselineConfig config_;
  State state_ = State::kCapturing;
  Wavelengths baseline_nm_{};
  Wavelengths sum_nm_{};
  std::array<int, kGratings> count_{};
  int captured_ = 0;
  int quiet_frames_ = 0;
};

}  // namespace ruffini::decode
