#pragma once
// From a dataset to what decoders learn from and are judged on: per-frame shifts measured against the
// baseline exactly as the decoder service will (BaselineTracker over the stream, in order), labels, and
// the paper's split of whole indentations (85 % train / 15 % test, spatially random; k folds in train).
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "ruffini/dataset/dataset.h"
#include "ruffini/decode/baseline.h"

namespace ruffini::eval {

struct Prepared {
  std::vector<decode::ShiftsPm> shift_pm;  // per frame; NaN where a peak is missing or no baseline yet
  std::vector<float> force_n, y_mm, r_deg;  // labels (load cell; probe position)
  std::vector<std::int32_t> indentation;    // -1 outside any
  // Every indentation: its id and its frame range [first, last).
  std::vector<std::int32_t> ids;
  std::vector<std::pair<std::size_t, std::size_t>> ranges;
  double sample_rate_hz = 100.0;
  double surface_radius_mm = 0.0;
  std::string patch_name, source;
  [[nodiscard]] std::size_t size() const { return force_n.size(); }
};

// The baseline tracker's config for a dataset: `config` at the dataset's sample rate.
decode::BaselineConfig BaselineConfigFor(const dataset::Dataset& data, const decode::BaselineConfig& config = {});

// Runs the baseline tracker (BaselineConfigFor) over the frames in order. Indentation frames must be contiguous per index.
Prepared PrepareFrames(const dataset::Dataset& data, const decode::BaselineConfig& config = {});

struct Split {
  std::vector<std::size_t> train, test;  // indices into Prepared::ids
  std::vector<int> fold;                  // fold of each train entry (0..folds-1)
  int folds = 0;
};

// Whole indentations only: shuffled with the seed, the first test_fraction go to test; the rest are dealt
// into `folds` folds. `forced_test` (ids), if given, fixes the test set (evaluation of a trained model).
Split MakeSplit(const Prepared& p, double test_fraction, int folds, std::uint64_t seed,
                const std::vector<std::int32_t>& forced_test = {});

}  // namespace ruffini::eval
