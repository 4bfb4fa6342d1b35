// Review 7 (docs/reviews/faint-refusal.md), end to end with the real executables on 127.0.0.1 (port 0, ports
// files): ruffini-sim plays tests/aggregator/faint-review-scenario.yaml (grating 16 left 0.8 pm low from 4 s: a
// faint phantom; a 2.25 N press at the centre from 14 s), one ruffini-decoder on the field model (it refuses
// faint contacts below 1 N; staleness after 2 or 8 s), ruffini-aggregator (1.5 N). This test is the operator
// (GetStatus, ResetStop) and scrapes the decoder's metrics. Every wait is a condition with a deadline; every
// process is stopped by pid. The sim's clock starts with its process.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "process.h"
#include "ruffini/decode/model_io.h"
#include "ruffini/v1/aggregator.grpc.pb.h"
#include "scrape.h"
#include "service_process.h"

namespace {

using namespace std::chrono_literals;
namespace v1 = ruffini::v1;
namespace rt = ruffini::testing;
namespace fs = std::filesystem;

const std::string kSrc = RUFFINI_SOURCE_DIR;
const std::string kScene = kSrc + "/tests/aggregator/faint-review.yaml";
const std::string kScenario = kSrc + "/tests/aggregator/faint-review-scenario.yaml";

class Operator {
 public:
  explicit Operator(const std::string& address)
      : stub_(v1::Aggregator::NewStub(grpc::CreateChannel(address, grpc::InsecureChannelCredentials()))) {}
  v1::AggregatorStatus Status() {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 2s);
    v1::AggregatorStatus s;
    stub_->GetStatus(&ctx, v1::GetStatusRequest{}, &s);
    return s;
  }
  v1::PatchStatus Patch() {
    const auto s = Status();
    return s.patches_size() > 0 ? s.patches(0) : v1::PatchStatus{};
  }
  bool Reset() {
    const auto s = Status();
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 2s);
    v1::ResetStopRequest r;
    r.set_stop_epoch(s.safety().stop_epoch());
    r.set_aggregator_run_id(s.aggregator_run_id());
    r.set_operator_name("faint_review_process_test");
    v1::ResetStopResponse resp;
    stub_->ResetStop(&ctx, r, &resp);
    return resp.accepted();
  }

 private:
  std::unique_ptr<v1::Aggregator::Stub> stub_;
};

std::vector<std::string> Concat(std::vector<std::string> a, const std::vector<std::string>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

struct Rig {
  std::string base;
  std::string scenario;
  std::string scene;
  int grpc_port = 0, sim_port = 0, decoder_metrics = 0;
  rt::Process agg, sim;
  std::chrono::steady_clock::time_point sim_started;  // initialised in this order: after the sim, before the decoder
  rt::Process decoder;
  explicit Rig(const std::string& name, const std::string& scenario_path = kScenario, const std::string& max_frozen_s = "2",
               const std::string& scene_path = kScene, const std::vector<std::string>& decoder_extra = {})
      : base((fs::current_path() / name).string()),
        scenario(scenario_path),
        scene(scene_path),
        agg(rt::StartWithPorts({RUFFINI_AGGREGATOR_EXE, "--insecure", "--scene", scene, "--listen", "127.0.0.1:0",
                                "--metrics", "127.0.0.1:0", "--patch-silence-ms", "200", "--patch-freshness-ms", "200"},
                               base + "/aggregator", "grpc", grpc_port)),
        sim(rt::StartWithPorts({RUFFINI_SIM_EXE, "--scene", scene, "--scenario", scenario, "--rate-hz", "100",
                                "--command-port", "0", "--stream-port", "0"},
                               base + "/sim", "stream", sim_port)),
        sim_started(std::chrono::steady_clock::now()),
        decoder(rt::StartWithPorts(Concat({RUFFINI_DECODER_EXE, "--insecure", "--scene", scene, "--interrogator",
                                           "127.0.0.1:" + std::to_string(sim_port), "--aggregator",
                                           "127.0.0.1:" + std::to_string(grpc_port), "--metrics", "127.0.0.1:0",
                                           "--rate-hz", "100", "--silence-ms", "100", "--freshness-budget-ms", "200",
                                           "--max-frozen-s", max_frozen_s},
                                          decoder_extra),
                                   base + "/decoder", "metrics", decoder_metrics)) {}
  [[nodiscard]] std::string address() const { return "127.0.0.1:" + std::to_string(grpc_port); }
  [[nodiscard]] double sim_s() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - sim_started).count();
  }
};

// The phantom that latches a flag-only decoder into a stale FAULT (the re-tare test's scenario; flag only it
// FAULTs about 12 s in, FlagOnlyTheSameHeldErrorFaultsBeforeThePress) FAULTs the refusing decoder as well, since
// review 7's fix (the stale clock runs while faint frames are refused): the robot is stopped before the press
// comes. The refusal is named in the decoder's log and its frames are counted.
TEST(FaintReviewProcess, ARefusingDecoderFaultsTheHeldPhantomAsFlagOnlyDoesAndNamesTheRefusal) {
  Rig rig("faint_review_stop", kScenario, "8");
  Operator op(rig.address());
  ASSERT_TRUE(rt::WaitFor([&] { return op.Reset(); }, 10s, 100ms)) << rig.agg.stderr_text() << rig.decoder.stderr_text();
  ASSERT_LT(rig.sim_s(), 4.0) << "the machine is too slow for this scenario's timeline";
  // The phantom from 4 s: by 13.5 s (past max_frozen_s 8 s) the patch is stale and the robot is not CLEAR.
  ASSERT_TRUE(rt::WaitFor([&] { return rig.sim_s() > 13.5; }, 15s, 50ms));
  const auto before = op.Status();
  EXPECT_NE(before.safety().state(), v1::SafetyState::STATE_CLEAR) << before.safety().DebugString();
  EXPECT_EQ(before.patches(0).last_heartbeat().baseline_state(), v1::BASELINE_STATE_STALE)
      << "refusing, the held phantom must go stale as flag only does";
  const std::string log = rig.decoder.stderr_text() + rig.decoder.stdout_text();
  EXPECT_NE(log.find("faint frames below 1.00 N refused (the model's)"), std::string::npos) << log;
  const std::string m = rt::Scrape(rig.decoder_metrics);
  EXPECT_NE(m.find("faint_refuse_below_n=\"1.00\""), std::string::npos) << m;
  EXPECT_NE(m.find("ruffini_decoder_frames_faint_total"), std::string::npos) << m;
  rig.decoder.Stop();
  rig.sim.Stop();
}

// The heartbeat says how long the baseline has been frozen (Heartbeat.baseline_frozen_s, "How long the baseline
// has been frozen, s"): that is what an operator or the aggregator can see of a baseline held against a faint
// phantom. Under kHold the stale clock does not run, and the heartbeat reports the clock, not the time held:
// measured 0.0 s after 8 s of hold.
TEST(FaintReviewProcess, AHeldBaselineIsReportedFrozenForAsLongAsItIsHeld) {
  Rig rig("faint_review_frozen", kScenario, "8");
  Operator op(rig.address());
  ASSERT_TRUE(rt::WaitFor([&] { return op.Reset(); }, 10s, 100ms)) << rig.agg.stderr_text() << rig.decoder.stderr_text();
  ASSERT_TRUE(rt::WaitFor([&] { return rig.sim_s() > 12.0; }, 15s, 50ms));
  const auto hb = op.Patch().last_heartbeat();
  ASSERT_EQ(hb.baseline_state(), v1::BASELINE_STATE_FROZEN) << hb.DebugString();
  EXPECT_GT(hb.baseline_frozen_s(), 4.0) << "held since the phantom at 4 s (now " << rig.sim_s() << " s)\n" << hb.DebugString();
  rig.decoder.Stop();
  rig.sim.Stop();
}

// A baseline error the refusal holds: grating 15 0.8 pm low from 4 s, then 2.25 N at the wrist edge on FBG 16
// from 20 s, held 5 s (faint-review-held-scenario.yaml; the decoder's max_frozen_s 8 s). Flag only the error
// makes the patch stale at about 12 s: FAULT. Refusing, nothing is reported and nothing faults before the
// press, and the press is read below the threshold. The property: the robot is held (STOP or FAULT) by the
// end of the press's hold. Measured: CLEAR throughout.
TEST(FaintReviewProcess, APressAtTheWristEdgeOverAHeldBaselineErrorHoldsTheRobot) {
  Rig rig("faint_review_held", kSrc + "/tests/aggregator/faint-review-held-scenario.yaml", "8");
  Operator op(rig.address());
  ASSERT_TRUE(rt::WaitFor([&] { return op.Reset(); }, 10s, 100ms)) << rig.agg.stderr_text() << rig.decoder.stderr_text();
  ASSERT_LT(rig.sim_s(), 4.0) << "the machine is too slow for this scenario's timeline";
  ASSERT_TRUE(rt::WaitFor([&] { return rig.sim_s() > 19.0; }, 25s, 50ms));
  const auto before = op.Status();
  std::printf("at 19 s (15 s into the error, max_frozen_s 8): %s, baseline %s, frozen_s %.1f\n",
              v1::SafetyState::State_Name(before.safety().state()).c_str(),
              v1::BaselineState_Name(before.patches(0).last_heartbeat().baseline_state()).c_str(),
              before.patches(0).last_heartbeat().baseline_frozen_s());
  // By the end of the press's hold (26 s at the sim's clock) the robot must be held.
  const bool held = rt::WaitFor([&] { return op.Status().safety().state() != v1::SafetyState::STATE_CLEAR; }, 10s, 20ms) &&
                    rig.sim_s() < 26.0;
  const auto st = op.Status();
  std::printf("at %.2f s: %s %s\n", rig.sim_s(), v1::SafetyState::State_Name(st.safety().state()).c_str(),
              st.safety().cause().DebugString().c_str());
  EXPECT_TRUE(held) << st.patches(0).last_heartbeat().DebugString();
  rig.decoder.Stop();
  rig.sim.Stop();
}

// Review 7 finding 4: the aggregator checks a refusing model against the region's threshold only when the
// scene names the model (`model:`; the hello's model_sha256 is then checked against it). A scene that names
// none takes any decoder's model: here a 0.8 N region, and a decoder given --model forearm-field.rmodel,
// which refuses faint contacts up to 1 N (a faint 0.8-1 N contact is no contact: the region's stop is lowered
// by the refusal). The hello does not carry the refusal (DecoderConfig has no faint field). The property: the
// aggregator does not run a patch whose decoder may refuse a force its region stops on. Measured: the patch
// is healthy and the aggregator CLEAR.
TEST(FaintReviewProcess, ADecoderThatRefusesBelowItsRegionsThresholdIsNotRunUnseen) {
  const std::string dir = (fs::current_path() / "faint_review_nomodel").string();
  fs::create_directories(dir);
  std::ifstream in(kScene);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string model_line = "    model: ../../config/models/forearm-field.rmodel\n";
  ASSERT_NE(text.find(model_line), std::string::npos);
  text.erase(text.find(model_line), model_line.size());
  text.replace(text.find("threshold_n: 1.5"), 16, "threshold_n: 0.8");
  for (std::size_t at = text.find("../../"); at != std::string::npos; at = text.find("../../", at)) text.replace(at, 6, kSrc + "/");
  const std::string scene = dir + "/no-model.yaml";
  std::ofstream(scene) << text;
  Rig rig("faint_review_nomodel", kScenario, "2", scene, {"--model", kSrc + "/config/models/forearm-field.rmodel"});
  Operator op(rig.address());
  const bool cleared = rt::WaitFor([&] { return op.Reset(); }, 10s, 100ms);
  const auto st = op.Status();
  std::printf("scene without a model, 0.8 N region, decoder on forearm-field.rmodel: reset %s, link %s, state %s\n",
              cleared ? "accepted" : "refused", v1::LinkState_Name(st.patches(0).link_state()).c_str(),
              v1::SafetyState::State_Name(st.safety().state()).c_str());
  EXPECT_FALSE(cleared) << rig.agg.stderr_text();
  rig.decoder.Stop();
  rig.sim.Stop();
}

// The contrast to finding 1: the same scenario, the decoder on a copy of the field model with the refusal off
// (faint_refuse_below_n 0, flag only). The error keeps the gate open, the baseline goes stale within
// max_frozen_s (8 s) and the patch FAULTs long before the press. Holds.
TEST(FaintReviewProcess, FlagOnlyTheSameHeldErrorFaultsBeforeThePress) {
  const std::string dir = (fs::current_path() / "faint_review_flag_only").string();
  fs::create_directories(dir);
  v1::DecoderModel m = ruffini::decode::LoadModel(kSrc + "/config/models/forearm-field.rmodel");
  ASSERT_GT(m.preprocessing().faint_refuse_below_n(), 0.0f) << "the shipped field model refuses";
  m.mutable_preprocessing()->set_faint_refuse_below_n(0.0f);
  ruffini::decode::SaveModel(dir + "/forearm-field-flag-only.rmodel", m);
  std::ifstream in(kScene);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string model_line = "../../config/models/forearm-field.rmodel";
  ASSERT_NE(text.find(model_line), std::string::npos);
  text.replace(text.find(model_line), model_line.size(), dir + "/forearm-field-flag-only.rmodel");
  for (std::size_t at = text.find("../../"); at != std::string::npos; at = text.find("../../", at)) text.replace(at, 6, kSrc + "/");
  const std::string scene = dir + "/flag-only.yaml";
  std::ofstream(scene) << text;
  Rig rig("faint_review_flag_only_run", kSrc + "/tests/aggregator/faint-review-held-scenario.yaml", "8", scene);
  Operator op(rig.address());
  ASSERT_TRUE(rt::WaitFor([&] { return op.Reset(); }, 10s, 100ms)) << rig.agg.stderr_text() << rig.decoder.stderr_text();
  ASSERT_LT(rig.sim_s(), 4.0) << "the machine is too slow for this scenario's timeline";
  ASSERT_TRUE(rt::WaitFor([&] { return op.Status().safety().state() != v1::SafetyState::STATE_CLEAR; }, 20s, 20ms));
  const auto st = op.Status();
  std::printf("flag only: held at %.2f s: %s\n", rig.sim_s(), st.safety().cause().DebugString().c_str());
  EXPECT_LT(rig.sim_s(), 20.0) << "held only at the press";
  EXPECT_EQ(st.safety().state(), v1::SafetyState::STATE_FAULT);
  EXPECT_EQ(st.safety().cause().patch_fault(), v1::PATCH_FAULT_CODE_BASELINE_STALE) << st.safety().DebugString();
  rig.decoder.Stop();
  rig.sim.Stop();
}

}  // namespace
