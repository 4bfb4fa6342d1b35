// ruffini-controller: a reference controller for a simulated robot. It asks the aggregator for the joint
// names (GetStatus), plays a smooth joint trajectory and publishes joint states at --rate-hz over
// PublishJointStates, and obeys the safety client (safety_client.h) for its robot (--robot): on every halt it
// freezes the trajectory and keeps publishing the held position; on a clear it resumes (ramping its speed up
// over --resume-s). stdout: one line per safety transition ("t=1.234 s HALT STOP: STOP epoch 3 cause contact
// upper_arm_a 1.60 N ...") and a summary at exit. Logs go to stderr. The operator acknowledges the safety
// layer's error-rate latch (HALT LINK_ERROR ... latched) with SIGUSR1 (`kill -USR1 PID`): one "ACK LINK_ERRORS"
// line says whether a latch was released. Exit codes as the other tools: 0 ok
// (SIGINT, SIGTERM or --duration-s), 1 bad input or an aggregator that cannot be reached or guards another
// robot (the message says which), 2 usage.
//
// Threads: the cycle (this main thread) never waits on gRPC or stdout. It hands each joint state to a
// publishing thread through a one-sample slot (a newer sample replaces one not yet sent: counted), and its
// lines go through a bounded queue to a writer thread (a line that does not fit is dropped: counted). The
// safety client's callbacks only queue lines. Shutdown has deadlines: a frozen link or a stuck stdout cannot
// hold SIGTERM for more than about a second.
#include <signal.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <exception>
#include <mutex>
#include <numbers>
#include <string>
#include <thread>
#include <vector>

#include "ruffini/error.h"
#include "ruffini/service/common.h"
#include "ruffini/service/tls.h"
#include "safety_client.h"

namespace {

namespace rc = ruffini::controller;
namespace v1 = ruffini::v1;
using Clock = std::chrono::steady_clock;

double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

// q_i(tau) = amplitude * sin(2 pi f_i tau + phi_i): small, smooth, within every joint's limits around zero.
struct SineTrajectory {
  double amplitude_rad = 0.2;
  double Frequency(std::size_t i) const { return 0.1 + 0.03 * static_cast<double>(i); }  // Hz
  double Phase(std::size_t i) const { return 0.7 * static_cast<double>(i); }
  double Position(std::size_t i, double tau_s) const {
    return amplitude_rad * std::sin(2 * std::numbers::pi * Frequency(i) * tau_s + Phase(i));
  }
  double Velocity(std::size_t i, double tau_s) const {
    const double w = 2 * std::numbers::pi * Frequency(i);
    return amplitude_rad * w * std::cos(w * tau_s + Phase(i));
  }
};

// stdout through a bounded queue and a writer thread: Push never blocks (a full queue drops the line and
// counts it); the writer may block in fwrite on a full pipe without holding anything up.
class LineWriter {
 public:
  explicit LineWriter(std::size_t capacity) : capacity_(capacity), thread_([this] { Run(); }) {}
  ~LineWriter() {
    {
      std::lock_guard lock(mu_);
      stop_ = true;
    }
    cv_.notify_all();
    if (thread_.joinable()) thread_.join();
  }
  void Push(std::string line, bool always = false) {
    {
      std::lock_guard lock(mu_);
      if (!always && queue_.size() >= capacity_) {
        ++dropped_;
        return;
      }
      queue_.push_back(std::move(line));
    }
    cv_.notify_one();
  }
  std::uint64_t dropped() {
    std::lock_guard lock(mu_);
    return dropped_;
  }
  // Waits until every queued line is written, at most `timeout`; false if stdout is stuck.
  bool Drain(std::chrono::milliseconds timeout) {
    std::unique_lock lock(mu_);
    return drained_cv_.wait_for(lock, timeout, [this] { return queue_.empty() && !writing_; });
  }
  // When Drain failed: the writer is stuck in a write that may never return; the process must not wait for it.
  void Abandon() { thread_.detach(); }

 private:
  void Run() {
    std::unique_lock lock(mu_);
    for (;;) {
      cv_.wait(lock, [this] { return stop_ || !queue_.empty(); });
      if (queue_.empty()) return;
      std::string line = std::move(queue_.front());
      queue_.pop_front();
      writing_ = true;
      lock.unlock();
      std::fwrite(line.data(), 1, line.size(), stdout);
      std::fflush(stdout);
      lock.lock();
      writing_ = false;
      if (queue_.empty()) drained_cv_.notify_all();
    }
  }
  std::size_t capacity_;
  std::mutex mu_;
  std::condition_variable cv_, drained_cv_;
  std::deque<std::string> queue_;
  std::uint64_t dropped_ = 0;
  bool stop_ = false, writing_ = false;
  std::thread thread_;
};

// The newest joint state, handed from the cycle to the publishing thread. The cycle holds the lock only to
// copy a few doubles; the publisher holds it only to copy them out, never across a gRPC call.
struct JointSlot {
  std::mutex mu;
  std::condition_variable cv;
  std::vector<double> q, qd;
  std::int64_t t_ns = 0;
  bool fresh = false, stop = false;
  std::uint64_t replaced = 0;  // samples overwritten before the publisher took them
};

}  // namespace

int main(int argc, char** argv) {
  spdlog::set_default_logger(spdlog::stderr_color_mt("ruffini-controller"));
  CLI::App app{"ruffini-controller: a reference controller that obeys the aggregator's safety state"};
  std::string aggregator, robot, trajectory = "sine", subscriber = "ruffini-controller";
  double rate_hz = 1000, duration_s = 0, amplitude_rad = 0.2, resume_s = 0.5, connect_timeout_s = 5;
  int heartbeat_timeout_ms = 30;
  double freshness_budget_ms = 20, link_error_window_s = 60;
  int link_error_limit = 2;
  bool watch_only = false, unix_time = false;
  app.add_option("--aggregator", aggregator, "The aggregator's gRPC address, HOST:PORT")->required();
  app.add_option("--robot", robot,
                 "This robot's name, the scene's (e.g. cobot): states from an aggregator guarding another robot are "
                 "refused (halt WRONG_ROBOT)")
      ->required();
  app.add_option("--rate-hz", rate_hz, "Joint-state publishing rate, Hz")->capture_default_str()->check(CLI::Range(1.0, 10000.0));
  app.add_option("--duration-s", duration_s, "Stop after this long, s (0: until SIGINT or SIGTERM)")
      ->capture_default_str()->check(CLI::NonNegativeNumber);
  app.add_option("--trajectory", trajectory, "The trajectory to play")->capture_default_str()->check(CLI::IsMember({"sine"}));
  app.add_option("--amplitude-rad", amplitude_rad, "Sine amplitude per joint, rad (about zero)")
      ->capture_default_str()->check(CLI::Range(0.0, 1.0));
  app.add_option("--resume-s", resume_s, "Speed ramp after a clear, s")->capture_default_str()->check(CLI::Range(0.0, 10.0));
  app.add_option("--heartbeat-timeout-ms", heartbeat_timeout_ms, "Halt when no safety state came for this long, ms")
      ->capture_default_str()->check(CLI::Range(11, 1000));
  app.add_option("--freshness-budget-ms", freshness_budget_ms,
                 "Discard (and halt LATE on) a safety state older than this, ms (docs/safety-channel.md)")
      ->capture_default_str()->check(CLI::Range(1.0, 10000.0));
  app.add_option("--link-error-limit", link_error_limit,
                 "Safety-layer errors within --link-error-window-s that latch the halt until SIGUSR1")
      ->capture_default_str()->check(CLI::Range(1, 8));
  app.add_option("--link-error-window-s", link_error_window_s, "The error-rate rule's window, s")
      ->capture_default_str()->check(CLI::Range(0.001, 86400.0));
  app.add_option("--connect-timeout-s", connect_timeout_s, "How long to wait for the aggregator's GetStatus at start, s")
      ->capture_default_str()->check(CLI::Range(0.1, 600.0));
  app.add_option("--subscriber", subscriber, "The name this controller gives the aggregator")->capture_default_str();
  app.add_flag("--watch-only", watch_only,
               "Publish no joint states: only obey the safety state (a second controller or a safety PLC beside the "
               "one that owns the robot's joint states)");
  app.add_flag("--unix-time", unix_time,
               "Stamp each stdout line with Unix time (t_unix_ns=N) instead of seconds since start (t=S s), so that "
               "a test harness can line them up with other processes' clocks");
  std::string tls_dir;
  bool insecure = false;
  auto* tls_opt = app.add_option("--tls-dir", tls_dir,
                                 "Mutual TLS: DIR/ca.crt, DIR/controller.crt and DIR/controller.key (docs/security.md)")
                      ->check(CLI::ExistingDirectory);
  app.add_flag("--insecure", insecure, "Plaintext gRPC to the aggregator (logged as a warning)")->excludes(tls_opt);
  CLI11_PARSE(app, argc, argv);

  // Blocked in every thread (all start after this) and taken by the cycle with sigpending/sigwait.
  sigset_t stop_signals, ack_signals, blocked;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  sigemptyset(&ack_signals);
  sigaddset(&ack_signals, SIGUSR1);
  blocked = stop_signals;
  sigaddset(&blocked, SIGUSR1);
  pthread_sigmask(SIG_BLOCK, &blocked, nullptr);
  signal(SIGPIPE, SIG_IGN);

  try {
    const auto address = ruffini::service::ParseHostPort(aggregator, "--aggregator");
    const auto tls = ruffini::service::LoadTls(tls_dir, insecure, "controller");
    ruffini::service::LogTls(tls, "the aggregator cannot tell this controller from anyone else");
    const auto credentials = ruffini::service::ChannelCredentials(tls);
    auto channel = rc::MakeAggregatorChannel(address.str(), credentials);  // GetStatus and joint states

    // The joint names, in the order the aggregator's robot model lists them.
    v1::AggregatorStatus status;
    {
      grpc::ClientContext ctx;
      ctx.set_wait_for_ready(true);
      ctx.set_deadline(std::chrono::system_clock::now() +
                       std::chrono::milliseconds(static_cast<std::int64_t>(connect_timeout_s * 1000)));
      auto stub = v1::Aggregator::NewStub(channel);
      const grpc::Status s = stub->GetStatus(&ctx, v1::GetStatusRequest{}, &status);
      if (!s.ok()) {
        throw ruffini::InputError("--aggregator " + address.str() + ": no aggregator answered GetStatus within " +
                                  std::to_string(connect_timeout_s) + " s (" + std::to_string(s.error_code()) + ": " +
                                  s.error_message() + ")");
      }
    }
    if (!status.robot_name().empty() && status.robot_name() != robot) {
      throw ruffini::InputError("--aggregator " + address.str() + " guards robot '" + status.robot_name() +
                                "', not --robot '" + robot + "'");
    }
    if (status.robot_name().empty()) {
      spdlog::warn("the aggregator at {} names no robot: its states will be refused (WRONG_ROBOT) until it does",
                   address.str());
    }
    const std::vector<std::string> names(status.joint_names().begin(), status.joint_names().end());
    if (names.empty()) throw ruffini::InputError("--aggregator " + address.str() + ": the aggregator lists no joints");
    spdlog::info("aggregator {} (version {}): {} joints, safety {}", address.str(), status.aggregator_version(),
                 names.size(), rc::DescribeState(status.safety()));

    const auto t0 = Clock::now();
    LineWriter out(1024);
    auto line = [t0, unix_time, &out](Clock::time_point t, const std::string& text) {
      char stamp[48];
      if (unix_time) {
        // The event's steady time on the Unix clock: now on both clocks, minus how long ago it was.
        const auto ago = std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - t).count();
        std::snprintf(stamp, sizeof stamp, "t_unix_ns=%lld ", static_cast<long long>(ruffini::service::UnixNowNs() - ago));
      } else {
        std::snprintf(stamp, sizeof stamp, "t=%.3f s ", Seconds(t - t0));
      }
      out.Push(stamp + text + "\n");
    };
    rc::SafetyClientConfig config;
    config.subscriber = subscriber;
    config.monitor.robot_name = robot;
    config.monitor.heartbeat_timeout = std::chrono::milliseconds(heartbeat_timeout_ms);
    config.monitor.link.freshness.budget_ns = static_cast<std::int64_t>(freshness_budget_ms * 1e6);
    config.monitor.link.error_rate.limit = link_error_limit;
    config.monitor.link.error_rate.window_ns = static_cast<std::int64_t>(link_error_window_s * 1e9);
    rc::SafetyClient safety(
        rc::AggregatorChannelFactory(address.str(), credentials), config,
        [&](const rc::HaltEvent& e) {
          std::string text = "HALT " + std::string(rc::HaltReasonName(e.reason));
          if (e.reason == rc::HaltReason::kStop || e.reason == rc::HaltReason::kFault ||
              e.reason == rc::HaltReason::kUnknownState) {
            text += ": " + rc::DescribeState(e.state);
          } else {
            text += ": " + e.detail;
          }
          if (e.link_errors_latched) text += " [latched: acknowledge with SIGUSR1]";
          line(e.t, text);
        },
        [&](const rc::ClearEvent& e) {
          char buf[64];
          std::snprintf(buf, sizeof buf, " (halted %.3f s)", Seconds(e.halted_for));
          line(e.t, "CLEAR " + rc::DescribeState(e.state) + buf);
        });
    safety.Start();

    // Joint states leave from a thread of their own: a gRPC write may block (a frozen link) and the cycle
    // must not.
    rc::JointStatePublisher publisher(channel, names);
    JointSlot slot;
    slot.q.resize(names.size());
    slot.qd.resize(names.size());
    std::atomic<bool> publisher_done{false};
    v1::PublishJointStatesResponse totals;
    grpc::Status finish;
    std::thread publishing([&] {
      if (watch_only) {  // no stream at all: this controller only obeys
        publisher_done = true;
        return;
      }
      std::vector<double> q(names.size()), qd(names.size());
      for (;;) {
        std::int64_t t_ns = 0;
        {
          std::unique_lock lock(slot.mu);
          slot.cv.wait(lock, [&] { return slot.fresh || slot.stop; });
          if (slot.stop) break;
          q = slot.q;
          qd = slot.qd;
          t_ns = slot.t_ns;
          slot.fresh = false;
        }
        publisher.Publish(q, qd, t_ns);
      }
      finish = publisher.Finish(&totals, std::chrono::milliseconds(500));
      publisher_done = true;
    });

    SineTrajectory traj;
    traj.amplitude_rad = amplitude_rad;
    const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / rate_hz));
    const auto end = duration_s > 0 ? t0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(duration_s))
                                    : Clock::time_point::max();
    std::vector<double> q(names.size()), qd(names.size());
    double tau_s = 0, speed = 0;  // trajectory time (advances only while moving) and the speed scale 0..1
    std::uint64_t cycles = 0, overruns = 0;
    auto next = Clock::now();
    int sig = 0;
    for (;;) {
      sigset_t pending;
      sigpending(&pending);
      if (sigismember(&pending, SIGINT) || sigismember(&pending, SIGTERM)) {
        sigwait(&stop_signals, &sig);
        spdlog::info("signal {}: stopping", sig);
        break;
      }
      if (sigismember(&pending, SIGUSR1)) {
        // The operator's acknowledgement of the error-rate latch. The robot still needs three clean states.
        int ack = 0;
        sigwait(&ack_signals, &ack);
        if (safety.AcknowledgeLinkErrors()) {
          line(Clock::now(), "ACK LINK_ERRORS: the operator acknowledged the error-rate latch (SIGUSR1); states are "
                             "used again, three clean CLEARs release");
          spdlog::warn("SIGUSR1: the safety layer's error-rate latch acknowledged by the operator");
        } else {
          line(Clock::now(), "ACK LINK_ERRORS: nothing to acknowledge (SIGUSR1; no error-rate latch held)");
        }
      }
      const auto now = Clock::now();
      if (now >= end) break;
      const double dt = Seconds(period);
      if (safety.halted()) {
        speed = 0;  // hold: the trajectory freezes where it is
      } else {
        speed = resume_s > 0 ? std::min(1.0, speed + dt / resume_s) : 1.0;
        tau_s += speed * dt;
      }
      for (std::size_t i = 0; i < names.size(); ++i) {
        q[i] = traj.Position(i, tau_s);
        qd[i] = speed * traj.Velocity(i, tau_s);
      }
      if (!watch_only) {
        std::lock_guard lock(slot.mu);
        std::copy(q.begin(), q.end(), slot.q.begin());
        std::copy(qd.begin(), qd.end(), slot.qd.begin());
        slot.t_ns = ruffini::service::UnixNowNs();
        if (slot.fresh) ++slot.replaced;
        slot.fresh = true;
      }
      slot.cv.notify_one();
      ++cycles;
      next += period;
      const auto after = Clock::now();
      if (after > next) {
        ++overruns;
        if (after > next + 10 * period) next = after;  // fell far behind: do not burst
      } else {
        std::this_thread::sleep_until(next);
      }
    }

    const auto t_end = Clock::now();
    safety.Stop();
    {
      std::lock_guard lock(slot.mu);
      slot.stop = true;
    }
    slot.cv.notify_one();
    // The publisher ends its stream itself (Finish, 500 ms deadline); a write stuck on a frozen link is
    // cancelled after 500 ms.
    const auto cancel_at = Clock::now() + std::chrono::milliseconds(500);
    while (!publisher_done && Clock::now() < cancel_at) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    if (!publisher_done) {
      spdlog::warn("joint-state stream stuck (a frozen link?): cancelling it");
      publisher.Cancel();
    }
    publishing.join();
    const rc::SafetyStats st = safety.Stats();

    char buf[512];
    std::snprintf(buf, sizeof buf, "summary: ran %.3f s, %llu cycles at %.0f Hz (%llu late)\n", Seconds(t_end - t0),
                  static_cast<unsigned long long>(cycles), rate_hz, static_cast<unsigned long long>(overruns));
    out.Push(buf, true);
    std::snprintf(buf, sizeof buf,
                  "summary: joint states written %llu, failed %llu, replaced before sending %llu; aggregator received "
                  "%llu accepted %llu rejected %llu%s%s\n",
                  static_cast<unsigned long long>(publisher.written()), static_cast<unsigned long long>(publisher.failed()),
                  static_cast<unsigned long long>(slot.replaced), static_cast<unsigned long long>(totals.received()),
                  static_cast<unsigned long long>(totals.accepted()), static_cast<unsigned long long>(totals.rejected()),
                  totals.last_rejection().empty() ? "" : ", last: ", totals.last_rejection().c_str());
    out.Push(buf, true);
    std::string halts;
    for (int r = 0; r < rc::kHaltReasonCount; ++r) {
      const auto n = st.halts[static_cast<std::size_t>(r)];
      if (n == 0) continue;
      if (!halts.empty()) halts += ", ";
      halts += std::string(rc::HaltReasonName(static_cast<rc::HaltReason>(r))) + " " + std::to_string(n);
    }
    std::snprintf(buf, sizeof buf, "summary: halts by reason: %s; clears %llu; time halted %.3f s of %.3f s\n",
                  halts.empty() ? "none" : halts.c_str(), static_cast<unsigned long long>(st.clears),
                  Seconds(st.time_halted), Seconds(t_end - t0));
    out.Push(buf, true);
    std::snprintf(buf, sizeof buf,
                  "summary: safety states %llu (skipped %llu, refused %llu), streams %llu, channels %llu, heartbeat gap "
                  "max %.1f ms, last %s\n",
                  static_cast<unsigned long long>(st.states), static_cast<unsigned long long>(st.skipped_states),
                  static_cast<unsigned long long>(st.discarded), static_cast<unsigned long long>(st.streams_opened),
                  static_cast<unsigned long long>(st.channels_created), static_cast<double>(st.max_state_gap.count()) / 1e6,
                  st.states > st.discarded ? rc::DescribeState(st.last_state).c_str() : "none");
    out.Push(buf, true);
    std::string errors;
    for (std::size_t k = 0; k < ruffini::channel::kErrorKinds; ++k) {
      if (st.link_errors.by_error[k] == 0) continue;
      if (!errors.empty()) errors += ", ";
      errors += std::string(ruffini::channel::Name(static_cast<ruffini::channel::Error>(k))) + " " +
                std::to_string(st.link_errors.by_error[k]);
    }
    std::snprintf(buf, sizeof buf, "summary: link errors: %s; error-rate latch %s, acknowledged %llu\n",
                  errors.empty() ? "none" : errors.c_str(), st.link_errors_latched ? "held" : "not held",
                  static_cast<unsigned long long>(st.link_acknowledgements));
    out.Push(buf, true);
    std::snprintf(buf, sizeof buf, "summary: stdout lines dropped %llu\n", static_cast<unsigned long long>(out.dropped()));
    out.Push(buf, true);
    if (!out.Drain(std::chrono::milliseconds(500))) {
      // stdout is stuck (a full pipe nobody reads): exit without waiting for it (exit() would flush it).
      spdlog::warn("stdout is not being read: exiting without the rest of the summary");
      out.Abandon();
      std::_Exit(0);
    }
    if (!finish.ok()) spdlog::warn("joint-state stream ended with {}: {}", static_cast<int>(finish.error_code()), finish.error_message());
    return 0;
  } catch (const ruffini::InputError& e) {
    spdlog::error("{}", e.what());
    return 1;
  } catch (const std::exception& e) {
    spdlog::error("unexpected error: {}", e.what());
    return 1;
  }
}
