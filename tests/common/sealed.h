#pragma once
// Tests that feed aggregate::Core directly play the decoder's part of the safety layer
// (docs/safety-channel.md): the decoder's run id, its steady clock (here the test's clock, so the learned
// offset is 0), the aggregator run the message is addressed to (0 in a stream's first hello), and the CRC.
// Header-only; link ruffini::channel.
#include <cstdint>

#include "ruffini/aggregate/core.h"
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

// Seals m as its decoder would and hands it to the Core at now_ns.
inline aggregate::Core::Reply Deliver(aggregate::Core& core, int stream, v1::PatchMessage m, std::int64_t now_ns) {
  SealAsDecoder(m, core.run_id(), now_ns);
  return core.OnPatchMessage(stream, m, now_ns);
}

}  // namespace ruffini::testing
