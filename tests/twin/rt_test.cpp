// The per-frame path allocates nothing: a counting global operator new, armed around the calls.
#include <gtest/gtest.h>

#include "../common/alloc_counter.h"
#include "ruffini/twin/scene.h"
#include "ruffini/twin/twin.h"

namespace ruffini::twin {
namespace {

TEST(RealTime, StrainShiftsAndInterrogatorReadDoNotAllocate) {
  const Scene scene = LoadScene(std::string(RUFFINI_SOURCE_DIR) + "/config/scenes/forearm.yaml");
  TwinEffects e = scene.effects;
  e.temperature = TemperatureEffect{5.0, 2.0, 60.0, 0.01, 10.0, 0.03};
  e.faults.push_back(FaultEffect{3, FaultEffect::Kind::kDimmed, 0.2, 4.0});
  const SkinTwin twin(scene.patches[0].spec, e, {5.5});
  InterrogatorSim sim(twin, 1);
  Contact contacts[2] = {{{40, 50}, 0.8, Probe{}}, {{90, 80}, 12.0, Probe{}}};
  Shifts s;
  std::array<double, 16> wl{};
  std::uint32_t flags = 0;
  EXPECT_EQ(testing::CountAllocations([&] {
              for (int k = 0; k < 10000; ++k) {
                contacts[0].at.y_mm = 20.0 + (k % 100);
                twin.StrainShiftsPm(contacts, s, flags);
                sim.Read(k * 0.01, s, wl, flags);
              }
            }),
            0);
  // The counter does count: an allocation while armed is seen.
  int* seen = nullptr;
  EXPECT_EQ(testing::CountAllocations([&] { seen = new int(3); }), 1);
  delete seen;
}

}  // namespace
}  // namespace ruffini::twin
