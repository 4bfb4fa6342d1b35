// libFuzzer driver for aggregate::Core: the fuzzer's bytes are a program of decoder streams, joint states,
// resets and ticks (core_program.h says how they are read and which invariants are checked after every step).
#include <cstddef>
#include <cstdint>

#include "core_program.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  (void)ruffini::core_program::Run(data, size);
  return 0;
}
