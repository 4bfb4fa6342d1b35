#pragma once
// Small pieces the whole-system runs (demo.cpp, soak.cpp) share.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <string>
#include <thread>

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

// The sim's sample 0 on the Unix clock, which it logs ("sample 0 is at Unix time N ns"): a scenario's time 0.
// Read from its stderr until `timeout`; throws InputError naming the log when it never comes.
inline std::int64_t SimSampleZeroNs(const std::function<std::string()>& stderr_text, std::chrono::milliseconds timeout) {
  constexpr const char* kLine = "sample 0 is at Unix time ";
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    const std::string err = stderr_text();
    const auto at = err.find(kLine);
    if (at != std::string::npos) {
      const std::int64_t t = std::strtoll(err.c_str() + at + std::char_traits<char>::length(kLine), nullptr, 10);
      if (t > 0) return t;
    }
    if (std::chrono::steady_clock::now() >= deadline) {
      throw InputError(std::string("ruffini-sim did not log its clock ('") + kLine + "'): " + err);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

}  // namespace ruffini::harness
