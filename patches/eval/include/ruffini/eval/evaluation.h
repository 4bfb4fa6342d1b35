#pragma once
// Evaluating a decoder as the paper did: on the held-out test indentations, force error (mN) over every
// frame, location error (mm on the surface) over frames whose force label exceeds the 50 mN gate, against
// random-guess baselines (the training part's median force and median position), with a two-sided
// Wilcoxon signed-rank test and Cohen's d (paired), error vs force, and error maps over the patch.
#include <array>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "ruffini/decode/inversion.h"
#include "ruffini/decode/network_decoder.h"
#include "ruffini/eval/prepared.h"
#include "ruffini/hypothesis.h"
#include "ruffini/patch/spec.h"
#include "ruffini/stats.h"
#include "ruffini/v1/model.pb.h"

namespace ruffini::eval {

// A decoder fed frames in stream order (network or physics-based).
class FrameDecoder {
 public:
  virtual ~FrameDecoder() = default;
  virtual void Reset(const decode::ShiftsPm* fill) = 0;
  virtual decode::DecodeOutput Decode(const decode::ShiftsPm& shift_pm) = 0;
};

template <typename Scalar>
class NetworkFrameDecoder final : public FrameDecoder {
 public:
  explicit NetworkFrameDecoder(const v1::DecoderModel& m, decode::DecoderOptions o = {})
      : decoder_(m, std::move(o)), data_(decoder_) {}
  void Reset(const decode::ShiftsPm* fill) override { decoder_.Reset(data_, fill); }
  decode::DecodeOutput Decode(const decode::ShiftsPm& s) override { return decoder_.Decode(s, data_); }

 private:
  decode::NetworkDecoder<Scalar> decoder_;
  typename decode::NetworkDecoder<Scalar>::Data data_;
};

class InversionFrameDecoder final : public FrameDecoder {
 public:
  explicit InversionFrameDecoder(const decode::InversionDecoder& d) : decoder_(d) {}
  void Reset(const decode::ShiftsPm*) override {}
  decode::DecodeOutput Decode(const decode::ShiftsPm& s) override { return decoder_.Decode(s); }

 private:
  const decode::InversionDecoder& decoder_;
};

// The inversion decoder's response map, learned from the frames of every indentation not in `test_ids`, on a
// grid over `area` (nullptr: the spec's indented area).
decode::ResponseModel FitResponse(const Prepared& data, const patch::PatchSpec& spec, const std::vector<std::int32_t>& test_ids,
                                  const patch::Region* area = nullptr);

struct Predictions {
  std::vector<float> force_n, y_mm, r_deg;
  std::vector<std::uint8_t> valid, located, test;
};

// Decodes every frame (or, with test_only, only the test indentations' frames; the others stay NaN/0);
// each indentation starts from a reset window filled with its first frame.
Predictions RunDecoder(FrameDecoder& decoder, const Prepared& data, const std::vector<std::int32_t>& test_ids,
                       const std::function<void(std::uint64_t, std::uint64_t)>& progress = {}, bool test_only = false);

// Latency: ruffini/eval/bench.h.

struct BinStats {
  double lo, hi;
  stats::Summary error;
  std::size_t n = 0;
};

struct Evaluation {
  std::size_t force_frames = 0, location_frames = 0, location_missed = 0;
  stats::Summary force_error_mn{}, location_error_mm{};
  stats::Summary rg_force_error_mn{}, rg_location_error_mm{};
  double rg_force_guess_n = 0;
  patch::SurfacePoint rg_location_guess;
  stats::WilcoxonResult force_wilcoxon, location_wilcoxon;
  double force_cohens_d = 0, location_cohens_d = 0;
  std::vector<BinStats> force_vs_force, force_vs_force_low, location_vs_force, location_vs_force_low;
  double force_error_r2 = 0;  // linear fit of the binned median force error against force
  // Error maps over the indented area: median error per coarse cell (NaN = no data), row-major, row 0 = y min.
  int map_ny = 0, map_nr = 0;
  std::vector<double> force_map_mn, location_map_mm;
  double edge_force_mn = 0, interior_force_mn = 0, edge_location_mm = 0, interior_location_mm = 0;
};

Evaluation Evaluate(const Prepared& data, const Predictions& pred, const patch::PatchSpec& spec, double gate_n = 0.05);


// Writes DIR/report.md, DIR/*.svg and DIR/predictions.h5. `front` is Markdown placed before the paper's tables,
// `extra` Markdown appended (other decoders).
void WriteReport(const std::string& dir, const v1::DecoderModel& model, const std::string& data_path,
                 const Prepared& data, const Predictions& pred, const Evaluation& ev, const patch::PatchSpec& spec,
                 const std::string& command, const std::string& extra = "", const std::string& front = "");
// /pred/force_n, /pred/y_mm, /pred/r_deg (f32), /pred/valid, /pred/located, /pred/test (u8), aligned with frames.
void WritePredictions(const std::string& path, const Predictions& pred);

}  // namespace ruffini::eval
