#pragma once
// Reading and writing decoder model files.
//
// A file is an envelope around the ruffini.v1.DecoderModel protobuf: 8 bytes magic "RFNMODL1", the payload
// size as u64 little-endian, the payload, and an FNV-1a 32-bit checksum of the payload (u32 LE). The
// envelope makes a truncated or corrupted file fail loudly (protobuf alone parses many truncations as a
// valid, shorter message). Every error is ruffini::InputError naming the file and what is wrong.
#include <string>

#include "ruffini/patch/spec.h"
#include "ruffini/v1/model.pb.h"

namespace ruffini::decode {

inline constexpr unsigned kModelFormatVersion = 1;

void SaveModel(const std::string& path, const v1::DecoderModel& model);
// Loads and validates structure and shapes (ValidateModel).
v1::DecoderModel LoadModel(const std::string& path);
// Shapes, layer chaining, grids, normalisation (std > 0), version. Throws InputError naming `where`.
void ValidateModel(const v1::DecoderModel& model, const std::string& where);
// Throws InputError unless the model was trained for this patch spec (name and fingerprint).
void CheckModelMatchesPatch(const v1::DecoderModel& model, const patch::PatchSpec& spec, const std::string& where);

}  // namespace ruffini::decode
