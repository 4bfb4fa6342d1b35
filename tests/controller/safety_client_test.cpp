// The safety client and ruffini-controller against a scripted aggregator in this process (scripted_aggregator.h:
// it names the robot and the run as the safety layer's aggregator does), directly or through a TCP proxy that
// freezes its links (freeze_proxy.h). Every wait is a condition with a deadline; ruffini-controller is
// started and stopped by pid. Timings are printed as "[ metric ]".
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <mutex>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include "freeze_proxy.h"
#include "process.h"
#include "safety_client.h"
#include "scripted_aggregator.h"

namespace {

using namespace std::chrono_literals;
namespace rc = ruffini::controller;
namespace v1 = ruffini::v1;
namespace rt = ruffini::testing;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double Ms(Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

rc::SafetyClientConfig Config() {
  rc::SafetyClientConfig c;
  c.monitor.robot_name = "cobot";
  return c;
}

// The client's decisions in the order the callbacks ran.
struct Recorder {
  std::mutex mu;
  std::vector<std::string> events;  // "HALT <REASON>" or "CLEAR"
  void Add(std::string e) {
    std::lock_guard lock(mu);
    events.push_back(std::move(e));
  }
  std::vector<std::string> Snapshot() {
    std::lock_guard lock(mu);
    return events;
  }
  bool Has(const std::string& e) {
    std::lock_guard lock(mu);
    return std::find(events.begin(), events.end(), e) != events.end();
  }
};

// Finding 8: the watchdog does not wait for a callback. The clear callback blocks for 2 s; the aggregator goes
// silent right after the clear; halted() must turn true while that callback is still blocked (nominally 30 ms
// after the last state: printed, not asserted, as a loaded machine can starve any thread), and the
// NO_HEARTBEAT callback comes after the clear callback returned (order kept). Before, the callbacks ran under
// the lock the watchdog needed, so halted() could not turn true before the callback returned.
TEST(SafetyClient, ACallbackThatBlocksDoesNotDelayTheWatchdog) {
  rt::ScriptedAggregator agg;
  agg.Set(v1::SafetyState::STATE_CLEAR, 1);
  Recorder rec;
  std::atomic<bool> in_clear{false};
  std::atomic<std::int64_t> decided_silence_ns{0};
  rc::SafetyClient client(
      rc::AggregatorChannelFactory(agg.address()), Config(),
      [&](const rc::HaltEvent& e) {
        if (e.reason == rc::HaltReason::kNoHeartbeat) decided_silence_ns = e.silence.count();
        rec.Add("HALT " + std::string(rc::HaltReasonName(e.reason)));
      },
      [&](const rc::ClearEvent&) {
        rec.Add("CLEAR");
        in_clear = true;
        std::this_thread::sleep_for(2s);
        rec.Add("CLEAR returned");
      });
  client.Start();
  ASSERT_TRUE(rt::WaitFor([&] { return in_clear.load(); }, 5s));
  EXPECT_FALSE(client.halted());
  agg.SetSilent(true);
  const auto silent_at = Clock::now();
  ASSERT_TRUE(rt::WaitFor([&] { return client.halted(); }, 2s, 1ms));
  const auto halted_at = Clock::now();
  const double after_last_ms = Ms(halted_at - agg.last_sent());
  std::printf("[ metric ] halted() true %.1f ms after the last state (%.1f ms after silence began), the clear "
              "callback still blocked: %s\n",
              after_last_ms, Ms(halted_at - silent_at), rec.Has("CLEAR returned") ? "no" : "yes");
  std::fflush(stdout);
  EXPECT_FALSE(rec.Has("CLEAR returned")) << "halted() waited for the callback";
  // After the clear (a slow first connect may have halted NO_HEARTBEAT before it): the clear callback's end,
  // then the silence's halt, in that order.
  auto after_clear = [&] {
    const auto ev = rec.Snapshot();
    const auto clear = std::find(ev.begin(), ev.end(), "CLEAR");
    return std::vector<std::string>(clear == ev.end() ? ev.end() : clear + 1, ev.end());
  };
  ASSERT_TRUE(rt::WaitFor([&] { return after_clear().size() >= 2; }, 5s));
  const auto ev = after_clear();
  EXPECT_EQ(ev[0], "CLEAR returned");
  EXPECT_EQ(ev[1], "HALT NO_HEARTBEAT") << "callbacks out of order";
  std::printf("[ metric ] the watchdog decided at a silence of %.1f ms (limit 30 ms)\n",
              static_cast<double>(decided_silence_ns.load()) / 1e6);
  std::fflush(stdout);
  client.Stop();
}

TEST(SafetyClient, AStateForAnotherRobotHaltsAndIsCounted) {
  rt::ScriptedAggregator agg("another-cell");
  agg.Set(v1::SafetyState::STATE_CLEAR, 1);
  Recorder rec;
  rc::SafetyClient client(
      rc::AggregatorChannelFactory(agg.address()), Config(),
      [&](const rc::HaltEvent& e) { rec.Add("HALT " + std::string(rc::HaltReasonName(e.reason))); },
      [&](const rc::ClearEvent&) { rec.Add("CLEAR"); });
  client.Start();
  ASSERT_TRUE(rt::WaitFor([&] { return client.Stats().discarded >= 20; }, 5s));
  EXPECT_TRUE(client.halted());
  EXPECT_TRUE(rec.Has("HALT WRONG_ROBOT"));
  EXPECT_FALSE(rec.Has("CLEAR"));
  // Misaddressed states are the safety layer's errors: past the error-rate limit the client uses no state
  // until an operator acknowledges it, even once the aggregator names this robot.
  EXPECT_TRUE(client.Stats().link_errors[ruffini::channel::Error::kAddressing] >= 20);
  agg.SetRobot("cobot");
  const std::uint64_t before = client.Stats().states;
  ASSERT_TRUE(rt::WaitFor([&] { return client.Stats().states >= before + 10; }, 5s));  // >= 100 ms of good states
  EXPECT_FALSE(rec.Has("CLEAR"));
  client.AcknowledgeLinkErrors();
  ASSERT_TRUE(rt::WaitFor([&] { return rec.Has("CLEAR"); }, 5s));
  client.Stop();
}

TEST(SafetyClient, TheRobotNameIsRequired) {
  EXPECT_THROW(rc::SafetyClient(rc::AggregatorChannelFactory("127.0.0.1:1"), rc::SafetyClientConfig{}, {}, {}),
               std::invalid_argument);
}

// Finding 5 (client half): the link freezes (no FIN, no RST: a vanished host). The client halts at 30 ms,
// cancels the silent stream at 500 ms and makes a new channel, so once the proxy lets NEW connections through
// (the frozen one stays frozen for good) it dials again and states flow within a few seconds. Before, it
// re-opened the stream on the same channel, i.e. on the dead connection, and never dialled again.
TEST(SafetyClient, AfterAFrozenLinkANewConnectionIsDialled) {
  rt::ScriptedAggregator agg;
  rt::FreezeProxy proxy(agg.port());
  Recorder rec;
  rc::SafetyClient client(
      rc::AggregatorChannelFactory(proxy.address()), Config(),
      [&](const rc::HaltEvent& e) { rec.Add("HALT " + std::string(rc::HaltReasonName(e.reason))); }, {});
  client.Start();
  ASSERT_TRUE(rt::WaitFor([&] { return client.Stats().states >= 10; }, 5s));
  EXPECT_EQ(proxy.connections(), 1);
  const auto frozen_at = Clock::now();
  proxy.Freeze();
  ASSERT_TRUE(rt::WaitFor([&] { return rec.Has("HALT NO_HEARTBEAT"); }, 2s, 1ms));
  // Frozen for 1.5 s (new connections too): nothing gets through.
  std::this_thread::sleep_for(1500ms);
  const auto states = client.Stats().states;
  EXPECT_TRUE(client.halted());
  const auto lifted_at = Clock::now();
  proxy.LiftForNew();
  ASSERT_TRUE(rt::WaitFor([&] { return client.Stats().states >= states + 10; }, 10s, 5ms))
      << "no states through a new connection; proxy connections " << proxy.connections();
  const auto st = client.Stats();
  std::printf("[ metric ] states again %.0f ms after new connections were let through (frozen %.0f ms; %d "
              "connections, %llu channels, %llu streams)\n",
              Ms(Clock::now() - lifted_at), Ms(lifted_at - frozen_at), proxy.connections(),
              static_cast<unsigned long long>(st.channels_created), static_cast<unsigned long long>(st.streams_opened));
  std::fflush(stdout);
  EXPECT_GE(proxy.connections(), 2);
  EXPECT_GE(st.channels_created, 2u);
  // Stop() does not hang on the frozen connection either.
  const auto stop_at = Clock::now();
  client.Stop();
  EXPECT_LT(Ms(Clock::now() - stop_at), 2000.0);  // the shutdown bound (measured far below)
}

// Finding 4: the ResetStop helper names the run as well as the epoch.
TEST(SafetyClient, TheResetStopHelperNamesTheRunAndTheEpoch) {
  rt::ScriptedAggregator agg("cobot", 0xabcdef0123456789ULL);
  agg.Set(v1::SafetyState::STATE_STOP, 6);
  auto stub = v1::Aggregator::NewStub(rc::MakeAggregatorChannel(agg.address()));
  v1::ResetStopResponse response;
  ASSERT_TRUE(rc::ResetStop(*stub, 0xabcdef0123456789ULL, 6, "test", "note", &response).ok());
  EXPECT_TRUE(response.accepted());
  EXPECT_EQ(agg.last_reset().aggregator_run_id(), 0xabcdef0123456789ULL);
  EXPECT_EQ(agg.last_reset().stop_epoch(), 6u);
  EXPECT_EQ(agg.last_reset().operator_name(), "test");
  ASSERT_TRUE(rc::ResetStop(*stub, 0x1234, 6, "test", "", &response).ok());
  EXPECT_FALSE(response.accepted());
  EXPECT_EQ(response.reason(), v1::RESET_REFUSAL_WRONG_RUN);
}

// ruffini-controller against the scripted aggregator.

std::string Base(const std::string& name) {
  const auto dir = fs::current_path() / ("controller_scripted_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir.string();
}

// Finding 8: SIGTERM with a frozen link. Before, the cycle blocked in a joint-state write once the frozen
// connection's flow-control window was full, and shutdown waited forever in EndStream.
TEST(RuffiniController, ExitsWithin2SecondsOfSigtermOnAFrozenLink) {
  rt::ScriptedAggregator agg;
  rt::FreezeProxy proxy(agg.port());
  const std::string base = Base("frozen");
  rt::Process ctl({RUFFINI_CONTROLLER_EXE, "--insecure", "--robot", "cobot", "--aggregator", proxy.address(),
                   "--rate-hz", "1000"},
                  base);
  ASSERT_TRUE(rt::WaitFor([&] { return agg.joint_states() >= 200 || !ctl.Running(); }, 10s)) << ctl.stderr_text();
  proxy.Freeze();
  // Long enough for the joint-state writes to fill the frozen connection's windows (1 kHz of ~150 bytes).
  ASSERT_TRUE(rt::WaitFor([&] { return ctl.stdout_text().find("HALT NO_HEARTBEAT") != std::string::npos; }, 5s));
  std::this_thread::sleep_for(1500ms);
  const auto term_at = Clock::now();
  ctl.Signal(SIGTERM);
  const int rc = ctl.WaitExit(10s);
  const double exit_ms = Ms(Clock::now() - term_at);
  std::printf("[ metric ] ruffini-controller exited %.0f ms after SIGTERM on a frozen link (status %d)\n", exit_ms, rc);
  std::fflush(stdout);
  EXPECT_EQ(rc, 0) << ctl.stderr_text();
  EXPECT_LT(exit_ms, 2000.0) << ctl.stderr_text();
  EXPECT_NE(ctl.stdout_text().find("summary: halts by reason"), std::string::npos) << ctl.stdout_text();
}

// Finding 8: a stdout nobody reads (a full pipe) must stop neither the cycle nor SIGTERM. The pipe is filled
// before the controller starts, so its first line blocks the writer. Before, the halt callback blocked in
// printf with the client's lock held, and shutdown joined that thread forever.
TEST(RuffiniController, AStuckStdoutStopsNeitherJointStatesNorSigterm) {
  rt::ScriptedAggregator agg;
  const std::string base = Base("stuck_stdout");
  int fds[2];
  ASSERT_EQ(pipe(fds), 0);
  fcntl(fds[1], F_SETFL, O_NONBLOCK);
  std::vector<char> junk(4096, 'x');
  while (write(fds[1], junk.data(), junk.size()) > 0) {
  }
  fcntl(fds[1], F_SETFL, 0);  // the child's writes block, as on any full pipe
  const std::string err = base + "/stderr";
  std::vector<std::string> args = {RUFFINI_CONTROLLER_EXE, "--insecure", "--robot", "cobot", "--aggregator",
                                   agg.address(), "--rate-hz", "500"};
  const pid_t pid = fork();
  if (pid == 0) {
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    dup2(fds[1], 1);
    if (!freopen(err.c_str(), "w", stderr)) _exit(126);
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    execv(argv[0], argv.data());
    _exit(127);
  }
  close(fds[1]);
  auto running = [&] { return waitpid(pid, nullptr, WNOHANG) == 0; };
  // Joint states flow, and keep flowing after the first halt line is stuck in the pipe.
  ASSERT_TRUE(rt::WaitFor([&] { return agg.joint_states() >= 100; }, 10s)) << rt::Slurp(err);
  const auto n = agg.joint_states();
  EXPECT_TRUE(rt::WaitFor([&] { return agg.joint_states() >= n + 250; }, 5s)) << "joint states stopped";
  const auto term_at = Clock::now();
  kill(pid, SIGTERM);
  int status = 0;
  const bool exited = rt::WaitFor([&] { return waitpid(pid, &status, WNOHANG) == pid; }, 10s, 5ms);
  const double exit_ms = Ms(Clock::now() - term_at);
  if (!exited) {
    kill(pid, SIGKILL);
    waitpid(pid, &status, 0);
  }
  (void)running;
  close(fds[0]);
  std::printf("[ metric ] ruffini-controller with a stuck stdout exited %.0f ms after SIGTERM\n", exit_ms);
  std::fflush(stdout);
  ASSERT_TRUE(exited) << rt::Slurp(err);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << status << rt::Slurp(err);
  EXPECT_LT(exit_ms, 2000.0);
}

TEST(RuffiniController, RefusesStatesForAnotherRobot) {
  rt::ScriptedAggregator agg("");  // an aggregator that names no robot: refused like another one
  agg.Set(v1::SafetyState::STATE_CLEAR, 1);
  const std::string base = Base("wrong_robot");
  rt::Process ctl({RUFFINI_CONTROLLER_EXE, "--insecure", "--robot", "cobot", "--aggregator", agg.address(),
                   "--rate-hz", "200", "--duration-s", "1"},
                  base);
  EXPECT_EQ(ctl.WaitExit(10s), 0) << ctl.stderr_text();
  const std::string out = ctl.stdout_text();
  EXPECT_NE(out.find("HALT WRONG_ROBOT: a state for robot '', not this controller's 'cobot'"), std::string::npos) << out;
  EXPECT_EQ(out.find(" CLEAR "), std::string::npos) << out;
  // Refused states are no heartbeat: the stream is also cancelled after 500 ms and dialled again (CONNECT_FAILED).
  EXPECT_TRUE(std::regex_search(out, std::regex("halts by reason: [^\n]*WRONG_ROBOT [0-9]+"))) << out;
  EXPECT_TRUE(std::regex_search(out, std::regex("safety states [0-9]+ \\(skipped 0, refused [1-9][0-9]*\\)"))) << out;
  // An aggregator that names another robot is refused at start.
  rt::ScriptedAggregator other("other-cell");
  rt::Process ctl2({RUFFINI_CONTROLLER_EXE, "--insecure", "--robot", "cobot", "--aggregator", other.address()},
                   base + "/other");
  EXPECT_EQ(ctl2.WaitExit(10s), 1);
  EXPECT_NE(ctl2.stderr_text().find("guards robot 'other-cell', not --robot 'cobot'"), std::string::npos)
      << ctl2.stderr_text();
  // --robot is required.
  rt::Process ctl3({RUFFINI_CONTROLLER_EXE, "--insecure", "--aggregator", other.address()}, base + "/none");
  EXPECT_NE(ctl3.WaitExit(10s), 0);
  EXPECT_NE(ctl3.stderr_text().find("--robot is required"), std::string::npos) << ctl3.stderr_text();
}

}  // namespace
