// The aggregator process's lifecycle against the real ruffini-aggregator (127.0.0.1, port 0, ports file,
// stopped by pid): watch subscribers that come and go from many threads, clients that vanish, a second copy
// on a taken port, and the health service. Only the aggregator runs (no sim, no decoder), so this target
// builds quickly under the debug (ASan/UBSan) preset too.
//
// The churn test runs RUFFINI_CHURN_S seconds (default 5). Under the address sanitizer:
//   cmake --preset debug && cmake --build --preset debug -- -j2 ruffini-aggregator aggregator_lifecycle_test
//   RUFFINI_CHURN_S=30 build/debug/tests/aggregator/aggregator_lifecycle_test --gtest_filter='*Churn*'
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

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
const std::string kScene = kSrc + "/config/scenes/cobot.yaml";

rt::Process StartAggregator(const std::string& dir, int& grpc_port, std::vector<std::string> extra = {}) {
  std::vector<std::string> args = {RUFFINI_AGGREGATOR_EXE, "--insecure", "--scene", kScene, "--listen", "127.0.0.1:0",
                                   "--metrics", "127.0.0.1:0"};
  args.insert(args.end(), extra.begin(), extra.end());
  return rt::StartWithPorts(args, dir, "grpc", grpc_port);
}

// A channel of its own (its own TCP connection: gRPC would otherwise share one subchannel between channels
// with equal arguments).
std::shared_ptr<grpc::Channel> OwnChannel(const std::string& address) {
  grpc::ChannelArguments args;
  args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
  return grpc::CreateCustomChannel(address, grpc::InsecureChannelCredentials(), args);
}

// Reads `n` SafetyStates from a fresh WatchSafety call within the timeout.
bool ReadsStates(v1::Aggregator::Stub& stub, int n, std::chrono::milliseconds timeout) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + timeout);
  auto reader = stub.WatchSafety(&ctx, v1::WatchSafetyRequest{});
  v1::SafetyState s;
  int got = 0;
  while (got < n && reader->Read(&s)) ++got;
  ctx.TryCancel();
  reader->Finish();
  return got == n;
}

// True when GetStatus (answered by the loop) does not come back within `within`: the loop is wedged.
bool LoopSilent(v1::Aggregator::Stub& stub, std::chrono::milliseconds within) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + within);
  v1::AggregatorStatus st;
  return stub.GetStatus(&ctx, v1::GetStatusRequest{}, &st).error_code() == grpc::StatusCode::DEADLINE_EXCEEDED;
}


// The sum of every series of a metric (all its label values); -1 when it has none.
double SumOf(const std::string& text, const std::string& metric) {
  double sum = -1;
  std::size_t at = 0;
  while ((at = text.find("\n" + metric, at)) != std::string::npos) {
    at += 1 + metric.size();
    if (at >= text.size() || (text[at] != ' ' && text[at] != '{')) continue;
    const auto value = text.find(' ', text.find_first_of(" }", at));
    sum = std::max(sum, 0.0) + std::stod(text.substr(value + 1));
  }
  return sum;
}

// The median gap between the arrivals of `n` messages of a fresh watch call (reader: the call's reader).
template <typename Msg, typename Reader>
double MedianGapMs(Reader& reader, int n) {
  Msg m;
  std::vector<double> arrivals_ms;
  while (static_cast<int>(arrivals_ms.size()) < n && reader.Read(&m)) {
    arrivals_ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now().time_since_epoch()).count());
  }
  if (arrivals_ms.size() < 3) return -1;
  std::vector<double> gaps;
  for (std::size_t i = 2; i < arrivals_ms.size(); ++i) gaps.push_back(arrivals_ms[i] - arrivals_ms[i - 1]);  // not the first
  std::nth_element(gaps.begin(), gaps.begin() + static_cast<long>(gaps.size() / 2), gaps.end());
  return gaps[gaps.size() / 2];
}

double EnvSeconds(const char* name, double fallback) {
  const char* v = std::getenv(name);
  return v && *v ? std::atof(v) : fallback;
}

// Finding 2 of the review (reviews/services.md): the loop called into WatchReactors that gRPC had already
// deleted (raw pointers in the subscriber sets until the posted erase ran); 8 threads of churning
// subscribers crashed the aggregator (SIGSEGV/SIGABRT) within 1-3 s, 4 runs of 4. Now the loop's sets own the
// reactors (shared_ptr) and every call checks, under the reactor's lock, that OnDone has not run.
// Release ctest: 5 s. Recorded under the debug preset (-fsanitize=address,undefined), RUFFINI_CHURN_S=30:
// 18460 calls in 30 s, passed, no sanitizer report (docs/aggregator.md, "Subscriber churn").
TEST(AggregatorLifecycle, WatchChurnFromEightThreadsNeitherCrashesNorStallsTheAggregator) {
  const double seconds = EnvSeconds("RUFFINI_CHURN_S", 5.0);
  const std::string dir = (fs::current_path() / "lifecycle_churn").string();
  int port = 0;
  rt::Process agg = StartAggregator(dir, port);
  ASSERT_GT(port, 0);
  const std::string address = "127.0.0.1:" + std::to_string(port);

  std::atomic<bool> stop{false};
  std::atomic<long> calls{0}, states{0}, contact_sets{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 8; ++t) {
    threads.emplace_back([&, t] {
      auto stub = v1::Aggregator::NewStub(OwnChannel(address));
      for (long i = 0; !stop; ++i) {
        grpc::ClientContext ctx;
        ctx.set_deadline(std::chrono::system_clock::now() + 2s);
        const int reads = static_cast<int>((i + t) % 3);  // 0, 1 or 2 messages, then cancel
        if ((i + t) % 2 == 0) {
          v1::WatchSafetyRequest req;
          req.set_subscriber("churn");
          auto reader = stub->WatchSafety(&ctx, req);
          v1::SafetyState s;
          for (int k = 0; k < reads && reader->Read(&s); ++k) states.fetch_add(1);
          ctx.TryCancel();
          reader->Finish();
        } else {
          auto reader = stub->WatchContacts(&ctx, v1::WatchContactsRequest{});
          v1::ContactSet c;
          for (int k = 0; k < reads && reader->Read(&c); ++k) contact_sets.fetch_add(1);
          ctx.TryCancel();
          reader->Finish();
        }
        calls.fetch_add(1);
      }
    });
  }
  const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(static_cast<long>(seconds * 1000));
  while (std::chrono::steady_clock::now() < until && agg.Running()) std::this_thread::sleep_for(50ms);
  stop = true;
  for (auto& th : threads) th.join();
  std::printf("[ metric ] churn for %.0f s: %ld calls, %ld states, %ld contact sets\n", seconds, calls.load(),
              states.load(), contact_sets.load());

  ASSERT_TRUE(agg.Running()) << "the aggregator died under subscriber churn:\n" << agg.stderr_text();
  EXPECT_GT(calls.load(), 100);
  EXPECT_GT(states.load(), 10);
  // It still publishes, and every churned subscriber is gone from its sets.
  auto stub = v1::Aggregator::NewStub(OwnChannel(address));
  EXPECT_TRUE(ReadsStates(*stub, 10, 5s)) << agg.stderr_text();
  EXPECT_TRUE(rt::WaitFor([&] {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 2s);
    v1::AggregatorStatus st;
    return stub->GetStatus(&ctx, v1::GetStatusRequest{}, &st).ok() && st.safety_subscribers() == 0 &&
           st.contact_subscribers() == 0;
  }, 5s, 50ms));
  // And it stops cleanly (the sanitizers report at exit: a report is a non-zero exit).
  EXPECT_EQ(agg.Stop(), 0) << agg.stderr_text();
  EXPECT_FALSE(agg.killed());
}

// Finding 7 of the review: a refused hello whose client had already gone left its Connect call unfinished
// (the refusal's write failed, and nothing finished the call after it), so SIGTERM hung in
// grpc::Server::Shutdown until SIGKILL. Now every reactor path ends in exactly one Finish.
// Made deterministic with the hidden --test-wedge-loop flag: while the loop sleeps, 50 clients each send a
// hello for a patch the scene does not name and cancel 5 ms later (gRPC's threads have read the hello by
// then); when the loop wakes it refuses hellos whose clients are gone, so every refusal's write fails.
TEST(AggregatorLifecycle, SigtermExitsWithinTwoSecondsAfterFiftyAbandonedRefusedHellos) {
  const std::string dir = (fs::current_path() / "lifecycle_abandoned").string();
  int port = 0;
  rt::Process agg = StartAggregator(dir, port, {"--test-wedge-loop", "300", "3000"});
  ASSERT_GT(port, 0);
  const std::string address = "127.0.0.1:" + std::to_string(port);
  auto stub = v1::Aggregator::NewStub(OwnChannel(address));
  ASSERT_TRUE(rt::WaitFor([&] { return LoopSilent(*stub, 100ms); }, 5s, 10ms)) << agg.stderr_text();
  const auto wedged = std::chrono::steady_clock::now();
  for (int i = 0; i < 50; ++i) {
    grpc::ClientContext ctx;
    auto stream = stub->Connect(&ctx);
    v1::PatchMessage hello;
    hello.set_patch_id("no_such_patch");
    hello.set_seq(1);
    hello.mutable_hello()->set_decoder_instance("abandoned-" + std::to_string(i));
    stream->Write(hello);
    std::this_thread::sleep_for(5ms);  // the hello's way into the server's read, not a wait for a condition
    ctx.TryCancel();
    stream->Finish();
  }
  const double sent_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wedged).count();
  // The loop answers again, and the refusals were counted (the test is not vacuous).
  ASSERT_TRUE(rt::WaitFor([&] { return !LoopSilent(*stub, 1s); }, 10s, 10ms));
  const int metrics = rt::ReadPorts(dir + "/ports")["metrics"];
  double refused = 0;
  ASSERT_TRUE(rt::WaitFor([&] {
    const double before = refused;
    refused = SumOf(rt::Scrape(metrics), "ruffini_aggregator_hellos_refused_total");
    return refused >= 1 && refused == before;  // counted, and no longer changing
  }, 5s, 100ms));
  std::printf("[ metric ] 50 abandoned hellos sent in %.2f s of a 3 s wedge; refusals counted: %.0f\n", sent_s, refused);
  const auto t0 = std::chrono::steady_clock::now();
  agg.Signal(SIGTERM);
  const int status = agg.WaitExit(2s);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("[ metric ] SIGTERM -> exit: %.3f s (status %d)\n", s, status);
  EXPECT_EQ(status, 0) << "still running 2 s after SIGTERM:\n" << agg.stderr_text();
}

// One port, one aggregator: gRPC's default SO_REUSEPORT let a second aggregator listen on a taken port, and
// calls were then split between two safety states (the review: 20 GetStatus calls answered by two runs). A
// second start on a taken port must fail loudly: exit 1, the address named, the first one untouched.
TEST(AggregatorLifecycle, ASecondAggregatorOnATakenPortFailsLoudly) {
  const std::string dir = (fs::current_path() / "lifecycle_two").string();
  int port = 0;
  rt::Process first = StartAggregator(dir + "/first", port);
  ASSERT_GT(port, 0);
  const std::string address = "127.0.0.1:" + std::to_string(port);
  fs::create_directories(dir + "/second");
  rt::Process second({RUFFINI_AGGREGATOR_EXE, "--insecure", "--scene", kScene, "--listen", address, "--metrics",
                      "127.0.0.1:0"},
                     dir + "/second");
  EXPECT_EQ(second.WaitExit(10s), 1) << "a second aggregator runs on " << address << ":\n" << second.stderr_text();
  EXPECT_NE(second.stderr_text().find("--listen " + address + ": cannot listen there"), std::string::npos)
      << second.stderr_text();
  // The first one still answers, alone.
  auto stub = v1::Aggregator::NewStub(OwnChannel(address));
  EXPECT_TRUE(ReadsStates(*stub, 3, 5s));
  EXPECT_TRUE(first.Running());
}

// The health service reflects the loop (finding 13 of the review: it was set SERVING once, so a wedged loop
// stayed "live" for the kubelet). The hidden --test-wedge-loop flag makes the loop sleep 3 s, 1 s after
// start: both health endpoints (the main port and --health-listen) must say NOT_SERVING (2) while it sleeps
// (the watcher's threshold is 200 ms) and SERVING (1) again after.
TEST(AggregatorLifecycle, HealthIsNotServingWhileTheLoopIsWedged) {
  const std::string dir = (fs::current_path() / "lifecycle_wedge").string();
  int port = 0;
  rt::Process agg = StartAggregator(dir, port, {"--health-listen", "127.0.0.1:0", "--test-wedge-loop", "1000", "3000"});
  ASSERT_GT(port, 0);
  const std::string main_address = "127.0.0.1:" + std::to_string(port);
  const std::string health_address = "127.0.0.1:" + std::to_string(rt::ReadPorts(dir + "/ports")["health"]);
  auto both = [&](int status) {
    return rt::HealthCheck(main_address, 500ms) == status && rt::HealthCheck(health_address, 500ms) == status;
  };
  EXPECT_TRUE(rt::WaitFor([&] { return both(2); }, 10s, 20ms)) << agg.stderr_text();
  EXPECT_TRUE(rt::WaitFor([&] { return both(1); }, 10s, 20ms)) << agg.stderr_text();
  EXPECT_NE(agg.stderr_text().find("health NOT_SERVING"), std::string::npos) << agg.stderr_text();
}

// Finding 11 of the review (server side): WatchSafetyRequest.heartbeat_period_ns was ignored (asked for 2 ms,
// states came every 10 ms) and ContactSets came every 20 ms where the contract says 10 ms. Now a period is
// honoured (clamped to 2..10 ms; the aggregator publishes at the shortest period any subscriber asked for),
// ContactSets come every 10 ms by default, and a negative period or force filter is INVALID_ARGUMENT.
// Medians of the arrival gaps, with margins for a loaded machine.
TEST(AggregatorLifecycle, WatchPeriodsAreHonouredAndContactSetsComeEveryTenMs) {
  const std::string dir = (fs::current_path() / "lifecycle_periods").string();
  int port = 0;
  rt::Process agg = StartAggregator(dir, port);
  ASSERT_GT(port, 0);
  auto stub = v1::Aggregator::NewStub(OwnChannel("127.0.0.1:" + std::to_string(port)));
  auto safety = [&](std::int64_t period_ns, int n) {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 10s);
    v1::WatchSafetyRequest req;
    req.set_heartbeat_period_ns(period_ns);
    auto reader = stub->WatchSafety(&ctx, req);
    const double gap = MedianGapMs<v1::SafetyState>(*reader, n);
    ctx.TryCancel();
    const grpc::Status st = reader->Finish();
    EXPECT_GT(gap, 0.0) << "period " << period_ns << ": " << st.error_message();
    return gap;
  };
  auto contacts = [&](std::int64_t period_ns, int n) {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 10s);
    v1::WatchContactsRequest req;
    req.set_heartbeat_period_ns(period_ns);
    auto reader = stub->WatchContacts(&ctx, req);
    const double gap = MedianGapMs<v1::ContactSet>(*reader, n);
    ctx.TryCancel();
    const grpc::Status st = reader->Finish();
    EXPECT_GT(gap, 0.0) << "period " << period_ns << ": " << st.error_message();
    return gap;
  };
  // One subscriber at a time (a subscriber's period applies to all while it is subscribed).
  const double safety_default = safety(0, 60), contacts_default = contacts(0, 60);
  const double safety_2ms = safety(2'000'000, 200), contacts_2ms = contacts(2'000'000, 200);
  const double safety_1s = safety(1'000'000'000, 40);
  std::printf("[ metric ] median gaps: SafetyState default %.2f ms, asked 2 ms %.2f ms, asked 1 s %.2f ms; "
              "ContactSet default %.2f ms, asked 2 ms %.2f ms\n",
              safety_default, safety_2ms, safety_1s, contacts_default, contacts_2ms);
  EXPECT_GT(safety_default, 5.0);
  EXPECT_LT(safety_default, 15.0);
  EXPECT_LT(safety_2ms, 6.0);  // was 10 ms
  EXPECT_LT(safety_1s, 15.0);  // clamped to 10 ms
  EXPECT_GT(contacts_default, 5.0);
  EXPECT_LT(contacts_default, 15.0);  // was 20 ms
  EXPECT_LT(contacts_2ms, 6.0);
  // Bad requests are refused, named.
  {
    grpc::ClientContext ctx;
    v1::WatchSafetyRequest req;
    req.set_heartbeat_period_ns(-1);
    auto reader = stub->WatchSafety(&ctx, req);
    v1::SafetyState st;
    EXPECT_FALSE(reader->Read(&st));
    const grpc::Status status = reader->Finish();
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << status.error_message();
    EXPECT_NE(status.error_message().find("heartbeat_period_ns (-1)"), std::string::npos) << status.error_message();
  }
  {
    grpc::ClientContext ctx;
    v1::WatchContactsRequest req;
    req.set_min_force_n(-1.0F);
    auto reader = stub->WatchContacts(&ctx, req);
    v1::ContactSet c;
    EXPECT_FALSE(reader->Read(&c));
    EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  }
}

}  // namespace
