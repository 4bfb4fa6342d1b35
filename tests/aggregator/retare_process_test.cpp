// The re-tare end to end (issue 17, docs/safety.md "Re-tare") with the real executables on 127.0.0.1 (port 0,
// ports files): ruffini-sim plays tests/aggregator/retare-scenario.yaml (a grating left 0.8 pm low: the
// decoder's baseline goes stale and stays stale; then a 1 N press held 22 s), one ruffini-decoder (staleness
// after 2 s), ruffini-aggregator; this test is the operator (GetStatus, RetarePatch, ResetStop). Every wait is
// a condition with a deadline; every process is stopped by pid. The sim's clock starts with its process:
// the press is asked about in the middle of its 22 s hold, well clear of the start-up's jitter.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <chrono>
#include <string>
#include <thread>

#include "process.h"
#include "ruffini/v1/aggregator.grpc.pb.h"
#include "scrape.h"
#include "service_process.h"

namespace {

using namespace std::chrono_literals;
namespace v1 = ruffini::v1;
namespace rt = ruffini::testing;
namespace fs = std::filesystem;

const std::string kSrc = RUFFINI_SOURCE_DIR;
const std::string kScene = kSrc + "/tests/aggregator/retare.yaml";
const std::string kScenario = kSrc + "/tests/aggregator/retare-scenario.yaml";

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
  v1::RetarePatchResponse Retare(std::uint64_t run) {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 2s);
    v1::RetarePatchRequest r;
    r.set_patch_id("forearm");
    r.set_aggregator_run_id(run);
    r.set_operator_name("retare_process_test");
    r.set_operator_note("patch stuck in baseline_stale");
    v1::RetarePatchResponse resp;
    const grpc::Status st = stub_->RetarePatch(&ctx, r, &resp);
    EXPECT_TRUE(st.ok()) << st.error_message();
    return resp;
  }
  v1::ResetStopResponse Reset() {
    const auto s = Status();
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 2s);
    v1::ResetStopRequest r;
    r.set_stop_epoch(s.safety().stop_epoch());
    r.set_aggregator_run_id(s.aggregator_run_id());
    r.set_operator_name("retare_process_test");
    v1::ResetStopResponse resp;
    stub_->ResetStop(&ctx, r, &resp);
    return resp;
  }
  // Asks for a re-tare and waits for the decoder's answer to it.
  v1::RetareResult RetareAndWait(std::uint64_t run) {
    const auto sent = Retare(run);
    EXPECT_TRUE(sent.sent()) << sent.message();
    v1::RetareResult result;
    EXPECT_TRUE(rt::WaitFor([&] {
      const auto p = Patch();
      result = p.last_retare();
      return result.request_id() == sent.request_id() && p.retare_pending() == 0;
    }, 10s, 20ms)) << "no answer to re-tare " << sent.request_id();
    return result;
  }

 private:
  std::unique_ptr<v1::Aggregator::Stub> stub_;
};

bool Stale(const v1::PatchStatus& p) { return p.last_heartbeat().baseline_state() == v1::BASELINE_STATE_STALE; }

// Review 6 (docs/reviews/retare-field.md), end to end. A field across the cover (around the limb only, 1 C) makes
// the patch stuck; a 1.5 N press held at (37.5, 22.5), outside the edge bands, must refuse a re-tare. With the
// field-separating judge on in the service (commit 4e97a65) the service accepted it and the press went into the
// baseline; the service now judges as before (the touch takes every shift) and refuses.
TEST(RetareProcess, AFieldStuckPatchRefusesAReTareWhileAPressOutsideTheEdgeBandsIsHeld) {
  const std::string scenario = kSrc + "/tests/aggregator/retare-field-review-scenario.yaml";
  const std::string base = (fs::current_path() / "retare_field_review").string();
  int grpc_port = 0, sim_port = 0, decoder_metrics = 0;
  rt::Process agg = rt::StartWithPorts({RUFFINI_AGGREGATOR_EXE, "--insecure", "--scene", kScene, "--listen", "127.0.0.1:0",
                                        "--metrics", "127.0.0.1:0", "--patch-silence-ms", "200", "--patch-freshness-ms", "200"},
                                       base + "/aggregator", "grpc", grpc_port);
  const std::string address = "127.0.0.1:" + std::to_string(grpc_port);
  Operator op(address);
  rt::Process sim = rt::StartWithPorts({RUFFINI_SIM_EXE, "--scene", kScene, "--scenario", scenario, "--rate-hz", "1000",
                                        "--command-port", "0", "--stream-port", "0"},
                                       base + "/sim", "stream", sim_port);
  const auto sim_started = std::chrono::steady_clock::now();
  auto sim_s = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - sim_started).count(); };
  rt::Process decoder = rt::StartWithPorts({RUFFINI_DECODER_EXE, "--insecure", "--scene", kScene, "--interrogator",
                                            "127.0.0.1:" + std::to_string(sim_port), "--aggregator", address, "--metrics",
                                            "127.0.0.1:0", "--rate-hz", "1000", "--silence-ms", "100",
                                            "--freshness-budget-ms", "200", "--max-frozen-s", "2"},
                                           base + "/decoder", "metrics", decoder_metrics);
  const std::uint64_t run = op.Status().aggregator_run_id();
  ASSERT_NE(run, 0u);
  ASSERT_TRUE(rt::WaitFor([&] { return op.Reset().accepted(); }, 10s, 100ms)) << agg.stderr_text() << decoder.stderr_text();
  // The field's phantom: stale, FAULT, the robot held.
  ASSERT_TRUE(rt::WaitFor([&] { return Stale(op.Patch()); }, 15s, 20ms)) << decoder.stderr_text();
  ASSERT_TRUE(rt::WaitFor([&] { return op.Status().safety().state() == v1::SafetyState::STATE_FAULT; }, 2s, 20ms));
  ASSERT_LT(sim_s(), 11.0) << "the machine is too slow for this scenario's timeline";
  // In the middle of the press's hold (12.3 to 34.3 s at the sim's clock): refused.
  ASSERT_TRUE(rt::WaitFor([&] { return sim_s() > 20.0; }, 25s, 50ms));
  const auto pressing = op.RetareAndWait(run);
  EXPECT_LT(sim_s(), 33.0) << "the answer came after the press ended: the timeline did not hold";
  EXPECT_EQ(pressing.outcome(), v1::RETARE_OUTCOME_PRESSING) << pressing.DebugString();
  EXPECT_TRUE(Stale(op.Patch()));
}

TEST(RetareProcess, AStuckPatchIsRefusedUnderAPressAcceptedAfterItHealsAndAResetClears) {
  const std::string base = (fs::current_path() / "retare_chain").string();
  int grpc_port = 0, sim_port = 0, decoder_metrics = 0;
  rt::Process agg = rt::StartWithPorts({RUFFINI_AGGREGATOR_EXE, "--insecure", "--scene", kScene, "--listen", "127.0.0.1:0",
                                        "--metrics", "127.0.0.1:0", "--patch-silence-ms", "200", "--patch-freshness-ms", "200"},
                                       base + "/aggregator", "grpc", grpc_port);
  const std::string address = "127.0.0.1:" + std::to_string(grpc_port);
  Operator op(address);
  rt::Process sim = rt::StartWithPorts({RUFFINI_SIM_EXE, "--scene", kScene, "--scenario", kScenario, "--rate-hz", "1000",
                                        "--command-port", "0", "--stream-port", "0"},
                                       base + "/sim", "stream", sim_port);
  const auto sim_started = std::chrono::steady_clock::now();
  auto sim_s = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - sim_started).count(); };
  rt::Process decoder = rt::StartWithPorts({RUFFINI_DECODER_EXE, "--insecure", "--scene", kScene, "--interrogator",
                                            "127.0.0.1:" + std::to_string(sim_port), "--aggregator", address, "--metrics",
                                            "127.0.0.1:0", "--rate-hz", "1000", "--silence-ms", "100",
                                            "--freshness-budget-ms", "200", "--max-frozen-s", "2"},
                                           base + "/decoder", "metrics", decoder_metrics);
  const std::uint64_t run = op.Status().aggregator_run_id();
  ASSERT_NE(run, 0u);

  // Healthy, then an operator reset clears the start-up FAULT (before the grating goes off at 4 s).
  ASSERT_TRUE(rt::WaitFor([&] { return op.Reset().accepted(); }, 10s, 100ms)) << agg.stderr_text() << decoder.stderr_text();
  EXPECT_EQ(op.Status().safety().state(), v1::SafetyState::STATE_CLEAR);
  // While CLEAR a re-tare is refused: the robot is not held.
  const auto not_held = op.Retare(run);
  EXPECT_FALSE(not_held.sent());
  EXPECT_EQ(not_held.reason(), v1::RETARE_REFUSAL_NOT_HELD);

  // The phantom keeps the gate open: the baseline goes stale, the patch faults, the robot is held.
  ASSERT_TRUE(rt::WaitFor([&] { return Stale(op.Patch()); }, 15s, 20ms)) << decoder.stderr_text();
  ASSERT_TRUE(rt::WaitFor([&] { return op.Status().safety().state() == v1::SafetyState::STATE_FAULT; }, 2s, 20ms));
  ASSERT_LT(sim_s(), 11.0) << "the machine is too slow for this scenario's timeline";
  EXPECT_FALSE(op.Reset().accepted()) << "a reset is refused while the baseline is stale";
  // Another run's request is refused and sends nothing.
  const auto wrong_run = op.Retare(run + 1);
  EXPECT_FALSE(wrong_run.sent());
  EXPECT_EQ(wrong_run.reason(), v1::RETARE_REFUSAL_WRONG_RUN);

  // In the middle of the press's hold (12.3 to 34.3 s at the sim's clock): refused, and still stale.
  ASSERT_TRUE(rt::WaitFor([&] { return sim_s() > 20.0; }, 25s, 50ms));
  const auto pressing = op.RetareAndWait(run);
  EXPECT_EQ(pressing.outcome(), v1::RETARE_OUTCOME_PRESSING) << pressing.DebugString();
  EXPECT_GE(pressing.force_n(), pressing.min_force_n());
  EXPECT_FLOAT_EQ(pressing.min_force_n(), 0.75f);  // half the region's 1.5 N
  EXPECT_LT(sim_s(), 33.0) << "the answer came after the press ended: the timeline did not hold";
  EXPECT_TRUE(Stale(op.Patch()));
  EXPECT_FALSE(op.Reset().accepted());

  // After the release the patch stays stale by itself (stuck) ...
  ASSERT_TRUE(rt::WaitFor([&] { return sim_s() > 37.0; }, 25s, 50ms));
  EXPECT_TRUE(Stale(op.Patch())) << "the stale baseline ended by itself: the scenario does not make a stuck patch";
  EXPECT_EQ(op.Status().safety().state(), v1::SafetyState::STATE_FAULT);
  // ... until a re-tare: accepted, the patch heals, a reset clears.
  const auto accepted = op.RetareAndWait(run);
  EXPECT_EQ(accepted.outcome(), v1::RETARE_OUTCOME_ACCEPTED) << accepted.DebugString();
  EXPECT_LT(accepted.force_n(), accepted.min_force_n());
  ASSERT_TRUE(rt::WaitFor([&] {
    const auto p = op.Patch();
    return p.last_heartbeat().healthy() && p.last_heartbeat().baseline_state() == v1::BASELINE_STATE_TRACKING;
  }, 5s, 20ms)) << op.Patch().DebugString();
  ASSERT_TRUE(rt::WaitFor([&] { return op.Reset().accepted(); }, 5s, 100ms)) << agg.stderr_text();
  EXPECT_EQ(op.Status().safety().state(), v1::SafetyState::STATE_CLEAR);

  // Counted at both ends, and logged by the aggregator.
  const std::string m = rt::Scrape(decoder_metrics);
  EXPECT_NE(m.find("ruffini_decoder_retares_total{patch=\"forearm\",outcome=\"pressing\"} 1"), std::string::npos) << m;
  EXPECT_NE(m.find("ruffini_decoder_retares_total{patch=\"forearm\",outcome=\"accepted\"} 1"), std::string::npos) << m;
  const std::string log = agg.stderr_text() + agg.stdout_text();
  EXPECT_NE(log.find("RETARE_OUTCOME_PRESSING"), std::string::npos);
  EXPECT_NE(log.find("RETARE_OUTCOME_ACCEPTED"), std::string::npos);

  decoder.Stop();
  sim.Stop();
  agg.Stop();
}

}  // namespace
