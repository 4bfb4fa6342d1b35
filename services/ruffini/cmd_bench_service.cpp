// ruffini bench-service: the decoder service's throughput, end-to-end latency and CPU share
// (service_bench.h) -> a table on stdout, docs/bench/service.md and service-latency.svg.
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include "commands.h"
#include "ruffini/service/common.h"
#include "ruffini/error.h"
#include "ruffini/harness/service_bench.h"

namespace ruffini::cli {
using namespace ruffini::harness;  // the runs themselves live in services/harness
namespace {

namespace fs = std::filesystem;

std::string Num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

void RegisterBenchService(CLI::App& app) {
  struct Args {
    ServiceBenchOptions o;
    std::string work_dir;
  };
  auto a = std::make_shared<Args>();
  a->o.scene_path = RUFFINI_DEFAULT_SCENE;
  a->o.scenario_path = RUFFINI_BENCH_SCENARIO;
  a->o.out_dir = "docs/bench";
  CLI::App* cmd = app.add_subcommand(
      "bench-service",
      "The decoder service: pipeline throughput on one thread, end-to-end latency and CPU share of the real "
      "ruffini-sim and ruffini-decoder processes (found next to this executable) -> OUT/service.md");
  cmd->add_option("--out", a->o.out_dir, "Folder for service.md and service-latency.svg")->capture_default_str();
  cmd->add_option("--frames", a->o.frames, "Frames pre-encoded and timed for the throughput")
      ->check(CLI::Range(1000, 10000000))->capture_default_str();
  cmd->add_option("--repeats", a->o.repeats, "Timed throughput passes per configuration")
      ->check(CLI::Range(1, 20))->capture_default_str();
  cmd->add_option("--seconds", a->o.seconds, "Measured window per rate, s (after the baseline capture and warm-up)")
      ->check(CLI::Range(1.0, 600.0))->capture_default_str();
  cmd->add_option("--warmup-s", a->o.warmup_s, "Warm-up after the decoder's first healthy heartbeat, s")
      ->check(CLI::Range(0.0, 60.0))->capture_default_str();
  cmd->add_option("--rates", a->o.rates_hz, "Interrogator rates for the end-to-end runs, Hz")
      ->check(CLI::Range(100.0, 5000.0))->capture_default_str();
  cmd->add_option("--scene", a->o.scene_path, "Scene (its patch names the model)")->check(CLI::ExistingFile)
      ->capture_default_str();
  cmd->add_option("--patch", a->o.patch, "The scene's patch")->capture_default_str();
  cmd->add_option("--scenario", a->o.scenario_path, "Presses for the twin (both the encoded frames and the sim)")
      ->check(CLI::ExistingFile)->capture_default_str();
  cmd->add_option("--work-dir", a->work_dir, "Logs and ports files of the processes (default: a temporary folder, "
                                             "removed after a successful run)");
  cmd->callback([a]() {
    ServiceBenchOptions& o = a->o;
    std::error_code ec;
    o.bin_dir = service::ExecutableDir();
    CheckServiceExecutables(o.bin_dir);
    const bool temp_work = a->work_dir.empty();
    o.work_dir = temp_work ? (fs::temp_directory_path() / ("ruffini-bench-service-" + std::to_string(getpid()))).string()
                           : a->work_dir;
    fs::create_directories(o.out_dir, ec);
    if (ec || !fs::is_directory(o.out_dir)) throw InputError("--out " + o.out_dir + ": cannot create the folder");
    o.command = "ruffini bench-service --out " + o.out_dir + " --frames " + std::to_string(o.frames) + " --seconds " +
                Num(o.seconds);
    if (o.repeats != 3) o.command += " --repeats " + std::to_string(o.repeats);
    if (o.warmup_s != 1.0) o.command += " --warmup-s " + Num(o.warmup_s);
    if (o.rates_hz != std::vector<double>{1000.0, 5000.0}) {
      o.command += " --rates";
      for (double r : o.rates_hz) o.command += " " + Num(r);
    }
    if (o.scene_path != RUFFINI_DEFAULT_SCENE) o.command += " --scene " + o.scene_path;
    if (o.scenario_path != RUFFINI_BENCH_SCENARIO) o.command += " --scenario " + o.scenario_path;
    const auto log = [](const std::string& s) { spdlog::info("bench-service: {}", s); };

    Machine machine = MachineNow();
    log("load average before: " + machine.load_before + " (" + std::to_string(machine.nproc) + " cores)");
    const ThroughputResult throughput = RunThroughput(o, log);
    std::vector<EndToEndRun> runs;
    for (double rate : o.rates_hz) runs.push_back(RunEndToEnd(o, rate, log));
    machine.load_after = LoadAverage();
    WriteServiceReport(o, machine, throughput, runs);
    if (temp_work) fs::remove_all(o.work_dir, ec);

    std::printf("throughput (frames/s, median of %d):\n", o.repeats);
    for (const auto& r : throughput.rows) std::printf("  %-12s %10.0f  %s\n", r.config.c_str(), r.median_fps, r.stage.c_str());
    std::printf("end to end (contact messages, arrival - t_ns):\n");
    for (const auto& r : runs) {
      std::printf("  %5.0f Hz: %zu messages, p50 %.1f us, p99 %.1f us, max %.1f us; CPU decoder %.1f %%, sim %.1f %%\n",
                  r.rate_hz, r.latency.count, r.latency.p50_us, r.latency.p99_us, r.latency.max_us, r.decoder_cpu_pct,
                  r.sim_cpu_pct);
    }
    std::printf("load average before %s, after %s\n", machine.load_before.c_str(), machine.load_after.c_str());
    std::printf("wrote %s and %s\n", (fs::path(o.out_dir) / "service.md").string().c_str(),
                (fs::path(o.out_dir) / "service-latency.svg").string().c_str());
  });
}

}  // namespace

void RegisterBenchServiceCommand(CLI::App& app) { RegisterBenchService(app); }

}  // namespace ruffini::cli
