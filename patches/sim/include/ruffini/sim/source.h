#pragma once
// Where a simulated interrogator's peaks come from. A FrameSource fills one Wavelengths per channel (one
// channel per patch of the scene) for each sample index; the server turns them into Hyperion frames.
#include <cstddef>
#include <cstdint>
#include <span>

#include "ruffini/dataset/dataset.h"
#include "ruffini/frame.h"

namespace ruffini::sim {

class FrameSource {
 public:
  virtual ~FrameSource() = default;
  // Channels this source fills (1..16): channel c carries patch c of the scene.
  [[nodiscard]] virtual std::size_t channels() const noexcept = 0;
  // The peaks (nm, NaN = peak missing) of every channel for sample `sample` (0, 1, 2, ...: one per tick of
  // the sample clock). out.size() == channels(). Called on the server's thread only.
  virtual void Sample(std::uint64_t sample, std::span<Wavelengths> out) = 0;
};

// Replays a dataset's /frames/wavelength_nm, looping: sample k plays row k mod N, on every channel (a scene
// of several patches sees the same recording on each of them).
class ReplaySource final : public FrameSource {
 public:
  // Throws InputError when the dataset has no frames or channels is not 1..16.
  ReplaySource(dataset::Dataset data, std::size_t channels);
  [[nodiscard]] std::size_t channels() const noexcept override { return channels_; }
  void Sample(std::uint64_t sample, std::span<Wavelengths> out) override;
  [[nodiscard]] const dataset::Dataset& data() const noexcept { return data_; }

 private:
  dataset::Dataset data_;
  std::size_t channels_;
};

}  // namespace ruffini::sim
