#pragma once
// From trained libtorch nets to the model file (ruffini.v1.DecoderModel): weights, normalisations, grids,
// gate, and golden vectors (libtorch's own outputs, which the Eigen runtime must reproduce to 1e-5).
// Internal to the training library.
#include <array>
#include <span>

#include "nets.h"
#include "ruffini/decode/grids.h"
#include "ruffini/train/trainer.h"
#include "ruffini/v1/model.pb.h"

namespace ruffini::train::detail {

// Writes the force net, the four location nets (unstacked from the bank, padding dropped), their grids and
// the gate into `m`.
void ExportNets(const FitNets& nets, const std::array<decode::GridSpec, 4>& grids, const TrainOptions& options,
                v1::DecoderModel& m);

// Appends one golden vector: the window the force net saw (W x 16 shifts, oldest first, missing peaks at
// their training mean), libtorch's force for it, every grid's softmax for the window's newest frame
// (concatenated in grid order) and the NIP's location from them.
void AddGoldenVector(std::span<const float> window_shift_pm, float force_n, std::span<const float> probabilities,
                     const decode::Nip& nip, v1::DecoderModel& m);

}  // namespace ruffini::train::detail
