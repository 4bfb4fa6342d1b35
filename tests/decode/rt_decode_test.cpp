// Decode() allocates nothing: a counting global operator new, armed around the calls.
#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <new>

#include "ruffini/decode/baseline.h"
#include "ruffini/decode/network_decoder.h"
#include "ruffini/patch/spec_loader.h"
#include "synthetic_model.h"

namespace {
std::atomic<bool> g_armed{false};
std::atomic<long> g_allocations{0};
}  // namespace

void* operator new(std::size_t n) {
  if (g_armed.load(std::memory_order_relaxed)) g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

namespace ruffini::decode {
namespace {

template <typename Scalar>
long CountAllocations(int window) {
  const auto spec = patch::LoadPatchSpec(RUFFINI_SOURCE_DIR "/config/patches/forearm.yaml");
  const auto m = testing::SyntheticModel(spec, window);
  NetworkDecoder<Scalar> d(m);
  typename NetworkDecoder<Scalar>::Data data(d);
  BaselineTracker baseline;
  Wavelengths wl;
  ShiftsPm s;
  g_allocations = 0;
  g_armed = true;
  for (int k = 0; k < 2000; ++k) {
    for (std::size_t i = 0; i < 16; ++i) wl[i] = 1530.0 + 2.3 * static_cast<double>(i) + (k > 200 && i == 3 ? 0.2 : 0.0);
    if (k % 97 == 0) wl[7] = std::nan("");
    baseline.Update(wl, s);
    const auto o = d.Decode(s, data);
    (void)o;
  }
  g_armed = false;
  return g_allocations.load();
}

TEST(RealTime, DecodeDoesNotAllocate) {
  EXPECT_EQ(CountAllocations<float>(1), 0);
  EXPECT_EQ(CountAllocations<float>(32), 0);
  EXPECT_EQ(CountAllocations<double>(8), 0);
  g_armed = true;  // the counter counts
  auto* p = new int(1);
  g_armed = false;
  delete p;
  EXPECT_GE(g_allocations.load(), 1);
}

}  // namespace
}  // namespace ruffini::decode
