// The twin's calibration against the paper's statistics (T1 detection, T2 hot spots, T3 cross-talk,
// protocol statistics), on the default scene.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "ruffini/stats.h"
#include "ruffini/twin/protocols.h"
#include "ruffini/twin/report.h"
#include "ruffini/twin/scene.h"
#include "ruffini/twin/twin.h"

#include "fixtures.h"

namespace ruffini::twin {
namespace {

constexpr std::size_t kN = patch::kGratings;

using fixtures::DefaultScene;
using fixtures::DefaultTwin;

const std::array<HotSpot, kN>& HotSpots() {
  static const auto hs = MeasureHotSpots(DefaultTwin(), DefaultScene().probe, 2.5 / 6.0, 20.0, 0.25);
  return hs;
}

std::string Areas(const std::array<HotSpot, kN>& hs) {
  std::string s;
  for (std::size_t i = 0; i < kN; ++i) {
    s += "FBG " + std::to_string(i + 1) + ": " + std::to_string(hs[i].area_mm2) + " mm2 [" +
         std::to_string(hs[i].areas) + "]\n";
  }
  return s;
}

// ---------------------------------------------------------------------------------------------------
// 16. T2 hot spots.

TEST(Calibration, T2HotSpotAreas) {
  const auto& hs = HotSpots();
  std::vector<double> areas;
  for (const auto& h : hs) areas.push_back(h.area_mm2);
  const double median = stats::Median(areas);
  EXPECT_NEAR(median, Targets::kHotSpotMedianMm2, Targets::kHotSpotTolerance * Targets::kHotSpotMedianMm2)
      << Areas(hs);
  // Quartiles near the paper's 9.0 / 20.9 mm2 (the gain spread is fitted to them).
  EXPECT_NEAR(stats::Quantile(areas, 0.25), Targets::kHotSpotQ1Mm2, 0.30 * Targets::kHotSpotQ1Mm2) << Areas(hs);
  EXPECT_NEAR(stats::Quantile(areas, 0.75), Targets::kHotSpotQ3Mm2, 0.30 * Targets::kHotSpotQ3Mm2) << Areas(hs);
  for (std::size_t i = 0; i < kN; ++i) {
    const int g = static_cast<int>(i) + 1;
    const int expected = (g == 2 || g == 12 || g == 13) ? 2 : 1;
    EXPECT_EQ(hs[i].areas, expected) << "FBG " << g << "\n" << Areas(hs);
    // FBG 6: one area made of clustered sub-regions; the regular gratings: one peak.
    if (g == 6) {
      EXPECT_GE(hs[i].peaks, 2) << "FBG 6 sub-regions";
    } else if (expected == 1) {
      EXPECT_EQ(hs[i].peaks, 1) << "FBG " << g;
    }
    EXPECT_GT(hs[i].area_mm2, 0.0) << "FBG " << g;
    EXPECT_GT(hs[i].peak_pm_per_n, 20.0 / (2.5 / 6.0)) << "FBG " << g;
  }
}

// ---------------------------------------------------------------------------------------------------
// 17. T3 cross-talk.

int Neighbours(const Shifts& s, std::size_t self) {
  int n = 0;
  for (std::size_t j = 0; j < kN; ++j) n += (j != self && std::abs(s[j]) > 2.0) ? 1 : 0;
  return n;
}

// a + b + c without GCC 12's false -Wrestrict on `"literal" + std::string`.
std::string Cat(const std::string& a, const std::string& b, const std::string& c = "") {
  std::string s(a);
  s.append(b).append(c);
  return s;
}

// The line of the text report that starts with `what`.
std::string ReportLine(const std::string& text, const std::string& what) {
  const auto at = text.find(Cat("\n", what));
  if (at == std::string::npos) return Cat("(no line '", what, "')");
  return text.substr(at + 1, text.find('\n', at + 1) - at - 1);
}

TEST(Calibration, T3CrossTalkVerdictIsComputedFromTheCounts) {
  const SkinTwin& twin = DefaultTwin();
  const auto& hs = HotSpots();
  TwinReport r;
  std::string table;
  for (std::size_t i = 0; i < kN; ++i) {
    r.crosstalk_1n[i] = Neighbours(twin.StrainShiftsPm(Contact{hs[i].peak_at, 1.0, DefaultScene().probe}), i);
    r.crosstalk_2n5[i] = Neighbours(twin.StrainShiftsPm(Contact{hs[i].peak_at, 2.5, DefaultScene().probe}), i);
    table += "FBG " + std::to_string(i + 1) + ": " + std::to_string(r.crosstalk_1n[i]) + " / " +
             std::to_string(r.crosstalk_2n5[i]) + "\n";
    // Physics, whatever the targets: more force never reaches fewer neighbours.
    EXPECT_GE(r.crosstalk_2n5[i], r.crosstalk_1n[i]) << "FBG " << i + 1;
  }
  RecordProperty("crosstalk_1n_2n5", table);
  const int min1 = *std::min_element(r.crosstalk_1n.begin(), r.crosstalk_1n.end());
  const int min25 = *std::min_element(r.crosstalk_2n5.begin(), r.crosstalk_2n5.end());
  EXPECT_EQ(MinNeighbours(r.crosstalk_2n5), min25);
  // The verdict function against its targets, at the boundary.
  EXPECT_EQ(CrossTalkVerdict(Targets::kCrossTalk2n5Min, Targets::kCrossTalk2n5Min), Verdict::kMet);
  EXPECT_EQ(CrossTalkVerdict(Targets::kCrossTalk2n5Min - 1, Targets::kCrossTalk2n5Min), Verdict::kShort);
  EXPECT_EQ(Targets::kCrossTalk2n5Min, 3) << "the issue's 'several' at 2.5 N";
  // The report prints the measured minimum and the verdict those numbers give: "short" when the twin
  // falls short of 3 neighbours (it does today: row-end gratings reach one), "met" otherwise.
  const std::string text = FormatReport(r);
  const std::string l25 = ReportLine(text, "T3 neighbours > 2 pm at 2.5 N");
  const std::string l1 = ReportLine(text, "T3 neighbours > 2 pm at 1 N");
  EXPECT_NE(l25.find(Cat(" ", std::to_string(min25), " / ")), std::string::npos) << l25;
  EXPECT_NE(l25.find(">= 3 (several)"), std::string::npos) << l25;
  EXPECT_NE(l25.find(min25 >= 3 ? " met" : " short"), std::string::npos) << l25 << "\n" << table;
  EXPECT_NE(l1.find(min1 >= 1 ? " met" : " short"), std::string::npos) << l1;
  // And the text says which it is: these lines are predictions, not fits.
  EXPECT_LT(text.find("FITTED"), text.find("T2 hot-spot area, median"));
  EXPECT_LT(text.find("PREDICTED"), text.find("T3 neighbours"));
  EXPECT_GT(text.find("PREDICTED"), text.find("T2 hot-spot area, quartiles"));
}

// ---------------------------------------------------------------------------------------------------
// 18. T1 detection.

void ExpectMostlyIncreasing(const DetectionFit& fit, const std::string& what) {
  int inversions = 0;
  for (std::size_t k = 1; k < fit.points.size(); ++k) {
    const double drop = fit.points[k - 1].rate() - fit.points[k].rate();
    EXPECT_GT(fit.points[k].force_n, fit.points[k - 1].force_n);
    if (drop > 0) {
      ++inversions;
      EXPECT_LE(drop, 0.10) << what << ": rate falls at " << fit.points[k].force_n << " N";
    }
  }
  EXPECT_LE(inversions, 1) << what;
}

TEST(Calibration, T1Detection) {
  const SkinTwin& twin = DefaultTwin();
  VonFreyProtocol p;
  p.subjects = 3;
  const DetectionFit uniform = MeasureDetection(twin, p, 1, 2.0);
  VonFreyProtocol near = p;
  near.near_grating_mm = 3.0;
  const DetectionFit close = MeasureDetection(twin, near, 1, 2.0);
  // Near-grating detection is nearly a step (about 8 % at 2 g, 100 % from 4 g up): the least-squares
  // logistic then steepens without bound and need not report convergence; only the uniform fit must.
  EXPECT_TRUE(uniform.converged);
  for (const DetectionFit* fit : {&uniform, &close}) {
    const std::string what = fit == &uniform ? "uniform" : "near grating";
    EXPECT_TRUE(std::isfinite(fit->threshold75_n)) << what;
    EXPECT_GT(fit->threshold75_n, 0.0) << what;
    ASSERT_EQ(fit->points.size(), p.filaments_g.size()) << what;
    for (const auto& pt : fit->points) EXPECT_EQ(pt.stimulations, p.subjects * p.sites) << what;
    ExpectMostlyIncreasing(*fit, what);
    // The heaviest filament (60 g) is felt nearly always, the lightest (0.4 g) rarely.
    EXPECT_GE(fit->points.back().rate(), 0.75) << what;
    EXPECT_LE(fit->points.front().rate(), 0.5) << what;
  }
  // Physics: touches near a grating are detected at lower forces than touches anywhere.
  EXPECT_LT(close.threshold75_n, uniform.threshold75_n)
      << "near " << close.threshold75_n << " N, uniform " << uniform.threshold75_n << " N";
  // What the report claims: the measured threshold and the verdict its number gives against 50.6 mN
  // +-30 % (short above, beyond below), whatever that verdict is.
  auto expected = [](double t) {
    if (!std::isfinite(t) || t > 0.0506 * 1.3) return std::string("short");
    return std::string(t < 0.0506 * 0.7 ? "beyond" : "met");
  };
  EXPECT_EQ(VerdictName(DetectionVerdict(uniform.threshold75_n)), expected(uniform.threshold75_n));
  EXPECT_EQ(VerdictName(DetectionVerdict(close.threshold75_n)), expected(close.threshold75_n));
  EXPECT_STREQ(VerdictName(DetectionVerdict(0.0506)), "met");
  EXPECT_STREQ(VerdictName(DetectionVerdict(0.0506 * 1.31)), "short");
  EXPECT_STREQ(VerdictName(DetectionVerdict(0.0506 * 0.69)), "beyond");
  EXPECT_STREQ(VerdictName(DetectionVerdict(std::numeric_limits<double>::quiet_NaN())), "short");
  TwinReport r;
  r.detection_uniform = uniform;
  r.detection_near_grating = close;
  const std::string text = FormatReport(r);
  const std::string lu = ReportLine(text, "T1 75 % detection, uniform random sites");
  char measured[32];
  std::snprintf(measured, sizeof measured, " %.0f mN", uniform.threshold75_n * 1e3);
  EXPECT_NE(lu.find(measured), std::string::npos) << lu;
  EXPECT_NE(lu.find("50.6 mN (+-30 %)"), std::string::npos) << lu;
  EXPECT_NE(lu.find(Cat(" ", expected(uniform.threshold75_n), " ")), std::string::npos) << lu;
  const std::string ln = ReportLine(text, "T1 75 % detection, sites <= 3 mm");
  EXPECT_NE(ln.find(Cat(" ", expected(close.threshold75_n), " ")), std::string::npos) << ln;
  RecordProperty("t1_uniform_mn", std::to_string(uniform.threshold75_n * 1e3));
  RecordProperty("t1_near_grating_mn", std::to_string(close.threshold75_n * 1e3));
}

// ---------------------------------------------------------------------------------------------------
// 19. The logistic fit.

TEST(Calibration, FitDetectionRecoversAKnownLogistic) {
  const double a = 20.0, b = 0.1;
  // Forces where the logistic is k / (1 + k): rates exactly representable with 60 stimulations.
  std::vector<DetectionPoint> pts;
  for (double k : {1.0 / 9, 1.0 / 4, 1.0 / 3, 1.0 / 2, 2.0, 3.0, 4.0, 9.0}) {
    DetectionPoint pt;
    pt.force_n = b + std::log(k) / a;
    pt.stimulations = 60;
    pt.detected = static_cast<int>(std::lround(60.0 * k / (1.0 + k)));
    ASSERT_NEAR(pt.rate(), 1.0 / (1.0 + std::exp(-a * (pt.force_n - b))), 1e-12);
    pts.push_back(pt);
  }
  std::mt19937_64 rng(3);
  std::shuffle(pts.begin(), pts.end(), rng);  // order must not matter
  const DetectionFit fit = FitDetection(pts);
  EXPECT_TRUE(fit.converged);
  EXPECT_NEAR(fit.a_per_n, a, 0.01 * a);
  EXPECT_NEAR(fit.b_n, b, 0.01 * b);
  EXPECT_NEAR(fit.threshold75_n, fit.b_n + std::log(3.0) / fit.a_per_n, 1e-12);
  EXPECT_NEAR(fit.threshold75_n, b + std::log(3.0) / a, 0.01 * (b + std::log(3.0) / a));
  ASSERT_EQ(fit.points.size(), pts.size());
  for (std::size_t k = 1; k < fit.points.size(); ++k) EXPECT_GT(fit.points[k].force_n, fit.points[k - 1].force_n);
}

// ---------------------------------------------------------------------------------------------------
// 20. Paper protocol statistics (a 400-indentation subset of the paper's 2700).

TEST(Calibration, PaperProtocolStatistics) {
  const SkinTwin& twin = DefaultTwin();
  PaperProtocol p;
  p.indentations = 400;
  std::vector<double> force, ys, rs;
  force.reserve(500000);
  ys.reserve(500000);
  rs.reserve(500000);
  const ProtocolRun run = RunPaper(twin, DefaultScene(), p, 1, [&](std::span<const dataset::Frame> frames) {
    for (const auto& f : frames) {
      if (f.indentation < 0) continue;
      force.push_back(f.force_n);
      ys.push_back(f.y_mm);
      rs.push_back(f.r_deg);
    }
  });
  EXPECT_EQ(run.indentations, 400);
  const double per_indent = static_cast<double>(force.size()) / 400.0;
  EXPECT_GT(per_indent, 700.0);
  EXPECT_LT(per_indent, 1300.0);

  const double median_force = stats::Median(force);
  EXPECT_NEAR(median_force, Targets::kMedianForceN, 0.15 * Targets::kMedianForceN);
  std::vector<double> err(force.size());
  for (std::size_t k = 0; k < force.size(); ++k) err[k] = std::abs(force[k] - median_force);
  const double rg_force = stats::Median(err);
  EXPECT_NEAR(rg_force, Targets::kRgForceErrorN, 0.15 * Targets::kRgForceErrorN);
  const auto force_err = stats::Summarize(err);
  EXPECT_NEAR(force_err.iqr(), Targets::kRgForceIqrN, 0.15 * Targets::kRgForceIqrN);
  const patch::SurfacePoint guess{stats::Median(ys), stats::Median(rs)};
  for (std::size_t k = 0; k < force.size(); ++k) err[k] = twin.geometry().SurfaceDistanceMm({ys[k], rs[k]}, guess);
  const double rg_location = stats::Median(err);
  EXPECT_NEAR(rg_location, Targets::kRgLocationMm, 0.10 * Targets::kRgLocationMm);  // 400 sites: noisier than 2700
  EXPECT_NEAR(stats::Summarize(err).iqr(), Targets::kRgLocationIqrMm, 0.15 * Targets::kRgLocationIqrMm);
  RecordProperty("median_force_mn", std::to_string(median_force * 1e3));
  RecordProperty("rg_force_error_mn", std::to_string(rg_force * 1e3));
  RecordProperty("rg_location_error_mm", std::to_string(rg_location));
}

}  // namespace
}  // namespace ruffini::twin
