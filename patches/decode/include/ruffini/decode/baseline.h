#pragma once
// Baseline per grating: the unloaded peak wavelength that shifts are measured against.
//
// Start-up: the first capture_frames frames in which every present peak stays within capture_tolerance_pm of
// its running mean are averaged (a touch during capture restarts it). Then:
//
// - Common mode (common_mode = true). Temperature moves every grating alike (about 10 pm/C); a touch moves
//   a few. Each frame's common-mode shift is the median of the present gratings' shifts; it is subtracted
//   from every grating before anything else looks at the shifts, so uniform drift never reads as a touch,
//   however fast it is, and the baseline keeps following it while a touch is on (the median of 16 is
//   untouched by a contact that moves up to 7 gratings). What remains of a drift is its per-grating
//   spread (a few % of it), which the slow filter below follows between touches.
// - Slow filter. While untouched the baseline follows each grating with a first-order filter of time
//   constant drift_tau_s.
// - Freeze, two modes.
//   Shift-driven (no decoder at hand: preparing training data). The slow filter stops while any
//   common-mode-free |shift| exceeds touch_on_pm; every |shift| must stay below touch_off_pm for
//   release_frames frames before it resumes.
//   Gate-driven (the decoding pipeline: the caller passes its force gate). The filter stops exactly while
//   the decoder says a touch is on, and resumes release_frames after the gate closes, whatever the shifts
//   are. The shifts alone cannot tell a light press from the drift that builds up under a long one, or from
//   the viscoelastic residual a release leaves: thresholds on them latch the baseline frozen in the field
//   (measured: docs/decoder-report). The decoder's gate can: a press it sees is never eaten (a long light
//   press between gratings that moves no grating by touch_on_pm included), and what it does not call a
//   touch is followed. The few frames between a touch's onset and the gate opening cost the touch
//   W / (drift_tau_s x rate) of its size (0.5 % at W = 16).
// - Staleness. Frozen longer than max_frozen_s is reported (stale()); the baseline is NOT released, since
//   releasing it under a real press would eat the press: the pipeline turns a stale baseline into an
//   invalid frame (a fault upstream), never into a quiet one.
//
// Real-time safe: no allocation, no lock, no throw.
#include <array>
#include <cstdint>
#include <limits>
#include <optional>

#include "ruffini/frame.h"

namespace ruffini::decode {

using ::ruffini::kGratings;    // ruffini/frame.h
using ::ruffini::Wavelengths;
using ShiftsPm = std::array<float, kGratings>;

struct BaselineConfig {
  double sample_rate_hz = 100.0;
  int capture_frames = 100;     // 1 s at 100 Hz (BaselineFor scales frame counts to the stream rate)
  double capture_tolerance_pm = 3.0;
  double drift_tau_s = 30.0;
  double touch_on_pm = 3.0;
  double touch_off_pm = 1.5;
  int release_frames = 20;      // 0.2 s at 100 Hz
  bool common_mode = true;       // remove each frame's median shift (see above); false = the paper's raw shifts
  int min_common_mode_gratings = 9;  // fewer present gratings: no common-mode estimate (shifts left raw)
  double common_mode_tau_s = 1.0;    // while frozen, the baseline follows the common mode with this filter
  double max_frozen_s = 300.0;   // frozen longer than this: stale()
  // Per-grating thermal sensitivity relative to the median grating: the common mode c comes off grating i
  // as thermal_ratio[i] x c (all 1: uniform). A cast property (model Preprocessing.thermal_ratio).
  std::array<float, kGratings> thermal_ratio = UnitRatios();
  // Thermal field (thermal_field = true; needs the gratings' places below; a model property, Preprocessing.
  // thermal_field). A cover is not at one temperature: a warm joint at one end, sunlight on one side. What the
  // median leaves of such a field is smooth over where the gratings sit, and it builds over minutes, faster
  // than the slow filter follows and right through a long press. So, after the common mode:
  // - untouched, or touched where the networks do not place it: the baseline follows a plane (y mm along,
  //   arc mm around) through the shifts with field_tau_s, robustly: the field_trim gratings furthest from a
  //   first fit are left out (a touch the gate has not seen). Only the plane's slopes are followed; its mean
  //   stays with the common mode;
  // - touched and placed: the gratings more than field_exclude_mm from the place and moving by less than
  //   touch_off_pm follow their own shift with field_far_tau_s (nothing presses them); a plane through what
  //   those baselines moved since the freeze began carries the gratings under the touch along.
  // Each baseline steps at most field_max_rate_pm_s (a field builds over minutes: a fit gone wrong cannot
  // carry off a press faster than that). Fewer than field_min_gratings usable, or places that pin no plane
  // (one row): no step. Measured: docs/experiments/thermal-field.md.
  bool thermal_field = false;
  double field_tau_s = 1.0;
  double field_far_tau_s = 10.0;
  int field_trim = 4;
  double field_exclude_mm = 30.0;
  int field_min_gratings = 6;
  double field_max_rate_pm_s = 1.0;
  std::array<float, kGratings> grating_y_mm{};    // the gratings' places on the patch (PatchSpec)
  std::array<float, kGratings> grating_arc_mm{};  // r_deg x surface radius, mm
  // The rest reference (review 10, finding 1): the baseline this patch last had at rest (a decoder that
  // restarts reads it back from its rest file). A start-up capture only checks that the peaks are still, and a
  // held press is still: a decoder restarted under a press took the press for its rest, was healthy and out of
  // contact, and the operator's reset cleared a STOP under 20 N. With a reference, a capture whose baseline
  // differs from it, after the common mode (each grating's thermal_ratio x the median difference), by more
  // than rest_tolerance_pm on any grating is refused and starts again: the patch stays capturing (unhealthy,
  // then a FAULT past the capture deadline) until what it sees is its rest again. Unset: no check.
  std::optional<Wavelengths> rest_nm;
  double rest_tolerance_pm = 6.0;

  static constexpr std::array<float, kGratings> UnitRatios() {
    std::array<float, kGratings> r{};
    for (auto& v : r) v = 1.0f;
    return r;
  }
};

class BaselineTracker {
 public:
  explicit BaselineTracker(const BaselineConfig& config = {}) noexcept : config_(config) {}

  enum class State : std::uint8_t { kCapturing, kTracking, kFrozen };

  enum class Gate : std::uint8_t { kNone, kClosed, kOpen };
  // Feeds one frame; writes shifts (pm, NaN where the peak is missing or no baseline yet), common mode
  // removed when configured. gate = kNone: shift-driven freeze; kOpen / kClosed: the decoder's force gate
  // (on the previous frame) drives it. Returns true when the shifts are usable (a baseline exists).
  bool Update(const Wavelengths& wavelength_nm, ShiftsPm& shift_pm, Gate gate = Gate::kNone) noexcept;
  // Update() in two steps, so a caller can look at the shifts before the frame moves the baseline (the
  // pipeline refuses out-of-range frames without letting them in): Measure() writes the shifts and the
  // common mode (false while capturing: then call Update()); Advance() moves the baseline and the freeze.
  bool Measure(const Wavelengths& wavelength_nm, ShiftsPm& shift_pm) noexcept;
  // touch_y_mm / touch_arc_mm: where the decoder placed the touch on the previous frame (NaN: not placed);
  // only the thermal field's fit uses it.
  void Advance(const Wavelengths& wavelength_nm, const ShiftsPm& shift_pm, Gate gate = Gate::kNone,
               float touch_y_mm = kNoPlace, float touch_arc_mm = kNoPlace) noexcept;
  static constexpr float kNoPlace = std::numeric_limits<float>::quiet_NaN();

  [[nodiscard]] State state() const noexcept { return state_; }
  [[nodiscard]] const Wavelengths& baseline_nm() const noexcept { return baseline_nm_; }
  // The last frame's common-mode shift (pm, 0 when off or not estimable).
  [[nodiscard]] float common_mode_pm() const noexcept { return common_mode_pm_; }
  // The last frame's fitted thermal field slopes (pm per mm along, around; 0 when off or not fitted).
  [[nodiscard]] float field_slope_y() const noexcept { return field_slope_y_; }
  [[nodiscard]] float field_slope_arc() const noexcept { return field_slope_arc_; }
  // How long the baseline has been frozen, s (0 while tracking).
  [[nodiscard]] double frozen_s() const noexcept { return static_cast<double>(frozen_frames_) / config_.sample_rate_hz; }
  [[nodiscard]] bool stale() const noexcept { return frozen_s() > config_.max_frozen_s; }
  // Baseline drift since capture: the mean over gratings of baseline - captured baseline, pm.
  [[nodiscard]] double drift_pm() const noexcept;
  [[nodiscard]] const BaselineConfig& config() const noexcept { return config_; }
  // Captures refused because they differed from the rest reference (BaselineConfig::rest_nm), and the largest
  // difference the last refused one showed (pm, common mode removed).
  [[nodiscard]] std::uint64_t captures_refused() const noexcept { return captures_refused_; }
  [[nodiscard]] float refused_residual_pm() const noexcept { return refused_residual_pm_; }
  // A baseline's difference from the rest reference, pm, after the common mode (the median difference, times
  // each grating's thermal ratio), NaN where a grating is missing. False when fewer than min_common_mode_gratings
  // gratings are present in both (no common mode to remove).
  [[nodiscard]] static bool RestDifferencePm(const Wavelengths& baseline_nm, const Wavelengths& rest_nm,
                                             const BaselineConfig& config, ShiftsPm& out) noexcept;
  // The largest |RestDifferencePm|; NaN when it cannot be computed.
  [[nodiscard]] static float RestResidualPm(const Wavelengths& baseline_nm, const Wavelengths& rest_nm,
                                            const BaselineConfig& config) noexcept;
  // The caller found the capture just made is not the patch's rest (the pipeline reads the difference from the
  // rest reference as a contact): counted, and the capture starts again.
  void RefuseCapture(float residual_pm) noexcept;
  // Sets a known baseline (e.g. a dataset's reference) and starts tracking.
  void Seed(const Wavelengths& baseline_nm) noexcept;
  void Reset() noexcept;

 private:
  BaselineConfig config_;
  State state_ = State::kCapturing;
  Wavelengths baseline_nm_{};
  Wavelengths captured_nm_{};
  Wavelengths sum_nm_{};
  std::array<int, kGratings> count_{};
  int captured_ = 0;
  std::uint64_t captures_refused_ = 0;
  float refused_residual_pm_ = 0.0f;
  int quiet_frames_ = 0;
  std::int64_t frozen_frames_ = 0;
  float common_mode_pm_ = 0.0f;
  float field_slope_y_ = 0.0f;
  float field_slope_arc_ = 0.0f;
  std::array<double, kGratings> moved_pm_{};  // thermal field: each baseline's own move since the freeze began

  void FollowField(const ShiftsPm& shift_pm, float touch_y_mm, float touch_arc_mm) noexcept;
};

// The median of the finite entries (NaN when fewer than min_count). No allocation.
float MedianOfPresent(const ShiftsPm& shift_pm, int min_count) noexcept;

}  // namespace ruffini::decode
