// Evaluate() on constructed data, where every number is known.
#include <gtest/gtest.h>

#include <hdf5.h>

#include <cmath>
#include <filesystem>

#include "ruffini/eval/evaluation.h"
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
