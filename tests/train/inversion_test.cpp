// The inversion decoder on twin data: it locates single contacts, reports its uncertainty, and says so
// (low confidence) when the shifts fit no single contact.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>

#include "ruffini/decode/inversion.h"
#include "ruffini/eval/evaluation.h"
#include "ruffini/stats.h"
#include "ruffini/twin/protocols.h"
#include "ruffini/twin/scene.h"

namespace ruffini::eval {
namespace {

struct Fixture {
  twin::Scene scene = twin::LoadScene(RUFFINI_SOURCE_DIR "/config/scenes/forearm.yaml");
  twin::SkinTwin twin{scene.Patch().spec, scene.effects, {scene.probe.radius_mm}};
  Prepared prepared;
  std::unique_ptr<decode::InversionDecoder> inv;
  Fixture() {
    dataset::Dataset d;
    d.info = twin::TwinDatasetInfo(twin, scene, "paper", 5, 100.0);
    twin::PaperProtocol p;
    p.indentations = 1200;  // the response map is learned from the sites: it needs their density
    twin::RunPaper(twin, scene, p, 5, [&](std::span<const dataset::Frame> f) {
      for (const auto& x : f) d.Append(x);
    });
    prepared = PrepareFrames(d);
    inv = std::make_unique<decode::InversionDecoder>(FitResponse(prepared, scene.Patch().spec, {}));
  }
  // Noise-free shifts of contacts as the decoder sees them (baseline = reference).
  decode::ShiftsPm Shifts(std::initializer_list<twin::Contact> cs) const {
    twin::Shifts s;
    std::uint32_t flags = 0;
    const std::vector<twin::Contact> v(cs);
    twin.StrainShiftsPm(v, s, flags);
    decode::ShiftsPm out;
    for (std::size_t i = 0; i < 16; ++i) out[i] = static_cast<float>(s[i]);
    return out;
  }
};

const Fixture& F() {
  static const Fixture f;
  return f;
}

// The map's grid steps 1.5 mm from the area's near corner and may end up to a step past its far edge (the indented
// area's maps always have), but never past the patch: a map reaching beyond it is refused by the pipeline, and
// `fit-response --area whole` (the area is the patch, 145 deg, not a whole number of steps) once wrote one. Such a
// grid is squeezed to end on the patch's edge; the indented area's grid keeps its 1.5 mm step (its maps refitted
// come out as before).
TEST(InversionTest, TheMapsGridNeverEndsPastThePatch) {
  std::vector<decode::ShiftsPm> s;
  std::vector<float> f, y, r;
  for (int site = 0; site < 30; ++site) {
    const float sy = static_cast<float>(5 + 4.5 * site), sr = static_cast<float>(3 + 4.6 * site);
    for (int k = 1; k <= 10; ++k) {
      decode::ShiftsPm v{};
      for (std::size_t i = 0; i < 16; ++i) v[i] = 0.3f * static_cast<float>(k * (1 + (static_cast<int>(i) + site) % 5));
      s.push_back(v);
      f.push_back(0.3f * static_cast<float>(k));
      y.push_back(sy);
      r.push_back(sr);
    }
  }
  const double radius = 37.36;
  const double arc_step_deg = 1.5 * 180.0 / (std::numbers::pi * radius);
  const patch::Region patch{0.0, 150.0, 0.0, 145.0};
  const decode::ResponseModel m = decode::ResponseModel::Fit(s, f, y, r, patch, radius, 0.1, &patch);
  EXPECT_DOUBLE_EQ(m.y0_mm, 0.0);
  EXPECT_DOUBLE_EQ(m.r0_deg, 0.0);
  EXPECT_NEAR(m.y0_mm + (m.ny - 1) * m.dy_mm, 150.0, 1e-9);
  EXPECT_NEAR(m.r0_deg + (m.nr - 1) * m.dr_deg, 145.0, 1e-9);
  EXPECT_LE(m.dr_deg, arc_step_deg);  // never coarser than 1.5 mm of arc
  EXPECT_GT(m.dr_deg, 0.98 * arc_step_deg);
  // Without the patch to stay within, the same grid runs past it (what the fix prevents).
  const decode::ResponseModel loose = decode::ResponseModel::Fit(s, f, y, r, patch, radius);
  EXPECT_GT(loose.r0_deg + (loose.nr - 1) * loose.dr_deg, 145.0 + 1.0);
  // The indented area (90 deg: 39.2 steps) keeps its step and its grid, up to a step past its edge.
  const patch::Region indented{15.0, 135.0, 27.5, 117.5};
  const decode::ResponseModel e = decode::ResponseModel::Fit(s, f, y, r, indented, radius, 0.1, &patch);
  EXPECT_DOUBLE_EQ(e.dr_deg, arc_step_deg);
  EXPECT_DOUBLE_EQ(e.dy_mm, 1.5);
  EXPECT_EQ(e.nr, 41);
  EXPECT_EQ(e.ny, 81);
  EXPECT_GT(e.r0_deg + (e.nr - 1) * e.dr_deg, 117.5);
}

TEST(InversionTest, LocatesSingleContacts) {
  const patch::Geometry geo(F().scene.Patch().spec);
  std::vector<double> err, ferr;
  int missed = 0;
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> uy(25, 125), ur(37, 108);
  for (int k = 0; k < 200; ++k) {
    const patch::SurfacePoint at{uy(rng), ur(rng)};
    const auto o = F().inv->Decode(F().Shifts({twin::Contact{at, 1.5, F().scene.probe}}));
    ASSERT_TRUE(o.valid);
    if (!o.located) {  // a weak spot between receptive fields: every shift below the detection level
      ++missed;
      continue;
    }
    err.push_back(geo.SurfaceDistanceMm({o.y_mm, o.r_deg}, at));
    ferr.push_back(std::abs(o.force_n - 1.5));
    EXPECT_TRUE(std::isfinite(o.location_sigma_mm));
  }
  RecordProperty("median_error_mm", std::to_string(stats::Median(err)));
  std::printf("located %zu, missed %d, median error %.2f mm, force error %.3f N\n", err.size(), missed, stats::Median(err), stats::Median(ferr));
  EXPECT_LT(missed, 20);                // at most 10 % of sites too weak at 1.5 N
  EXPECT_LT(stats::Median(err), 4.0);   // a response map learned from 1200 indentations
  EXPECT_LT(stats::Median(ferr), 0.35);
}

TEST(InversionTest, UntouchedIsZeroForce) {
  decode::ShiftsPm s;
  s.fill(0.5f);
  const auto o = F().inv->Decode(s);
  EXPECT_TRUE(o.valid);
  EXPECT_FALSE(o.located);
  EXPECT_EQ(o.force_n, 0.0f);
}

TEST(InversionTest, TwoTouchesGiveLowConfidence) {
  const auto& probe = F().scene.probe;
  std::vector<double> single, dual;
  for (double y : {40.0, 60.0, 80.0, 100.0}) {
    const auto a = F().inv->Decode(F().Shifts({twin::Contact{{y, 45.0}, 1.5, probe}}));
    const auto b = F().inv->Decode(F().Shifts({twin::Contact{{y, 100.0}, 1.5, probe}}));
    const auto ab = F().inv->Decode(F().Shifts({twin::Contact{{y, 45.0}, 1.5, probe}, twin::Contact{{y, 100.0}, 1.5, probe}}));
    single.push_back(a.confidence);
    single.push_back(b.confidence);
    dual.push_back(ab.confidence);
  }
  EXPECT_LT(stats::Median(dual), 0.5 * stats::Median(single))
      << "single " << stats::Median(single) << " two touches " << stats::Median(dual);
}

TEST(InversionTest, DeadGratingIsLeftOutOfTheFit) {
  const patch::SurfacePoint at{66.0, 72.5};
  auto s = F().Shifts({twin::Contact{at, 1.5, F().scene.probe}});
  s[6] = std::nanf("");  // FBG 7 sits at (66, 72.5): lose the most informative grating
  const auto o = F().inv->Decode(s);
  EXPECT_TRUE(o.valid);
  EXPECT_EQ(o.missing, 1);
  ASSERT_TRUE(o.located);
  EXPECT_TRUE(std::isfinite(o.y_mm) && std::isfinite(o.r_deg) && std::isfinite(o.force_n));
  const patch::Geometry geo(F().scene.Patch().spec);
  EXPECT_LT(geo.SurfaceDistanceMm({o.y_mm, o.r_deg}, at), 20.0);
  for (std::size_t i = 7; i < 14; ++i) s[i] = std::nanf("");  // too many missing: invalid, not NaN
  const auto bad = F().inv->Decode(s);
  EXPECT_FALSE(bad.valid);
  EXPECT_EQ(bad.force_n, 0.0f);
}

TEST(InversionTest, MoreIterationsFitBetter) {
  decode::InversionOptions o0;
  o0.iterations = 0;
  decode::InversionOptions o10;
  o10.iterations = 10;
  const decode::InversionDecoder d0(F().inv->model(), o0), d10(F().inv->model(), o10);
  double chi0 = 0, chi10 = 0;
  int used = 0;
  for (double y = 30; y < 125; y += 9) {
    const auto s = F().Shifts({twin::Contact{{y, 70.0}, 1.2, F().scene.probe}});
    chi0 += d0.Solve(s, used).chi2_reduced;
    chi10 += d10.Solve(s, used).chi2_reduced;
  }
  EXPECT_LT(chi10, chi0);
}

}  // namespace
}  // namespace ruffini::eval
