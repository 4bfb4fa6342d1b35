#pragma once
// Decoding a dataset as one continuous stream through decode::Pipeline (the code the decoder service runs:
// no resets at label boundaries, the baseline tracked throughout), and scoring it as a skeptical reviewer
// would: force over all frames and above 50 mN, location above 50 mN with every miss scored as a failure,
// miss and false-contact rates per force bin, invalid frames by reason, and the calibration of the
// reported uncertainty.
#include <array>
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "ruffini/dataset/dataset.h"
#include "ruffini/decode/pipeline.h"
#include "ruffini/decode/retare.h"
#include "ruffini/patch/spec.h"
#include "ruffini/stats.h"
#include "ruffini/v1/model.pb.h"

namespace ruffini::eval {

// Per frame, aligned with the dataset's frames.
struct StreamPredictions {
  std::vector<float> force_n, force_sd_n, y_mm, r_deg, confidence, common_mode_pm;
  std::vector<float> pos_cov_mm2;  // n x 3: yy, yr, rr (mm^2 on the surface)
  std::vector<std::uint8_t> valid, located, in_contact, reason, baseline_frozen;
  std::vector<std::uint8_t> over_range;  // reported as a contact of at least force_n (valid is 0)
  decode::PipelineCounters counters;
  [[nodiscard]] std::size_t size() const { return force_n.size(); }
};

using ProgressFn = std::function<void(std::uint64_t, std::uint64_t)>;

StreamPredictions DecodeStream(const decode::Pipeline<float>& pipeline, const dataset::Dataset& data,
                               const ProgressFn& progress = {});

// The operator's re-tare (docs/experiments/retare.md): when the patch goes baseline_stale (its FAULT), the
// operator asks for a re-tare (decode::Retare, judged against the model's response map; RetarePatch in the
// service), and asks again every every_s while it stays stale. What happened to the requests:
struct OperatorRetare {
  const v1::ResponseMap* map = nullptr;  // the model's (nullptr: every request is refused, no_map)
  decode::RetareConfig config{};
  double every_s = 10.0;
  // Filled by DecodeStream:
  int requests = 0, accepted = 0, refused_pressing = 0, refused_other = 0;
  int accepted_while_pressed = 0;     // an accepted window held a true press above 20 mN
  int refused_pressing_nothing = 0;   // refused as pressing while no true press above 20 mN was on (the map's doing)
  double accepted_max_true_n = 0;     // the largest true force an accepted window held
};
// As above, with that operator (data must carry the true force only for the accepted_* figures).
StreamPredictions DecodeStream(const decode::Pipeline<float>& pipeline, const dataset::Dataset& data,
                               OperatorRetare& op, const ProgressFn& progress = {});

// /pred/force_n, force_sd_n, y_mm, r_deg, confidence, common_mode_pm (f32), pos_cov_mm2 (f32 n x 3),
// located, valid, in_contact, reason, baseline_frozen (u8; reason codes named in the root attribute
// `reasons`). Written with the dataset library's HDF5 plumbing.
void WriteStreamPredictions(const std::string& path, const StreamPredictions& pred, const std::string& model,
                            const std::string& data);

struct ForceBinRow {
  double lo_n = 0, hi_n = 0;
  std::size_t frames = 0;
  double missed = 0;         // share not located (or invalid)
  double in_contact = 0;     // share reported in contact (below 20 mN: false contacts)
  double force_error_mn = 0; // median |error|
  double location_error_mm = 0;  // median, misses as failures (NaN below 50 mN)
};

// Pressed frames (reference force above 50 mN, position known) of one zone of the patch (StreamMetrics).
struct EdgeZone {
  std::size_t frames = 0, missed = 0;  // missed: not located (gate closed or invalid)
  std::size_t over_range = 0;          // reported over range (invalid, in contact: force "at least")
  stats::Summary force_mn{};           // |error|; an invalid frame reports 0, as everywhere in this scoring
  stats::Summary location_mm{};        // misses as failures (scored at the random guess's error)
  stats::Summary location_located_mm{};
  // Median of reported / true force over the zone's frames above 1 N (below 1: read too light). NaN: none.
  double force_ratio_above_1n = std::numeric_limits<double>::quiet_NaN();
  std::size_t frames_above_1n = 0;
  // Location over the zone's frames above 1 N (a press the region thresholds care about): misses as failures.
  stats::Summary location_above_1n_mm{};
};

struct StreamMetrics {
  std::size_t frames = 0;      // frames scored (the mask)
  std::size_t invalid = 0;
  std::array<std::size_t, decode::kReasonCount> reasons{};
  bool has_true_force = false; // the dataset has applied-force labels (twin)
  // Force error |predicted - reference| (mN): reference = applied force when known, else the load cell.
  stats::Summary force_all_mn{}, force_above_mn{};       // all scored frames; frames above 50 mN
  stats::Summary force_all_loadcell_mn{};                 // against the load cell (the paper's labels)
  // Location above 50 mN: misses (not located, invalid) scored as the random guess would be.
  stats::Summary location_above_mm{}, location_located_mm{};
  std::size_t above_frames = 0, above_missed = 0;
  double miss_rate_above_100mn = 0;
  std::size_t quiet_frames = 0, false_contacts = 0;       // true force < 20 mN; of them reported in contact
  double false_contact_rate = 0;
  std::vector<ForceBinRow> bins;
  // Uncertainty: share of in-contact frames with |force error| <= 1 / 2 / 3 sd; share of located frames above
  // 50 mN whose Mahalanobis^2 lies within chi-square(2) 68.27 % / 95.45 % / 99.73 % (2.30 / 6.18 / 11.83).
  // NaN: uncalibrated.
  double force_within_1sd = 0, force_within_2sd = 0, position_within_1sd = 0, position_within_2sd = 0;
  double force_within_3sd = 0, position_within_3sd = 0;
  std::size_t force_cov_frames = 0, position_cov_frames = 0;
  // Baseline: longest frozen stretch and longest press (true force > 20 mN, contiguous), s.
  double longest_frozen_s = 0, longest_press_s = 0;
  patch::SurfacePoint guess;   // the random guess's position
  // Pressed frames by the true position's distance from the patch's nearest edge (patch::EdgeDistanceMm):
  // within kEdgeBandMm (issue 16's "within 10 mm of an edge") or farther in.
  static constexpr double kEdgeBandMm = 10.0;
  EdgeZone near_edge, interior;
};

// Scores the frames where mask[k] != 0 (empty mask: every frame). guess: the position a random guess names
// (the training part's median position).
StreamMetrics ScoreStream(const dataset::Dataset& data, const StreamPredictions& pred, const patch::PatchSpec& spec,
                          const std::vector<std::uint8_t>& mask, const patch::SurfacePoint& guess);

// Frames of the listed indentations (for scoring a held-out split of the training data).
std::vector<std::uint8_t> MaskOfIndentations(const dataset::Dataset& data, const std::vector<std::int32_t>& ids);

// One Markdown table row per metric set, for reports: "| name | force all | force > 50 | location | ..."
std::string StreamMetricsHeader();
std::string StreamMetricsRow(const std::string& name, const StreamMetrics& m);
// One Markdown table of the near-edge and interior zones, one row pair per metric set.
std::string EdgeZoneTable(const std::vector<std::pair<std::string, const StreamMetrics*>>& rows);
// The per-force-bin table (miss rate, false contacts, errors).
std::string ForceBinTable(const StreamMetrics& m);

struct StreamReportRow {
  std::string label;       // Markdown, e.g. "`paper_seed3.h5`" or "cast1 (`cast1_test.h5`)"
  StreamMetrics scored;
};
// The report's "scored as a skeptical reviewer would" section: the rows (the first is the main data), the
// main data's whole stream (false contacts, baseline, invalid frames by reason), its per-force-bin table and
// the uncertainty's coverage against its targets (uncertainty = nullptr: the model has none).
std::string StreamReportSection(const std::vector<StreamReportRow>& rows, const StreamMetrics& whole, bool training_data,
                                const v1::Uncertainty* uncertainty);

// Where the calibrated uncertainty is honest and where not: coverage at 1 / 2 / 3 sigma (gates as ScoreStream,
// every frame of the stream) per group of frames: predicted force, the press's phase (onset before the reference
// force first reaches 90 % of its indentation's peak, hold, release after it last does), the true position
// (inside the spec's indented area 5 mm or more from its border, within 5 mm of it, outside), the same for the
// reported position (located frames: what the runtime knows), and the size of the reported covariance
// (det^(1/4), mm). The shape: the share of position errors within 1 sd along Y and
// along the arc alone (both 68.27 % when the covariance has the errors' shape).
struct CoverageRow {
  std::string group;
  std::size_t force_frames = 0, position_frames = 0;
  std::array<double, 3> force{}, position{};  // share within 1, 2, 3 sigma
  double y_within_1sd = 0, arc_within_1sd = 0;
};
std::vector<CoverageRow> CoverageBreakdown(const dataset::Dataset& data, const StreamPredictions& pred, const patch::PatchSpec& spec);
std::string CoverageTable(const std::vector<CoverageRow>& rows);

}  // namespace ruffini::eval
