#pragma once
// Message (the real-time thread's plain struct) -> ruffini.v1.PatchMessage (on the publisher thread; this
// allocates, the decode thread never calls it).
#include <cstdint>
#include <string>

#include "ruffini/link/messages.h"
#include "ruffini/v1/patch.pb.h"

namespace ruffini::link {

// Fills out's envelope (patch_id, seq, serial, times) and body from m; out is cleared first (reuse it).
void ToProto(const Message& m, const std::string& patch_id, std::uint64_t seq, v1::PatchMessage& out);

}  // namespace ruffini::link
