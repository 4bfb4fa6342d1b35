#pragma once
// Fitting what a trained model needs to run in the field, on data it was not trained on:
// - InputRange: the per-grating shifts the model has been shown to handle (outside it: invalid frames);
// - Uncertainty: force sd and position-covariance scale as functions of the predicted force, fitted so
//   68.27 % of frames fall within 1 sigma on the fitting data (2-sigma coverage is measured, not forced);
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

v1::Uncertainty FitUncertainty(const v1::DecoderModel& model, const patch::PatchSpec& spec, const dataset::Dataset& data);

struct GainFit {
  std::vector<float> gain;            // 16
  double before = 0, after = 0;       // objective (median force error mN + median location error mm)
  int evaluations = 0;
};
using GainProgress = std::function<void(int sweep, int sweeps, double objective)>;
// Coordinate search over per-grating gains (0.6..1.6), the objective scored with the Eigen runtime on a
// subsample of the data's indentation frames. The returned gains are not yet applied.
GainFit FitGains(const v1::DecoderModel& model, const patch::PatchSpec& spec, const dataset::Dataset& data,
                 int sweeps = 3, const GainProgress& progress = {});
// Creep compensation: decodes press-hold-release data without compensation and fits the Prony gains g_k
// (tau_s fixed: 1, 10, 100 s) by non-negative least squares of (decoded - applied force) on the applied
// force low-passed with each tau. Throws InputError when the data hold no presses.
v1::CreepCompensation FitCreep(const v1::DecoderModel& model, const patch::PatchSpec& spec, const dataset::Dataset& data);

// Per-grating thermal sensitivity relative to the median grating, from a recording whose temperature moves:
// the baseline tracker's per-grating drift while untouched, regressed on its median drift. Normalised to a
// median of 1. Throws InputError when the temperature hardly moved (common drift RMS under 3 pm).
std::vector<float> FitThermalRatio(const v1::DecoderModel& model, const patch::PatchSpec& spec, const dataset::Dataset& data);

// Folds per-grating gains into every network's input normalisation: z = (g s - mean) / std.
void ApplyGains(v1::DecoderModel& model, const std::vector<float>& gain);

}  // namespace ruffini::eval
