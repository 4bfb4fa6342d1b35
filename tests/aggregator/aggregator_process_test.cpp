// The whole chain as real processes on 127.0.0.1 (port 0, ports files): ruffini-sim on the cobot scene with a
// scripted scenario, one ruffini-decoder per patch, ruffini-aggregator; this test is the controller (a
// WatchSafety subscriber and a 100 Hz joint-state publisher over gRPC). Every wait is a condition with a
// deadline; every process is stopped by pid.
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <fstream>
#include <future>
#include <map>
#include <optional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "process.h"
#include "service_process.h"
#include "scrape.h"
#include "ruffini/v1/aggregator.grpc.pb.h"

namespace {

using namespace std::chrono_literals;
namespace v1 = ruffini::v1;
namespace rt = ruffini::testing;
namespace fs = std::filesystem;

const std::string kSrc = RUFFINI_SOURCE_DIR;
const std::string kScene = kSrc + "/config/scenes/cobot.yaml";
const std::string kScenario = kSrc + "/config/scenarios/cobot-demo.yaml";
const std::vector<std::string> kPatches = {"forearm_a", "forearm_b", "upper_arm_a", "upper_arm_b"};

using rt::ReadPorts;

struct Seen {
  v1::SafetyState state;
  std::int64_t arrival_ns = 0;
};

std::int64_t UnixNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count();
}

// The test's controller: subscribes to WatchSafety, publishes joint states at 100 Hz. With `resubscribe` it
// subscribes again when its stream ends (as a real controller would, halted meanwhile: on a loaded machine the
// aggregator drops a subscriber whose write is stuck for 50 ms); ended() is then true only after the destructor.
class Controller {
 public:
  explicit Controller(const std::string& address, bool resubscribe = false) : resubscribe_(resubscribe) {
    channel_ = grpc::CreateChannel(address, grpc::InsecureChannelCredentials());
    stub_ = v1::Aggregator::NewStub(channel_);
    watcher_ = std::thread([this] { Watch(); });
  }
  ~Controller() {
    StopJoints();
    {
      std::lock_guard lock(mu_);
      closing_ = true;
      if (watch_ctx_) watch_ctx_->TryCancel();
    }
    watcher_.join();
  }
  void StartJoints(const std::vector<std::string>& names) {
    joints_ = std::thread([this, names] {
      grpc::ClientContext ctx;
      v1::PublishJointStatesResponse resp;
      auto w = stub_->PublishJointStates(&ctx, &resp);
      std::uint64_t seq = 0;
      while (!stop_joints_) {
        v1::JointState js;
        for (std::size_t i = 0; i < names.size(); ++i) {
          js.add_names(names[i]);
          js.add_positions_rad(0.3 * std::sin(1e-9 * static_cast<double>(UnixNs()) + static_cast<double>(i)));
        }
        js.set_t_ns(UnixNs());
        js.set_seq(++seq);
        if (!w->Write(js)) break;
        std::this_thread::sleep_for(10ms);  // the publishing period of a 100 Hz controller, not a wait
      }
      w->WritesDone();
      w->Finish();
    });
  }
  void StopJoints() {
    stop_joints_ = true;
    if (joints_.joinable()) joints_.join();
  }
  v1::AggregatorStatus Status() {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 2s);
    v1::AggregatorStatus s;
    stub_->GetStatus(&ctx, v1::GetStatusRequest{}, &s);
    return s;
  }
  v1::ResetStopResponse Reset(std::uint64_t epoch) {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 2s);
    v1::ResetStopRequest r;
    r.set_stop_epoch(epoch);
    r.set_aggregator_run_id(Status().aggregator_run_id());  // the run whose epoch this is
    r.set_operator_name("aggregator_process_test");
    v1::ResetStopResponse resp;
    stub_->ResetStop(&ctx, r, &resp);
    return resp;
  }
  std::vector<Seen> Snapshot() {
    std::lock_guard lock(mu_);
    return seen_;
  }
  bool ended() const { return ended_; }
  // From now on the next end of the stream is final (ended() turns true).
  void StopResubscribing() { resubscribe_ = false; }
  grpc::Status end_status() {
    std::lock_guard lock(mu_);
    return end_;
  }

 private:
  void Watch() {
    for (;;) {
      grpc::ClientContext ctx;
      {
        std::lock_guard lock(mu_);
        if (closing_) return;
        watch_ctx_ = &ctx;
      }
      v1::WatchSafetyRequest req;
      req.set_subscriber("aggregator_process_test");
      auto r = stub_->WatchSafety(&ctx, req);
      v1::SafetyState s;
      while (r->Read(&s)) {
        std::lock_guard lock(mu_);
        seen_.push_back({s, UnixNs()});
      }
      const grpc::Status st = r->Finish();
      std::lock_guard lock(mu_);
      watch_ctx_ = nullptr;
      end_ = st;
      if (!resubscribe_ || closing_) {
        ended_ = true;
        return;
      }
      ++resubscribed_;
      std::this_thread::sleep_for(10ms);  // a reconnecting controller's pace, not a wait
    }
  }
  std::atomic<bool> resubscribe_;
  bool closing_ = false;
  int resubscribed_ = 0;
  grpc::ClientContext* watch_ctx_ = nullptr;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::Aggregator::Stub> stub_;
  std::thread watcher_, joints_;
  std::atomic<bool> stop_joints_{false}, ended_{false};
  std::mutex mu_;
  std::vector<Seen> seen_;
  grpc::Status end_;
};

// The newest state seen (a copy: snapshots are temporaries).
std::optional<Seen> Last(const std::vector<Seen>& s) {
  if (s.empty()) return std::nullopt;
  return s.back();
}

TEST(AggregatorProcess, StartsInFaultClearsByResetStopsOnAHardTouchNotOnALightOne) {
  const std::string base = (fs::current_path() / "aggregator_chain").string();
  int grpc_port = 0, sim_port = 0;
  // Deadlines widened (200 ms silence, 200 ms joint-state age, 200 ms freshness) so that a loaded 2-core CI machine does not
  // fault a healthy patch on the way to CLEAR; the scene's own 30 ms / 50 ms deadlines meet real processes in
  // TheScenesOwnDeadlinesASigstoppedDecoderFaultsWithinFiftyMs below (and on an injected clock in the safety tests).
  rt::Process agg = rt::StartWithPorts({RUFFINI_AGGREGATOR_EXE, "--insecure", "--scene", kScene, "--listen", "127.0.0.1:0", "--metrics",
                                    "127.0.0.1:0", "--patch-silence-ms", "200", "--joint-max-age-ms", "200",
                                    "--patch-freshness-ms", "200"},
                                   base + "/aggregator", "grpc", grpc_port);
  const std::string address = "127.0.0.1:" + std::to_string(grpc_port);
  Controller controller(address, /*resubscribe=*/true);
  // Before any decoder: FAULT, epoch 1, cause start-up; heartbeats every 10 ms.
  ASSERT_TRUE(rt::WaitFor([&] { return controller.Snapshot().size() >= 10; }, 5s)) << agg.stderr_text();
  {
    const auto seen = controller.Snapshot();
    EXPECT_EQ(seen.front().state.state(), v1::SafetyState::STATE_FAULT);
    EXPECT_EQ(seen.front().state.stop_epoch(), 1u);
    EXPECT_EQ(seen.front().state.cause().kind(), v1::SafetyCause::KIND_STARTUP);
    for (std::size_t i = 1; i < seen.size(); ++i) EXPECT_GT(seen[i].state.seq(), seen[i - 1].state.seq());
  }
  const auto status = controller.Status();
  ASSERT_EQ(status.joint_names_size(), 7);
  controller.StartJoints({status.joint_names().begin(), status.joint_names().end()});

  rt::Process sim = rt::StartWithPorts({RUFFINI_SIM_EXE, "--scene", kScene, "--scenario", kScenario, "--rate-hz", "1000",
                                    "--command-port", "0", "--stream-port", "0"},
                                   base + "/sim", "stream", sim_port);
  std::vector<rt::Process> decoders;
  for (const auto& p : kPatches) {
    int metrics = 0;
    decoders.push_back(rt::StartWithPorts({RUFFINI_DECODER_EXE, "--insecure", "--scene", kScene, "--patch", p, "--interrogator",
                                       "127.0.0.1:" + std::to_string(sim_port), "--aggregator", address, "--metrics",
                                       "127.0.0.1:0", "--rate-hz", "1000", "--silence-ms", "100",
                                       "--freshness-budget-ms", "200"},
                                      base + "/decoder_" + p, "metrics", metrics));
  }
  // A reset is refused while a patch is missing or not yet healthy; once every patch has been healthy for
  // 200 ms, a reset naming the current epoch clears.
  const auto refused = controller.Reset(1);
  EXPECT_FALSE(refused.accepted());
  bool cleared = false;
  ASSERT_TRUE(rt::WaitFor([&] {
    const auto seen = controller.Snapshot();
    if (seen.empty()) return false;
    const auto r = controller.Reset(seen.back().state.stop_epoch());
    cleared = r.accepted();
    return cleared;
  }, 10s, 100ms)) << agg.stderr_text();
  ASSERT_TRUE(rt::WaitFor([&] {
    const auto l = Last(controller.Snapshot());
    return l && l->state.state() == v1::SafetyState::STATE_CLEAR;
  }, 2s));
  const std::int64_t cleared_at = UnixNs();
  // A wrong epoch is refused and changes nothing.
  const auto wrong = controller.Reset(999);
  EXPECT_FALSE(wrong.accepted());
  EXPECT_EQ(wrong.state().state(), v1::SafetyState::STATE_CLEAR);

  // The scenario: a light touch at 4 s (no stop), a hard one on the forearm seam at 7 s (STOP).
  ASSERT_TRUE(rt::WaitFor([&] {
    const auto l = Last(controller.Snapshot());
    return l && l->state.state() != v1::SafetyState::STATE_CLEAR;
  }, 15s)) << agg.stderr_text();
  const auto seen = controller.Snapshot();
  // The first state after the CLEAR that is not CLEAR (the wait above polls; more may have arrived since).
  const Seen stop = *std::find_if(seen.begin(), seen.end(), [&](const Seen& s) {
    return s.arrival_ns >= cleared_at && s.state.state() != v1::SafetyState::STATE_CLEAR;
  });
  const std::int64_t clear_ms = (stop.arrival_ns - cleared_at) / 1'000'000;
  std::printf("[ metric ] CLEAR for %lld ms, then %s (cause %s, patch %s, force %.2f N > %.2f N): %s\n",
              static_cast<long long>(clear_ms), v1::SafetyState::State_Name(stop.state.state()).c_str(),
              v1::SafetyCause::Kind_Name(stop.state.cause().kind()).c_str(), stop.state.cause().patch_id().c_str(),
              static_cast<double>(stop.state.cause().force_n()), static_cast<double>(stop.state.cause().threshold_n()),
              stop.state.cause().message().c_str());
  EXPECT_EQ(stop.state.state(), v1::SafetyState::STATE_STOP) << stop.state.DebugString();
  EXPECT_EQ(stop.state.cause().kind(), v1::SafetyCause::KIND_CONTACT);
  EXPECT_TRUE(stop.state.cause().patch_id() == "forearm_a" || stop.state.cause().patch_id() == "forearm_b")
      << stop.state.cause().patch_id();
  EXPECT_EQ(stop.state.cause().link(), "forearm_link");
  EXPECT_EQ(stop.state.cause().body_region(), "forearm");
  EXPECT_GT(stop.state.cause().force_n(), 1.5f);
  EXPECT_GT(stop.state.stop_epoch(), 1u);
  // The stop came after the light touch (4 s to 6.1 s of the scenario) had passed without one.
  EXPECT_GT(clear_ms, 1500);
  // The body-frame position is set (the joint states place it).
  const auto& p = stop.state.cause().p_bc_m();
  EXPECT_GT(std::abs(p.x()) + std::abs(p.y()) + std::abs(p.z()), 0.1);
  // Frame-to-stop: the cause's frame time vs the STOP's arrival here.
  const double latency_ms = static_cast<double>(stop.arrival_ns - stop.state.cause().t_ns()) / 1e6;
  std::printf("[ metric ] frame-to-stop at the controller: %.3f ms\n", latency_ms);
  EXPECT_GT(latency_ms, 0.0);
  // A bound (review finding 15: only "> 0" was asserted, which the 29 s STOP of a throttled link passed). The
  // demo measures about 1 ms; 250 ms is generous for a loaded 2-core machine, and fails any stale stop.
  EXPECT_LT(latency_ms, 250.0);
  // STOP latches: it stays STOP (never CLEAR) after the touch is released.
  const std::int64_t stop_seen = UnixNs();
  ASSERT_TRUE(rt::WaitFor([&] { return Last(controller.Snapshot())->arrival_ns > stop_seen + 2'000'000'000; }, 5s));
  for (const auto& s : controller.Snapshot()) {
    if (s.arrival_ns >= stop.arrival_ns) {
      EXPECT_NE(s.state.state(), v1::SafetyState::STATE_CLEAR);
    }
  }

  // Issue 17 end to end: the scenario's seam touch begins with frames whose every shift is within 1.25 pm of
  // its baseline (measured: the first STOP frame's cause says "[faint: ...]"); the real decoders flag them, the
  // flag crosses the link in PatchContact.faint and the aggregator counts it.
  {
    const std::string text = rt::Scrape(rt::ReadPorts(base + "/aggregator/ports")["metrics"]);
    const std::string name = "\nruffini_aggregator_contacts_faint_total ";
    const auto at = text.find(name);
    ASSERT_NE(at, std::string::npos) << text;
    EXPECT_GT(std::stod(text.substr(at + name.size())), 0.0) << "no contact frame arrived flagged faint";
  }

  // A decoder dies (kill -9): every WatchSafety subscriber sees FAULT within 50 ms. A second subscriber joins
  // first.
  Controller second(address, /*resubscribe=*/true);
  ASSERT_TRUE(rt::WaitFor([&] { return second.Snapshot().size() >= 3; }, 5s));
  const std::int64_t killed_at = UnixNs();
  decoders[3].Signal(SIGKILL);
  for (Controller* c : {&controller, &second}) {
    std::int64_t arrival = 0;
    ASSERT_TRUE(rt::WaitFor([&] {
      for (const auto& s : c->Snapshot()) {
        if (s.arrival_ns >= killed_at && s.state.state() == v1::SafetyState::STATE_FAULT &&
            s.state.cause().patch_id() == "upper_arm_b") {
          arrival = s.arrival_ns;
          return true;
        }
      }
      return false;
    }, 5s));
    const double ms = static_cast<double>(arrival - killed_at) / 1e6;
    std::printf("[ metric ] kill -9 of a decoder -> FAULT at a subscriber: %.2f ms\n", ms);
    EXPECT_LT(ms, 50.0);
  }
  // Joint states stop: a new cause (joint states stale) on top of the latched FAULT, epoch + 1.
  const std::uint64_t epoch = Last(controller.Snapshot())->state.stop_epoch();
  const std::int64_t joints_stopped = UnixNs();
  controller.StopJoints();
  EXPECT_TRUE(rt::WaitFor([&] {
    const auto l = Last(controller.Snapshot());
    return l && l->state.cause().kind() == v1::SafetyCause::KIND_JOINT_STATES_STALE && l->state.stop_epoch() > epoch;
  }, 3s));
  std::printf("[ metric ] joint states stopped -> FAULT (stale, limit 200 ms here): %.1f ms\n",
              static_cast<double>(UnixNs() - joints_stopped) / 1e6);
  // A reset now is refused (the causes persist) and changes nothing.
  const auto refused_now = controller.Reset(Last(controller.Snapshot())->state.stop_epoch());
  EXPECT_FALSE(refused_now.accepted());
  EXPECT_EQ(refused_now.state().state(), v1::SafetyState::STATE_FAULT);

  // The aggregator shuts down: FAULT (shutting down), the stream ends, exit 0.
  controller.StopResubscribing();
  EXPECT_EQ(agg.Stop(), 0);
  EXPECT_FALSE(agg.killed());
  EXPECT_TRUE(rt::WaitFor([&] { return controller.ended(); }, 3s));
  const auto last = controller.Snapshot().back();
  EXPECT_EQ(last.state.state(), v1::SafetyState::STATE_FAULT);
  EXPECT_EQ(last.state.cause().kind(), v1::SafetyCause::KIND_SHUTTING_DOWN);
}

TEST(AggregatorProcess, MetricsPassPromtool) {
  if (std::system("command -v promtool >/dev/null 2>&1") != 0) GTEST_SKIP() << "promtool not installed";
  const std::string dir = (fs::current_path() / "aggregator_metrics").string();
  int grpc_port = 0;
  rt::Process agg = rt::StartWithPorts({RUFFINI_AGGREGATOR_EXE, "--insecure", "--scene", kScene, "--listen", "127.0.0.1:0", "--metrics",
                                    "127.0.0.1:0"},
                                   dir, "grpc", grpc_port);
  Controller watcher("127.0.0.1:" + std::to_string(grpc_port));
  ASSERT_TRUE(rt::WaitFor([&] { return watcher.Snapshot().size() >= 3; }, 5s));
  const std::string text = rt::Scrape(rt::ReadPorts(dir + "/ports")["metrics"]);
  ASSERT_NE(text.find("ruffini_aggregator_safety_state{state=\"fault\"} 1"), std::string::npos) << text;
  EXPECT_NE(text.find("ruffini_aggregator_safety_subscribers 1"), std::string::npos) << text;
  // The seam counters (review 3, finding 7) and faint contact frames (issue 17) are exported, 0 before any contact.
  for (const char* series : {"ruffini_aggregator_seam_pairs_total 0", "ruffini_aggregator_seam_mixtures_total 0",
                             "ruffini_aggregator_seam_sums_total 0", "ruffini_aggregator_contacts_faint_total 0"}) {
    EXPECT_NE(text.find(std::string("\n") + series + "\n"), std::string::npos) << series << "\n" << text;
  }
  std::ofstream(dir + "/scrape.txt") << text;
  EXPECT_EQ(std::system(("promtool check metrics < " + dir + "/scrape.txt").c_str()), 0) << text;
}

TEST(AggregatorProcess, ASubscriberThatStopsReadingIsDroppedNotWaitedFor) {
  const std::string dir = (fs::current_path() / "aggregator_stuck").string();
  int grpc_port = 0;
  rt::Process agg = rt::StartWithPorts({RUFFINI_AGGREGATOR_EXE, "--insecure", "--scene", kScene, "--listen", "127.0.0.1:0", "--metrics",
                                    "127.0.0.1:0"},
                                   dir, "grpc", grpc_port);
  const std::string address = "127.0.0.1:" + std::to_string(grpc_port);
  // A subscriber that never reads: a small, fixed flow-control window (no BDP probing), so the aggregator's
  // writes back up after a few hundred states and one stays in flight past the 50 ms write deadline.
  grpc::ChannelArguments args;
  args.SetInt(GRPC_ARG_HTTP2_BDP_PROBE, 0);
  args.SetInt(GRPC_ARG_HTTP2_STREAM_LOOKAHEAD_BYTES, 1024);
  auto channel = grpc::CreateCustomChannel(address, grpc::InsecureChannelCredentials(), args);
  auto stub = v1::Aggregator::NewStub(channel);
  grpc::ClientContext ctx;
  v1::WatchSafetyRequest req;
  req.set_subscriber("never reads");
  auto reader = stub->WatchSafety(&ctx, req);
  // A well-behaved subscriber keeps getting its heartbeats meanwhile.
  Controller good(address);
  const int metrics = rt::ReadPorts(dir + "/ports")["metrics"];
  auto drops = [&] {
    const std::string text = rt::Scrape(metrics);
    const std::string series = "\nruffini_aggregator_subscriber_drops_total ";  // the sample, not # HELP
    const auto at = text.find(series);
    return at == std::string::npos ? 0.0 : std::stod(text.substr(at + series.size()));
  };
  ASSERT_TRUE(rt::WaitFor([&] { return drops() >= 1.0; }, 30s, 100ms)) << agg.stderr_text();
  const std::size_t before = good.Snapshot().size();
  ASSERT_TRUE(rt::WaitFor([&] { return good.Snapshot().size() >= before + 5; }, 2s));
  EXPECT_FALSE(good.ended());
  // The stuck subscriber's stream ends with an error once it reads again: its controller would stop.
  v1::SafetyState s;
  while (reader->Read(&s)) {
  }
  EXPECT_FALSE(reader->Finish().ok());
}

TEST(AggregatorProcess, HealthIsServedInPlaintextOnItsOwnPort) {
  const std::string dir = (fs::current_path() / "aggregator_health").string();
  int grpc_port = 0;
  rt::Process agg = rt::StartWithPorts({RUFFINI_AGGREGATOR_EXE, "--scene", kScene, "--listen", "127.0.0.1:0", "--metrics",
                                    "127.0.0.1:0", "--health-listen", "127.0.0.1:0", "--insecure"},
                                   dir, "grpc", grpc_port);
  const int health = rt::ReadPorts(dir + "/ports")["health"];
  ASSERT_GT(health, 0);
  EXPECT_EQ(rt::HealthCheck("127.0.0.1:" + std::to_string(health)), 1);
  EXPECT_EQ(rt::HealthCheck("127.0.0.1:" + std::to_string(grpc_port)), 1);  // and on the service port
  // Only health there: the Aggregator service is not on the health port.
  auto stub = v1::Aggregator::NewStub(grpc::CreateChannel("127.0.0.1:" + std::to_string(health),
                                                          grpc::InsecureChannelCredentials()));
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + 3s);
  v1::AggregatorStatus status;
  EXPECT_EQ(stub->GetStatus(&ctx, v1::GetStatusRequest{}, &status).error_code(), grpc::StatusCode::UNIMPLEMENTED);
}

TEST(AggregatorProcess, ASceneWithoutSafetyIsAClearError) {
  const std::string dir = (fs::current_path() / "aggregator_nosafety").string();
  fs::create_directories(dir);
  rt::Process p({RUFFINI_AGGREGATOR_EXE, "--insecure", "--scene", kSrc + "/config/scenes/forearm.yaml", "--listen", "127.0.0.1:0",
                 "--metrics", "127.0.0.1:0"},
                dir);
  EXPECT_EQ(p.WaitExit(10s), 1);
  EXPECT_NE(p.stderr_text().find("no `safety:` section"), std::string::npos) << p.stderr_text();
}

// The scene's own deadlines (review finding 15: the only chain test widened them to 200 ms): silence 30 ms,
// joint-state age 50 ms, with real processes (sim, one decoder, the aggregator; this test the controller,
// publishing joint states at 100 Hz). A SIGSTOPped decoder sends nothing and closes nothing: its patch must
// FAULT (KIND_PATCH_SILENT) at the subscriber within the 50 ms bound (30 ms of silence, up to one 10 ms
// heartbeat period before it, the tick and the publication) plus 100 ms of margin for a loaded 2-core machine
// (the review measured 37.9 ms on a quiet one). The FAULT latches: no CLEAR after SIGCONT.
TEST(AggregatorProcess, TheScenesOwnDeadlinesASigstoppedDecoderFaultsWithinFiftyMs) {
  const std::string base = (fs::current_path() / "aggregator_deadlines").string();
  int grpc_port = 0, sim_port = 0, metrics = 0;
  rt::Process agg = rt::StartWithPorts({RUFFINI_AGGREGATOR_EXE, "--insecure", "--scene", kScene, "--listen", "127.0.0.1:0",
                                    "--metrics", "127.0.0.1:0"},
                                   base + "/aggregator", "grpc", grpc_port);
  const std::string address = "127.0.0.1:" + std::to_string(grpc_port);
  Controller controller(address, /*resubscribe=*/true);
  const auto status = controller.Status();
  ASSERT_EQ(status.joint_names_size(), 7);
  controller.StartJoints({status.joint_names().begin(), status.joint_names().end()});
  rt::Process sim = rt::StartWithPorts({RUFFINI_SIM_EXE, "--scene", kScene, "--scenario", kScenario, "--rate-hz", "1000",
                                    "--command-port", "0", "--stream-port", "0"},
                                   base + "/sim", "stream", sim_port);
  rt::Process decoder = rt::StartWithPorts({RUFFINI_DECODER_EXE, "--insecure", "--scene", kScene, "--patch", "forearm_a",
                                        "--interrogator", "127.0.0.1:" + std::to_string(sim_port), "--aggregator", address,
                                        "--metrics", "127.0.0.1:0", "--rate-hz", "1000", "--silence-ms", "100"},
                                       base + "/decoder", "metrics", metrics);
  auto link = [&] {
    const v1::AggregatorStatus st = controller.Status();
    for (const auto& p : st.patches()) {
      if (p.patch_id() == "forearm_a") return p.link_state();
    }
    return v1::LINK_STATE_UNSPECIFIED;
  };
  // Healthy under the 30 ms deadline for half a second in a row.
  std::int64_t healthy_since = 0;
  ASSERT_TRUE(rt::WaitFor([&] {
    if (link() != v1::LINK_STATE_HEALTHY) {
      healthy_since = 0;
      return false;
    }
    if (healthy_since == 0) healthy_since = UnixNs();
    return UnixNs() - healthy_since > 500'000'000;
  }, 20s, 20ms)) << agg.stderr_text();
  const std::uint64_t epoch = Last(controller.Snapshot())->state.stop_epoch();
  const std::int64_t stopped_at = UnixNs();
  decoder.Signal(SIGSTOP);
  std::optional<Seen> fault;
  ASSERT_TRUE(rt::WaitFor([&] {
    for (const auto& s : controller.Snapshot()) {
      if (s.arrival_ns >= stopped_at && s.state.stop_epoch() > epoch &&
          s.state.state() == v1::SafetyState::STATE_FAULT &&
          s.state.cause().kind() == v1::SafetyCause::KIND_PATCH_SILENT && s.state.cause().patch_id() == "forearm_a") {
        fault = s;
        return true;
      }
    }
    return false;
  }, 5s)) << [&] {
    std::string out = "epoch before " + std::to_string(epoch) + "; after:\n";
    int n = 0;
    for (const auto& s : controller.Snapshot()) {
      if (s.arrival_ns >= stopped_at && n++ < 5) out += s.state.ShortDebugString() + "\n";
    }
    return out;
  }() << agg.stderr_text();
  const double ms = static_cast<double>(fault->arrival_ns - stopped_at) / 1e6;
  std::printf("[ metric ] SIGSTOP of a decoder -> FAULT (patch silent, 30 ms deadline) at the subscriber: %.1f ms\n", ms);
  EXPECT_LT(ms, 50.0 + 100.0);  // the 50 ms bound + 100 ms margin for a loaded 2-core machine
  // It latches: SIGCONT, the link heals, and no CLEAR comes without a reset.
  decoder.Signal(SIGCONT);
  EXPECT_TRUE(rt::WaitFor([&] { return link() == v1::LINK_STATE_HEALTHY; }, 10s, 20ms));
  const std::int64_t resumed = UnixNs();
  ASSERT_TRUE(rt::WaitFor([&] { return Last(controller.Snapshot())->arrival_ns > resumed + 500'000'000; }, 5s));
  for (const auto& s : controller.Snapshot()) {
    if (s.arrival_ns >= stopped_at) {
      EXPECT_NE(s.state.state(), v1::SafetyState::STATE_CLEAR);
    }
  }
}

}  // namespace
