// Fuser::Update, Lift and covariance intersection allocate nothing: a counting global operator new, armed
// around thousands of updates with merges, force-only contacts and bad inputs mixed in.
#include <gtest/gtest.h>

#include <limits>
#include <vector>

// GCC 12 inlines the replaced operator delete (std::free) into std::vector<FusionPatch>'s deallocation and
// then flags it as not matching the (builtin) operator new: a false positive for a program-wide replacement
// whose operator new does call std::malloc.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
#include "../common/alloc_counter.h"
#pragma GCC diagnostic pop
#include "fixture.h"
#include "ruffini/fusion/fuser.h"

namespace ruffini::fusion {
namespace {

TEST(FusionRealTime, UpdateDoesNotAllocate) {
  const auto model = testing::TestModel();
  FusionConfig config;
  config.patches = {testing::Patch("a", "fore", 0.0), testing::Patch("b", "fore", 0.15),
                    testing::Patch("c", "hand", 0.0), testing::Patch("d", "fore", 0.075)};
  const Fuser fuser(model, config);
  robot::Data fk = testing::PosesAtZero(model);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  SurfaceContact bad = testing::Located(10, 10);
  bad.cov_ys_mm2 = nan;
  std::vector<PatchInput> inputs;  // built before arming
  inputs.reserve(8);
  std::array<double, 3> q{0, 0, 0};
  std::size_t contacts = 0;
  std::uint64_t merges = 0;
  long n = 0;
  {
    FusionData* data = nullptr;
    const long making = ruffini::testing::CountAllocations([&] {
      static FusionData d;  // function-local static: constructed inside the armed region
      data = &d;
    });
    EXPECT_EQ(making, 0);
    n = ruffini::testing::CountAllocations([&] {
      for (int k = 0; k < 5000; ++k) {
        q[1] = 1e-4 * k;
        (void)robot::ForwardKinematics(model, q, fk);
        inputs.clear();
        const double s = 0.01 * (k % 100);
        inputs.push_back({0, testing::Located(147 + s, 60, 1.0)});
        inputs.push_back({1, k % 7 == 0 ? testing::ForceOnly(0.5) : testing::Located(1 + s, 60, 1.0)});
        inputs.push_back({2, k % 13 == 0 ? bad : testing::Located(5, 100)});
        inputs.push_back({3, testing::Located(74 + s, 60 + s, 2.0)});
        if (k % 11 == 0) inputs.push_back({99, testing::Located(1, 1)});
        if (k % 17 == 0) inputs.push_back({0, testing::Located(1, 1)});
        contacts += fuser.Update(inputs, fk.X_BL, *data);
      }
      Estimate f;
      (void)CovarianceIntersection({}, {}, f);
    });
    merges = data->counters.merges;
  }
  EXPECT_EQ(n, 0);
  EXPECT_GT(merges, 5000u);  // the fusing path did run
  EXPECT_GT(contacts, 5000u);
  int* seen = nullptr;  // the counter counts
  EXPECT_EQ(ruffini::testing::CountAllocations([&] { seen = new int(1); }), 1);
  delete seen;
}

}  // namespace
}  // namespace ruffini::fusion
