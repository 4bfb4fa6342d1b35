// Sensitivity maps (docs/coverage.md): they round-trip through the model file, malformed ones are refused,
// and a region's guarantee follows its maps and the scene's accepted bands.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>

#include "ruffini/decode/model_io.h"
#include "ruffini/decode/sensitivity.h"
#include "ruffini/error.h"
#include "ruffini/patch/spec_loader.h"
#include "synthetic_model.h"

namespace ruffini::decode {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

const patch::PatchSpec& Spec() {
  static const patch::PatchSpec s = patch::LoadPatchSpec(RUFFINI_SOURCE_DIR "/config/patches/forearm.yaml");
  return s;
}

// A 3 x 2 map of level `level`: every point reliable at `base` N, except (Y 75, R 100) at `weak` N.
v1::SensitivityMap Map(float level, float base, float weak) {
  v1::SensitivityMap m;
  m.set_level_n(level);
  m.set_reliability(0.95f);
  for (double y : {2.0, 75.0, 148.0}) m.add_y_mm(y);
  for (double r : {3.0, 100.0}) m.add_r_deg(r);
  for (int iy = 0; iy < 3; ++iy) {
    for (int ir = 0; ir < 2; ++ir) {
      const bool is_weak = iy == 1 && ir == 1;
      m.add_min_force_n(is_weak ? weak : base);
      m.add_location_error_mm(std::isinf(is_weak ? weak : base) ? kNaN : 2.5f + static_cast<float>(iy));
    }
  }
  for (float f : {1.0f, 2.0f, 5.0f, 200.0f}) m.add_forces_n(f);
  m.set_presses(20);
  m.set_probe_radius_mm(5.5);
  m.set_source("test");
  return m;
}

std::string Error(const v1::SensitivityMap& m) {
  try {
    ValidateSensitivity(m, "m");
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

TEST(Sensitivity, TheMapRoundTripsThroughTheModelFileInfinityAndNaNIncluded) {
  const std::string path = (std::filesystem::temp_directory_path() / "ruffini_sensitivity_roundtrip.rmodel").string();
  auto model = testing::SyntheticModel(Spec());
  *model.add_sensitivity() = Map(1.0f, 1.2f, kInf);
  *model.add_sensitivity() = Map(1.5f, 2.0f, 5.0f);
  SaveModel(path, model);
  const v1::DecoderModel back = LoadModel(path);
  std::filesystem::remove(path);
  ASSERT_EQ(back.sensitivity_size(), 2);
  EXPECT_EQ(back.SerializeAsString(), model.SerializeAsString());
  EXPECT_TRUE(std::isinf(back.sensitivity(0).min_force_n(3)));
  EXPECT_TRUE(std::isnan(back.sensitivity(0).location_error_mm(3)));
  EXPECT_FLOAT_EQ(back.sensitivity(1).min_force_n(3), 5.0f);
  EXPECT_FLOAT_EQ(back.sensitivity(1).location_error_mm(0), 2.5f);
}

TEST(Sensitivity, MalformedMapsAreRefusedByName) {
  auto m = Map(1.5f, 2.0f, 5.0f);
  m.mutable_min_force_n()->RemoveLast();
  EXPECT_NE(Error(m).find("5 forces and 6 location errors for 6 grid points"), std::string::npos) << Error(m);
  m = Map(1.5f, 2.0f, 5.0f);
  m.set_min_force_n(2, kNaN);
  EXPECT_NE(Error(m).find("point 2 has min_force_n"), std::string::npos) << Error(m);
  m = Map(1.5f, 2.0f, 5.0f);
  m.set_y_mm(1, 1.0);
  EXPECT_NE(Error(m).find("ascending in Y and R"), std::string::npos) << Error(m);
  m = Map(0.0f, 2.0f, 5.0f);
  EXPECT_NE(Error(m).find("level_n"), std::string::npos) << Error(m);
  // In a model: levels ascending, one map per level.
  auto model = testing::SyntheticModel(Spec());
  *model.add_sensitivity() = Map(1.5f, 2.0f, 5.0f);
  *model.add_sensitivity() = Map(1.5f, 2.0f, 5.0f);
  EXPECT_THROW(ValidateModel(model, "x"), InputError);
}

TEST(Sensitivity, TheMapForAThresholdIsTheSmallestLevelAtOrAboveIt) {
  google::protobuf::RepeatedPtrField<v1::SensitivityMap> maps;
  *maps.Add() = Map(1.0f, 1.2f, 2.0f);
  *maps.Add() = Map(2.0f, 2.4f, 3.0f);
  EXPECT_FLOAT_EQ(MapForThreshold(maps, 0.5)->level_n(), 1.0f);
  EXPECT_FLOAT_EQ(MapForThreshold(maps, 1.0)->level_n(), 1.0f);
  EXPECT_FLOAT_EQ(MapForThreshold(maps, 1.5)->level_n(), 2.0f);
  EXPECT_EQ(MapForThreshold(maps, 2.5), nullptr);  // a map below the threshold would not be conservative
}

TEST(Sensitivity, ARegionBelowItsGuaranteeIsRefusedAnAcceptedBandMakesItHold) {
  google::protobuf::RepeatedPtrField<v1::SensitivityMap> a, b;
  *a.Add() = Map(1.5f, 2.0f, 5.0f);   // one weak point: 5 N > 1.5 x 1.5 N
  *b.Add() = Map(1.5f, 2.0f, 2.0f);
  const std::vector<CoveragePatch> patches = {{"a", &a}, {"b", &b}};
  RegionGuarantee g = GuaranteeRegion(patches, {}, 1.5, 1.5);
  EXPECT_FALSE(g.ok());
  EXPECT_DOUBLE_EQ(g.stop_force_n, 5.0);
  EXPECT_NEAR(g.guaranteed_threshold_n, 5.0 / 1.5, 1e-9);
  EXPECT_EQ(g.points, 12u);
  EXPECT_EQ(g.covered_points, 12u);
  ASSERT_EQ(g.uncovered.size(), 1u);
  EXPECT_EQ(g.uncovered[0].patch, "a");
  EXPECT_DOUBLE_EQ(g.uncovered[0].y_mm, 75.0);
  // A larger press factor: 3 x 1.5 N is still below 5 N; 5 / 1.5 x 1.5 N reaches it.
  EXPECT_FALSE(GuaranteeRegion(patches, {}, 1.5, 3.0).ok());
  EXPECT_TRUE(GuaranteeRegion(patches, {}, 1.5, 5.0 / 1.5).ok());
  // The band accepting the weak point: the region holds over the rest, and the band counts it.
  const std::vector<UncoveredBand> bands = {{"middle", "a", 70, 80, 90, 110, "test"}, {"elsewhere", "b", 0, 10, 0, 145, "t"}};
  g = GuaranteeRegion(patches, bands, 1.5, 1.5);
  EXPECT_TRUE(g.ok());
  EXPECT_DOUBLE_EQ(g.stop_force_n, 2.0);
  EXPECT_EQ(g.covered_points, 9u);  // the middle band holds 1 point, the other 2
  ASSERT_EQ(g.bands.size(), 2u);
  EXPECT_EQ(g.bands[0].points, 1u);
  EXPECT_EQ(g.bands[0].uncovered_points, 1u);
  EXPECT_EQ(g.bands[1].points, 2u);
  EXPECT_EQ(g.bands[1].uncovered_points, 0u);
  // A band on the wrong patch does not help.
  EXPECT_FALSE(GuaranteeRegion(patches, {{"middle", "b", 70, 80, 90, 110, "t"}}, 1.5, 1.5).ok());
  // A stop rule that may lower a force by 0.5 N needs maps at 2.0 N: these 1.5 N maps guarantee nothing.
  g = GuaranteeRegion(patches, bands, 1.5, 1.5, 0.5);
  EXPECT_FALSE(g.ok());
  EXPECT_EQ(g.unmapped.size(), 2u);
}

// Review 10, finding 4: a map measured 20 mm inside every edge guaranteed the whole patch, and 200 N presses at its
// edges went unstopped. A strip between an edge and the map's outermost grid line wider than 2.5 mm is covered
// surface never measured: the region is refused, naming it, unless accepted bands hold the whole strip.
TEST(Sensitivity, AMapThatStopsShortOfAnEdgeGuaranteesNothingThere) {
  google::protobuf::RepeatedPtrField<v1::SensitivityMap> full, trunc;
  *full.Add() = Map(1.5f, 2.0f, 2.0f);  // Y 2..148 of 150 mm
  v1::SensitivityMap t = Map(1.5f, 2.0f, 2.0f);
  t.set_y_mm(0, 20.0);                  // Y 20..148: the first 20 mm never measured
  *trunc.Add() = t;
  const double mm_per_deg = 37.4 * 3.14159265358979 / 180.0;
  // R 3..100 deg of 145: the R strips are judged only with the radius.
  CoveragePatch a{"a", &full}, b{"b", &trunc};
  EXPECT_TRUE(GuaranteeRegion({a}, {}, 1.5, 1.5).ok());
  RegionGuarantee g = GuaranteeRegion({b}, {}, 1.5, 1.5);
  EXPECT_FALSE(g.ok());
  ASSERT_EQ(g.unmeasured.size(), 1u);
  EXPECT_NE(g.unmeasured[0].find("20.0 mm from the Y 0 edge"), std::string::npos) << g.unmeasured[0];
  EXPECT_TRUE(std::isinf(g.stop_force_n));
  // A band holding Y 0..20 on every R accepts the strip; one that leaves a sliver (Y 0..19) does not.
  EXPECT_TRUE(GuaranteeRegion({b}, {{"wrist", "b", 0, 20, 0, 145, "t"}}, 1.5, 1.5).ok());
  EXPECT_FALSE(GuaranteeRegion({b}, {{"wrist", "b", 0, 19, 0, 145, "t"}}, 1.5, 1.5).ok());
  EXPECT_FALSE(GuaranteeRegion({b}, {{"wrist", "b", 0, 20, 0, 140, "t"}}, 1.5, 1.5).ok());
  // With the radius, R 3 deg (2 mm) is within reach and R 100 of 145 deg (29 mm) is not.
  a.mm_per_deg = mm_per_deg;
  g = GuaranteeRegion({a}, {}, 1.5, 1.5);
  ASSERT_EQ(g.unmeasured.size(), 1u);
  EXPECT_NE(g.unmeasured[0].find("R end edge"), std::string::npos) << g.unmeasured[0];
  EXPECT_TRUE(GuaranteeRegion({a}, {{"side", "a", 0, 150, 100, 145, "t"}}, 1.5, 1.5).ok());
}

TEST(Sensitivity, ABandWithoutAPatchLiesOnEveryPatch) {
  google::protobuf::RepeatedPtrField<v1::SensitivityMap> a, b;
  *a.Add() = Map(1.5f, 2.0f, 5.0f);
  *b.Add() = Map(1.5f, 2.0f, 6.0f);
  const std::vector<CoveragePatch> patches = {{"a", &a}, {"b", &b}};
  const RegionGuarantee g = GuaranteeRegion(patches, {{"middle", "", 70, 80, 90, 110, "every patch"}}, 1.5, 1.5);
  EXPECT_TRUE(g.ok());
  ASSERT_EQ(g.bands.size(), 1u);
  EXPECT_EQ(g.bands[0].points, 2u);  // one on each patch
  EXPECT_EQ(g.bands[0].uncovered_points, 2u);
  EXPECT_EQ(g.covered_points, 10u);
}

TEST(Sensitivity, APointNeverReportedMakesTheGuaranteeInfinite) {
  google::protobuf::RepeatedPtrField<v1::SensitivityMap> a;
  *a.Add() = Map(1.5f, 2.0f, kInf);
  const RegionGuarantee g = GuaranteeRegion({{"a", &a}}, {}, 1.5, 1.5);
  EXPECT_FALSE(g.ok());
  EXPECT_TRUE(std::isinf(g.guaranteed_threshold_n));
  EXPECT_FALSE(GuaranteeRegion({{"a", &a}}, {}, 1000.0, 1.5).ok());  // no map at or above 1000 N
}

TEST(Sensitivity, APatchWithoutAMapIsUnmappedUnlessAcceptedWhole) {
  google::protobuf::RepeatedPtrField<v1::SensitivityMap> none;
  RegionGuarantee g = GuaranteeRegion({{"a", nullptr}, {"b", &none}}, {}, 1.5, 1.5);
  EXPECT_FALSE(g.ok());
  EXPECT_EQ(g.unmapped, (std::vector<std::string>{"a", "b"}));
  g = GuaranteeRegion({{"a", nullptr}}, {{"part", "a", 0, 100, 0, 145, "t"}}, 1.5, 1.5);
  EXPECT_FALSE(g.ok());  // part of it is not a whole patch
  g = GuaranteeRegion({{"a", nullptr}}, {{"all", "a", 0, 150, 0, 145, "t"}}, 1.5, 1.5);
  EXPECT_TRUE(g.ok());
  EXPECT_EQ(g.covered_points, 0u);
}

}  // namespace
}  // namespace ruffini::decode
