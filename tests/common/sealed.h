#pragma once
// Tests that feed aggregate::Core directly play the decoder's part of the safety layer (seal.h), with the test's
// clock as the decoder's steady clock (so the learned offset is 0). Header-only; link ruffini::channel.
#include "ruffini/aggregate/core.h"
#include "seal.h"

namespace ruffini::testing {

// Seals m as its decoder would and hands it to the Core at now_ns.
inline aggregate::Core::Reply Deliver(aggregate::Core& core, int stream, v1::PatchMessage m, std::int64_t now_ns) {
  SealAsDecoder(m, core.run_id(), now_ns);
  return core.OnPatchMessage(stream, m, now_ns);
}

}  // namespace ruffini::testing
