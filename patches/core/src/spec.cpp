#include <cstdint>
#include <cstdio>

#include "ruffini/patch/spec.h"
#include "ruffini/patch/spec_loader.h"

namespace ruffini::patch {

std::string PatchSpec::Fingerprint() const {
  // FNV-1a over the canonical YAML dump: every physical field, in a fixed order and number format.
  const std::string text = DumpPatchSpec(*this);
  std::uint64_t h = 1469598103934665603ull;
  for (unsigned char c : text) {
    h ^= c;
    h *= 1099511628211ull;
  }
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(h));
  return buf;
}

}  // namespace ruffini::patch
