// ruffini soak: the whole system under load and injected faults, every safety promise checked (soak.h).
#include <cstdio>
#include <memory>
#include <string>

#include "commands.h"
#include "ruffini/harness/soak.h"
#include "ruffini/service/common.h"

namespace ruffini::cli {

void RegisterSoakCommand(CLI::App& app) {
  auto o = std::make_shared<harness::SoakOptions>();
  o->scene_path = RUFFINI_SOAK_SCENE;
  CLI::App* cmd = app.add_subcommand(
      "soak",
      "The sim, one decoder per patch, the aggregator and two controllers for a given time, with scripted presses "
      "while decoders are killed, the aggregator restarts, links freeze and throttle and watchers churn; checks "
      "that no stop is lost or wrongly cleared and every fault is explained -> OUT/report.md (exit 3 when not)");
  cmd->add_option("--scene", o->scene_path, "Scene with a robot, a safety section and up to 16 patches")
      ->check(CLI::ExistingFile)->capture_default_str();
  cmd->add_option("--patches", o->patches, "Only the scene's first N patches (a derived scene in OUT/scene.yaml); 0: all")
      ->check(CLI::Range(0, 16))
      ->default_val(0);
  cmd->add_option("--realtime-priority", o->realtime_priority,
                  "SCHED_FIFO priority for the decoders, aggregator and controllers (the sim and the proxies 10 above), "
                  "as a robot cell runs its safety chain; needs CAP_SYS_NICE (0: normal priority)")
      ->check(CLI::Range(0, 89))
      ->default_val(0);
  cmd->add_option("--stand-in-priority", o->stand_in_priority,
                  "SCHED_FIFO priority for the stand-ins only: the sim (the interrogator, hardware) and the proxies "
                  "(the network) (0: --realtime-priority + 10 when that is set, else normal priority)")
      ->check(CLI::Range(0, 99))
      ->default_val(0);
  cmd->add_option("--duration-s", o->duration_s, "How long the presses and faults go on, s (after a 10 s start-up)")
      ->check(CLI::Range(10.0, 86400.0))->capture_default_str();
  cmd->add_option("--rate-hz", o->rate_hz, "Interrogator rate")->check(CLI::Range(100.0, 5000.0))->capture_default_str();
  cmd->add_option("--joint-rate-hz", o->joint_rate_hz, "controller_a's joint-state rate")
      ->check(CLI::Range(10.0, 5000.0))->capture_default_str();
  cmd->add_option("--seed", o->seed, "Seed of the presses and the faults")->capture_default_str();
  cmd->add_option("--out", o->out_dir, "Report folder (report.md, SVG figures, logs/)")->capture_default_str();
  cmd->add_option("--press-every-s", o->press_every_s, "Mean time between press starts, s")
      ->check(CLI::Range(1.5, 600.0))->capture_default_str();
  cmd->add_option("--kill-every-s", o->kill_every_s, "Mean time between decoder kills, s (0: none)")
      ->check(CLI::NonNegativeNumber)->capture_default_str();
  cmd->add_option("--link-fault-every-s", o->link_fault_every_s, "Mean time between link freezes/throttles, s (0: none)")
      ->check(CLI::NonNegativeNumber)->capture_default_str();
  cmd->add_option("--restart-aggregator", o->restart_aggregator, "Restart the aggregator once, at half time")
      ->capture_default_str();
  cmd->add_option("--proxied-decoders", o->proxied_decoders, "Decoders behind a TCP proxy (freeze/throttle targets)")
      ->check(CLI::Range(0, 16))->capture_default_str();
  cmd->add_option("--churn-threads", o->churn_threads, "Threads churning watch streams")
      ->check(CLI::Range(0, 16))->capture_default_str();
  cmd->add_option("--stop-bound-ms", o->stop_bound_ms, "True crossing to halt at every controller, ms")
      ->check(CLI::Range(1.0, 10000.0))->capture_default_str();
  cmd->add_option("--unexplained-faults-fail", o->unexplained_faults_fail,
                  "An unexplained FAULT fails the run (false: counted and reported only, e.g. on a shared CI machine)")
      ->capture_default_str();
  cmd->add_option("--freshness-budget-ms", o->freshness_budget_ms,
                  "Freshness budget for the decoders' queues and the aggregator (0: the services' defaults)")
      ->check(CLI::Range(0, 10000))->capture_default_str();
  cmd->callback([o]() {
    o->bin_dir = service::ExecutableDir();
    const auto r = harness::RunSoak(*o, [](const std::string& line) {
      std::printf("%s\n", line.c_str());
      std::fflush(stdout);
    });
    std::printf("%s: lost stops %d of %d, false clears %d, unexplained faults %d, crashes %d; report: %s\n",
                r.pass ? "PASS" : "FAIL", r.lost_stops, r.presses_above, r.false_clears, r.unexplained_faults, r.crashes,
                r.report_path.c_str());
    if (!r.pass) throw CLI::RuntimeError(3);
  });
}

}  // namespace ruffini::cli
