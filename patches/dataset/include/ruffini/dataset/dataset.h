#pragma once
// The Ruffini dataset: one HDF5 file per recording or simulation, readable from h5py or MATLAB.
//
// Layout (version 1):
//   /                       attrs: format = "ruffini.dataset" (string), version = 1 (int32),
//                                  sample_rate_hz (f64), source (string), plus any extra string attrs
//   /frames/wavelength_nm   f64 [N,16]  interrogator peaks; NaN = peak missing
//   /frames/t_s             f64 [N]
//   /frames/serial          u64 [N]     rises by 1 per sample; a gap is a lost sample
//   /frames/flags           u32 [N]     twin flags (FrameFlags), 0 for recordings
//   /labels/force_n         f32 [N]     the load cell's reading (noisy); NaN when unknown
//   /labels/true_force_n    f32 [N]     the force the twin applied; NaN for recordings
//   /labels/y_mm, r_deg     f32 [N]     probe position through a whole indentation; NaN outside any
//   /labels/indentation     i32 [N]     index of the indentation on each of its frames; -1 outside any
//   /patch                  attrs: name (string), surface_radius_mm (f64)
//   /patch/reference_wavelength_nm  f64 [16]  each grating's unloaded reference wavelength
// Files are written without object timestamps, so the same input gives bit-identical files.
#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "ruffini/frame.h"

namespace ruffini::dataset {

inline constexpr std::size_t kChannels = ::ruffini::kGratings;  // ruffini/frame.h
inline constexpr int kFormatVersion = 1;

using ::ruffini::FrameFlags;  // ruffini/frame.h
using enum ::ruffini::FrameFlags;

// One interrogator sample with its labels.
struct Frame {
  std::array<double, kChannels> wavelength_nm{};
  double t_s = 0.0;
  std::uint64_t serial = 0;
  std::uint32_t flags = 0;
  float force_n = 0.0f;
  float true_force_n = 0.0f;
  float y_mm = 0.0f;
  float r_deg = 0.0f;
  std::int32_t indentation = -1;
};

struct DatasetInfo {
  double sample_rate_hz = 100.0;
  std::string source;  // "twin: scene=..., seed=..., effects=..." or "recording"
  std::string patch_name;
  double surface_radius_mm = 0.0;
  std::array<double, kChannels> reference_wavelength_nm{};
  std::vector<std::pair<std::string, std::string>> attributes;  // extra root string attributes
};

// Column-wise contents of a dataset file.
struct Dataset {
  DatasetInfo info;
  std::vector<std::array<double, kChannels>> wavelength_nm;
  std::vector<double> t_s;
  std::vector<std::uint64_t> serial;
  std::vector<std::uint32_t> flags;
  std::vector<float> force_n, true_force_n, y_mm, r_deg;
  std::vector<std::int32_t> indentation;
  [[nodiscard]] std::size_t size() const { return t_s.size(); }
  void Append(const Frame& f);  // appends one frame to every column
};

// Streams frames into a new file (truncating an existing one), in chunks, so a dataset of millions of
// frames never sits in memory whole. Throws ruffini::InputError naming the path on any HDF5 failure.
class DatasetWriter {
 public:
  // compression_level: 0 = none, 1..9 = shuffle + deflate at that level.
  DatasetWriter(const std::string& path, const DatasetInfo& info, int compression_level = 0);
  ~DatasetWriter();  // closes (flushing) if Close() was not called; never throws
  DatasetWriter(const DatasetWriter&) = delete;
  DatasetWriter& operator=(const DatasetWriter&) = delete;

  void Append(const Frame& frame);
  void Append(std::span<const Frame> frames);
  void Close();  // flushes and closes; throws on failure
  [[nodiscard]] std::uint64_t frames_written() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Reads and validates a dataset file: format, version, every dataset present with the right type and
// shape. Throws ruffini::InputError naming the file and what is wrong.
Dataset ReadDataset(const std::string& path);
// A column of a side file (predictions, per-frame results): rows x cols, row-major, of one element type.
struct Column {
  enum class Type { kF32, kU8, kI32 };
  std::string name;
  Type type = Type::kF32;
  std::size_t rows = 0, cols = 1;
  const void* data = nullptr;
};
// Writes the columns under /group of a new file (truncating an existing one), no timestamps (same input,
// bit-identical file), with string attributes on the root. All columns must have the same rows. Throws
// ruffini::InputError naming the path and the column.
void WriteColumns(const std::string& path, const std::string& group, std::span<const Column> columns,
                  const std::vector<std::pair<std::string, std::string>>& attributes = {});
// Writes a whole in-memory dataset (uses DatasetWriter).
void WriteDataset(const std::string& path, const Dataset& data, int compression_level = 0);

}  // namespace ruffini::dataset
