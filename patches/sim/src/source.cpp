#include "ruffini/sim/source.h"

#include <string>
#include <utility>

#include "ruffini/error.h"
#include "ruffini/ingest/hyperion.h"

namespace ruffini::sim {

ReplaySource::ReplaySource(dataset::Dataset data, std::size_t channels)
    : data_(std::move(data)), channels_(channels) {
  if (data_.wavelength_nm.empty()) throw InputError("replay: the dataset has no frames");
  if (channels_ < 1 || channels_ > ingest::kChannels) {
    throw InputError("replay: " + std::to_string(channels_) + " channels; a Hyperion frame carries 1..16");
  }
}

void ReplaySource::Sample(std::uint64_t sample, std::span<Wavelengths> out) {
  const auto& row = data_.wavelength_nm[static_cast<std::size_t>(sample % data_.wavelength_nm.size())];
  for (auto& ch : out) ch = row;
}

}  // namespace ruffini::sim
