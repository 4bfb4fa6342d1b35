// Decode() allocates nothing: a counting global operator new, armed around the calls.
#include <gtest/gtest.h>

#include "../common/alloc_counter.h"
#include "ruffini/decode/baseline.h"
#include "ruffini/decode/network_decoder.h"
#include "ruffini/patch/spec_loader.h"
#include "synthetic_model.h"

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
  return ruffini::testing::CountAllocations([&] {
    for (int k = 0; k < 2000; ++k) {
      for (std::size_t i = 0; i < 16; ++i) wl[i] = 1530.0 + 2.3 * static_cast<double>(i) + (k > 200 && i == 3 ? 0.2 : 0.0);
      if (k % 97 == 0) wl[7] = std::nan("");
      baseline.Update(wl, s);
      const auto o = d.Decode(s, data);
      (void)o;
    }
  });
}

TEST(RealTime, DecodeDoesNotAllocate) {
  EXPECT_EQ(CountAllocations<float>(1), 0);
  EXPECT_EQ(CountAllocations<float>(32), 0);
  EXPECT_EQ(CountAllocations<double>(8), 0);
  int* seen = nullptr;  // the counter counts
  EXPECT_EQ(ruffini::testing::CountAllocations([&] { seen = new int(1); }), 1);
  delete seen;
}

}  // namespace
}  // namespace ruffini::decode
