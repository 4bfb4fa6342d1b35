// The safety part of a scene: config/scenes/cobot.yaml's regions, thresholds and deadlines, and every bad
// safety key with its message.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdio>

#include <filesystem>
#include <fstream>
#include <string>
#include <unistd.h>

#include "ruffini/error.h"
#include "ruffini/safety/scene.h"

namespace ruffini::safety {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

constexpr std::int64_t kMsNs = 1'000'000;
const std::string kSpec = RUFFINI_SOURCE_DIR "/config/patches/forearm.yaml";
const std::string kUrdf = RUFFINI_SOURCE_DIR "/config/robots/srs7.urdf";

TEST(CobotScene, SafetySection) {
  const Config c = ConfigFromScene(std::string(RUFFINI_SOURCE_DIR "/config/scenes/cobot.yaml"));
  ASSERT_EQ(c.regions.size(), 2u);
  EXPECT_EQ(c.regions[0].name, "forearm");
  EXPECT_EQ(c.regions[1].name, "upper_arm");
  for (const RegionConfig& r : c.regions) {
    EXPECT_EQ(r.threshold_n, 1.5f) << r.name;  // a force the skin can reach (it was characterised to 2.5 N)
    EXPECT_THAT(r.source, HasSubstr("ISO/TS 15066")) << r.name;
    EXPECT_THAT(r.source, HasSubstr("not checked")) << r.name;
  }
  ASSERT_EQ(c.patches.size(), 4u);
  const char* ids[] = {"forearm_a", "forearm_b", "upper_arm_a", "upper_arm_b"};
  const char* regions[] = {"forearm", "forearm", "upper_arm", "upper_arm"};
  for (std::size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(c.patches[i].id, ids[i]);
    EXPECT_EQ(c.patches[i].region, regions[i]);
    EXPECT_EQ(c.patches[i].silence_deadline_ns, 30 * kMsNs);
  }
  EXPECT_TRUE(c.joint_states_required);  // the scene names a robot
  EXPECT_EQ(c.joint_state_max_age_ns, 50 * kMsNs);
  EXPECT_EQ(c.healthy_before_reset_ns, 200 * kMsNs);
  EXPECT_TRUE(c.new_epoch_per_cause);  // the default: the contract's one epoch per cause
  for (const RegionConfig& r : c.regions) {
    EXPECT_FLOAT_EQ(r.release.fraction, 0.1f) << r.name;
    EXPECT_EQ(r.release.hold_ns, 100 * kMsNs) << r.name;
    EXPECT_THAT(r.release.source, HasSubstr("35 mN")) << r.name;
  }
  EXPECT_FLOAT_EQ(c.input.negative_force_tolerance_n, 0.05f);
  EXPECT_EQ(c.input.max_time_skew_ns, 2000 * kMsNs);
  EXPECT_EQ(c.input.position_tolerance_y_mm, 5.0);
  EXPECT_EQ(c.input.position_tolerance_r_deg, 5.0);
  EXPECT_EQ(c.input.sample_rate_hz, 0.0);  // the cobot scene pins no rate: ruffini demo --rate-hz may vary it
  EXPECT_THAT(c.input.source, HasSubstr("time_skew: "));
  // The coverage it states (docs/coverage.md): issue 16's press factor, and every accepted band says it is not
  // covered and lies on every patch (so scenes generated from this safety section keep it).
  EXPECT_EQ(c.coverage.press_factor, 1.5);
  EXPECT_FALSE(c.coverage.accepted_uncovered.empty());
  for (const auto& b : c.coverage.accepted_uncovered) {
    EXPECT_THAT(b.source, HasSubstr("NOT covered")) << b.name;
    EXPECT_EQ(b.patch, "") << b.name;
  }
  // The policy takes it as it is.
  const Policy policy(c);
  EXPECT_EQ(policy.patch_count(), 4u);
}

TEST(ForearmScene, HasNoSafetySection) {
  const std::string path = RUFFINI_SOURCE_DIR "/config/scenes/forearm.yaml";
  try {
    (void)ConfigFromScene(path);
    FAIL() << "forearm.yaml has no safety section";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), path + ": 'safety' is missing (a mapping with regions and deadlines expected)");
  }
}

class SafetyScene : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::path(::testing::TempDir()) / (std::to_string(::getpid()) + "_ruffini_safety_" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  // Two patches (their `region:` lines are 5 and 8), no robot; `safety` starts on line 9 and its first
  // region on line 11.
  std::string Write(const std::string& region_a, const std::string& region_b, const std::string& regions,
                    const std::string& rest = "", const std::string& patch_b_extra = "") const {
    const std::string path = (dir_ / "s.yaml").string();
    std::ofstream(path) << "name: t\n"                                              // 1
                        << "patches:\n"                                             // 2
                        << "  - name: a\n"                                          // 3
                        << "    spec: " << kSpec << "\n"                            // 4
                        << "    region: " << region_a << "\n"                       // 5
                        << "  - name: b\n"                                          // 6
                        << "    spec: " << kSpec << "\n"                            // 7
                        << "    region: " << region_b << "\n" << patch_b_extra      // 8
                        << "safety:\n"                                              // 9
                        << "  regions:\n"                                           // 10
                        << regions                                                  // 11..
                        << rest;
    return path;
  }
  static std::string Message(const std::string& path) {
    try {
      (void)ConfigFromScene(path);
    } catch (const InputError& e) {
      return e.what();
    }
    return "(no error)";
  }
  static constexpr const char* kArm = "    - {name: arm, threshold_n: 2, source: our choice}\n";
  fs::path dir_;
};

TEST_F(SafetyScene, DefaultsAndOverrides) {
  const Config c = ConfigFromScene(Write("arm", "arm", kArm, "  silence_deadline_ms: 12.5\n  new_epoch_per_cause: false\n",
                                         "    silence_deadline_ms: 40\n"));
  EXPECT_FALSE(c.joint_states_required);  // no robot
  ASSERT_EQ(c.patches.size(), 2u);
  EXPECT_EQ(c.patches[0].silence_deadline_ns, 12'500'000);
  EXPECT_EQ(c.patches[1].silence_deadline_ns, 40 * kMsNs);
  EXPECT_EQ(c.healthy_before_reset_ns, Config{}.healthy_before_reset_ns);
  EXPECT_FALSE(c.new_epoch_per_cause);
  EXPECT_EQ(c.regions[0].threshold_n, 2.0f);
  EXPECT_EQ(c.regions[0].source, "our choice");
}

TEST_F(SafetyScene, UnknownRegion) {
  const std::string p = Write("arm", "hand", kArm);
  EXPECT_EQ(Message(p), p + ":8:5: 'patches[1].region' (hand) names no region in safety.regions (regions: arm)");
}

TEST_F(SafetyScene, NegativeZeroNaNAndHugeThresholds) {
  const std::string what =
      " must be a force above 0 N and at most 1000 N (a contact above it stops the robot)";
  std::string p = Write("arm", "arm", "    - {name: arm, threshold_n: -1, source: x}\n");
  EXPECT_EQ(Message(p), p + ":11:19: 'safety.regions[0].threshold_n' (-1)" + what);
  p = Write("arm", "arm", "    - {name: arm, threshold_n: 0, source: x}\n");
  EXPECT_EQ(Message(p), p + ":11:19: 'safety.regions[0].threshold_n' (0)" + what);
  p = Write("arm", "arm", "    - {name: arm, threshold_n: 1500, source: x}\n");
  EXPECT_EQ(Message(p), p + ":11:19: 'safety.regions[0].threshold_n' (1500)" + what);
  p = Write("arm", "arm", "    - {name: arm, threshold_n: .nan, source: x}\n");
  EXPECT_EQ(Message(p), p + ":11:19: 'safety.regions[0].threshold_n' (.nan) must be a finite number");
}

TEST_F(SafetyScene, MissingSource) {
  const std::string p = Write("arm", "arm", "    - {name: arm, threshold_n: 2}\n");
  EXPECT_EQ(Message(p), p + ":11:7: 'safety.regions[0].source' is missing: say where the threshold comes from "
                            "(ISO/TS 15066 values vary between sources, FACTS.md), or why it was chosen");
}

TEST_F(SafetyScene, DuplicateRegionAndNoRegions) {
  std::string p = Write("arm", "arm", std::string(kArm) + kArm);
  EXPECT_EQ(Message(p), p + ":12:8: 'safety.regions[1].name' (arm) is used by two regions; region names must be unique");
  p = Write("arm", "arm", "    []\n");
  EXPECT_THAT(Message(p), HasSubstr(":10:3: 'safety.regions' must list at least one body region"));
}

TEST_F(SafetyScene, BadDeadlinesAndKeys) {
  std::string p = Write("arm", "arm", kArm, "  silence_deadline_ms: 0\n");
  EXPECT_EQ(Message(p), p + ":12:3: 'safety.silence_deadline_ms' (0) must lie inside 0.001..60000");
  p = Write("arm", "arm", kArm, "", "    silence_deadline_ms: -5\n");
  EXPECT_EQ(Message(p), p + ":9:5: 'patches[1].silence_deadline_ms' (-5) must lie inside 0.001..60000");
  p = Write("arm", "arm", kArm, "  joint_state_max_age_ms: 50\n");
  EXPECT_EQ(Message(p), p + ":12:3: 'safety.joint_state_max_age_ms' (50) needs a robot: the scene has no 'robot' "
                            "section, so no joint states");
  p = Write("arm", "arm", kArm, "  threshold_n: 5\n");
  EXPECT_EQ(Message(p), p + ":12:3: 'safety.threshold_n' is not a known key here");
}

TEST_F(SafetyScene, ContactReleaseAndInputLimits) {
  const Config c = ConfigFromScene(Write(
      "arm", "arm",
      std::string(kArm) + "    - {name: hand, threshold_n: 3, source: y, release: {fraction: 0.2, hold_ms: 30, source: z}}\n",
      "  contact_release: {fraction: 0.05, hold_ms: 250, source: r}\n"
      "  negative_force_tolerance: {force_n: 0.01, source: n}\n"
      "  time_skew: {max_ms: 500, source: t}\n"
      "  position_tolerance: {y_mm: 2, r_deg: 1, source: p}\n"
      "  decoders: {sample_rate_hz: 1000, config_sha256: " + std::string(64, 'a') + ", source: d}\n"));
  EXPECT_FLOAT_EQ(c.regions[0].release.fraction, 0.05f);  // the section's
  EXPECT_EQ(c.regions[0].release.hold_ns, 250 * kMsNs);
  EXPECT_EQ(c.regions[0].release.source, "r");
  EXPECT_FLOAT_EQ(c.regions[1].release.fraction, 0.2f);   // the region's own
  EXPECT_EQ(c.regions[1].release.hold_ns, 30 * kMsNs);
  EXPECT_FLOAT_EQ(c.input.negative_force_tolerance_n, 0.01f);
  EXPECT_EQ(c.input.max_time_skew_ns, 500 * kMsNs);
  EXPECT_EQ(c.input.position_tolerance_y_mm, 2.0);
  EXPECT_EQ(c.input.position_tolerance_r_deg, 1.0);
  EXPECT_EQ(c.input.sample_rate_hz, 1000.0);
  EXPECT_EQ(c.input.decoder_config_sha256, std::string(64, 'a'));
  EXPECT_EQ(c.input.source, "negative_force_tolerance: n; time_skew: t; position_tolerance: p; decoders: d");
  // Defaults when absent.
  const Config d = ConfigFromScene(Write("arm", "arm", kArm));
  EXPECT_FLOAT_EQ(d.regions[0].release.fraction, ContactRelease{}.fraction);
  EXPECT_EQ(d.input.max_time_skew_ns, InputLimits{}.max_time_skew_ns);
}

TEST_F(SafetyScene, StopRule) {
  const Config c = ConfigFromScene(Write("arm", "arm", kArm, "  stop_rule: {sd_k: -1.5, max_sd_n: 0.3, source: measured}\n"));
  EXPECT_FLOAT_EQ(c.stop_rule.sd_k, -1.5f);
  EXPECT_FLOAT_EQ(c.stop_rule.max_sd_n, 0.3f);
  EXPECT_EQ(c.stop_rule.source, "measured");
  EXPECT_EQ(ConfigFromScene(Write("arm", "arm", kArm)).stop_rule.sd_k, 0.0f);  // absent: the force alone
  std::string p = Write("arm", "arm", kArm, "  stop_rule: {sd_k: 1}\n");
  EXPECT_NE(Message(p).find("'safety.stop_rule.source' is missing"), std::string::npos) << Message(p);
  p = Write("arm", "arm", kArm, "  stop_rule: {sd_k: 4, source: x}\n");
  EXPECT_NE(Message(p).find("'safety.stop_rule.sd_k' (4) must lie inside -3..3"), std::string::npos) << Message(p);
}

TEST_F(SafetyScene, SeamSumIsOffUnlessTheSceneSaysWhy) {
  EXPECT_FALSE(ConfigFromScene(Write("arm", "arm", kArm)).seam_sum.enabled);
  const Config c = ConfigFromScene(Write("arm", "arm", kArm, "  seam_sum: {enabled: true, source: measured}\n"));
  EXPECT_TRUE(c.seam_sum.enabled);
  EXPECT_EQ(c.seam_sum.source, "measured");
  const std::string p = Write("arm", "arm", kArm, "  seam_sum: {enabled: true}\n");
  EXPECT_NE(Message(p).find("'safety.seam_sum.source' is missing"), std::string::npos) << Message(p);
}

// Review 4: safety.seam_sum is parsed strictly: an unknown key and a bad value are errors, the default is off.
TEST_F(SafetyScene, Review4SeamSumIsParsedStrictly) {
  std::string p = Write("arm", "arm", kArm, "  seam_sum: {enabled: true, source: measured, window_ms: 5}\n");
  EXPECT_NE(Message(p).find("window_ms"), std::string::npos) << Message(p);
  p = Write("arm", "arm", kArm, "  seam_sum: {enabled: 2, source: measured}\n");
  EXPECT_NE(Message(p).find("must be true or false"), std::string::npos) << Message(p);
  p = Write("arm", "arm", kArm, "  seam_sum: true\n");
  EXPECT_NE(Message(p), "(no error)");
  // yaml-cpp's booleans: "yes"/"on" read as true (as every other BoolOr in the scene). Printed, not judged.
  p = Write("arm", "arm", kArm, "  seam_sum: {enabled: on, source: measured}\n");
  const std::string m = Message(p);
  std::printf("seam_sum enabled: on -> %s\n", m == "(no error)" ? (ConfigFromScene(p).seam_sum.enabled ? "true" : "false") : m.c_str());
  EXPECT_FALSE(ConfigFromScene(Write("arm", "arm", kArm, "  seam_sum: {source: only why}\n")).seam_sum.enabled);
}

TEST_F(SafetyScene, ContactReleaseAndInputLimitsAreValidated) {
  std::string p = Write("arm", "arm", kArm, "  contact_release: {fraction: 0.1, hold_ms: 100}\n");
  EXPECT_EQ(Message(p), p + ":12:20: 'safety.contact_release.source' is missing: say why this release level and "
                            "hold time (a number carries where it comes from)");
  p = Write("arm", "arm", kArm, "  contact_release: {fraction: 1, source: x}\n");
  EXPECT_EQ(Message(p), p + ":12:21: 'safety.contact_release.fraction' (1) must lie inside 0..0.9");
  p = Write("arm", "arm", kArm, "  time_skew: {max_ms: 0, source: x}\n");
  EXPECT_THAT(Message(p), HasSubstr("'safety.time_skew.max_ms' (0) must lie inside"));
  p = Write("arm", "arm", kArm, "  negative_force_tolerance: {force_n: 0.05}\n");
  EXPECT_THAT(Message(p), HasSubstr("'safety.negative_force_tolerance.source' is missing"));
  p = Write("arm", "arm", kArm, "  decoders: {config_sha256: ABC, source: x}\n");
  EXPECT_THAT(Message(p), HasSubstr("'safety.decoders.config_sha256' (ABC) must be a SHA-256 in lower-case hex"));
  p = Write("arm", "arm", "    - {name: arm, threshold_n: 2, source: x, release: {hold_ms: 5, source: x, extra: 1}}\n");
  EXPECT_THAT(Message(p), HasSubstr("'safety.regions[0].release.extra' is not a known key here"));
}

TEST_F(SafetyScene, CoverageAndItsAcceptedBands) {
  Config c = ConfigFromScene(Write("arm", "arm", kArm));
  EXPECT_EQ(c.coverage.press_factor, 1.5);  // issue 16's target, also without the section
  EXPECT_TRUE(c.coverage.accepted_uncovered.empty());
  c = ConfigFromScene(Write("arm", "arm", kArm,
                            "  coverage:\n    press_factor: 2\n    source: why\n    accepted_uncovered:\n"
                            "      - {name: end, patch: b, y_mm: [140, 150], r_deg: [0, 145], source: no fibre there}\n"));
  EXPECT_EQ(c.coverage.press_factor, 2.0);
  EXPECT_EQ(c.coverage.source, "why");
  ASSERT_EQ(c.coverage.accepted_uncovered.size(), 1u);
  const auto& b = c.coverage.accepted_uncovered[0];
  EXPECT_EQ(b.name, "end");
  EXPECT_EQ(b.patch, "b");
  EXPECT_EQ(b.y_min_mm, 140.0);
  EXPECT_EQ(b.y_max_mm, 150.0);
  EXPECT_EQ(b.r_min_deg, 0.0);
  EXPECT_EQ(b.r_max_deg, 145.0);
  EXPECT_EQ(b.source, "no fibre there");
  // Without `patch:` a band lies on every patch.
  c = ConfigFromScene(Write("arm", "arm", kArm,
                            "  coverage:\n    source: why\n    accepted_uncovered:\n"
                            "      - {name: ends, y_mm: [0, 5], r_deg: [0, 145], source: every patch's elbow end}\n"));
  ASSERT_EQ(c.coverage.accepted_uncovered.size(), 1u);
  EXPECT_EQ(c.coverage.accepted_uncovered[0].patch, "");
}

TEST_F(SafetyScene, CoverageIsValidated) {
  const auto band = [&](const std::string& text) {
    return Write("arm", "arm", kArm, "  coverage:\n    source: why\n    accepted_uncovered:\n      - " + text + "\n");
  };
  std::string p = Write("arm", "arm", kArm, "  coverage: {press_factor: 1.5}\n");
  EXPECT_THAT(Message(p), HasSubstr("'safety.coverage.source' is missing"));
  p = Write("arm", "arm", kArm, "  coverage: {press_factor: 0.5, source: x}\n");
  EXPECT_THAT(Message(p), HasSubstr("'safety.coverage.press_factor' (0.5) must lie inside"));
  p = band("{name: e, patch: c, y_mm: [0, 1], r_deg: [0, 1], source: x}");
  EXPECT_THAT(Message(p), HasSubstr("'safety.coverage.accepted_uncovered[0].patch' (c) names no patch of the scene"));
  p = band("{name: e, patch: a, y_mm: [5, 1], r_deg: [0, 1], source: x}");
  EXPECT_THAT(Message(p), HasSubstr("'safety.coverage.accepted_uncovered[0].y_mm'"));
  EXPECT_THAT(Message(p), HasSubstr("must be [min, max] with min <= max"));
  p = band("{name: e, patch: a, y_mm: [0, 1], r_deg: [0, 1]}");
  EXPECT_THAT(Message(p), HasSubstr("'safety.coverage.accepted_uncovered[0].source' is missing: say why this band"));
  // At most 256 bands (review 12: the scene check's cost grows with the cube of the bands crossing one cell).
  std::string many;
  for (int i = 0; i < 257; ++i) {
    many += "      - {name: b" + std::to_string(i) + ", y_mm: [0, 1], r_deg: [0, 1], source: x}\n";
  }
  p = Write("arm", "arm", kArm, "  coverage:\n    source: why\n    accepted_uncovered:\n" + many);
  EXPECT_THAT(Message(p), HasSubstr("names 257 bands; at most 256"));
  p = Write("arm", "arm", kArm, "  coverage:\n    source: why\n    accepted_uncovered:\n"
                                "      - {name: e, patch: a, y_mm: [0, 1], r_deg: [0, 1], source: x}\n"
                                "      - {name: e, patch: b, y_mm: [0, 1], r_deg: [0, 1], source: x}\n");
  EXPECT_THAT(Message(p), HasSubstr("is used by two bands"));
}

TEST_F(SafetyScene, RegionAndSafetyGoTogether) {
  // The root reader's presence rules: every patch of a scene with safety has a region, and none without.
  const std::string path = (dir_ / "s.yaml").string();
  std::ofstream(path) << "name: t\npatches:\n  - name: a\n    spec: " << kSpec << "\n    region: arm\n";
  EXPECT_EQ(Message(path), path + ":5:5: 'patches[0].region' (arm) needs a safety section: the scene has no "
                                  "'safety' section");
  std::ofstream(path) << "name: t\npatches:\n  - name: a\n    spec: " << kSpec << "\nsafety:\n  regions:\n" << kArm;
  EXPECT_EQ(Message(path), path + ":3:5: 'patches[0].region' is missing: the scene has a safety section, so every "
                                  "patch needs a body region");
}

TEST_F(SafetyScene, WithARobotJointStatesAreRequired) {
  const std::string path = (dir_ / "s.yaml").string();
  std::ofstream(path) << "name: t\nrobot: {urdf: " << kUrdf << "}\npatches:\n  - name: a\n    spec: " << kSpec
                      << "\n    region: arm\n    mount: {link: forearm_link, xyz_m: [0, 0, 0], rpy_rad: [0, 0, 0]}\n"
                      << "safety:\n  regions:\n" << kArm << "  joint_state_max_age_ms: 20\n";
  const Config c = ConfigFromScene(path);
  EXPECT_TRUE(c.joint_states_required);
  EXPECT_EQ(c.joint_state_max_age_ns, 20 * kMsNs);
}

}  // namespace
}  // namespace ruffini::safety
