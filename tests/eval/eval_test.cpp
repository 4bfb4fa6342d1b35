// Evaluate() on constructed data, where every number is known.
#include <gtest/gtest.h>

#include <hdf5.h>

#include <array>
#include <cmath>
#include <filesystem>

#include "ruffini/eval/evaluation.h"
#include "ruffini/eval/stream.h"
#include "ruffini/patch/geometry.h"
#include "ruffini/patch/spec_loader.h"

namespace ruffini::eval {
namespace {

const patch::PatchSpec& Spec() {
  static const patch::PatchSpec s = patch::LoadPatchSpec(RUFFINI_SOURCE_DIR "/config/patches/forearm.yaml");
  return s;
}

// 10 indentations of 100 frames at distinct positions, force ramping 0..2 N.
Prepared MakeData() {
  Prepared p;
  for (int i = 0; i < 10; ++i) {
    p.ids.push_back(i);
    p.ranges.emplace_back(p.size(), p.size() + 100);
    for (int k = 0; k < 100; ++k) {
      p.shift_pm.push_back({});
      p.force_n.push_back(0.02f * static_cast<float>(k));
      p.y_mm.push_back(30.0f + 8.0f * static_cast<float>(i));
      p.r_deg.push_back(40.0f + 6.0f * static_cast<float>(i));
      p.indentation.push_back(i);
    }
  }
  return p;
}

Predictions Perfect(const Prepared& p, const std::vector<int>& test) {
  Predictions q;
  for (std::size_t k = 0; k < p.size(); ++k) {
    q.force_n.push_back(p.force_n[k]);
    q.y_mm.push_back(p.y_mm[k]);
    q.r_deg.push_back(p.r_deg[k]);
    q.valid.push_back(1);
    q.located.push_back(p.force_n[k] > 0.05f ? 1 : 0);
    q.test.push_back(std::find(test.begin(), test.end(), p.indentation[k]) != test.end() ? 1 : 0);
  }
  return q;
}

TEST(EvaluateTest, PerfectPredictionsHaveZeroErrorAndBeatTheGuess) {
  const Prepared p = MakeData();
  const Predictions q = Perfect(p, {7, 8, 9});
  const Evaluation ev = Evaluate(p, q, Spec());
  EXPECT_EQ(ev.force_frames, 300u);
  EXPECT_EQ(ev.location_frames, 3u * 97u);  // force > 50 mN: k >= 3
  EXPECT_EQ(ev.location_missed, 0u);
  EXPECT_DOUBLE_EQ(ev.force_error_mn.median, 0.0);
  EXPECT_DOUBLE_EQ(ev.location_error_mm.median, 0.0);
  // The guess is the training part's median force (0.99 N over 0..1.98) and median position.
  EXPECT_NEAR(ev.rg_force_guess_n, 0.99, 1e-6);
  EXPECT_NEAR(ev.rg_location_guess.y_mm, 54.0, 1e-6);  // indentations 0..6: y = 30..78, median 54
  EXPECT_GT(ev.rg_force_error_mn.median, 100.0);
  EXPECT_LT(ev.force_wilcoxon.p_two_sided, 1e-10);
  EXPECT_LT(ev.location_wilcoxon.p_two_sided, 1e-10);
}

TEST(EvaluateTest, KnownErrorsAndMissedFrames) {
  const Prepared p = MakeData();
  Predictions q = Perfect(p, {9});
  for (std::size_t k = 900; k < 1000; ++k) {
    q.force_n[k] += 0.05f;  // +50 mN everywhere
    q.y_mm[k] += 3.0f;      // 3 mm along Y
  }
  q.located[950] = 0;       // one frame above the gate the decoder did not locate
  q.valid[960] = 0;         // an invalid frame scores as 0 N
  const Evaluation ev = Evaluate(p, q, Spec());
  EXPECT_NEAR(ev.force_error_mn.median, 50.0, 1e-3);
  EXPECT_NEAR(ev.location_error_mm.median, 3.0, 1e-4);
  EXPECT_EQ(ev.location_missed, 1u);
  EXPECT_EQ(ev.location_frames, 96u);
}

// One 100 Hz frame appended to d: force f (load cell and true), the probe at (y, r), indentation id.
void AppendFrame(dataset::Dataset& d, float f, float y, float r, int id) {
  dataset::Frame fr;
  fr.t_s = static_cast<double>(d.size()) * 0.01;
  fr.serial = d.size();
  fr.force_n = fr.true_force_n = f;
  fr.y_mm = y;
  fr.r_deg = r;
  fr.indentation = id;
  d.Append(fr);
}

// ScoreStream on constructed data: a rest of 200 frames, then 10 indentations of 100 frames (0..1.98 N).
dataset::Dataset StreamData() {
  dataset::Dataset d;
  d.info.sample_rate_hz = 100.0;
  auto add = [&](float f, float y, float r, int id) { AppendFrame(d, f, y, r, id); };
  for (int k = 0; k < 200; ++k) add(0.0f, NAN, NAN, -1);
  for (int i = 0; i < 10; ++i) {
    for (int k = 0; k < 100; ++k) add(0.02f * static_cast<float>(k), 30.0f + 8.0f * static_cast<float>(i), 40.0f + 6.0f * static_cast<float>(i), i);
  }
  return d;
}

StreamPredictions PerfectStream(const dataset::Dataset& d) {
  StreamPredictions p;
  for (std::size_t k = 0; k < d.size(); ++k) {
    const bool on = d.true_force_n[k] > 0.05f;
    p.force_n.push_back(d.true_force_n[k]);
    p.force_sd_n.push_back(0.01f);
    p.y_mm.push_back(on ? d.y_mm[k] : NAN);
    p.r_deg.push_back(on ? d.r_deg[k] : NAN);
    for (float c : {1.0f, 0.0f, 1.0f}) p.pos_cov_mm2.push_back(on ? c : NAN);
    p.confidence.push_back(1.0f);
    p.common_mode_pm.push_back(0.0f);
    p.valid.push_back(1);
    p.located.push_back(on);
    p.in_contact.push_back(on);
    p.reason.push_back(0);
    p.baseline_frozen.push_back(on);
  }
  return p;
}

TEST(ScoreStreamTest, MissesScoreAsFailuresAndFalseContactsCount) {
  const dataset::Dataset d = StreamData();
  StreamPredictions p = PerfectStream(d);
  const patch::SurfacePoint guess{62.5, 72.5};
  // Indentation 9 (frames 1100..1199): 10 frames above the gate not located, 5 invalid (reason 7).
  for (std::size_t k = 1150; k < 1160; ++k) p.located[k] = 0;
  for (std::size_t k = 1160; k < 1165; ++k) {
    p.valid[k] = 0;
    p.reason[k] = 7;
  }
  // Rest frames 100..119 reported in contact: 20 false contacts.
  for (std::size_t k = 100; k < 120; ++k) p.in_contact[k] = 1;
  const StreamMetrics m = ScoreStream(d, p, Spec(), {}, guess);
  EXPECT_EQ(m.frames, 1200u);
  EXPECT_EQ(m.invalid, 5u);
  EXPECT_EQ(m.reasons[7], 5u);
  EXPECT_EQ(m.above_frames, 10u * 97u);
  EXPECT_EQ(m.above_missed, 15u);  // not located + invalid
  // 200 rest frames + each indentation's frames at 0 N and at 0.02 N (as float 0.0199999996 < 0.02): 220.
  EXPECT_EQ(m.quiet_frames, 220u);
  EXPECT_EQ(m.false_contacts, 20u);
  EXPECT_NEAR(m.false_contact_rate, 20.0 / 220.0, 1e-12);
  // Location with misses as failures: the 15 missed frames score the guess's distance; located-only is 0.
  EXPECT_DOUBLE_EQ(m.location_located_mm.median, 0.0);
  EXPECT_NEAR(m.location_above_mm.q3, 0.0, 1e-9);  // 15 of 970 do not move the quartiles...
  // ...but they count in the miss rate above 100 mN (indentation frames at >= 0.12 N: 94 each).
  EXPECT_NEAR(m.miss_rate_above_100mn, 15.0 / (10.0 * 94.0), 1e-12);
  // Scored as the guess: with most frames missed, the median is the guess's distance.
  StreamPredictions lost = PerfectStream(d);
  for (std::size_t k = 1100; k < 1200; ++k) lost.located[k] = 0;
  for (std::size_t k = 200; k < 1100; ++k) lost.located[k] = 0;
  const StreamMetrics ml = ScoreStream(d, lost, Spec(), MaskOfIndentations(d, {9}), guess);
  const patch::Geometry geo(Spec().surface_radius_mm);
  EXPECT_NEAR(ml.location_above_mm.median, geo.SurfaceDistanceMm(guess, {102.0, 94.0}), 1e-4);
  EXPECT_TRUE(std::isnan(ml.location_located_mm.median));
  // Invalid frames report 0 N: their force error is the whole force (5 frames at 1.2..1.28 N).
  StreamPredictions inv = PerfectStream(d);
  for (std::size_t k = 1100; k < 1200; ++k) inv.valid[k] = 0;
  const StreamMetrics mi = ScoreStream(d, inv, Spec(), MaskOfIndentations(d, {9}), guess);
  EXPECT_NEAR(mi.force_all_mn.median, 0.02 * 49.5 * 1e3, 1.0);
  // Coverage: every in-contact frame is exact, sd 10 mN: 100 % within 1 sd (the 20 false contacts err by 0).
  EXPECT_DOUBLE_EQ(m.force_within_1sd, 1.0);
  EXPECT_DOUBLE_EQ(m.position_within_1sd, 1.0);
  EXPECT_DOUBLE_EQ(m.force_within_3sd, 1.0);
  EXPECT_DOUBLE_EQ(m.position_within_3sd, 1.0);
  // The longest freeze (97 frames an indentation) against the longest press (98 frames > 20 mN).
  EXPECT_NEAR(m.longest_frozen_s, 0.97, 1e-9);
  EXPECT_NEAR(m.longest_press_s, 0.98, 1e-9);
  // A mask restricts the scored frames, not the stream properties.
  const StreamMetrics only9 = ScoreStream(d, p, Spec(), MaskOfIndentations(d, {9}), guess);
  EXPECT_EQ(only9.frames, 100u);
  EXPECT_EQ(only9.false_contacts, 0u);
  EXPECT_NEAR(only9.longest_frozen_s, 0.97, 1e-9);
  // Half the located frames 3 sd off: coverage drops to the share within.
  StreamPredictions q = PerfectStream(d);
  for (std::size_t k = 200; k < 1200; k += 2) q.force_n[k] += 0.03f;
  const StreamMetrics c = ScoreStream(d, q, Spec(), {}, guess);
  EXPECT_NEAR(c.force_within_1sd, 0.5, 0.01);
  EXPECT_NEAR(c.force_within_2sd, 0.5, 0.01);
}

// Pressed frames are split by the press's distance from the patch's nearest edge (10 mm, on the surface):
// an edge press placed 12 mm inward and read at half its force shows in the near-edge zone only.
TEST(ScoreStreamTest, PressesNearAnEdgeAreScoredApart) {
  dataset::Dataset d;
  d.info.sample_rate_hz = 100.0;
  auto add = [&](float f, float y, float r, int id) { AppendFrame(d, f, y, r, id); };
  for (int k = 0; k < 50; ++k) add(0.0f, NAN, NAN, -1);
  // 0: 4 mm from the elbow edge (Y = 0); 1: the centre; 2: R 10 deg = 6.5 mm of arc from the R = 0 edge;
  // 3: R 128 deg, 11.1 mm of arc from the R = 145 edge (interior by 1 mm).
  const std::array<patch::SurfacePoint, 4> at = {{{4.0, 72.5}, {75.0, 72.5}, {75.0, 10.0}, {75.0, 128.0}}};
  for (int i = 0; i < 4; ++i) {
    for (int k = 0; k < 100; ++k) add(0.02f * static_cast<float>(k), static_cast<float>(at[i].y_mm), static_cast<float>(at[i].r_deg), i);
  }
  StreamPredictions p = PerfectStream(d);
  for (std::size_t k = 0; k < d.size(); ++k) {
    const int id = d.indentation[k];
    if (id == 0 || id == 2) {
      p.force_n[k] *= 0.5f;
      if (p.located[k]) p.y_mm[k] += 12.0f;
    }
  }
  const StreamMetrics m = ScoreStream(d, p, Spec(), {}, {75.0, 72.5});
  EXPECT_EQ(m.near_edge.frames, 2u * 97u);
  EXPECT_EQ(m.interior.frames, 2u * 97u);
  EXPECT_NEAR(m.near_edge.location_mm.median, 12.0, 1e-4);
  EXPECT_NEAR(m.near_edge.location_located_mm.median, 12.0, 1e-4);
  EXPECT_NEAR(m.interior.location_mm.median, 0.0, 1e-4);
  EXPECT_NEAR(m.near_edge.force_ratio_above_1n, 0.5, 1e-6);
  EXPECT_NEAR(m.interior.force_ratio_above_1n, 1.0, 1e-6);
  EXPECT_EQ(m.near_edge.frames_above_1n, 2u * 49u);  // 1.02 .. 1.98 N
  EXPECT_NEAR(m.near_edge.location_above_1n_mm.median, 12.0, 1e-4);
  EXPECT_NEAR(m.interior.location_above_1n_mm.median, 0.0, 1e-4);
  EXPECT_GT(m.near_edge.force_mn.median, 100.0);
  EXPECT_NEAR(m.interior.force_mn.median, 0.0, 1e-3);
  EXPECT_EQ(m.near_edge.missed, 0u);
  // Over range (invalid, in contact) counts in its zone and scores as a miss at 0 N.
  for (std::size_t k = 0; k < d.size(); ++k) {
    if (d.indentation[k] == 1 && d.true_force_n[k] > 1.5f) {
      p.valid[k] = 0;
      p.in_contact[k] = 1;
    }
  }
  const StreamMetrics o = ScoreStream(d, p, Spec(), {}, {75.0, 72.5});
  EXPECT_EQ(o.interior.over_range, 24u);  // 1.52 .. 1.98 N
  EXPECT_EQ(o.interior.missed, 24u);
  EXPECT_EQ(o.near_edge.over_range, 0u);
  const std::string table = EdgeZoneTable({{"constructed", &m}});
  EXPECT_NE(table.find("within 10 mm of an edge"), std::string::npos);
  EXPECT_NE(table.find("| constructed | interior | 194 |"), std::string::npos) << table;
}

// CoverageBreakdown splits the coverage by where the frames are: a press 2 mm inside the indented area's border
// (Y 17, the area starts at 15) placed 3 mm inward (Mahalanobis^2 9: outside 2 sigma, inside 3) and one at the
// centre placed exactly.
TEST(CoverageBreakdownTest, GroupsByTruePositionReportedPositionAndPhase) {
  dataset::Dataset d;
  d.info.sample_rate_hz = 100.0;
  auto add = [&](float f, float y, float r, int id) { AppendFrame(d, f, y, r, id); };
  for (int k = 0; k < 50; ++k) add(0.0f, NAN, NAN, -1);
  const std::array<patch::SurfacePoint, 2> at = {{{17.0, 72.5}, {75.0, 72.5}}};
  for (int i = 0; i < 2; ++i) {
    for (int k = 0; k < 100; ++k) add(0.02f * static_cast<float>(k), static_cast<float>(at[i].y_mm), static_cast<float>(at[i].r_deg), i);
  }
  StreamPredictions p = PerfectStream(d);
  for (std::size_t k = 0; k < d.size(); ++k) {
    if (d.indentation[k] == 0 && p.located[k]) p.y_mm[k] += 3.0f;
  }
  const auto rows = CoverageBreakdown(d, p, Spec());
  const auto row = [&rows](const std::string& g) {
    for (const auto& r : rows) {
      if (r.group == g) return r;
    }
    ADD_FAILURE() << "no group " << g;
    return CoverageRow{};
  };
  const CoverageRow all = row("all"), edge = row("true position: indented area, < 5 mm from its border"),
                    inner = row("true position: indented area, >= 5 mm inside"),
                    reported_inner = row("reported position: indented area, >= 5 mm inside"),
                    hold = row("hold (>= 90 % of the peak)"), onset = row("onset (before 90 % of the peak)");
  EXPECT_EQ(all.position_frames, 2u * 97u);  // above 50 mN: 0.06 .. 1.98 N
  EXPECT_EQ(edge.position_frames, 97u);
  EXPECT_DOUBLE_EQ(edge.position[0], 0.0);
  EXPECT_DOUBLE_EQ(edge.position[1], 0.0);
  EXPECT_DOUBLE_EQ(edge.position[2], 1.0);
  EXPECT_DOUBLE_EQ(edge.y_within_1sd, 0.0);
  EXPECT_DOUBLE_EQ(edge.arc_within_1sd, 1.0);
  EXPECT_DOUBLE_EQ(inner.position[0], 1.0);
  EXPECT_EQ(reported_inner.position_frames, 2u * 97u);  // placed at Y 20: 5 mm inside
  EXPECT_DOUBLE_EQ(reported_inner.position[1], 0.5);
  EXPECT_EQ(hold.position_frames, 2u * 10u);  // 1.80 .. 1.98 N: at least 90 % of the 1.98 N peak
  EXPECT_EQ(onset.position_frames, 2u * 87u);
  EXPECT_DOUBLE_EQ(all.force[0], 1.0);
  EXPECT_NE(CoverageTable(rows).find("| hold (>= 90 % of the peak) | 20 | 100.0 / 100.0 / 100.0 % | 20 | 50.0 / 50.0 / 100.0 % |"),
            std::string::npos)
      << CoverageTable(rows);
}

TEST(EvaluateTest, PredictionsFileIsAligned) {
  const Prepared p = MakeData();
  const Predictions q = Perfect(p, {9});
  const auto path = (std::filesystem::temp_directory_path() / "ruffini_eval_pred.h5").string();
  WritePredictions(path, q);
  const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(f, 0);
  for (const char* name : {"/pred/force_n", "/pred/y_mm", "/pred/r_deg", "/pred/valid", "/pred/located", "/pred/test"}) {
    const hid_t d = H5Dopen2(f, name, H5P_DEFAULT);
    ASSERT_GE(d, 0) << name;
    const hid_t s = H5Dget_space(d);
    hsize_t n = 0;
    H5Sget_simple_extent_dims(s, &n, nullptr);
    EXPECT_EQ(n, p.size()) << name;
    H5Sclose(s);
    H5Dclose(d);
  }
  std::vector<float> force(p.size());
  const hid_t d = H5Dopen2(f, "/pred/force_n", H5P_DEFAULT);
  H5Dread(d, H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, force.data());
  H5Dclose(d);
  H5Fclose(f);
  EXPECT_EQ(force[123], q.force_n[123]);
  std::filesystem::remove(path);
}

TEST(SplitTest, WholeIndentationsAndFolds) {
  const Prepared p = MakeData();
  const Split s = MakeSplit(p, 0.2, 4, 7);
  EXPECT_EQ(s.test.size(), 2u);
  EXPECT_EQ(s.train.size(), 8u);
  std::vector<int> per_fold(4, 0);
  for (int f : s.fold) ++per_fold[static_cast<std::size_t>(f)];
  for (int n : per_fold) EXPECT_EQ(n, 2);
  for (std::size_t t : s.test) {
    for (std::size_t r : s.train) EXPECT_NE(t, r);
  }
  EXPECT_EQ(MakeSplit(p, 0.2, 4, 7).test, s.test);  // seeded
  const Split forced = MakeSplit(p, 0.2, 4, 7, {3, 5});
  ASSERT_EQ(forced.test.size(), 2u);
}

}  // namespace
}  // namespace ruffini::eval
