#pragma once
// Tests that play a decoder play its part of the safety layer (docs/safety-channel.md): the decoder's run id,
// its steady clock, the aggregator run the message is addressed to (0 in a stream's first hello), and the CRC.
// Header-only; link ruffini::channel.
#include <cstdint>

#include "ruffini/channel/crc.h"

namespace ruffini::testing {

inline constexpr std::uint64_t kTestDecoderRun = 0xDEC0DE0001ULL;

inline void SealAsDecoder(v1::PatchMessage& m, std::uint64_t aggregator_run_id, std::int64_t steady_ns,
                          std::uint64_t decoder_run = kTestDecoderRun) {
  m.set_sender_run_id(decoder_run);
  m.set_sender_steady_ns(steady_ns);
  m.set_aggregator_run_id(m.has_hello() && m.seq() <= 1 ? 0 : aggregator_run_id);
  channel::Seal(m);
}

}  // namespace ruffini::testing
