#pragma once
// Training the paper's decoders with libtorch (training only: the runtime is Eigen, ruffini::decode).
//
// Force: a CNN (3 x [conv 16 filters, kernel 16, stride 1, 'same' padding, ReLU, max-pool 2], flatten,
// dense 100 ReLU, dense 1) over a window of the last W frames of 16 z-scored shifts, regressing the
// z-scored load-cell force, MSE (L1 as a measured variant). Location: one MLP per grid (3 hidden ReLU layers,
// dropout after the second, softmax over the grid's cells), cross-entropy against the contact's cell (or soft
// Gaussian labels, a measured variant), trained on frames whose force label exceeds the gate. SGD with
// momentum 0.9 (Adam and cosine decay as measured variants). Fixed seeds. Whole indentations are never split.
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "ruffini/eval/prepared.h"
#include "ruffini/patch/spec.h"
#include "ruffini/v1/model.pb.h"

namespace ruffini::train {

struct TrainOptions {
  int window = 1;                          // W: frames the force net sees
  std::vector<int> mlp_widths = {64, 64, 64};
  double dropout = 0.2;
  int epochs_force = 12;
  int epochs_location = 12;
  int frames_per_epoch = 100000;           // samples drawn (with replacement) per epoch
  int batch = 256;
  double lr_force = 0.01;
  double lr_location = 0.05;
  double momentum = 0.9;
  std::string optimizer = "sgd";           // sgd | adam
  std::string lr_schedule = "constant";    // constant | cosine (decay to 2 % over the epochs)
  std::string force_loss = "mse";          // mse (the paper's) | l1
  std::string location_input = "raw";      // raw (the paper's) | unit (shifts / their norm)
  double unit_floor_pm = 1.0;              // unit: smallest norm divided by
  double label_sigma_mm = 0.0;             // 0: one-hot cell labels (the paper's); > 0: Gaussian soft labels
  double drift_augment_pm = 0.0;           // > 0: per-sample per-grating offsets of this sigma in training (field drift)
  int folds = 5;                           // 0: no cross-validation
  double test_fraction = 0.15;
  double gate_n = 0.05;
  // What the location grids span: "indented" (the paper's: PaperGrids over the spec's indented area) or
  // "whole" (WholeSurfaceGrids: the patch's full extent, for data pressed edge to edge). The model file
  // records the grids, so the decoder locates with whichever was trained.
  std::string area = "indented";
  std::uint64_t seed = 1;
  int threads = 2;                         // fits trained at once (one core each)
  int golden_vectors = 4;
};

// (phase of the epoch just finished, e.g. "fold 2/5 force" or "final location (4 grids)"; epochs finished
// over all fits; epochs of all fits; that epoch's mean loss). Fits run in parallel; calls are serialised.
using TrainProgress = std::function<void(const std::string& phase, int epoch, int epochs, double loss)>;

// Trains on `data` for `spec` (grids from its indented area, or its whole extent: TrainOptions::area). Fills every field of the model, including the
// cross-validation table, the held-out test indentations and golden vectors computed by libtorch.
v1::DecoderModel Train(const eval::Prepared& data, const patch::PatchSpec& spec, const TrainOptions& options,
                       const std::string& dataset_path, const TrainProgress& progress = {});

// libtorch inference of a trained model (eager and frozen TorchScript): ruffini/train/torch_decoder.h.

}  // namespace ruffini::train
