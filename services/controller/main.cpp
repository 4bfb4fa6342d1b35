// ruffini-controller: a reference controller for a simulated robot. It asks the aggregator for the joint
// names (GetStatus), plays a smooth joint trajectory and publishes joint states at --rate-hz over
// PublishJointStates, and obeys the safety client (safety_client.h): on every halt it freezes the trajectory
// and keeps publishing the held position; on a clear it resumes (ramping its speed up over --resume-s).
// stdout: one line per safety transition ("t=1.234 s HALT STOP epoch 3 cause contact upper_arm_a 1.60 N ...")
// and a summary at exit. Logs go to stderr. Exit codes as the other tools: 0 ok (SIGINT, SIGTERM or
// --duration-s), 1 bad input or an aggregator that cannot be reached (the message says which), 2 usage.
#include <signal.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <numbers>
#include <string>
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

}  // namespace

int main(int argc, char** argv) {
  spdlog::set_default_logger(spdlog::stderr_color_mt("ruffini-controller"));
  CLI::App app{"ruffini-controller: a reference controller that obeys the aggregator's safety state"};
  std::string aggregator, trajectory = "sine", subscriber = "ruffini-controller";
  double rate_hz = 1000, duration_s = 0, amplitude_rad = 0.2, resume_s = 0.5, connect_timeout_s = 5;
  int heartbeat_timeout_ms = 30;
  app.add_option("--aggregator", aggregator, "The aggregator's gRPC address, HOST:PORT")->required();
  app.add_option("--rate-hz", rate_hz, "Joint-state publishing rate, Hz")->capture_default_str()->check(CLI::Range(1.0, 10000.0));
  app.add_option("--duration-s", duration_s, "Stop after this long, s (0: until SIGINT or SIGTERM)")
      ->capture_default_str()->check(CLI::NonNegativeNumber);
  app.add_option("--trajectory", trajectory, "The trajectory to play")->capture_default_str()->check(CLI::IsMember({"sine"}));
  app.add_option("--amplitude-rad", amplitude_rad, "Sine amplitude per joint, rad (about zero)")
      ->capture_default_str()->check(CLI::Range(0.0, 1.0));
  app.add_option("--resume-s", resume_s, "Speed ramp after a clear, s")->capture_default_str()->check(CLI::Range(0.0, 10.0));
  app.add_option("--heartbeat-timeout-ms", heartbeat_timeout_ms, "Halt when no safety state came for this long, ms")
      ->capture_default_str()->check(CLI::Range(11, 1000));
  app.add_option("--connect-timeout-s", connect_timeout_s, "How long to wait for the aggregator's GetStatus at start, s")
      ->capture_default_str()->check(CLI::Range(0.1, 600.0));
  app.add_option("--subscriber", subscriber, "The name this controller gives the aggregator")->capture_default_str();
  std::string tls_dir;
  bool insecure = false;
  auto* tls_opt = app.add_option("--tls-dir", tls_dir,
                                 "Mutual TLS: DIR/ca.crt, DIR/controller.crt and DIR/controller.key (docs/security.md)")
                      ->check(CLI::ExistingDirectory);
  app.add_flag("--insecure", insecure, "Plaintext gRPC to the aggregator (logged as a warning)")->excludes(tls_opt);
  CLI11_PARSE(app, argc, argv);

  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);
  signal(SIGPIPE, SIG_IGN);

  try {
    const auto address = ruffini::service::ParseHostPort(aggregator, "--aggregator");
    const auto tls = ruffini::service::LoadTls(tls_dir, insecure, "controller");
    ruffini::service::LogTls(tls, "the aggregator cannot tell this controller from anyone else");
    auto channel = rc::MakeAggregatorChannel(address.str(), ruffini::service::ChannelCredentials(tls));

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
    const std::vector<std::string> names(status.joint_names().begin(), status.joint_names().end());
    if (names.empty()) throw ruffini::InputError("--aggregator " + address.str() + ": the aggregator lists no joints");
    spdlog::info("aggregator {} (version {}): {} joints, safety {}", address.str(), status.aggregator_version(),
                 names.size(), rc::DescribeState(status.safety()));

    const auto t0 = Clock::now();
    auto line = [t0](Clock::time_point t, const std::string& text) {
      std::printf("t=%.3f s %s\n", Seconds(t - t0), text.c_str());
      std::fflush(stdout);
    };
    rc::SafetyClientConfig config;
    config.subscriber = subscriber;
    config.monitor.heartbeat_timeout = std::chrono::milliseconds(heartbeat_timeout_ms);
    rc::SafetyClient safety(
        channel, config,
        [&](const rc::HaltEvent& e) {
          std::string text = "HALT " + std::string(rc::HaltReasonName(e.reason));
          if (e.reason == rc::HaltReason::kStop || e.reason == rc::HaltReason::kFault ||
              e.reason == rc::HaltReason::kUnknownState) {
            text += ": " + rc::DescribeState(e.state);
          } else {
            text += ": " + e.detail;
          }
          line(e.t, text);
        },
        [&](const rc::ClearEvent& e) {
          char buf[64];
          std::snprintf(buf, sizeof buf, " (halted %.3f s)", Seconds(e.halted_for));
          line(e.t, "CLEAR " + rc::DescribeState(e.state) + buf);
        });
    safety.Start();

    rc::JointStatePublisher publisher(channel, names);
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
      publisher.Publish(q, qd, ruffini::service::UnixNowNs());
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
    v1::PublishJointStatesResponse totals;
    const grpc::Status finish = publisher.Finish(&totals);
    const rc::SafetyStats st = safety.Stats();

    std::printf("summary: ran %.3f s, %llu cycles at %.0f Hz (%llu late)\n", Seconds(t_end - t0),
                static_cast<unsigned long long>(cycles), rate_hz, static_cast<unsigned long long>(overruns));
    std::printf("summary: joint states written %llu, failed %llu; aggregator received %llu accepted %llu rejected %llu%s%s\n",
                static_cast<unsigned long long>(publisher.written()), static_cast<unsigned long long>(publisher.failed()),
                static_cast<unsigned long long>(totals.received()), static_cast<unsigned long long>(totals.accepted()),
                static_cast<unsigned long long>(totals.rejected()), totals.last_rejection().empty() ? "" : ", last: ",
                totals.last_rejection().c_str());
    std::string halts;
    for (int r = 0; r < rc::kHaltReasonCount; ++r) {
      const auto n = st.halts[static_cast<std::size_t>(r)];
      if (n == 0) continue;
      if (!halts.empty()) halts += ", ";
      halts += std::string(rc::HaltReasonName(static_cast<rc::HaltReason>(r))) + " " + std::to_string(n);
    }
    std::printf("summary: halts by reason: %s; clears %llu; time halted %.3f s of %.3f s\n",
                halts.empty() ? "none" : halts.c_str(), static_cast<unsigned long long>(st.clears),
                Seconds(st.time_halted), Seconds(t_end - t0));
    std::printf("summary: safety states %llu (skipped %llu), streams %llu, heartbeat gap max %.1f ms, last %s\n",
                static_cast<unsigned long long>(st.states), static_cast<unsigned long long>(st.skipped_states),
                static_cast<unsigned long long>(st.streams_opened), static_cast<double>(st.max_state_gap.count()) / 1e6,
                st.states ? rc::DescribeState(st.last_state).c_str() : "none");
    std::fflush(stdout);
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
