#pragma once
// Small pieces the whole-system runs (demo.cpp, soak.cpp) share.
#include <cstdio>
#include <filesystem>
#include <string>

#include "ruffini/error.h"
#include "ruffini/v1/aggregator.pb.h"

namespace ruffini::harness {

// printf-formats one number ("%.2f").
inline std::string Fmt(const char* format, double v) {
  char b[64];
  std::snprintf(b, sizeof b, format, v);
  return b;
}

inline const char* StateName(v1::SafetyState::State s) {
  switch (s) {
    case v1::SafetyState::STATE_CLEAR: return "CLEAR";
    case v1::SafetyState::STATE_STOP: return "STOP";
    case v1::SafetyState::STATE_FAULT: return "FAULT";
    default: return "UNSPECIFIED";
  }
}

// The four service executables must lie in `bin_dir` (next to the `ruffini` tool); throws InputError naming the
// first missing one.
inline void RequireServiceExecutables(const std::string& bin_dir) {
  for (const char* exe : {"ruffini-sim", "ruffini-decoder", "ruffini-aggregator", "ruffini-controller"}) {
    if (!std::filesystem::exists(std::filesystem::path(bin_dir) / exe)) {
      throw InputError(std::string(exe) + " is not next to this executable (" + bin_dir +
                       "); build every target (cmake --workflow --preset release)");
    }
  }
}

}  // namespace ruffini::harness
