// Never a hard press read as light (issue 16): hard presses through the twin, the Hyperion bytes, the ingest
// codec, link::Monitor and the shipped model's pipeline (tests/decode/hard_press.h) come out as over-range
// contacts whose force is at least the stated bound, so the aggregator's threshold rule stops on them.
#include <gtest/gtest.h>

#include "hard_press.h"

namespace ruffini::testing {
namespace {

}  // namespace
struct Shipped {
  twin::Scene scene = twin::LoadScene(RUFFINI_SOURCE_DIR "/config/scenes/cobot.yaml");
  v1::DecoderModel model = decode::LoadModel(scene.patches[0].model_path);
};
const Shipped& Get() {
  static const Shipped s;
  return s;
}
namespace {

struct Case {
  const char* where;
  double y_mm, r_deg;
};

// The centre of the patch's width on FBG 7 (the grating nearest the patch's centre), and edge points where
// the fibre runs: 2 mm inside the elbow edge where it enters (Y 2, R 18), and beside the U-turns 9 mm
// from the R edges.
const Case kCases[] = {
    {"centre, on FBG 7", 66.0, 72.5},
    {"elbow edge, where the fibre enters", 2.0, 18.0},
    {"R = 0 edge side, at a U-turn", 46.5, 14.0},
    {"R = 145 edge side, at a U-turn", 66.0, 131.0},
};

TEST(HardPress, FiftyAndTwoHundredNewtonsAreOverRangeContactsOfAtLeastTheBound) {
  const Shipped& s = Get();
  HardPressRig rig(s.scene, 0, s.model);
  for (const Case& c : kCases) {
    for (double f : {50.0, 200.0}) {
      SCOPED_TRACE(std::string(c.where) + " at " + std::to_string(f) + " N");
      const ProbeAt p{c.y_mm, c.r_deg, f};
      const PressOutcome o = rig.Press(std::span<const ProbeAt>(&p, 1), 1.5);
      EXPECT_TRUE(o.over_range);
      EXPECT_GE(o.max_force_n, 2.5f);
      EXPECT_TRUE(o.stops());
      EXPECT_FALSE(o.fault);  // reported as what it is, a contact, not as a broken stream
    }
  }
}

// The patch's very centre lies between two rows of gratings, 9 mm from each: at 50 and 200 N every
// grating stays inside the range the model was calibrated on (+ its 104 pm margin), so nothing says "over
// range"; the decoded force is above the threshold all the same (it reads like 2.5 N on FBG 7). Where
// physics gives no evidence of overload, only a decoder trained beyond 2.5 N can tell (a later session).
TEST(HardPress, BetweenTwoRowsAHardPressStopsOnItsDecodedForce) {
  const Shipped& s = Get();
  HardPressRig rig(s.scene, 0, s.model);
  for (double f : {50.0, 200.0}) {
    const ProbeAt p{75.0, 72.5, f};
    const PressOutcome o = rig.Press(std::span<const ProbeAt>(&p, 1), 1.5);
    EXPECT_TRUE(o.stop_force) << f << " N: " << o.max_force_n;
  }
}

// A light press is still decoded as one: no over range at 1 N in the centre.
TEST(HardPress, AOneNewtonPressIsNotOverRange) {
  const Shipped& s = Get();
  HardPressRig rig(s.scene, 0, s.model);
  const ProbeAt p{75.0, 72.5, 1.0};
  const PressOutcome o = rig.Press(std::span<const ProbeAt>(&p, 1), 1.5);
  EXPECT_FALSE(o.over_range);
  EXPECT_GT(o.max_force_n, 0.5f);
  EXPECT_LT(o.max_force_n, 1.5f);
}

}  // namespace
}  // namespace ruffini::testing
