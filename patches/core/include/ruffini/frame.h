#pragma once
// The one place the tree says how many gratings a patch has and what a frame's flags mean.
#include <array>
#include <cstddef>
#include <cstdint>

namespace ruffini {

// One fibre, 16 Fiber Bragg Gratings: a compile-time size everywhere (patch specs, datasets, decoders).
inline constexpr std::size_t kGratings = 16;

// Peak wavelengths of one interrogator frame, nm (NaN = peak missing).
using Wavelengths = std::array<double, kGratings>;

// Flags a frame can carry: the twin sets them and datasets store them. Offline decoding (decode::Pipeline over a
// dataset's frames: `ruffini decode`, evaluate, bench) rejects a frame flagged kFlagSaturated as `saturated`. No
// interrogator stream carries flags: the decoder service's frames carry only kFlagPeakMissing (from the
// ingest's channel pick), so live, a peak out of its band is rejected as `out_of_band` instead.
enum FrameFlags : std::uint32_t {
  kFlagNone = 0,
  // The twin went beyond its linear model: a sphere pressed past the layer's linear range (the hard-press law
  // takes over), a point probe's force capped at its limit, or a peak shifted out of its band (the peak is
  // reported where it is, not clipped).
  kFlagSaturated = 1u << 0,
  kFlagOffPatch = 1u << 1,      // a contact lay outside the patch and was ignored
  kFlagPeakMissing = 1u << 2,   // some peak is NaN (dead or dimmed grating)
  kFlagBadContact = 1u << 3,    // a contact had a non-finite or negative force and was ignored
};

}  // namespace ruffini
