// ruffini demo: the whole system on loopback, its scripted events checked, a report written (demo.h).
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include "commands.h"
#include "ruffini/harness/demo.h"
#include "ruffini/service/common.h"
#include "ruffini/error.h"

namespace ruffini::cli {
using namespace ruffini::harness;  // the runs themselves live in services/harness

void RegisterDemoCommand(CLI::App& app) {
  auto o = std::make_shared<DemoOptions>();
  o->scene_path = RUFFINI_DEMO_SCENE;
  o->scenario_path = RUFFINI_DEMO_SCENARIO;
  CLI::App* cmd = app.add_subcommand(
      "demo",
      "The whole system as processes on loopback: sim, one decoder per patch, aggregator, controller; scripted "
      "touches and faults, each checked against its expected safety response -> OUT/report.md");
  cmd->add_option("--scene", o->scene_path, "Scene with a robot and a safety section")->check(CLI::ExistingFile)
      ->capture_default_str();
  cmd->add_option("--scenario", o->scenario_path, "The sim's scripted touches")->check(CLI::ExistingFile)
      ->capture_default_str();
  cmd->add_option("--out", o->out_dir, "Report folder (report.md, SVG figures, logs/)")->capture_default_str();
  cmd->add_option("--rate-hz", o->rate_hz, "Interrogator rate")->check(CLI::Range(100.0, 5000.0))->capture_default_str();
  cmd->add_option("--joint-rate-hz", o->joint_rate_hz, "The controller's joint-state rate (a KUKA RSI cycle is 4 ms)")
      ->check(CLI::Range(50.0, 5000.0))
      ->capture_default_str();
  cmd->add_option("--tls-dir", o->tls_dir,
                  "Mutual TLS for every process (deploy/tls/make-dev-ca.sh DIR --scene SCENE; the demo is the "
                  "operator); default: every process --insecure on loopback")
      ->check(CLI::ExistingDirectory);
  cmd->callback([o]() {
    o->bin_dir = service::ExecutableDir();
    const DemoResult r = RunDemo(*o, [](const std::string& line) {
      std::printf("%s\n", line.c_str());
      std::fflush(stdout);
    });
    std::printf("%d of %d scripted events got their expected safety response; report: %s\n", r.passed, r.events,
                r.report_path.c_str());
    if (r.passed != r.events) throw CLI::RuntimeError(3);
  });
}

}  // namespace ruffini::cli
