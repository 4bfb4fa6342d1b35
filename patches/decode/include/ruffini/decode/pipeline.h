#pragma once
// The per-frame decode path, the one code every consumer runs: `ruffini decode` over a dataset, `ruffini
// evaluate`, and the decoder service over a live interrogator stream. One call per interrogator frame, in
// stream order, never reset between touches:
//
//   peaks (nm) + source flags
//     -> plausibility of the raw frame (saturation, no light, a peak outside its grating's band, too many
//        peaks missing)
//     -> baseline (common mode removed, frozen exactly while the decoder's own gate is open; see baseline.h)
//     -> plausibility of the shifts (baseline stale, a shift outside the range the model was calibrated on)
//     -> the paper's networks (force CNN over a window, gated grid MLPs + NIP); a contact on shifts that all
//        stay within faint_pm of the baseline is flagged `faint` (a baseline error reads the same)
//     -> calibrated uncertainty (force sd, 2x2 position covariance on the surface)
//
// A frame that fails a check is invalid with one Reason and carries no force (0, never NaN); it is not fed
// to the networks' window, so it cannot poison later frames. Except one kind, "never a hard press read as
// light": a frame that shows more load than the model knows is invalid (not decoded) AND over range: reported
// as a contact whose force is at least over_range_force_n (force_n = that bound, over_range = true, not
// located). The evidence, once the baseline exists: the source's saturated flag; a peak outside its band;
// a shift beyond the model's calibrated range (InputRange, else the z limit); or, while a contact is open,
// over_range_missing or more peaks lost at once (a pinched fibre darkens the gratings beyond the pinch),
// too many missing or no signal at all. A Hyperion stream carries no saturation flag: the lost, out-of-band
// and out-of-range peaks are the evidence. Reasons are counted; the decoder service turns
// persistent ones into faults. Model (immutable) and Data (per stream) are separate, as in NetworkDecoder.
#include <array>
#include <cstdint>
#include <optional>
#include <string_view>

#include "ruffini/decode/baseline.h"
#include "ruffini/decode/network_decoder.h"
#include "ruffini/decode/touches.h"
#include "ruffini/patch/spec.h"
#include "ruffini/v1/model.pb.h"

namespace ruffini::decode {

enum class Reason : std::uint8_t {
  kOk = 0,
  kCapturing,       // no baseline yet (start-up capture of the untouched peaks)
  kSaturated,       // the source flagged the frame kFlagSaturated (ruffini/frame.h: beyond the twin's linear model)
  kNoSignal,        // every peak missing or at 0 nm: no light, a broken fibre, an empty frame
  kOutOfBand,       // a peak outside its grating's band: it cannot be that grating's peak
  kTooManyMissing,  // more missing peaks than max_missing
  kBaselineStale,   // the baseline has been frozen longer than max_frozen_s
  kOutOfRange,      // a shift outside what the model was calibrated on (or a z-score beyond z_limit)
  kNonFinite,       // the networks produced a non-finite force (a broken model; never expected)
};
inline constexpr std::size_t kReasonCount = 9;
// snake_case names, stable: used as metric label values and in prediction files.
std::string_view ReasonName(Reason r) noexcept;

struct PipelineConfig {
  BaselineConfig baseline;     // sample_rate_hz must be the stream's rate; common_mode is set from the model
  int max_missing = 3;         // missing peaks tolerated (each replaced by its training mean)
  double band_margin_nm = 0.1; // a peak may sit this far beyond its band (cast tolerance) before it is out of band
  double z_limit = 40.0;       // models without an InputRange: |z| of any shift above this is out of range
  // A contact is reported once the force gate has stayed open this long (0: at once). Filters the single
  // noisy frames that cross the gate at rest, at the price of this much onset latency.
  double contact_confirm_s = 0.0;
  // A frame on which no grating moves by more than this (pm, common mode removed) is no contact, whatever
  // the force net's window still remembers (0: off). Cuts the window's lag after a release.
  double quiet_release_pm = 1.0;
  // > 0: the quiet release applies only after a drop, when the largest shift of the last moments (decaying
  // with a 0.5 s time constant) was at least this many times the threshold. A light press that never moves
  // a grating by much keeps being decided by the nets.
  double quiet_release_drop = 4.0;
  bool freeze_on_gate = true;  // the decoder's gate drives the baseline's freeze (false: the shifts do, as before v1.1)
  // The force an over-range frame is reported at ("at least"): the largest force the shipped models are
  // trained on (the paper protocol's 2.5 N indentations, FACTS.md). A region threshold above it would not
  // stop on an over-range contact: keep thresholds at or below it (docs/twin.md, "Hard presses").
  double over_range_force_n = 2.5;
  // Peaks lost at once, while a contact is open, that make a frame over range (a single lost peak is a
  // dimmed grating's dropout and is decoded from the others, as before).
  int over_range_missing = 2;
  // Two touches (docs/decoders.md, "Two touches"). On a located contact frame, the gratings whose |shift| is
  // at least multi_rel of the frame's largest (and at least multi_floor_pm) are grouped: two of them are in
  // one group when their centres lie within multi_link_mm on the surface (single linkage). One touch moves
  // one group; two or more groups are two or more touches: the frame is flagged `multiple` and its
  // covariance widened to hold every group's centre (|shift|-weighted) within 1 sigma, plus multi_margin_mm
  // (a group's centre is not its touch) in every direction. multi_link_mm 0: off. Chosen on validation
  // presses (docs/decoders.md).
  double multi_rel = 0.3;
  double multi_floor_pm = 3.0;
  double multi_link_mm = 30.0;
  double multi_margin_mm = 10.0;
  // While frames stay flagged, the two-touch fit (about 100 us) runs once every multi_refit_s; the frames in
  // between reuse its places. 0: every frame.
  double multi_refit_s = 0.01;
  // TouchCheck::Check's confirm_anywhere: a flag stands only when no single touch anywhere on the map explains the
  // frame either. Measured on validation and off (docs/experiments/pair.md, "Review 14").
  bool multi_confirm_anywhere = false;
  // TouchCheck::Check's window around the networks' place, +- nodes of the response map (2: +-3 mm).
  int multi_window_nodes = TouchCheck::kDefaultWindow;
  // What a frame flagged `multiple` whose pair the response map explains reports as its force (the stop rule
  // compares it with the threshold; docs/decoders.md "Two touches"). The networks read a pair as one touch
  // they were never shown, sometimes below either touch. Each fitted touch counts at its lower bound,
  // force - multi_force_k x its sd (0 at the least), and only where its place moves some grating by at least
  // multi_force_min_gain pm/N (a place far from every grating explains a few pm with any force):
  //   kNetworks: the networks' force, whatever the pair (before v1.4);
  //   kLargest:  the larger of the networks' force and the larger touch's bound;
  //   kTotal:    the larger of the networks' force and the sum of both touches' bounds.
  // The force is only ever raised. Chosen on validation presses (docs/experiments/two-touches.md).
  enum class MultiForce : std::uint8_t { kNetworks, kLargest, kTotal };
  MultiForce multi_force = MultiForce::kLargest;
  double multi_force_k = 2.0;
  double multi_force_min_gain = 3.0;
  // Faint frames (issue 17; docs/decoders.md "Faint frames"). A gate-open frame whose largest |shift|,
  // smoothed over faint_smooth_s, is below faint_pm is flagged `faint`: its force rests on shifts that a
  // baseline error of that size gives as well. The networks amplify: a lone grating 1 pm off its baseline
  // reads as up to 1 N, and it must, because a real 1-2 N press at the wrist edge moves FBG 16 alone by
  // -1 to -1.7 pm (docs/experiments/one-grating.md). So by default the flag changes nothing else: the
  // contact and its force stand. faint_refuse: a flagged frame whose networks' force is below faint_max_n is
  // no contact (force 0); the baseline stays frozen as under any contact, and its stale clock runs, so a
  // light press is never absorbed and a baseline error that lasts still FAULTs after max_frozen_s (letting
  // the baseline track ate a held press; pausing the clock let a sub-pm error hide a 2.25 N press for good,
  // review 7: docs/reviews/faint-refusal.md). What it buys: fewer false contacts. A frame
  // at or above faint_max_n is never refused: that mode never lowers a stop at a threshold of faint_max_n or
  // more (with sd_k <= 0; the aggregator refuses a scene where it could). Unset, the model decides
  // (Preprocessing.faint_refuse_below_n > 0: on, at that force; the pipeline's config() then holds the
  // choice made); true or false overrides the model, at faint_max_n. faint_pm 0: off. faint_pm is the
  // smallest that flags the review's probe (docs/experiments/one-grating.md).
  double faint_pm = 1.25;
  double faint_smooth_s = 0.1;
  std::optional<bool> faint_refuse;
  double faint_max_n = 1.0;
  // Refused after a release (issue 17; only where faint frames are refused, and never above faint_max_n, so
  // within the force the hello declares and the aggregator checks against every threshold). A gate-open frame
  // whose networks' force is below release_refuse_n, while the networks' force of the last moments (its peak,
  // decaying with release_tau_s) reached release_peak_n, is no contact (force 0). After a press the cover's
  // residual strain fades over seconds and the window lags the release: those frames read 50-250 mN with
  // nothing touching, most of the field's false contacts. As with a faint frame the gate stays open, so the
  // baseline stays frozen and its stale clock runs: nothing is absorbed, only the report changes.
  // release_refuse_n 0: off. Chosen on validation hours (docs/experiments/field-hours.md).
  double release_refuse_n = 0.2;
  double release_peak_n = 0.3;
  double release_tau_s = 10.0;
};

struct PipelineOutput {
  float force_n = 0.0f;        // 0 when invalid
  float force_sd_n = 0.0f;     // calibrated 1-sigma; NaN when the model has no Uncertainty or the frame is invalid
  float y_mm = 0.0f, r_deg = 0.0f;  // valid when located
  // Calibrated 2x2 position covariance on the surface, mm^2: y, and arc length (R in rad x surface radius).
  // NaN when not located or the model has no Uncertainty.
  float cov_yy_mm2 = 0.0f, cov_yr_mm2 = 0.0f, cov_rr_mm2 = 0.0f;
  float confidence = 0.0f;
  float common_mode_pm = 0.0f;  // the uniform shift removed this frame (temperature: about 10 pm/C)
  bool valid = false;
  bool in_contact = false;      // the force gate is open
  bool located = false;
  // Over range: the frame shows more load than the model knows (valid is false, reason says which evidence);
  // reported as a contact of at least force_n = over_range_force_n, in_contact true, not located.
  bool over_range = false;
  // Located, and the shifts show more than one touch (PipelineConfig::multi_*): the covariance holds them.
  bool multiple = false;
  // Located frames: touches seen (1; 2 when a pair explains a flagged frame; 0 when a flagged frame fits no
  // pair, or nothing moved). 0 when not located.
  std::uint8_t touch_groups = 0;
  // In contact on shifts a baseline error gives as well (PipelineConfig::faint_*): every |shift|, smoothed,
  // below faint_pm. The contact and force stand (with faint_refuse: no contact below faint_max_n).
  bool faint = false;
  Reason reason = Reason::kCapturing;
  std::uint8_t missing = 0;
};

// Plain counters a service copies into its metrics off the real-time thread.
struct PipelineCounters {
  std::uint64_t frames = 0, valid = 0, located = 0, onsets = 0;
  std::uint64_t over_range = 0;  // frames reported over range (also counted in invalid[reason])
  std::uint64_t multiple = 0;    // located frames flagged as more than one touch
  std::uint64_t faint = 0;       // gate-open frames flagged faint (PipelineConfig::faint_*)
  std::uint64_t release_refused = 0;  // gate-open frames refused after a release (PipelineConfig::release_*)
  std::array<std::uint64_t, kReasonCount> invalid{};  // indexed by Reason (kOk stays 0)
};

template <typename Scalar>
class Pipeline {
 public:
  // Throws InputError when the model does not fit the spec or is malformed.
  Pipeline(const v1::DecoderModel& model, const patch::PatchSpec& spec, PipelineConfig config,
           DecoderOptions options = {});

  class Data {
   public:
    explicit Data(const Pipeline& p);
    [[nodiscard]] const BaselineTracker& baseline() const noexcept { return tracker_; }
    [[nodiscard]] const PipelineCounters& counters() const noexcept { return counters_; }
    // The stream broke (frames lost, a reconnect): the next flagged frame fits its two touches afresh
    // instead of re-solving forces at places fitted before the break.
    void ForgetTouches() noexcept { pair_age_ = 1 << 30; }

   private:
    friend class Pipeline;
    BaselineTracker tracker_;
    typename NetworkDecoder<Scalar>::Data net_;
    PipelineCounters counters_;
    bool primed_ = false;   // the networks' window holds valid frames
    int invalid_run_ = 0;   // consecutive invalid frames since the last valid one
    int open_run_ = 0;      // consecutive valid frames with the force gate open
    bool gate_ = false;     // the decoder's force gate (drives the baseline)
    bool contact_ = false;  // the reported contact (the gate, confirmed)
    bool over_range_ = false;  // the last frame was over range
    float recent_peak_pm_ = 0.0f;  // largest |shift| lately, decaying (quiet release after a drop)
    float recent_force_n_ = 0.0f;  // largest networks' force lately, decaying (refused after a release)
    TouchVerdict pair_;            // the last two-touch fit, reused for multi_refit_s while the flag holds
    int pair_age_ = 1 << 30;       // frames since it (large: none)
    ShiftsPm smooth_{};            // the shifts, smoothed over faint_smooth_s
    bool smooth_primed_ = false;
    float place_y_mm_ = BaselineTracker::kNoPlace;  // where the networks placed the last valid frame (the
    float place_a_mm_ = BaselineTracker::kNoPlace;  // thermal field's fit leaves the gratings near it out)
  };

  // An accepted re-tare (retare.h): the baseline becomes baseline_nm (tracking, not frozen), and whatever
  // remembered the old one starts afresh: the networks' window holds the new baseline (zero shifts, as if
  // untouched for the whole window), the gate and the contact are closed, the two-touch cache is gone.
  // Real-time safe.
  void Retare(const Wavelengths& baseline_nm, Data& d) const noexcept {
    d.tracker_.Seed(baseline_nm);
    ShiftsPm rest{};
    decoder_.Reset(d.net_, &rest);
    d.primed_ = true;
    d.invalid_run_ = 0;
    d.open_run_ = 0;
    d.gate_ = d.contact_ = d.over_range_ = false;
    d.recent_peak_pm_ = 0.0f;
    d.recent_force_n_ = 0.0f;
    d.pair_age_ = 1 << 30;
    d.place_y_mm_ = d.place_a_mm_ = BaselineTracker::kNoPlace;
  }

  // One interrogator frame. Real-time safe: no allocation, no lock, no throw.
  PipelineOutput Process(const Wavelengths& wavelength_nm, std::uint32_t source_flags, Data& data) const noexcept;

  [[nodiscard]] const NetworkDecoder<Scalar>& decoder() const noexcept { return decoder_; }
  [[nodiscard]] const PipelineConfig& config() const noexcept { return config_; }
  [[nodiscard]] bool calibrated_uncertainty() const noexcept { return !force_knots_.empty(); }

  // Source flag bit meaning "saturated" (ruffini/frame.h).
  static constexpr std::uint32_t kSourceSaturated = ::ruffini::kFlagSaturated;

 private:
  [[nodiscard]] Reason CheckRaw(const Wavelengths& wl, std::uint32_t flags) const noexcept;
  [[nodiscard]] bool InRange(const ShiftsPm& s) const noexcept;
  [[nodiscard]] float Interp(const std::vector<float>& ys, float x) const noexcept;
  // Groups the moved gratings of a frame; widens out's covariance (when calibrated) when there are two or
  // more. Returns the number of groups.
  int Touches(const ShiftsPm& shift, PipelineOutput& out, Data& d) const noexcept;
  // A found pair's force for the stop rule (PipelineConfig::multi_force): raises out.force_n, never lowers it.
  void RaiseForPair(const TouchVerdict& v, PipelineOutput& out) const noexcept;
  // A capture just made against the rest reference: refused when the networks read the difference as a contact.
  void RestCheck(Data& d) const noexcept;
  // Smooths the shifts (every valid frame): whether the largest smoothed |shift| is below faint_pm.
  bool Faint(const ShiftsPm& shift, Data& d) const noexcept;

  NetworkDecoder<Scalar> decoder_;
  PipelineConfig config_;
  std::array<double, kGratings> band_lo_nm_{}, band_hi_nm_{};
  bool has_range_ = false;
  std::array<float, kGratings> range_lo_pm_{}, range_hi_pm_{};
  std::array<float, kGratings> mean_pm_{}, std_pm_{};  // force-net normalisation, for the z check
  std::vector<float> force_knots_, force_sd_, position_scale_;
  float position_floor_mm2_ = 0.0f;
  double mm_per_deg_ = 0.0;
  int confirm_frames_ = 0;
  std::optional<TouchCheck> touches_;  // with the model's ResponseMap
  int refit_frames_ = 0;               // multi_refit_s in frames
  double half_y_mm_ = 0.0, half_a_mm_ = 0.0;  // half the patch's extent (an unexplained frame's spread)
  std::array<double, kGratings> grating_y_mm_{}, grating_a_mm_{};  // centres, arc length for R
  std::array<std::uint16_t, kGratings> linked_{};  // bit j of linked_[i]: gratings i and j within multi_link_mm
  float peak_decay_ = 0.0f;
  float force_decay_ = 0.0f;   // release_tau_s as a decay per frame
  float smooth_alpha_ = 1.0f;  // faint_smooth_s as an exponential filter's weight per frame
};

extern template class Pipeline<float>;
extern template class Pipeline<double>;

// The baseline settings a model was trained with (common mode, thermal ratios), at the stream's rate: the
// capture (1 s) and release (0.2 s) keep their durations at any rate.
BaselineConfig BaselineFor(const v1::DecoderModel& model, double sample_rate_hz);

}  // namespace ruffini::decode
