#pragma once
// Scoring a decoded stream the way the robot lives it: press by press and episode by episode against the
// stop rule, not frame by frame against the force (issue 17's field-hours targets; review field.md asked for
// it: "missed > 100 mN" cannot see a 2.5 N press read as 0.3 N, and a per-frame false-contact share says
// nothing about stops).
//
// The decoder service and the safety policy are replayed on the decoded frames, for one patch:
// - the decoder service (link::Monitor): a valid frame in contact, or the frame that ends a contact (its force
//   clamped at 0), is a contact message; an over-range frame is a contact of at least its force; a run of rejected frames
//   (max(3, 20 ms of frames)) or a stale baseline is a FAULT while it lasts; the start-up capture is neither.
// - the policy (safety::Policy::OnContact): a contact cause starts when the judged force is above the
//   threshold (strictly; JudgedForce's sd_k rule), below -negative_tolerance, not finite, or located beyond
//   the patch by more than the position tolerance (a doubt); it ends when the decoder's gate closes or the
//   force stays below threshold x (1 - release fraction) for the release hold.
// A STOP episode is a run of frames with a cause present (a contact cause or a FAULT); causes that come back
// within operator_latch_s of the last one belong to the same episode (the STOP is latched until the operator
// resets, and nobody resets within a second).
//
// Presses are the dataset's indentations (the twin's label), each judged by its true (applied) peak force:
// - due: peak >= due_factor x threshold. Stopped when a cause is present on some frame from the press's
//   start to tail_s after its end; the delay runs from the first frame whose true force is above the
//   threshold to the first such frame (negative: the decoder stopped before the true crossing). Stopped
//   "by a FAULT only" when every such frame was a FAULT and no contact cause: the arm stopped, the press was
//   not seen.
// - light: peak <= light_factor x threshold. A STOP episode that starts in its window is spurious.
// - between the two: a stop is neither required nor spurious (the grey band of the targets).
// An episode that starts outside every press window (a rest) is spurious too.
#include <cstdint>
#include <string>
#include <vector>

#include "ruffini/dataset/dataset.h"
#include "ruffini/eval/stream.h"
#include "ruffini/patch/spec.h"

namespace ruffini::eval {

// The scene's safety rule for one region, and how the replay judges presses. The defaults are
// config/scenes/cobot.yaml's (docs/safety.md).
struct StopRuleModel {
  double threshold_n = 1.5;
  double sd_k = 0.0, max_sd_n = 1.0;             // safety.stop_rule (0: the force alone)
  double negative_tolerance_n = 0.05;            // safety.negative_force_tolerance
  double release_fraction = 0.1, release_hold_s = 0.1;  // safety.contact_release
  double position_tolerance_y_mm = 5.0, position_tolerance_r_deg = 5.0;  // safety.position_tolerance
  double reject_fault_s = 0.02;                  // link::MonitorConfig::reject_fault_frames = 0
  int reject_fault_min_frames = 3;
  double operator_latch_s = 1.0;                 // causes this close together are one STOP episode
  double tail_s = 0.5;                           // a stop up to this long after a press's end belongs to it
  double due_factor = 1.1, light_factor = 0.9;   // issue 17's bands
  double stuck_s = 60.0;                         // a FAULT without a present cause longer than this: stuck
  double quiet_n = 0.02;                         // below this true force a reported contact is false
};

// What started an episode: a contact judged above the threshold, an over-range contact, a doubt (a force
// below -negative_tolerance or not finite; a place beyond the patch), or a FAULT.
enum class EpisodeKind : std::uint8_t { kContact, kOverRange, kNegativeForce, kBeyondPatch, kFault };
std::string_view EpisodeKindName(EpisodeKind k);
enum class EpisodeCause : std::uint8_t { kDuePress, kGreyPress, kLightPress, kRest };

struct StopEpisode {
  double t_s = 0, end_s = 0;     // first and last frame with a cause present
  EpisodeKind kind = EpisodeKind::kContact;  // what started it
  EpisodeCause cause = EpisodeCause::kRest;
  std::int32_t press = -1;       // the press whose window it started in (-1: a rest)
  float press_peak_n = 0;        // that press's true peak (0 for a rest)
  float reported_max_n = 0;      // the largest reported force while it lasted (contacts only)
  float y_mm = 0, r_deg = 0;     // the press's true place (NaN for a rest)
};

struct DuePress {
  std::int32_t press = -1;
  double t_s = 0;                // the true crossing
  float peak_n = 0, y_mm = 0, r_deg = 0;
  bool stopped = false, fault_only = false;
  double delay_ms = 0;           // stopped only
  float reported_max_n = 0;      // the largest reported force in the window
};

struct StopScore {
  double hours = 0;              // scored time (after the start-up capture)
  std::size_t frames = 0;
  int presses = 0, due = 0, grey = 0, light = 0;
  std::vector<DuePress> due_presses;
  std::vector<StopEpisode> episodes;
  // FAULT time, and the part of it while no press was above the threshold (no present cause).
  double fault_s = 0, fault_no_cause_s = 0, longest_fault_no_cause_s = 0;
  std::size_t quiet_frames = 0, false_contact_frames = 0;  // true force < quiet_n; of them reported in contact
  std::size_t pressed_frames = 0, unseen_frames = 0;       // true force > 100 mN; of them not reported in contact

  [[nodiscard]] int CountEpisodes(EpisodeCause c) const;
  // Spurious STOPs as a user counts them: every episode that starts in a rest, and every light press in whose
  // window one or more episodes start (a press hovering about the threshold is one unneeded stop, not ten).
  [[nodiscard]] int spurious() const { return CountEpisodes(EpisodeCause::kRest) + light_stopped; }
  int light_stopped = 0;  // light presses in whose window an episode started
  [[nodiscard]] int due_stopped() const;
  [[nodiscard]] int due_missed() const { return due - due_stopped(); }
  [[nodiscard]] int due_fault_only() const;
  [[nodiscard]] bool stuck(const StopRuleModel& rule) const { return longest_fault_no_cause_s > rule.stuck_s; }
  // Delays of the stopped due presses, ms, sorted.
  [[nodiscard]] std::vector<double> Delays() const;
};

// Throws InputError when the predictions do not match the dataset or the dataset has no true force.
StopScore ScoreStops(const dataset::Dataset& data, const StreamPredictions& pred, const patch::PatchSpec& spec,
                     const StopRuleModel& rule);

std::string_view EpisodeCauseName(EpisodeCause c);

}  // namespace ruffini::eval
