#pragma once
// Re-tare: the way out of a stale baseline (issue 17, docs/safety.md "Re-tare"), asked for by an operator
// while the robot is held.
//
// A baseline frozen longer than max_frozen_s is stale and every frame is invalid (baseline.h): the patch
// stays in FAULT until the baseline is replaced. Re-capturing it blindly would absorb whatever presses the
// skin now. A re-tare therefore takes one capture window of frames (capture_frames, 1 s) and replaces the
// baseline with their mean only when
//   1. every frame is a readable frame of this fibre (no saturation, no missing light, no peak out of its
//      band, no more missing peaks than the pipeline tolerates, never over range): else kInvalidFrames,
//      or kPressing for an over-range frame (more load than the model knows);
//   2. every present peak stays within capture_tolerance_pm of its running mean (the start-up capture's
//      rule): else kMoving; and
//   3. no single touch anywhere on the response map explains the window's mean shift (nor the mean of its
//      first tenth, nor a moving average over its last tenth: a press starting or ending inside the window)
//      against the OLD
//      baseline (common mode removed) with a force at or above min_force_n while moving some grating by at
//      least min_shift_pm: at every node the touch's amplitude is the least-squares projection of the
//      shift on the node's response (a press pushes: only positive amplitudes count), its force F from
//      amplitude = F (1 + c F). Else kPressing, naming the force and the place. The networks' reading is not used: a light press at an edge that the
//      networks read as 0 still moves the gratings the map knows, and the networks' phantom (the reason a
//      baseline goes stale) is not a press.
// A model without a response map cannot judge 3: every re-tare is refused (kNoMap).
//
// What it cannot see: a press the OLD baseline had already absorbed (it was gone from the shifts before the
// re-tare; the re-tare keeps it absorbed, no worse than before), and a press whose shift pattern an
// unrelated baseline error happens to cancel. min_force_n is the caller's (the service: half the patch's
// smallest region threshold).
//
// Real-time safe: no allocation after construction, no lock, no throw.
#include <cstdint>
#include <optional>
#include <string_view>
#include <vector>

#include "ruffini/decode/inversion.h"
#include "ruffini/decode/pipeline.h"
#include "ruffini/patch/spec.h"
#include "ruffini/v1/model.pb.h"

namespace ruffini::decode {

enum class RetareOutcome : std::uint8_t {
  kAccepted = 0,     // the window's mean is the new baseline
  kPressing,         // a touch of at least min_force_n explains the shifts (or a frame was over range)
  kMoving,           // a peak moved by more than capture_tolerance_pm during the window
  kInvalidFrames,    // a frame of the window was unreadable (saturated, dark, out of band, too many missing)
  kNoBaseline,       // the start-up capture is still under way: there is nothing to re-tare
  kNoMap,            // the model has no response map: a re-tare cannot be judged, so none is done
  kBusy,             // a re-tare is already under way (the new request is refused; the running one goes on)
  kInterrupted,      // the stream broke during the window (a reconnect, lost frames)
};
inline constexpr std::size_t kRetareOutcomeCount = 8;
// snake_case, stable: metric label values and log text.
std::string_view RetareOutcomeName(RetareOutcome o) noexcept;

struct RetareConfig {
  double min_force_n = 0.75;  // a touch explaining the shifts with at least this force refuses the re-tare
  // A touch counts only when it moves some grating by at least this much (pm): at a place the gratings
  // barely see (the map's weakest corners move no grating by 0.3 pm per newton), any sub-picometre error
  // is "explained" by a newton or more, and refusing on it would keep every stale patch stuck. What is
  // absorbed there moves no grating by more than this: the pipeline's quiet_release_pm, below which a
  // frame is no contact.
  double min_shift_pm = 1.0;
  // Separate a temperature field from a touch (docs/experiments/field-hours.md). The window's shifts are fitted
  // as one touch plus a first-order field across the cover: a constant, a slope along Y, and the first harmonic
  // around the limb (cos R, sin R), each at the gratings' centres. Only the touch is judged. A smooth field (a
  // warm end, sunlight on one side) then explains no press, and a touch's force is estimated without bias
  // whatever smooth field lies under it. With too few peaks for the fit (fewer than 8), or at a place whose
  // response the field could mimic (less than kMinOwnShare of its energy outside the field's span), the judge
  // falls back to the touch taking every shift (the conservative reading). Where one touch alone explains the
  // shifts well (kTouchLikeMisfit), its plain reading counts too, so a press with no field under it keeps its
  // plain reading at the places that explain it (RetareField tests: refused wherever the plain judge refuses it,
  // on a 10 mm grid over the patch).
  // Off: the touch takes every shift. SeparateField(spec) switches it on with the spec's grating centres.
  // EXPERIMENTAL, off in the decoder service: review 6 (docs/reviews/retare-field.md) made it accept a held 1.5 N
  // press the plain judge refuses, end to end; its probes (tests/decode/retare_field_review_test.cpp) gate it.
  bool separate_field = false;
  std::array<double, kGratings> grating_y_mm{}, grating_r_deg{};
  void SeparateField(const patch::PatchSpec& spec) noexcept;
};

struct RetareResult {
  RetareOutcome outcome = RetareOutcome::kAccepted;
  // The largest force a single touch on the map explains (N), and where (patch frame). 0 / NaN when not
  // judged (the window was refused before).
  double force_n = 0.0;
  double y_mm = 0.0, r_deg = 0.0;
  double motion_pm = 0.0;  // the largest excursion of a peak from its running mean in the window
  int frames = 0;          // frames taken
};

// The judgement of one shift vector (rule 3 above), usable on its own (tests, reports).
class RetareJudge {
 public:
  // Throws InputError when the map is malformed.
  explicit RetareJudge(const v1::ResponseMap& map, RetareConfig config = {});
  // The largest force any node explains (force_n, y_mm, r_deg filled; outcome kPressing when at or above
  // min_force_n, else kAccepted). Missing (NaN) shifts are left out.
  [[nodiscard]] RetareResult Judge(const ShiftsPm& shift_pm) const noexcept;
  [[nodiscard]] const RetareConfig& config() const noexcept { return config_; }

 private:
  [[nodiscard]] double Force(double amplitude) const noexcept;
  ResponseModel model_;
  RetareConfig config_;
  // separate_field: the field's basis at the gratings (columns 1, Y / 100 mm, cos R, sin R), and each node's
  // response with its field part removed (every grating present), and that part's energy.
  std::array<std::array<double, 4>, kGratings> basis_{};
  std::vector<std::array<float, kGratings>> own_g_;
  std::vector<double> own_gg_;
  bool field_ready_ = false;

 public:
  // A touch's share of a place's response must hold at least this much of its energy for the field fit to judge
  // it; below, the field could mimic the touch and the judge takes every shift.
  static constexpr double kMinOwnShare = 0.05;
  static constexpr int kMinPeaksForField = 8;
  // With the field separated, a place's plain reading (the touch taking every shift) still counts where that
  // touch alone leaves at most this share of the shifts' energy unexplained: the shifts look like a touch, not
  // like a field, and the separation must not judge such a press lighter there.
  static constexpr double kTouchLikeMisfit = 0.5;
};

// The procedure over a stream: Start() when the operator asks, then Feed() every frame after the pipeline
// processed it, until it returns a result. On kAccepted the caller hands baseline_nm() to the pipeline's
// Data::Retare(); on anything else the baseline stays as it was (a stale one stays stale).
class Retare {
 public:
  // map nullptr: the model has none (every re-tare is refused with kNoMap). Throws InputError on a bad map.
  Retare(const v1::ResponseMap* map, const BaselineConfig& baseline, RetareConfig config = {});

  // false (and nothing changes) when one is already under way: the caller reports kBusy.
  bool Start() noexcept;
  [[nodiscard]] bool active() const noexcept { return active_; }
  // The stream broke: an active re-tare ends with kInterrupted.
  std::optional<RetareResult> Interrupt() noexcept;
  // One frame: its wavelengths, what the pipeline made of it, and the pipeline's baseline (the old one).
  std::optional<RetareResult> Feed(const Wavelengths& wavelength_nm, const PipelineOutput& out,
                                   const BaselineTracker& tracker) noexcept;
  // The window's mean wavelengths (valid after a kAccepted result).
  [[nodiscard]] const Wavelengths& baseline_nm() const noexcept { return mean_nm_; }
  [[nodiscard]] const RetareConfig& config() const noexcept { return config_; }
  [[nodiscard]] bool has_map() const noexcept { return judge_.has_value(); }

 private:
  std::optional<RetareResult> End(RetareOutcome o) noexcept;

  std::optional<RetareJudge> judge_;
  BaselineConfig baseline_;
  RetareConfig config_;
  bool active_ = false;
  int frames_ = 0;
  double motion_pm_ = 0.0;
  Wavelengths sum_nm_{}, mean_nm_{};
  std::array<int, kGratings> count_{};
  std::array<double, kGratings> shift_sum_pm_{};
  std::array<int, kGratings> shift_count_{};
  // The window's first tenth (its mean) and its last frames (a moving average over a tenth of the window):
  // a press starting or ending inside the window is judged at its full force there, not at the window's mean.
  std::array<double, kGratings> head_sum_pm_{};
  std::array<int, kGratings> head_count_{};
  ShiftsPm tail_pm_{};
};

}  // namespace ruffini::decode
