#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <regex>
#include <sstream>

#include "ruffini/error.h"
#include "ruffini/patch/geometry.h"
#include "ruffini/patch/spec_loader.h"

namespace ruffini::patch {
namespace {

const std::string kForearm = std::string(RUFFINI_SOURCE_DIR) + "/config/patches/forearm.yaml";

std::string ReadText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Replaces the first occurrence of `from` in the forearm file and expects the load to fail with `message`.
std::string LoadError(const std::string& from, const std::string& to) {
  std::string text = ReadText(kForearm);
  const auto at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  text.replace(at, from.size(), to);
  try {
    (void)ParsePatchSpec(text, "forearm.yaml");
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

TEST(SpecTest, LoadsThePapersPatch) {
  const PatchSpec s = LoadPatchSpec(kForearm);
  EXPECT_EQ(s.name, "forearm");
  EXPECT_DOUBLE_EQ(s.extent_y_mm, 150.0);
  EXPECT_DOUBLE_EQ(s.extent_r_deg, 145.0);
  EXPECT_DOUBLE_EQ(s.layer.thickness_mm, 8.0);
  for (std::size_t i = 0; i < kGratings; ++i) {
    EXPECT_NEAR(s.gratings[i].wavelength_nm, 1530.0 + 2.3 * static_cast<double>(i), 1e-9);
    EXPECT_DOUBLE_EQ(s.gratings[i].length_mm, 8.0);
    EXPECT_TRUE(s.indented_area.Contains(s.gratings[i].centre)) << "FBG " << i + 1;
  }
}

// The paper: neighbour spacing 12.9-24.5 mm, denser toward the wrist.
TEST(SpecTest, LayoutSpacingAndDensity) {
  const PatchSpec s = LoadPatchSpec(kForearm);
  const Geometry g(s);
  double elbow_sum = 0, wrist_sum = 0;
  int elbow_n = 0, wrist_n = 0;
  double lo = 1e9, hi = 0;
  for (std::size_t i = 0; i < kGratings; ++i) {
    double nn = 1e9;
    for (std::size_t j = 0; j < kGratings; ++j) {
      if (i != j) nn = std::min(nn, g.SurfaceDistanceMm(s.gratings[i].centre, s.gratings[j].centre));
    }
    lo = std::min(lo, nn);
    hi = std::max(hi, nn);
    if (s.gratings[i].centre.y_mm < 75.0) {
      elbow_sum += nn;
      ++elbow_n;
    } else {
      wrist_sum += nn;
      ++wrist_n;
    }
  }
  EXPECT_GE(lo, 12.9 - 0.1);
  EXPECT_LE(hi, 24.5 + 0.1);
  EXPECT_LT(wrist_sum / wrist_n, elbow_sum / elbow_n);
}

TEST(SpecTest, RoundTripSaveThenLoad) {
  const PatchSpec a = LoadPatchSpec(kForearm);
  const PatchSpec b = ParsePatchSpec(DumpPatchSpec(a), "dump.yaml");
  EXPECT_EQ(DumpPatchSpec(a), DumpPatchSpec(b));
  EXPECT_EQ(a.Fingerprint(), b.Fingerprint());
  PatchSpec c = a;
  c.gratings[3].centre.y_mm += 0.5;
  EXPECT_NE(a.Fingerprint(), c.Fingerprint());
  EXPECT_NO_THROW(ValidatePatchSpec(a));
}

TEST(SpecTest, RejectsWrongGratingCount) {
  std::string text = ReadText(kForearm);
  const auto last = text.rfind("  - {y_mm");
  text.erase(last);
  try {
    (void)ParsePatchSpec(text, "forearm.yaml");
    FAIL() << "expected an error";
  } catch (const InputError& e) {
    EXPECT_TRUE(std::regex_search(e.what(), std::regex(R"(^forearm\.yaml:\d+:1: 'gratings' has 15 entries; a patch carries exactly 16 gratings$)")))
        << e.what();
  }
}

TEST(SpecTest, RejectsWavelengthOutsideWindow) {
  const std::string e = LoadError("wavelength_nm: 1530.0}", "wavelength_nm: 1509.5}");
  EXPECT_TRUE(std::regex_search(e, std::regex(R"(^forearm\.yaml:\d+:\d+: 'gratings\[0\]\.wavelength_nm' \(1509\.5\) with its band of \+-1\.1 nm must lie inside the interrogator window 1510\.\.1590 nm$)")))
      << e;
}

TEST(SpecTest, RejectsOverlappingBands) {
  const std::string e = LoadError("wavelength_nm: 1532.3}", "wavelength_nm: 1531.9}");
  EXPECT_NE(e.find("'gratings[1].wavelength_nm' (1531.9) must be at least 2.2 nm above gratings[0] (1530 nm)"), std::string::npos) << e;
}

TEST(SpecTest, RejectsGratingOutsidePatch) {
  const std::string e = LoadError("{y_mm: 24, r_deg: 42.5,", "{y_mm: 24, r_deg: 150,");
  EXPECT_NE(e.find("'gratings[0].y_mm' (24) with r_deg 150 puts the grating outside the patch (Y 0..150 mm, R 0..145 deg)"),
            std::string::npos)
      << e;
}

TEST(SpecTest, RejectsGratingOffTheFibre) {
  const std::string e = LoadError("{y_mm: 24, r_deg: 42.5,", "{y_mm: 30, r_deg: 42.5,");
  EXPECT_NE(e.find("lies 6 mm from the fibre path"), std::string::npos) << e;
}

TEST(SpecTest, RejectsUnknownKeyWithPosition) {
  const std::string e = LoadError("surface_radius_mm: 37.4", "surface_radius_mm: 37.4\nsurface_colour: blue");
  EXPECT_TRUE(std::regex_search(e, std::regex(R"(^forearm\.yaml:\d+:1: 'surface_colour' is not a known key here$)"))) << e;
}

TEST(SpecTest, RejectsOutOfRangeAndMissing) {
  EXPECT_NE(LoadError("thickness_mm: 8", "thickness_mm: 0.2").find("'layer.thickness_mm' (0.2) must lie inside 1..50"),
            std::string::npos);
  EXPECT_NE(LoadError("poisson_ratio: 0.49", "poisson_ratio: abc").find("'layer.material.poisson_ratio' (abc) must be a finite number"),
            std::string::npos);
  EXPECT_NE(LoadError("surface_radius_mm: 37.4", "").find("'surface_radius_mm' is missing"), std::string::npos);
  EXPECT_NE(LoadError("name: forearm", "name: [forearm").find("YAML syntax error"), std::string::npos);
}

TEST(SpecTest, MissingFileIsAClearError) {
  try {
    (void)LoadPatchSpec("/nonexistent/patch.yaml");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "/nonexistent/patch.yaml: cannot open patch spec");
  }
}

}  // namespace
}  // namespace ruffini::patch

namespace ruffini::patch {
namespace {

TEST(SpecTest, RejectsDuplicateAndComplexKeys) {
  EXPECT_NE(LoadError("surface_radius_mm: 37.4", "surface_radius_mm: 37.4\nsurface_radius_mm: 40").find("'surface_radius_mm' appears twice"),
            std::string::npos);
  EXPECT_NE(LoadError("surface_radius_mm: 37.4", "surface_radius_mm: 37.4\n? [a, b]\n: 1").find("is not a plain name"),
            std::string::npos);
}

TEST(SpecTest, GratingsShareOneLength) {
  const std::string e = LoadError("length_mm: 8, wavelength_nm: 1532.3}", "length_mm: 10, wavelength_nm: 1532.3}");
  EXPECT_NE(e.find("'gratings[1].length_mm' (10) must equal gratings[0].length_mm (8 mm)"), std::string::npos) << e;
}

}  // namespace
}  // namespace ruffini::patch
