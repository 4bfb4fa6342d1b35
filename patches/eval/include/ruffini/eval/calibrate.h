#pragma once
// Fitting what a trained model needs to run in the field, on data it was not trained on:
// - InputRange: the per-grating shifts the model has been shown to handle (outside it: invalid frames);
// - Uncertainty: force sd and position-covariance scale as functions of the predicted force (and one floor on
//   the position covariance), fitted so the shares within 1 and 2 sigma on the fitting data both lie as far
//   inside their bands (68 +- 5 %, 95 +- 3 %) as the errors' tails allow;
// - cast adaptation: per-grating input gains for another cast of the same design, fitted on at most a
//   hundred of its indentations and folded into the networks' normalisations (no new weights).
// Never fit on test data: `ruffini calibrate` takes a validation recording (another seed, or the new cast's
// calibration indentations).
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "ruffini/dataset/dataset.h"
#include "ruffini/patch/spec.h"
#include "ruffini/v1/model.pb.h"

namespace ruffini::eval {

// The frames up to the end of the first `indentations` indentations (all when <= 0 or more than there are).
dataset::Dataset FirstIndentations(const dataset::Dataset& data, int indentations);

// Per-grating min/max of the preprocessed shifts over the dataset's valid frames; margin = margin_fraction of
// the widest span + margin_pm. Merged with the model's existing range if it has one.
v1::InputRange FitInputRange(const v1::DecoderModel& model, const patch::PatchSpec& spec, const dataset::Dataset& data,
                             double margin_fraction = 0.5, double margin_pm = 5.0);

// What the uncertainty fit sees: each in-contact frame's predicted force and |force error|; each located frame
// above 50 mN its position error (Y, arc mm) and the NIP's raw covariance (mm^2, before any scale or floor).
struct UncertaintyRows {
  struct Force {
    double pred, err;
  };
  struct Position {
    double pred, dy, da, cyy, cya, caa;
  };
  std::vector<Force> force;
  std::vector<Position> position;
};
// Decodes the data with unit scales (every frame the nets can take: no input range) and collects the rows.
UncertaintyRows CollectUncertaintyRows(const v1::DecoderModel& model, const patch::PatchSpec& spec, const dataset::Dataset& data);
// Per bin of predicted force (>= 100 frames each): the force sd and the position scale, each the scale at which
// the band-scaled deviations of the 1- and 2-sigma shares from 68.27 % and 95.45 % cancel (both shares grow with
// the scale, so this is the scale nearest both targets), and never a scale that leaves the 2-sigma share below
// 92.45 % (when the tails are too heavy for both bands, the 1-sigma share exceeds its band); the position floor (0.25-16 mm^2) is the one whose bins
// end nearest both targets. Source and measured coverage are left empty. Throws InputError on too few rows.
v1::Uncertainty FitUncertaintyRows(const UncertaintyRows& rows);
// CollectUncertaintyRows, FitUncertaintyRows, then the coverage the fitted functions reach on the data.
v1::Uncertainty FitUncertainty(const v1::DecoderModel& model, const patch::PatchSpec& spec, const dataset::Dataset& data);

struct GainFit {
  std::vector<float> gain;            // 16
  double before = 0, after = 0;       // objective (median force error mN + median location error mm)
  int evaluations = 0;
};
using GainProgress = std::function<void(int sweep, int sweeps, double objective)>;
// Coordinate search over per-grating gains (0.6..1.6), the objective scored with the Eigen runtime on a
// subsample of the data's indentation frames. The force net is scored against the applied force, or, when the
// model has a creep compensation, against the strain force F + sum g x it reads under the creeping cover
// (the compensation turns that back into F): fit the creep first. The returned gains are not yet applied.
GainFit FitGains(const v1::DecoderModel& model, const patch::PatchSpec& spec, const dataset::Dataset& data,
                 int sweeps = 3, const GainProgress& progress = {});
// Creep compensation: decodes press-hold-release data without compensation and fits the Prony gains g_k
// (tau_s fixed: 1, 10, 100 s, g >= 0) of decoded = s_p (F + sum g_k x_k), x_k the applied force F low-passed
// with tau_k, with a free static scale s_p per press (the press and the rest after it): the creep is what
// changes within a press, its scale error is the gains' (another cast, where on the patch it presses).
// Alternating least squares. Throws InputError when the data hold too few pressed frames.
v1::CreepCompensation FitCreep(const v1::DecoderModel& model, const patch::PatchSpec& spec, const dataset::Dataset& data);

// Per-grating thermal sensitivity relative to the median grating, from a recording whose temperature moves:
// the baseline tracker's per-grating drift while untouched, regressed on its median drift. Normalised to a
// median of 1. Throws InputError when the temperature hardly moved (common drift RMS under 3 pm).
std::vector<float> FitThermalRatio(const v1::DecoderModel& model, const patch::PatchSpec& spec, const dataset::Dataset& data);

// The ids of up to `max_ids` indentations after the first `indentations` (FirstIndentations' cut), in frame order:
// the ones a calibration on the first `indentations` never saw. Empty when the data hold no more.
std::vector<std::int32_t> IndentationsAfter(const dataset::Dataset& data, int indentations, std::size_t max_ids);

// The model on the indentations `ids` of the data, as `ruffini evaluate` scores it (RunDecoder from a reset window
// per indentation, Evaluate): median force error over their frames, median location error over their located
// frames above 50 mN. Throws InputError when `ids` is empty.
v1::CastScore ScoreIndentations(const v1::DecoderModel& model, const patch::PatchSpec& spec, const dataset::Dataset& data,
                                const std::vector<std::int32_t>& ids);

// Folds per-grating gains into every network's input normalisation: z = (g s - mean) / std.
void ApplyGains(v1::DecoderModel& model, const std::vector<float>& gain);

}  // namespace ruffini::eval
