// Scene guarantees with the real processes (docs/coverage.md): a one-patch scene whose model carries a
// sensitivity map made here (every point reliable at 2 N except one at 5 N), so the figures are this test's,
// not a measurement's. ruffini-aggregator refuses the scene below its guarantee, loads it once the scene
// accepts the weak point's band and lists the band in its log and GetStatus, which carries the patch's map;
// a real ruffini-decoder's hello carries its model's map. `ruffini check-scene` says the same.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>

#include "process.h"
#include "sensitivity_grid.h"
#include "ruffini/decode/model_io.h"
#include "scene_setup.h"
#include "ruffini/v1/aggregator.grpc.pb.h"
#include "service_process.h"

namespace {

using namespace std::chrono_literals;
namespace v1 = ruffini::v1;
namespace rt = ruffini::testing;
namespace fs = std::filesystem;

const std::string kSrc = RUFFINI_SOURCE_DIR;

// The map: `ruffini sensitivity`'s grid (Y every 5 mm, arc every 5 mm, 2 mm from every edge: 31 x 20 points); 2 N
// everywhere but (Y 75, R 141.94 deg, the last column): 5 N. Level 1.5 N.
const double kWeakR = rt::ForearmRs().back();
v1::SensitivityMap Map(const std::vector<double>& ys = rt::ForearmYs(), const std::vector<double>& rs = rt::ForearmRs()) {
  return rt::GridMap(1.5f, 2.0f, 75.0, kWeakR, 5.0f, ys, rs, "coverage_process_test");
}

// A folder with the model (the shipped networks, this test's map) and a one-patch scene; `coverage` is the
// scene's safety.coverage section (empty: none).
std::string MakeScene(const std::string& dir, const std::string& coverage,
                      const std::function<void(v1::DecoderModel&)>& edit = {}, bool bind = true,
                      const std::function<void(v1::DecoderModel&)>& after_bind = {}) {
  fs::remove_all(dir);
  fs::create_directories(dir);
  std::ifstream in(kSrc + "/tests/fault/one-patch.yaml");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const auto replace = [&](const std::string& from, const std::string& to) {
    const auto at = text.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    text.replace(at, from.size(), to);
  };
  replace("spec: ../../config/patches/forearm.yaml", "spec: " + kSrc + "/config/patches/forearm.yaml");
  replace("model: ../../config/models/forearm.rmodel", "model: mapped.rmodel");
  // The template's own coverage section (the shipped model's bands) gives way to this test's.
  const auto from = text.find("  # The cobot scene's coverage"), to = text.find("  link_layer:");
  EXPECT_NE(from, std::string::npos);
  EXPECT_NE(to, std::string::npos);
  if (from != std::string::npos && to != std::string::npos && from < to) text.erase(from, to - from);
  replace("  silence_deadline_ms: 200\n", "  silence_deadline_ms: 200\n" + coverage);
  std::ofstream(dir + "/scene.yaml") << text;
  // The model: the shipped networks with this test's map, then `edit`; the map bound to this scene's patch and
  // this decoder as `ruffini sensitivity` binds what it measures (unless `bind` is false); then `after_bind`.
  v1::DecoderModel model = ruffini::decode::LoadModel(kSrc + "/config/models/forearm.rmodel");
  model.clear_sensitivity();
  *model.add_sensitivity() = Map();
  if (edit) edit(model);
  ruffini::decode::SaveModel(dir + "/mapped.rmodel", model);  // the scene must name a file that exists to load
  if (bind) ruffini::aggregator::BindMap(*model.mutable_sensitivity(0), dir + "/scene.yaml", "forearm", model);
  if (after_bind) after_bind(model);
  ruffini::decode::SaveModel(dir + "/mapped.rmodel", model);
  return dir + "/scene.yaml";
}

const std::string kBand =
    "  coverage:\n"
    "    press_factor: 1.5\n"
    "    source: issue 16's target\n"
    "    accepted_uncovered:\n"
    "      - {name: middle, patch: forearm, y_mm: [70, 80], r_deg: [135, 145], source: the test's weak point}\n";

v1::AggregatorStatus Status(const std::string& address) {
  auto stub = v1::Aggregator::NewStub(grpc::CreateChannel(address, grpc::InsecureChannelCredentials()));
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + 3s);
  v1::AggregatorStatus st;
  EXPECT_TRUE(stub->GetStatus(&ctx, v1::GetStatusRequest{}, &st).ok());
  return st;
}

TEST(CoverageProcess, ASceneBelowItsGuaranteeIsRefused) {
  const std::string dir = (fs::current_path() / "coverage_refused").string();
  const std::string scene = MakeScene(dir, "");
  rt::Process agg({RUFFINI_AGGREGATOR_EXE, "--insecure", "--scene", scene, "--listen", "127.0.0.1:0", "--metrics",
                   "127.0.0.1:0"},
                  dir);
  EXPECT_EQ(agg.WaitExit(10s), 1);
  const std::string err = agg.stderr_text();
  EXPECT_NE(err.find("region 'forearm' threshold 1.50 N is below what its patches guarantee, 3.33 N"), std::string::npos)
      << err;
  EXPECT_NE(err.find("1 of 620 covered map points need more than 1.50 x 1.50 N"), std::string::npos) << err;
  // check-scene says the same, and names the point.
  rt::Process check({RUFFINI_EXE, "check-scene", scene, "--points"}, dir);
  EXPECT_EQ(check.WaitExit(30s), 1);
  EXPECT_NE(check.stdout_text().find("NOT GUARANTEED"), std::string::npos) << check.stdout_text();
  EXPECT_NE(check.stdout_text().find("forearm Y 75.00 mm R 141.94 deg: 5.00 N"), std::string::npos) << check.stdout_text();
}

TEST(CoverageProcess, AcceptedBandsMakeItLoadAndAreListedInTheLogAndStatusWithEveryMapAndTheHello) {
  const std::string base = (fs::current_path() / "coverage_accepted").string();
  const std::string scene = MakeScene(base, kBand);
  rt::Process check({RUFFINI_EXE, "check-scene", scene}, base);
  EXPECT_EQ(check.WaitExit(30s), 0) << check.stdout_text() << check.stderr_text();
  EXPECT_NE(check.stdout_text().find("accepted uncovered band middle on forearm"), std::string::npos) << check.stdout_text();

  int grpc_port = 0, sim_port = 0, metrics = 0;
  rt::Process agg = rt::StartWithPorts({RUFFINI_AGGREGATOR_EXE, "--insecure", "--scene", scene, "--listen", "127.0.0.1:0",
                                        "--metrics", "127.0.0.1:0"},
                                       base + "/aggregator", "grpc", grpc_port);
  const std::string address = "127.0.0.1:" + std::to_string(grpc_port);
  ASSERT_TRUE(rt::WaitFor([&] { return agg.stderr_text().find("accepted uncovered: middle on forearm") != std::string::npos; }, 5s))
      << agg.stderr_text();
  EXPECT_NE(agg.stderr_text().find("guaranteed from 1.33333 N"), std::string::npos) << agg.stderr_text();
  v1::AggregatorStatus st = Status(address);
  ASSERT_EQ(st.coverage_size(), 1);
  const v1::RegionCoverage& c = st.coverage(0);
  EXPECT_EQ(c.region(), "forearm");
  EXPECT_FLOAT_EQ(c.threshold_n(), 1.5f);
  EXPECT_FLOAT_EQ(c.stop_force_n(), 2.0f);
  EXPECT_NEAR(c.guaranteed_threshold_n(), 2.0 / 1.5, 1e-6);
  EXPECT_EQ(c.points(), 620u);
  EXPECT_EQ(c.covered_points(), 619u);  // the weak point's cells all lie in the band
  ASSERT_EQ(c.accepted_bands_size(), 1);
  EXPECT_EQ(c.accepted_bands(0).name(), "middle");
  EXPECT_EQ(c.accepted_bands(0).patch_id(), "forearm");
  EXPECT_EQ(c.accepted_bands(0).points(), 6u);  // Y 70, 75, 80 x R 137.87, 141.94
  EXPECT_EQ(c.accepted_bands(0).uncovered_points(), 1u);
  EXPECT_EQ(c.accepted_bands(0).source(), "the test's weak point");
  ASSERT_EQ(st.patches_size(), 1);
  ASSERT_EQ(st.patches(0).sensitivity_size(), 1);
  const v1::SensitivityMap stored = ruffini::decode::LoadModel(base + "/mapped.rmodel").sensitivity(0);
  EXPECT_EQ(st.patches(0).sensitivity(0).SerializeAsString(), stored.SerializeAsString());
  EXPECT_FALSE(stored.measured_on().empty());
  EXPECT_EQ(st.patches(0).hello().sensitivity_size(), 0);  // no decoder yet

  // A decoder: its hello carries its model's map, and GetStatus shows it.
  rt::Process sim = rt::StartWithPorts({RUFFINI_SIM_EXE, "--scene", scene, "--scenario", kSrc + "/tests/fault/quiet.yaml", "--rate-hz", "1000", "--command-port", "0",
                                        "--stream-port", "0"},
                                       base + "/sim", "stream", sim_port);
  rt::Process decoder = rt::StartWithPorts({RUFFINI_DECODER_EXE, "--insecure", "--scene", scene, "--patch", "forearm",
                                            "--interrogator", "127.0.0.1:" + std::to_string(sim_port), "--aggregator",
                                            address, "--metrics", "127.0.0.1:0", "--rate-hz", "1000"},
                                           base + "/decoder", "metrics", metrics);
  ASSERT_TRUE(rt::WaitFor([&] { return Status(address).patches(0).hello().sensitivity_size() > 0; }, 20s, 50ms))
      << agg.stderr_text() << decoder.stderr_text();
  st = Status(address);
  ASSERT_EQ(st.patches(0).hello().sensitivity_size(), 1);
  EXPECT_EQ(st.patches(0).hello().sensitivity(0).SerializeAsString(), stored.SerializeAsString());
}

// Review 10, finding 4: a map whose grid stops short of the patch's edges (here 20 mm from the Y 0 edge, and
// 45 deg, about 30 mm, from the R end) left those strips counted as covered. The aggregator and check-scene refuse
// the scene and name each strip never measured.
TEST(CoverageProcess, AMapThatStopsShortOfTheEdgesIsRefusedNamingTheStrips) {
  const std::string dir = (fs::current_path() / "coverage_truncated").string();
  const std::string scene = MakeScene(dir, kBand, [](v1::DecoderModel& m) {
    std::vector<double> ys{20.0}, rs;  // Y from 20 mm, R up to 99.6 deg
    for (double y : rt::ForearmYs()) {
      if (y > 20.0) ys.push_back(y);
    }
    for (double r : rt::ForearmRs()) {
      if (r < 100.0) rs.push_back(r);
    }
    *m.mutable_sensitivity(0) = Map(ys, rs);
  });
  rt::Process agg({RUFFINI_AGGREGATOR_EXE, "--insecure", "--scene", scene, "--listen", "127.0.0.1:0", "--metrics",
                   "127.0.0.1:0"},
                  dir);
  EXPECT_EQ(agg.WaitExit(10s), 1);
  const std::string err = agg.stderr_text();
  EXPECT_NE(err.find("patch forearm: its grid stops 20.0 mm from the Y 0 edge"), std::string::npos) << err;
  EXPECT_NE(err.find("from the R end edge"), std::string::npos) << err;
  rt::Process check({RUFFINI_EXE, "check-scene", scene}, dir);
  EXPECT_EQ(check.WaitExit(30s), 1);
  EXPECT_NE(check.stdout_text().find("never measured"), std::string::npos) << check.stdout_text();
}

// Review 10, finding 5: a scene naming another patch's or another cast's model file, or a model recalibrated
// after its map was measured, was judged on that map. A map counts only for the patch it was measured on (the
// spec, the cast, each edge as mounted) and the decoder it was measured with; any other is named and not used,
// and the patch, left without a map, refuses the scene.
TEST(CoverageProcess, AMapMeasuredElsewhereOrWithAnotherDecoderIsNotUsed) {
  const std::string dir = (fs::current_path() / "coverage_bound").string();
  // The same scene with the map as bound: it loads (the control).
  rt::Process ok({RUFFINI_EXE, "check-scene", MakeScene(dir + "/ok", kBand)}, dir);
  EXPECT_EQ(ok.WaitExit(30s), 0) << ok.stdout_text() << ok.stderr_text();
  // Recalibrated after the map: the gratings' gains changed (as `ruffini calibrate` fits them to a cast).
  const std::string recal = MakeScene(dir + "/recal", kBand, {}, true, [](v1::DecoderModel& m) {
    auto* cal = m.mutable_cast_calibration();
    cal->clear_grating_gain();
    for (int i = 0; i < 16; ++i) cal->add_grating_gain(i == 3 ? 1.1f : 1.0f);
  });
  rt::Process agg({RUFFINI_AGGREGATOR_EXE, "--insecure", "--scene", recal, "--listen", "127.0.0.1:0", "--metrics",
                   "127.0.0.1:0"},
                  dir);
  EXPECT_EQ(agg.WaitExit(10s), 1);
  EXPECT_NE(agg.stderr_text().find("has no sensitivity map at or above 1.50 N"), std::string::npos) << agg.stderr_text();
  EXPECT_NE(agg.stderr_text().find("but the model's decoder is"), std::string::npos) << agg.stderr_text();
  // Measured on another cast.
  const std::string moved = MakeScene(dir + "/moved", kBand, {}, true, [](v1::DecoderModel& m) {
    std::string on = m.sensitivity(0).measured_on();
    const auto at = on.find("cast 0");
    ASSERT_NE(at, std::string::npos) << on;
    on.replace(at, 6, "cast 11");  // another skin sample
    m.mutable_sensitivity(0)->set_measured_on(on);
  });
  rt::Process check({RUFFINI_EXE, "check-scene", moved}, dir);
  EXPECT_EQ(check.WaitExit(30s), 1);
  EXPECT_NE(check.stdout_text().find("maps not used: patch forearm: the map of level 1.50 N in"), std::string::npos)
      << check.stdout_text();
  EXPECT_NE(check.stdout_text().find("is not used: it was measured on spec forearm ("), std::string::npos)
      << check.stdout_text();
  EXPECT_NE(check.stdout_text().find("), cast 11, edges not modelled, twin "), std::string::npos) << check.stdout_text();
  EXPECT_NE(check.stdout_text().find(", but here the patch is spec forearm ("), std::string::npos)
      << check.stdout_text();
  // A map that records nothing (from before stop 31).
  rt::Process old({RUFFINI_EXE, "check-scene", MakeScene(dir + "/old", kBand, {}, false)}, dir);
  EXPECT_EQ(old.WaitExit(30s), 1);
  EXPECT_NE(old.stdout_text().find("it records neither the patch nor the decoder"), std::string::npos) << old.stdout_text();
  // Accepted whole, the patch needs no map: the unused one is named and the scene loads.
  const std::string whole =
      "  coverage:\n    press_factor: 1.5\n    source: t\n    accepted_uncovered:\n"
      "      - {name: all, patch: forearm, y_mm: [0, 150], r_deg: [0, 145], source: t}\n";
  rt::Process all({RUFFINI_EXE, "check-scene", MakeScene(dir + "/whole", whole, {}, false)}, dir);
  EXPECT_EQ(all.WaitExit(30s), 0) << all.stdout_text() << all.stderr_text();
}

TEST(CoverageProcess, ABandBeyondItsPatchIsAClearError) {
  const std::string dir = (fs::current_path() / "coverage_beyond").string();
  std::string band = kBand;
  band.replace(band.find("r_deg: [135, 145]"), 17, "r_deg: [135, 200]");
  const std::string scene = MakeScene(dir, band);
  rt::Process agg({RUFFINI_AGGREGATOR_EXE, "--insecure", "--scene", scene, "--listen", "127.0.0.1:0", "--metrics",
                   "127.0.0.1:0"},
                  dir);
  EXPECT_EQ(agg.WaitExit(10s), 1);
  EXPECT_NE(agg.stderr_text().find("'middle' reaches beyond patch forearm's surface"), std::string::npos)
      << agg.stderr_text();
}

}  // namespace

// A model that refuses faint contacts below 1 N (Preprocessing.faint_refuse_below_n) must not sit under a stop
// rule that could stop on less: with sd_k 3 and the model's largest sd 0.2 N, a 0.9 N reading stops at 1.5 N.
// The aggregator refuses that scene and says why; with sd_k 1 (stops down to 1.3 N) it loads.
TEST(CoverageProcess, AFaintRefusingModelUnderAStopRuleThatCouldStopBelowItIsRefused) {
  const auto refusing = [](v1::DecoderModel& m) {
    m.mutable_preprocessing()->set_faint_refuse_below_n(1.0f);
    auto* u = m.mutable_uncertainty();
    u->clear_force_knots_n();
    u->clear_force_sd_n();
    u->clear_position_scale();
    for (auto [knot, sd] : {std::pair{0.1f, 0.1f}, {2.0f, 0.2f}}) {
      u->add_force_knots_n(knot);
      u->add_force_sd_n(sd);
      u->add_position_scale(1.0f);
    }
  };
  const auto rule = [](const char* k) {
    return kBand + "  stop_rule:\n    sd_k: " + k + "\n    source: coverage_process_test\n";
  };
  const std::string dir = (fs::current_path() / "coverage_faint").string();
  const std::string scene = MakeScene(dir, rule("3"), refusing);
  rt::Process agg({RUFFINI_AGGREGATOR_EXE, "--insecure", "--scene", scene, "--listen", "127.0.0.1:0", "--metrics",
                   "127.0.0.1:0"},
                  dir);
  EXPECT_EQ(agg.WaitExit(10s), 1);
  EXPECT_NE(agg.stderr_text().find("refuses faint contacts below 1.00 N, but region 'forearm' (threshold 1.50 N, stop "
                                   "rule sd_k 3.00) may stop on a force of 0.90 N"),
            std::string::npos)
      << agg.stderr_text();
  rt::Process check({RUFFINI_EXE, "check-scene", scene}, dir);
  EXPECT_EQ(check.WaitExit(30s), 1) << check.stdout_text() << check.stderr_text();
  const std::string dir1 = (fs::current_path() / "coverage_faint_ok").string();
  rt::Process ok({RUFFINI_EXE, "check-scene", MakeScene(dir1, rule("1"), refusing)}, dir1);
  EXPECT_EQ(ok.WaitExit(30s), 0) << ok.stdout_text() << ok.stderr_text();
  rt::Process plain({RUFFINI_EXE, "check-scene", MakeScene(dir1, rule("3"))}, dir1);
  EXPECT_EQ(plain.WaitExit(30s), 0) << "the flag-only model under the same rule\n" << plain.stdout_text() << plain.stderr_text();
}

// Review 7 (docs/reviews/faint-refusal.md), finding 3: the faint-refusal check compares each patch's refusal
// force with its region's threshold alone, but a contact on a seam is judged on the sum of both sides' forces
// (safety.seam_sum, aggregate::Core::JudgeOnSeam; the fuser adds them as well). On the
// cobot scene (forearm_a | forearm_b, a seam, 1.5 N) with both forearm models refusing below 1 N, a seam touch
// read 0.8 N on each side stops at 1.6 N flag only and is refused on both sides (no contact at all). The
// property: a scene where refused frames could add up to a stop is refused (or the threshold is at least the
// largest sum of refusal forces a fused contact can have).
TEST(CoverageProcess, ASceneWhereRefusedFaintFramesOfASeamCouldAddUpToAStopIsRefused) {
  const std::string dir = (fs::current_path() / "coverage_faint_seam").string();
  fs::remove_all(dir);
  fs::create_directories(dir);
  for (const char* p : {"forearm_a", "forearm_b"}) {
    v1::DecoderModel m = ruffini::decode::LoadModel(kSrc + "/config/models/cobot-" + p + ".rmodel");
    m.mutable_preprocessing()->set_faint_refuse_below_n(1.0f);
    // The test's premise: the maps still hold for the refusing decoder (it refuses only below 1 N); re-stamp them
    // so the scene is refused for the seam, not for maps measured with another decoder.
    for (auto& map : *m.mutable_sensitivity()) map.set_model_sha256(ruffini::aggregator::DecoderSha256(m));
    ruffini::decode::SaveModel(dir + "/refusing-" + p + ".rmodel", m);
  }
  std::ifstream in(kSrc + "/config/scenes/cobot.yaml");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  auto replace_all = [&](const std::string& from, const std::string& to) {
    for (std::size_t at = text.find(from); at != std::string::npos; at = text.find(from, at + to.size())) {
      text.replace(at, from.size(), to);
    }
  };
  replace_all("../models/cobot-forearm_a.rmodel", dir + "/refusing-forearm_a.rmodel");
  replace_all("../models/cobot-forearm_b.rmodel", dir + "/refusing-forearm_b.rmodel");
  replace_all("../", kSrc + "/config/");
  const std::string scene = dir + "/cobot-refusing.yaml";
  std::ofstream(scene) << text;
  // the same scene with the shipped (flag-only) models loads: the test can tell
  std::string plain_text = text;
  {
    std::string t = text;
    for (const char* p : {"forearm_a", "forearm_b"}) {
      const std::string from = dir + "/refusing-" + p + ".rmodel";
      t.replace(t.find(from), from.size(), kSrc + "/config/models/cobot-" + p + ".rmodel");
    }
    plain_text = t;
  }
  std::ofstream(dir + "/cobot-plain.yaml") << plain_text;
  rt::Process plain({RUFFINI_EXE, "check-scene", dir + "/cobot-plain.yaml"}, dir);
  ASSERT_EQ(plain.WaitExit(60s), 0) << plain.stdout_text() << plain.stderr_text();
  rt::Process check({RUFFINI_EXE, "check-scene", scene}, dir);
  EXPECT_EQ(check.WaitExit(60s), 1) << "check-scene accepts two refusing models on a seam under a 1.5 N region:\n"
                                    << check.stdout_text() << check.stderr_text();
  EXPECT_NE(check.stderr_text().find("but the patch shares a seam"), std::string::npos) << check.stderr_text();
  EXPECT_EQ(check.stdout_text().find("maps not used"), std::string::npos) << check.stdout_text();
}
