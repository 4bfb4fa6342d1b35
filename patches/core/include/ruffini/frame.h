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

// Flags a frame can carry (the twin sets them; datasets store them; the decoder reads kFlagSaturated).
enum FrameFlags : std::uint32_t {
  kFlagNone = 0,
  kFlagSaturated = 1u << 0,     // some peak was clipped to its band (overload)
  kFlagOffPatch = 1u << 1,      // a contact lay outside the patch and was ignored
  kFlagPeakMissing = 1u << 2,   // some peak is NaN (dead or dimmed grating)
  kFlagBadContact = 1u << 3,    // a contact had a non-finite or negative force and was ignored
};

}  // namespace ruffini
