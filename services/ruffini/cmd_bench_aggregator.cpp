// ruffini bench-aggregator: frame-to-stop latency through the real chain, fan-in capacity with synthetic
// decoders, and (when aggregate_bench is built beside this executable) FK and fusion per update
// (aggregator_bench.h) -> a summary on stdout, docs/bench/aggregator.md and aggregator-latency.svg.
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>

#include "ruffini/harness/aggregator_bench.h"
#include "commands.h"
#include "ruffini/service/common.h"
#include "ruffini/error.h"
#include "ruffini/service/child.h"

namespace ruffini::cli {
using namespace ruffini::harness;  // the runs themselves live in services/harness
namespace {

namespace fs = std::filesystem;

std::string Num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

// Runs aggregate_bench (Google Benchmark) when it sits beside `ruffini`; its console table, or "".
std::string RunMicro(const std::string& bin_dir, const std::string& work_dir, double min_time_s, std::string& command) {
  const std::string exe = (fs::path(bin_dir) / "aggregate_bench").string();
  if (access(exe.c_str(), X_OK) != 0) return {};
  const std::string arg = "--benchmark_min_time=" + Num(min_time_s);
  command = "build/release/bin/aggregate_bench " + arg;
  service::Child child({exe, arg}, (fs::path(work_dir) / "micro").string());
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::minutes(5);
  while (child.Running() && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  if (child.Stop() != 0) {
    spdlog::warn("bench-aggregator: aggregate_bench failed: {}", child.stderr_text());
    return {};
  }
  return child.stdout_text();
}

void RegisterBenchAggregator(CLI::App& app) {
  struct Args {
    AggregatorBenchOptions o;
    std::string work_dir;
    double micro_min_time_s = 0.5;
    bool no_micro = false;
  };
  auto a = std::make_shared<Args>();
  a->o.cobot_scene = RUFFINI_COBOT_SCENE;
  a->o.out_dir = "docs/bench";
  CLI::App* cmd = app.add_subcommand(
      "bench-aggregator",
      "The aggregator: frame-to-stop latency through the real ruffini-sim, ruffini-decoder and ruffini-aggregator "
      "processes (found next to this executable), fan-in capacity with synthetic decoders, FK and fusion cost "
      "(aggregate_bench, when built) -> OUT/aggregator.md");
  cmd->add_option("--out", a->o.out_dir, "Folder for aggregator.md and aggregator-latency.svg")->capture_default_str();
  cmd->add_option("--seconds", a->o.seconds, "Latency window per configuration, s (after the first CLEAR)")
      ->check(CLI::Range(1.0, 600.0))->capture_default_str();
  cmd->add_option("--latency-patches", a->o.latency_patches,
                  "Patch counts of the latency runs (4: the cobot scene; others generated, at most 16)")
      ->check(CLI::Range(1, 16))->capture_default_str();
  cmd->add_option("--touch-period-s", a->o.touch_period_s, "One hard press every this many seconds")
      ->check(CLI::Range(0.8, 10.0))->capture_default_str();
  cmd->add_option("--fanin-patches", a->o.fanin_patches, "Patch counts of the fan-in runs (at most 64)")
      ->check(CLI::Range(1, 64))->capture_default_str();
  cmd->add_option("--fanin-seconds", a->o.fanin_seconds, "Fan-in window per patch count, s")
      ->check(CLI::Range(1.0, 600.0))->capture_default_str();
  cmd->add_option("--micro-min-time-s", a->micro_min_time_s, "aggregate_bench's --benchmark_min_time")
      ->check(CLI::Range(0.01, 10.0))->capture_default_str();
  cmd->add_flag("--no-micro", a->no_micro, "Do not run aggregate_bench even when it is built");
  cmd->add_option("--scene", a->o.cobot_scene, "The 4-patch scene (generated scenes copy its robot, patch and safety)")
      ->check(CLI::ExistingFile)->capture_default_str();
  cmd->add_option("--work-dir", a->work_dir, "Generated scenes, logs and ports files (default: a temporary folder, "
                                             "removed after a successful run)");
  cmd->callback([a]() {
    AggregatorBenchOptions& o = a->o;
    std::error_code ec;
    o.bin_dir = service::ExecutableDir();
    CheckAggregatorExecutables(o.bin_dir);
    const bool temp_work = a->work_dir.empty();
    o.work_dir = temp_work ? (fs::temp_directory_path() / ("ruffini-bench-aggregator-" + std::to_string(getpid()))).string()
                           : a->work_dir;
    fs::create_directories(o.work_dir, ec);
    fs::create_directories(o.out_dir, ec);
    if (ec || !fs::is_directory(o.out_dir)) throw InputError("--out " + o.out_dir + ": cannot create the folder");
    o.command = "ruffini bench-aggregator --out " + o.out_dir + " --seconds " + Num(o.seconds);
    auto list = [](const std::vector<int>& v) {
      std::string s;
      for (int x : v) s += " " + std::to_string(x);
      return s;
    };
    if (o.latency_patches != std::vector<int>{4, 16}) o.command += " --latency-patches" + list(o.latency_patches);
    if (o.fanin_patches != std::vector<int>{4, 8, 16, 32, 48, 64}) o.command += " --fanin-patches" + list(o.fanin_patches);
    if (o.fanin_seconds != 10.0) o.command += " --fanin-seconds " + Num(o.fanin_seconds);
    if (o.touch_period_s != 1.5) o.command += " --touch-period-s " + Num(o.touch_period_s);
    if (a->no_micro) o.command += " --no-micro";
    else if (a->micro_min_time_s != 0.5) o.command += " --micro-min-time-s " + Num(a->micro_min_time_s);
    if (o.cobot_scene != RUFFINI_COBOT_SCENE) o.command += " --scene " + o.cobot_scene;
    const auto log = [](const std::string& s) { spdlog::info("bench-aggregator: {}", s); };

    Machine machine = MachineNow();
    log("load average before: " + machine.load_before + " (" + std::to_string(machine.nproc) + " cores)");
    std::vector<LatencyRun> latency;
    for (int n : o.latency_patches) latency.push_back(RunLatency(o, n, log));
    std::vector<FanInRun> fanin;
    for (int n : o.fanin_patches) fanin.push_back(RunFanIn(o, n, log));
    std::string micro, micro_command;
    if (!a->no_micro) {
      log("running aggregate_bench (FK, fusion, Core::OnPatchMessage)");
      micro = RunMicro(o.bin_dir, o.work_dir, a->micro_min_time_s, micro_command);
    }
    machine.load_after = LoadAverage();
    WriteAggregatorReport(o, machine, latency, fanin, micro, micro_command);
    if (temp_work) fs::remove_all(o.work_dir, ec);

    std::printf("frame-to-stop (STOP at the subscriber - cause t_ns):\n");
    for (const auto& r : latency) {
      std::printf("  %2d patches: %zu STOPs, p50 %.1f us, p99 %.1f us, max %.1f us; %d FAULTs\n", r.patches,
                  r.latency.count, r.latency.p50_us, r.latency.p99_us, r.latency.max_us, r.faults);
    }
    std::printf("fan-in (synthetic decoders at 1 kHz):\n");
    for (const auto& r : fanin) {
      std::printf("  %2d patches: %s; aggregator CPU %.1f %%, max gap %.1f ms\n", r.patches,
                  !r.ran ? ("setup failed: " + r.error).c_str() : r.miss ? ("miss: " + r.miss_reason).c_str() : "no miss",
                  r.aggregator_cpu_pct, r.max_heartbeat_gap_ms);
    }
    std::printf("load average before %s, after %s\n", machine.load_before.c_str(), machine.load_after.c_str());
    std::printf("wrote %s and %s\n", (fs::path(o.out_dir) / "aggregator.md").string().c_str(),
                (fs::path(o.out_dir) / "aggregator-latency.svg").string().c_str());
  });
}

}  // namespace

void RegisterBenchAggregatorCommand(CLI::App& app) { RegisterBenchAggregator(app); }

}  // namespace ruffini::cli
