// ForwardKinematics, WithinLimits and the mount maps allocate nothing: a counting global operator new,
// armed around the calls (its own binary: the replacement is program-wide).
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "../common/alloc_counter.h"
#include "ruffini/robot/kinematics.h"
#include "ruffini/robot/mount.h"

namespace ruffini::robot {
namespace {

TEST(RealTime, ForwardKinematicsDoesNotAllocate) {
  const Model m = Model::FromUrdfFile(RUFFINI_SOURCE_DIR "/config/robots/srs7.urdf");
  Data data;
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> u(-3, 3);
  std::vector<std::vector<double>> states(1000, std::vector<double>(7));
  for (auto& q : states) {
    for (auto& v : q) v = u(rng);
  }
  states[17][3] = std::nan("");  // refused inputs take the same allocation-free path
  const std::vector<double> short_state(6, 0.0);
  const PatchMount mount{"forearm_link", Eigen::Isometry3d::Identity(), 37.4};
  long ok = 0;
  double sink = 0;
  const long n = ruffini::testing::CountAllocations([&] {
    for (int rep = 0; rep < 10; ++rep) {
      for (const auto& q : states) {
        ok += ForwardKinematics(m, q, data) == FkStatus::kOk;
        ok += WithinLimits(m, q, 0.01);
        const auto s = PatchToLink(mount, {q[0] * 10 + 75, q[1] * 10 + 70});
        const auto back = LinkToPatch(mount, s.p_LS_m);
        sink += back ? back->point.y_mm : 0.0;
        sink += data.X_BL[8].translation().x();
      }
      ok += ForwardKinematics(m, short_state, data) == FkStatus::kOk;
    }
  });
  EXPECT_EQ(n, 0);
  EXPECT_GT(ok, 9900);  // the path under test did run
  EXPECT_TRUE(std::isfinite(sink));
  int* seen = nullptr;  // the counter counts
  EXPECT_EQ(ruffini::testing::CountAllocations([&] { seen = new int(1); }), 1);
  delete seen;
}

// A Data is fixed-size: making one (e.g. per thread, at configure) does not allocate either.
TEST(RealTime, DataIsFixedSize) {
  const long n = ruffini::testing::CountAllocations([] {
    Data d;
    (void)d;
  });
  EXPECT_EQ(n, 0);
}

}  // namespace
}  // namespace ruffini::robot
