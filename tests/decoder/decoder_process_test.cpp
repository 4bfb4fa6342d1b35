// The real ruffini-sim and ruffini-decoder processes on 127.0.0.1 (port 0, ports files), the decoder
// publishing to an in-test Aggregator (a real gRPC server in this process). Every wait is a condition with a
// deadline; every process is stopped by pid.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "aggregator_stub.h"
#include "process.h"
#include "scrape.h"

using ruffini::testing::Scrape;

namespace {

using namespace std::chrono_literals;
namespace v1 = ruffini::v1;
namespace rt = ruffini::testing;
using rt::AggregatorStub;
using rt::Process;
using rt::Received;
namespace fs = std::filesystem;

const std::string kSrc = RUFFINI_SOURCE_DIR;
const std::string kScene = kSrc + "/config/scenes/forearm.yaml";
const std::string kScenario = kSrc + "/tests/decoder/data/presses.yaml";

std::int64_t UnixNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count();
}

using rt::ReadPorts;

struct Sim {
  Process process;
  int stream_port = 0;
  // extra: fault flags; port: a fixed stream port (0: any).
  static Sim Start(const std::string& dir, std::vector<std::string> extra = {}, int port = 0, double rate = 1000,
                   const std::string& scenario = kScenario) {
    Sim s;
    fs::remove_all(dir);
    fs::create_directories(dir);
    const std::string ports = dir + "/ports";
    std::vector<std::string> args = {RUFFINI_SIM_EXE, "--scene", kScene, "--scenario", scenario, "--rate-hz",
                                     std::to_string(rate), "--command-port", "0", "--stream-port",
                                     std::to_string(port), "--ports-file", ports};
    args.insert(args.end(), extra.begin(), extra.end());
    s.process = Process(args, dir);
    EXPECT_TRUE(rt::WaitFor([&] { return ReadPorts(ports).count("stream") > 0 || !s.process.Running(); }, 10s));
    s.stream_port = ReadPorts(ports)["stream"];
    EXPECT_GT(s.stream_port, 0) << s.process.stderr_text();
    return s;
  }
};

struct Decoder {
  Process process;
  int metrics_port = 0;
  static Decoder Start(const std::string& dir, int stream_port, const std::string& aggregator,
                       std::vector<std::string> extra = {}) {
    Decoder d;
    fs::remove_all(dir);
    fs::create_directories(dir);
    const std::string ports = dir + "/ports";
    std::vector<std::string> args = {RUFFINI_DECODER_EXE, "--insecure", "--scene", kScene, "--patch", "forearm",
                                     "--interrogator", "127.0.0.1:" + std::to_string(stream_port), "--aggregator",
                                     aggregator, "--metrics", "127.0.0.1:0", "--ports-file", ports, "--rate-hz", "1000"};
    args.insert(args.end(), extra.begin(), extra.end());
    d.process = Process(args, dir);
    EXPECT_TRUE(rt::WaitFor([&] { return ReadPorts(ports).count("metrics") > 0 || !d.process.Running(); }, 10s));
    d.metrics_port = ReadPorts(ports)["metrics"];
    EXPECT_GT(d.metrics_port, 0) << d.process.stderr_text();
    return d;
  }
};

// The value of one sample line of the exposition ("name{labels} value"), or -1.
double Metric(const std::string& text, const std::string& series) {
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind(series + " ", 0) == 0) return std::stod(line.substr(series.size() + 1));
  }
  return -1;
}

const v1::Heartbeat* LastHeartbeat(const std::vector<Received>& r) {
  for (auto it = r.rbegin(); it != r.rend(); ++it) {
    if (it->message.has_heartbeat()) return &it->message.heartbeat();
  }
  return nullptr;
}
bool HealthyHeartbeat(const std::vector<Received>& r) {
  const auto* h = LastHeartbeat(r);
  return h != nullptr && h->healthy();
}
std::uint64_t Rejected(const v1::Heartbeat& h, v1::FrameRejectReason reason) {
  for (const auto& r : h.rejected()) {
    if (r.reason() == reason) return r.frames();
  }
  return 0;
}
bool HasFault(const std::vector<Received>& r, v1::PatchFaultCode code, std::int64_t after_ns = 0) {
  return std::any_of(r.begin(), r.end(), [&](const Received& m) {
    return m.message.has_fault() && m.message.fault().code() == code && m.arrival_unix_ns >= after_ns;
  });
}

class DecoderProcess : public ::testing::Test {
 protected:
  std::string Dir(const std::string& name) const {
    return (fs::current_path() / ("decoder_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) + "_" + name)).string();
  }
};

TEST_F(DecoderProcess, HelloThenHeartbeatsThenContactsWithTheDecodersAccuracy) {
  AggregatorStub agg;
  Sim sim = Sim::Start(Dir("sim"));
  Decoder dec = Decoder::Start(Dir("dec"), sim.stream_port, agg.address(), {"--silence-ms", "100"});
  // The first press is held from 2.3 s to 3.8 s of the scenario; wait for its release (at most 15 s).
  // A contact segment (onset .. release) whose force passed 1.5 N.
  const auto pressed = [](const std::vector<Received>& r) {
    float peak = 0.0f;
    for (const auto& m : r) {
      if (!m.message.has_contact()) continue;
      peak = std::max(peak, m.message.contact().force_n());
      if (m.message.contact().released() && peak > 1.5f) return true;
      if (m.message.contact().released()) peak = 0.0f;
    }
    return false;
  };
  ASSERT_TRUE(agg.WaitFor(pressed, 15s)) << dec.process.stderr_text();
  const auto got = agg.Snapshot();
  ASSERT_FALSE(got.empty());
  // The hello comes first and names the patch, the model and the configuration.
  const auto& first = got.front().message;
  ASSERT_TRUE(first.has_hello());
  EXPECT_EQ(first.seq(), 1u);
  EXPECT_EQ(first.patch_id(), "forearm");
  EXPECT_EQ(first.hello().model_name(), "forearm.rmodel");
  EXPECT_EQ(first.hello().model_sha256().size(), 64u);
  EXPECT_EQ(first.hello().patch_fingerprint(), first.hello().model_patch_fingerprint());
  EXPECT_EQ(first.hello().decoder_config().scalar(), "float");
  EXPECT_EQ(first.hello().decoder_config().config_sha256().size(), 64u);
  EXPECT_EQ(first.hello().heartbeat_period_ns(), 10'000'000);
  EXPECT_DOUBLE_EQ(first.hello().sample_rate_hz(), 1000.0);
  // seq rises by exactly 1 per message.
  for (std::size_t i = 1; i < got.size(); ++i) ASSERT_EQ(got[i].message.seq(), got[i - 1].message.seq() + 1);
  // Heartbeats every 10 ms of the decoder's clock, whatever else is sent. The aggregator's watchdog is 30 ms: a
  // gap past it costs a FAULT (the safe side). On a loaded 2-core CI host without a real-time priority
  // (`ruffini soak --realtime-priority` gives one) the OS may hold the decode thread for 20 ms now and then
  // (a 31.9 ms gap was seen once in three CI runs), so the schedule is judged on its distribution: the median
  // gap is the period, 99 % of gaps are within twice it, at most two pass the watchdog and none the decoder's
  // own 100 ms silence deadline.
  std::vector<std::int64_t> gaps;
  std::int64_t prev = 0;
  for (const auto& m : got) {
    if (!m.message.has_heartbeat()) continue;
    if (prev != 0) gaps.push_back(m.message.decoder_t_ns() - prev);
    prev = m.message.decoder_t_ns();
  }
  ASSERT_GT(gaps.size(), 200u);  // 3.8 s at least
  std::sort(gaps.begin(), gaps.end());
  const std::int64_t gap_p50 = gaps[gaps.size() / 2], gap_p99 = gaps[gaps.size() * 99 / 100], worst = gaps.back();
  const auto past_watchdog = std::count_if(gaps.begin(), gaps.end(), [](std::int64_t g) { return g > 30'000'000; });
  std::printf("[ metric ] heartbeat gaps: p50 %.2f ms, p99 %.2f ms, largest %.2f ms, %td past 30 ms\n",
              static_cast<double>(gap_p50) / 1e6, static_cast<double>(gap_p99) / 1e6, static_cast<double>(worst) / 1e6,
              past_watchdog);
  EXPECT_GE(gap_p50, 9'000'000);
  EXPECT_LE(gap_p50, 11'000'000);
  EXPECT_LE(gap_p99, 20'000'000);
  EXPECT_LE(past_watchdog, 2);
  EXPECT_LT(worst, 100'000'000);
  // The press: an onset, located frames near (66 mm, 40 deg), a release. Contacts before it (light false
  // contacts right after the baseline capture, if any) are counted and reported, not scored.
  std::vector<double> err_mm;
  int onsets = 0;
  float peak_n = 0.0f;
  for (const auto& m : got) {
    if (!m.message.has_contact()) continue;
    const auto& c = m.message.contact();
    onsets += c.onset();
    peak_n = std::max(peak_n, c.force_n());
    if (c.released() && peak_n < 1.5f) peak_n = 0.0f;  // a light segment: not the press
    for (float v : {c.force_n(), c.force_sd_n(), c.y_mm(), c.r_deg(), c.cov_yy_mm2(), c.cov_rr_mm2()}) {
      ASSERT_TRUE(std::isfinite(v));
    }
    if (c.located() && c.force_n() > 1.0f) {
      const double dy = c.y_mm() - 66.0;
      const double da = 37.4 * (c.r_deg() - 40.0) * M_PI / 180.0;  // arc length on the forearm's surface
      err_mm.push_back(std::hypot(dy, da));
    }
  }
  std::printf("[ metric ] contact onsets up to the end of the 2.5 N press: %d\n", onsets);
  EXPECT_GE(onsets, 1);
  EXPECT_LE(onsets, 3);
  EXPECT_GT(peak_n, 1.8f);
  EXPECT_LT(peak_n, 3.2f);
  ASSERT_GT(err_mm.size(), 200u);
  std::sort(err_mm.begin(), err_mm.end());
  const double median = err_mm[err_mm.size() / 2];
  std::printf("[ metric ] located frames above 1 N: %zu, median position error %.2f mm, peak force %.2f N\n",
              err_mm.size(), median, static_cast<double>(peak_n));
  EXPECT_LT(median, 8.0);
  // The decoder is healthy while all this happens, and says so.
  EXPECT_TRUE(HealthyHeartbeat(got));

  // Metrics: live, named by the rules, consistent with what was sent.
  const std::string text = Scrape(dec.metrics_port);
  EXPECT_GT(Metric(text, "ruffini_decoder_frames_total{patch=\"forearm\"}"), 3000.0);
  EXPECT_GE(Metric(text, "ruffini_decoder_contacts_total{patch=\"forearm\"}"), 1.0);
  // Every contact message flagged faint came from a frame the decoder counted (it sends fewer than it decodes).
  std::size_t faint_sent = 0;
  for (const auto& m : got) faint_sent += m.message.has_contact() && m.message.contact().faint() ? 1 : 0;
  EXPECT_GE(Metric(text, "ruffini_decoder_frames_faint_total{patch=\"forearm\"}"), static_cast<double>(faint_sent));
  // A flag-only model never refuses after a release either (PipelineConfig::release_*).
  EXPECT_EQ(Metric(text, "ruffini_decoder_frames_release_refused_total{patch=\"forearm\"}"), 0.0);
  EXPECT_EQ(Metric(text, "ruffini_decoder_aggregator_connected{patch=\"forearm\"}"), 1.0);
  EXPECT_EQ(Metric(text, "ruffini_decoder_healthy{patch=\"forearm\"}"), 1.0);
  EXPECT_NE(text.find("ruffini_decoder_info{patch=\"forearm\",decoder=\"paper-float\""), std::string::npos);
  EXPECT_NE(text.find("faint_refuse_below_n=\"off\""), std::string::npos) << "forearm.rmodel: flag only";
  EXPECT_EQ(first.hello().decoder_config().faint_refuse_below_n(), 0.0f);

  // SIGTERM: the last message is the shutting_down fault, and the process exits 0.
  EXPECT_EQ(dec.process.Stop(), 0);
  EXPECT_FALSE(dec.process.killed());
  const auto after = agg.Snapshot();
  ASSERT_TRUE(after.back().message.has_fault()) << after.back().message.DebugString();
  EXPECT_EQ(after.back().message.fault().code(), v1::PATCH_FAULT_CODE_SHUTTING_DOWN);
  EXPECT_TRUE(agg.WaitFor([&](const auto&) { return agg.streams_open() == 0; }, 2s));
}

// A model that refuses faint contacts says so where an operator looks: the hello's decoder config, the
// decoder_info metric and the start-up line.
TEST_F(DecoderProcess, AFaintRefusingModelSaysSoInTheHelloTheMetricsAndTheLog) {
  AggregatorStub agg;
  Sim sim = Sim::Start(Dir("sim"));
  Decoder dec = Decoder::Start(Dir("dec"), sim.stream_port, agg.address(),
                               {"--model", kSrc + "/config/models/forearm-field.rmodel"});
  ASSERT_TRUE(agg.WaitFor([](const auto& r) { return !r.empty(); }, 10s)) << dec.process.stderr_text();
  const auto first = agg.Snapshot().front().message;
  ASSERT_TRUE(first.has_hello());
  EXPECT_FLOAT_EQ(first.hello().decoder_config().faint_refuse_below_n(), 1.0f);
  EXPECT_NE(Scrape(dec.metrics_port).find("faint_refuse_below_n=\"1.00\""), std::string::npos);
  EXPECT_EQ(dec.process.Stop(), 0);
  EXPECT_NE(dec.process.stderr_text().find("faint frames below 1.00 N refused (the model's)"), std::string::npos)
      << dec.process.stderr_text();
}

TEST_F(DecoderProcess, MetricsPassPromtool) {
  if (std::system("command -v promtool >/dev/null 2>&1") != 0) GTEST_SKIP() << "promtool not installed";
  AggregatorStub agg;
  Sim sim = Sim::Start(Dir("sim"), {"--nan-every", "50", "--drop-every", "70"});
  Decoder dec = Decoder::Start(Dir("dec"), sim.stream_port, agg.address());
  ASSERT_TRUE(agg.WaitFor([](const auto& r) {
    const auto* h = LastHeartbeat(r);
    return h != nullptr && h->frames() > 500;
  }, 10s));
  const std::string text = Scrape(dec.metrics_port);
  const std::string path = Dir("scrape.txt");
  std::ofstream(path) << text;
  EXPECT_EQ(std::system(("promtool check metrics < " + path).c_str()), 0) << text;
}

TEST_F(DecoderProcess, InjectedStreamFaultsAreCountedNotFatal) {
  AggregatorStub agg;
  // A NaN peak every 50th frame, every 70th frame dropped, each client cut after 1500 frames.
  Sim sim = Sim::Start(Dir("sim"), {"--nan-every", "50", "--drop-every", "70", "--disconnect-after", "1500"});
  Decoder dec = Decoder::Start(Dir("dec"), sim.stream_port, agg.address(), {"--silence-ms", "100"});
  // Wait for the first disconnect and a reconnect after it (frames counted past 2000).
  ASSERT_TRUE(agg.WaitFor([](const auto& r) {
    const auto* h = LastHeartbeat(r);
    return h != nullptr && h->frames() > 2000 && HasFault(r, v1::PATCH_FAULT_CODE_INTERROGATOR_DISCONNECTED, 1);
  }, 15s)) << dec.process.stderr_text();
  const auto got = agg.Snapshot();
  const v1::Heartbeat& h = *LastHeartbeat(got);
  EXPECT_GT(Rejected(h, v1::FRAME_REJECT_REASON_NON_FINITE_PEAK), 20u);
  EXPECT_GT(h.serial_gaps(), 10u);
  EXPECT_GE(h.frames_lost(), h.serial_gaps());
  // One rejected frame in 50 is not persistent: no frames_rejected fault.
  EXPECT_FALSE(HasFault(got, v1::PATCH_FAULT_CODE_FRAMES_REJECTED));
  const std::string text = Scrape(dec.metrics_port);
  EXPECT_GE(Metric(text, "ruffini_decoder_interrogator_connects_total{patch=\"forearm\"}"), 2.0);
  EXPECT_GT(Metric(text, "ruffini_decoder_frames_rejected_total{patch=\"forearm\",reason=\"stream_non_finite\"}"), 20.0);
  EXPECT_TRUE(dec.process.Running());
  // Healthy again after the reconnect.
  EXPECT_TRUE(agg.WaitFor([](const auto& r) { return HealthyHeartbeat(r); }, 5s));
}

TEST_F(DecoderProcess, SilenceIsAFaultWithinTheDeadlineAndFramesResumingHealIt) {
  AggregatorStub agg;
  Sim sim = Sim::Start(Dir("sim"));
  Decoder dec = Decoder::Start(Dir("dec"), sim.stream_port, agg.address(), {"--silence-ms", "10"});
  ASSERT_TRUE(agg.WaitFor([](const auto& r) { return HealthyHeartbeat(r); }, 10s)) << dec.process.stderr_text();
  // Freeze the interrogator: the connection stays open, no frame comes.
  const std::int64_t stopped = UnixNs();
  sim.process.Signal(SIGSTOP);
  const bool faulted = agg.WaitFor([&](const auto& r) {
    return HasFault(r, v1::PATCH_FAULT_CODE_INTERROGATOR_SILENT, stopped);
  }, 2s);
  sim.process.Signal(SIGCONT);
  ASSERT_TRUE(faulted);
  std::int64_t arrival = 0;
  for (const auto& m : agg.Snapshot()) {
    if (m.message.has_fault() && m.message.fault().code() == v1::PATCH_FAULT_CODE_INTERROGATOR_SILENT &&
        m.arrival_unix_ns >= stopped) {
      arrival = m.arrival_unix_ns;
      break;
    }
  }
  const double ms = static_cast<double>(arrival - stopped) / 1e6;
  std::printf("[ metric ] SIGSTOP of the sim -> interrogator_silent fault at the aggregator: %.2f ms (deadline 10 ms)\n", ms);
  // The 10 ms silence deadline plus scheduling; the safety budget is 50 ms.
  EXPECT_LT(ms, 50.0);
  // Frames resume: healthy heartbeats again.
  const std::int64_t resumed = UnixNs();
  EXPECT_TRUE(agg.WaitFor([&](const auto& r) {
    return !r.empty() && r.back().arrival_unix_ns > resumed && HealthyHeartbeat(r);
  }, 5s));
}

TEST_F(DecoderProcess, ReconnectsAfterTheSimRestarts) {
  AggregatorStub agg;
  Sim sim = Sim::Start(Dir("sim1"));
  const int port = sim.stream_port;
  Decoder dec = Decoder::Start(Dir("dec"), port, agg.address(), {"--silence-ms", "100"});
  ASSERT_TRUE(agg.WaitFor([](const auto& r) { return HealthyHeartbeat(r); }, 10s));
  EXPECT_EQ(sim.process.Stop(), 0);
  const std::int64_t down = UnixNs();
  ASSERT_TRUE(agg.WaitFor([&](const auto& r) { return HasFault(r, v1::PATCH_FAULT_CODE_INTERROGATOR_DISCONNECTED, down - 1'000'000'000); }, 5s));
  // A new interrogator on the same port: the decoder reconnects and is healthy again (its baseline kept).
  Sim again = Sim::Start(Dir("sim2"), {}, port);
  const std::int64_t up = UnixNs();
  EXPECT_TRUE(agg.WaitFor([&](const auto& r) {
    return !r.empty() && r.back().arrival_unix_ns > up && HealthyHeartbeat(r) && LastHeartbeat(r)->frames() > 0;
  }, 10s)) << dec.process.stderr_text();
  EXPECT_GE(Metric(Scrape(dec.metrics_port), "ruffini_decoder_interrogator_connects_total{patch=\"forearm\"}"), 2.0);
}

TEST_F(DecoderProcess, ReconnectsToTheAggregatorWithoutReplayingStaleMessages) {
  auto agg = std::make_unique<AggregatorStub>();
  const int port = agg->port();
  Sim sim = Sim::Start(Dir("sim"));
  Decoder dec = Decoder::Start(Dir("dec"), sim.stream_port, agg->address(), {"--silence-ms", "100"});
  ASSERT_TRUE(agg->WaitFor([](const auto& r) { return r.size() > 20; }, 10s));
  agg.reset();  // the aggregator goes away
  // Back on the same port 300 ms later.
  std::this_thread::sleep_for(300ms);  // the outage itself (not a wait for a condition)
  const std::int64_t back = UnixNs();
  AggregatorStub again(port);
  ASSERT_EQ(again.port(), port) << "could not rebind port " << port;
  ASSERT_TRUE(again.WaitFor([](const auto& r) { return r.size() > 10; }, 10s)) << dec.process.stderr_text();
  const auto got = again.Snapshot();
  EXPECT_TRUE(got.front().message.has_hello());
  EXPECT_EQ(got.front().message.seq(), 1u);
  // Nothing made while the aggregator was away is sent on the new stream.
  for (const auto& m : got) EXPECT_GE(m.message.decoder_t_ns(), back - 50'000'000) << m.message.DebugString();
}

TEST_F(DecoderProcess, GarbageBytesForceAResyncAndTheDecoderRecovers) {
  AggregatorStub agg;
  // Every 1500th frame is preceded by 16 garbage bytes (a header claiming 0xDEADBEEF bytes of content).
  Sim sim = Sim::Start(Dir("sim"), {"--garbage-every", "1500"});
  Decoder dec = Decoder::Start(Dir("dec"), sim.stream_port, agg.address(), {"--silence-ms", "100"});
  ASSERT_TRUE(agg.WaitFor([](const auto& r) {
    const auto* h = LastHeartbeat(r);
    return h != nullptr && Rejected(*h, v1::FRAME_REJECT_REASON_CONTENT_TOO_LONG) >= 1 && h->frames() > 2000;
  }, 15s)) << dec.process.stderr_text();
  const std::string text = Scrape(dec.metrics_port);
  EXPECT_GE(Metric(text, "ruffini_decoder_interrogator_resyncs_total{patch=\"forearm\"}"), 1.0);
  EXPECT_GE(Metric(text, "ruffini_decoder_interrogator_connects_total{patch=\"forearm\"}"), 2.0);
  EXPECT_TRUE(HasFault(agg.Snapshot(), v1::PATCH_FAULT_CODE_INTERROGATOR_DISCONNECTED, 1));
  EXPECT_TRUE(agg.WaitFor([](const auto& r) { return HealthyHeartbeat(r); }, 5s));
  EXPECT_TRUE(dec.process.Running());
}

TEST_F(DecoderProcess, ADarkGratingIsAMissingPeakNotARejectedFrame) {
  AggregatorStub agg;
  // Every 10th frame, one grating's peak is left out of the channel (15 peaks), as the instrument does.
  Sim sim = Sim::Start(Dir("sim"), {"--missing-every", "10"});
  Decoder dec = Decoder::Start(Dir("dec"), sim.stream_port, agg.address(), {"--silence-ms", "100"});
  ASSERT_TRUE(agg.WaitFor([](const auto& r) {
    const auto* h = LastHeartbeat(r);
    return h != nullptr && h->valid_frames() > 1000;
  }, 15s)) << dec.process.stderr_text();
  const v1::Heartbeat h = *LastHeartbeat(agg.Snapshot());
  EXPECT_EQ(Rejected(h, v1::FRAME_REJECT_REASON_WRONG_PEAK_COUNT), 0u);
  EXPECT_EQ(Rejected(h, v1::FRAME_REJECT_REASON_PEAK_OUTSIDE_BANDS), 0u);
  EXPECT_TRUE(h.healthy());
  // Every frame after the capture was decoded, the ones with a dark grating included.
  const std::uint64_t capturing = Rejected(h, v1::FRAME_REJECT_REASON_CAPTURING);
  EXPECT_EQ(h.valid_frames() + capturing, h.frames());
}

TEST_F(DecoderProcess, ARefusedHelloIsLoggedAndRetried) {
  AggregatorStub agg;
  agg.RefuseHellos(v1::HELLO_REFUSAL_MODEL_MISMATCH);
  Sim sim = Sim::Start(Dir("sim"));
  Decoder dec = Decoder::Start(Dir("dec"), sim.stream_port, agg.address());
  ASSERT_TRUE(agg.WaitFor([&](const auto&) { return agg.streams_opened() >= 2; }, 10s));
  EXPECT_TRUE(dec.process.Running());
  EXPECT_TRUE(rt::WaitFor([&] { return dec.process.stderr_text().find("hello refused (HELLO_REFUSAL_MODEL_MISMATCH)") != std::string::npos; }, 2s));
  EXPECT_GE(Metric(Scrape(dec.metrics_port), "ruffini_decoder_hello_refused_total{patch=\"forearm\"}"), 1.0);
}

TEST_F(DecoderProcess, AnAggregatorOfAnotherRobotIsRefusedThenTheRightOneGetsTheStream) {
  AggregatorStub agg;
  agg.SetRobotName("other-cell");  // accepts the hello, but guards another robot than forearm-bench
  Sim sim = Sim::Start(Dir("sim"));
  Decoder dec = Decoder::Start(Dir("dec"), sim.stream_port, agg.address());
  ASSERT_TRUE(agg.WaitFor([&](const auto&) { return agg.streams_opened() >= 2; }, 10s));
  EXPECT_TRUE(dec.process.Running());
  EXPECT_TRUE(rt::WaitFor([&] {
    return dec.process.stderr_text().find("guards robot 'other-cell', not this scene's 'forearm-bench'") != std::string::npos;
  }, 2s)) << dec.process.stderr_text();
  EXPECT_GE(Metric(Scrape(dec.metrics_port), "ruffini_decoder_hello_wrong_robot_total{patch=\"forearm\"}"), 1.0);
  // Nothing but hellos went to the wrong aggregator.
  for (const Received& r : agg.Snapshot()) EXPECT_TRUE(r.message.has_hello()) << r.message.ShortDebugString();
  // The aggregator of this scene's robot gets the stream: heartbeats follow.
  agg.SetRobotName("forearm-bench");
  EXPECT_TRUE(agg.WaitFor(HealthyHeartbeat, 15s));
}


// Review 10, finding 1: a decoder restarted while a press is held captured the press as its rest, was healthy
// and out of contact, and the operator's reset cleared a STOP under the press. With --rest-file the first decoder
// writes the patch's rest; the restarted one refuses every capture that is not that rest while the press is
// held (unhealthy: the aggregator keeps its FAULT and refuses a reset), and becomes healthy once it is lifted. A
// decoder started beside it without the file takes the press for its rest (the hazard, so the test can tell).
TEST_F(DecoderProcess, ARestartUnderAHeldPressIsNotTakenForTheRest) {
  AggregatorStub agg, agg_b, agg_c;
  Sim sim = Sim::Start(Dir("sim"), {}, 0, 1000, kSrc + "/tests/decoder/data/held.yaml");
  const std::string rest = Dir("rest") + ".txt";
  fs::remove(rest);
  Decoder a = Decoder::Start(Dir("a"), sim.stream_port, agg.address(), {"--rest-file", rest});
  ASSERT_TRUE(rt::WaitFor([&] { return fs::exists(rest); }, 15s)) << a.process.stderr_text();
  // The press (8 s into the scenario): once it reads above 1.5 N, the decoder goes away (SIGTERM, by pid).
  ASSERT_TRUE(agg.WaitFor([](const std::vector<Received>& r) {
    return std::any_of(r.begin(), r.end(), [](const Received& m) {
      return m.message.has_contact() && m.message.contact().force_n() > 1.5f;
    });
  }, 20s)) << a.process.stderr_text();
  EXPECT_EQ(a.process.Stop(), 0);
  Decoder b = Decoder::Start(Dir("b"), sim.stream_port, agg_b.address(), {"--rest-file", rest});
  Decoder c = Decoder::Start(Dir("c"), sim.stream_port, agg_c.address());
  const std::string healthy = "ruffini_decoder_healthy{patch=\"forearm\"}";
  const std::string refused = "ruffini_decoder_captures_refused_total{patch=\"forearm\"}";
  // Without the file: healthy under the held press, and no contact.
  ASSERT_TRUE(rt::WaitFor([&] { return Metric(Scrape(c.metrics_port), healthy) == 1.0; }, 10s)) << c.process.stderr_text();
  // With it: capture after capture refused, never healthy, while the press is held (until 23.5 s).
  bool b_healthy = false;
  ASSERT_TRUE(rt::WaitFor([&] {
    const std::string m = Scrape(b.metrics_port);
    b_healthy = b_healthy || Metric(m, healthy) == 1.0;
    return Metric(m, refused) >= 3.0;
  }, 10s)) << b.process.stderr_text();
  EXPECT_FALSE(b_healthy) << "healthy under the held press";
  const std::vector<Received> from_c = agg_c.Snapshot();
  EXPECT_TRUE(std::none_of(from_c.begin(), from_c.end(), [](const Received& m) {
    return m.message.has_contact() && m.message.contact().force_n() > 1.5f;
  })) << "the decoder without the file reports the held press (then this test no longer shows the hazard)";
  EXPECT_NE(b.process.stderr_text().find("the start-up capture must match the rest"), std::string::npos)
      << b.process.stderr_text();
  // Each refusal is counted and said (off the decode thread, at most every 10 s: the first one at least, within the
  // rest writer's 5 s wake), naming the check, and offering no way round it.
  EXPECT_TRUE(rt::WaitFor([&] { return b.process.stderr_text().find("start-up capture refused (") != std::string::npos; }, 12s))
      << b.process.stderr_text();
  EXPECT_NE(b.process.stderr_text().find("would trust the next capture unchecked, a held press included"), std::string::npos)
      << b.process.stderr_text();
  // Lifted (23.5 s): the rest again, captured, healthy.
  ASSERT_TRUE(rt::WaitFor([&] { return Metric(Scrape(b.metrics_port), healthy) == 1.0; }, 25s)) << b.process.stderr_text();
  EXPECT_EQ(b.process.Stop(), 0);
  EXPECT_EQ(c.process.Stop(), 0);
  // The file is the rest: four lines, this patch.
  std::ifstream in(rest);
  std::string first, second;
  std::getline(in, first);
  std::getline(in, second);
  EXPECT_EQ(first, "ruffini-rest 1");
  EXPECT_EQ(second, "patch forearm");
}

// A rest file that is not this patch's, or not one at all, is a clear error at start-up (exit 2 or 1 with the
// reason), never a silently trusted capture.
TEST_F(DecoderProcess, ABadRestFileIsAClearError) {
  AggregatorStub agg;
  const std::string dir = Dir("bad");
  fs::remove_all(dir);
  fs::create_directories(dir);
  const auto run = [&](const std::string& text) {
    std::ofstream(dir + "/rest.txt") << text;
    Process p({RUFFINI_DECODER_EXE, "--insecure", "--scene", kScene, "--patch", "forearm", "--interrogator",
               "127.0.0.1:1", "--aggregator", agg.address(), "--metrics", "127.0.0.1:0", "--rest-file",
               dir + "/rest.txt"},
              dir);
    EXPECT_NE(p.WaitExit(10s), 0);
    return p.stderr_text();
  };
  EXPECT_NE(run("hello\n").find("not a ruffini rest file"), std::string::npos);
  EXPECT_NE(run("ruffini-rest 1\npatch elbow\nunix_s 1\nwavelength_nm 1\n").find("written for patch 'elbow'"),
            std::string::npos);
  std::string far = "ruffini-rest 1\npatch forearm\nunix_s 1\nwavelength_nm";
  for (int i = 0; i < 16; ++i) far += " 1400";
  EXPECT_NE(run(far + "\n").find("outside grating 1's band"), std::string::npos) << run(far + "\n");
  EXPECT_NE(run("ruffini-rest 1\npatch forearm\nunix_s 1\nwavelength_nm 1530\n").find("fewer than 16"),
            std::string::npos);
  EXPECT_NE(run("ruffini-rest 1\npatch forearm\nunix_s 99999999999\nwavelength_nm 1530\n").find("in the future"),
            std::string::npos);
  // A path that cannot be written (no such directory) is refused at start-up, not found out at the next restart
  // (review 11: it silently left every restart trusting its first capture).
  Process p({RUFFINI_DECODER_EXE, "--insecure", "--scene", kScene, "--patch", "forearm", "--interrogator", "127.0.0.1:1",
             "--aggregator", agg.address(), "--metrics", "127.0.0.1:0", "--rest-file", dir + "/no/such/dir/rest.txt"},
            dir);
  EXPECT_NE(p.WaitExit(10s), 0);
  EXPECT_NE(p.stderr_text().find("cannot be written there"), std::string::npos) << p.stderr_text();
}
}  // namespace
