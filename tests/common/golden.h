#pragma once
// Test helper: the newest frame of a golden vector's window (what the location nets saw).
#include "ruffini/decode/baseline.h"
#include "ruffini/v1/model.pb.h"

namespace ruffini::testing {

inline decode::ShiftsPm LastFrame(const v1::GoldenVector& g, const v1::DecoderModel& m) {
  decode::ShiftsPm last{};
  const int base = (static_cast<int>(m.force().window()) - 1) * 16;
  for (int i = 0; i < 16; ++i) last[static_cast<std::size_t>(i)] = g.window_shift_pm(base + i);
  return last;
}

}  // namespace ruffini::testing
