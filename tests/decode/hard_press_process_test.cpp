// Never a hard press read as light, end to end: the real ruffini-sim (a scripted 200 N press 2 mm inside
// the elbow edge, config/scenarios/forearm-hard-edge.yaml) and the real ruffini-decoder on 127.0.0.1 (port 0,
// ports files), publishing to an in-test aggregator. The Hyperion stream carries no saturation flag: the
// lost peaks are the evidence, and the decoder's contacts say over_range with a force of at least 2.5 N.
// Every wait is a condition with a deadline; every process is stopped by pid.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <chrono>
#include <filesystem>
#include <string>
#include <vector>

#include "aggregator_stub.h"
#include "process.h"

namespace {

using namespace std::chrono_literals;
namespace v1 = ruffini::v1;
namespace rt = ruffini::testing;
namespace fs = std::filesystem;

const std::string kSrc = RUFFINI_SOURCE_DIR;

std::string Dir(const std::string& name) {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const fs::path d = fs::current_path() / ("hard_press_" + std::string(info->name()) + "_" + name);
  fs::remove_all(d);
  fs::create_directories(d);
  return d.string();
}

TEST(HardPressProcess, A200NewtonEdgePressReachesTheAggregatorAsOverRangeContacts) {
  rt::AggregatorStub agg;
  const std::string sim_dir = Dir("sim"), dec_dir = Dir("dec");
  rt::Process sim({RUFFINI_SIM_EXE, "--scene", kSrc + "/config/scenes/forearm.yaml", "--scenario",
                   kSrc + "/config/scenarios/forearm-hard-edge.yaml", "--rate-hz", "1000", "--command-port", "0",
                   "--stream-port", "0", "--ports-file", sim_dir + "/ports"},
                  sim_dir);
  ASSERT_TRUE(rt::WaitFor([&] { return rt::ReadPorts(sim_dir + "/ports").count("stream") > 0 || !sim.Running(); }, 10s));
  const int stream_port = rt::ReadPorts(sim_dir + "/ports")["stream"];
  ASSERT_GT(stream_port, 0) << sim.stderr_text();
  rt::Process dec({RUFFINI_DECODER_EXE, "--insecure", "--scene", kSrc + "/config/scenes/forearm.yaml", "--patch",
                   "forearm", "--interrogator", "127.0.0.1:" + std::to_string(stream_port), "--aggregator",
                   agg.address(), "--metrics", "127.0.0.1:0", "--ports-file", dec_dir + "/ports", "--rate-hz", "1000",
                   "--silence-ms", "100"},
                  dec_dir);
  // The script loops every 8 s (8000 samples at 1 kHz; a message's serial is its frame's sample): the press
  // ramps from 4.0 s, holds 4.3..5.3 s and is released by 5.6 s.
  const auto in_press = [](std::uint64_t serial) { return serial % 8000 >= 4000 && serial % 8000 < 5700; };
  const auto over_range = [&](const std::vector<rt::Received>& r) {
    return std::count_if(r.begin(), r.end(), [&](const rt::Received& m) {
             return m.message.has_contact() && m.message.contact().over_range() && in_press(m.message.interrogator_serial());
           }) >= 50;
  };
  ASSERT_TRUE(agg.WaitFor(over_range, 20s)) << dec.stderr_text() << sim.stderr_text();
  const auto got = agg.Snapshot();
  bool onset_seen = false;
  for (const auto& m : got) {
    if (!m.message.has_contact()) continue;
    const auto& c = m.message.contact();
    if (c.onset()) onset_seen = true;
    if (!c.over_range()) continue;
    EXPECT_TRUE(in_press(m.message.interrogator_serial())) << "over range at rest, sample " << m.message.interrogator_serial();
    // "At least" the stated bound, and the force says so: the aggregator's threshold rule (1.5 N) stops.
    EXPECT_FLOAT_EQ(c.force_lower_bound_n(), 2.5f);
    EXPECT_GE(c.force_n(), c.force_lower_bound_n());
    EXPECT_FALSE(c.released());
  }
  EXPECT_TRUE(onset_seen);
  // No frame was refused for it: the contacts are the report, not a fault.
  EXPECT_FALSE(std::any_of(got.begin(), got.end(), [](const rt::Received& m) {
    return m.message.has_fault() && m.message.fault().code() == v1::PATCH_FAULT_CODE_FRAMES_REJECTED;
  }));
  dec.Stop();
  sim.Stop();
}

}  // namespace
