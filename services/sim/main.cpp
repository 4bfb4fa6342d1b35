// ruffini-sim: a simulated Hyperion interrogator serving a scene's patches (one channel each) on the peak
// stream and command ports. Exit codes as the `ruffini` tool: 0 ok, 1 bad input (the message says what),
// 2 usage. stdout carries one line, the ports; logs go to stderr.
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

#include "ruffini/dataset/dataset.h"
#include "ruffini/error.h"
#include "ruffini/sim/scenario.h"
#include "server.h"
#include "ruffini/sim/source.h"
#include "ruffini/twin/scene.h"

namespace {

// Written to a temporary name and renamed, so a reader never sees half a file.
void WritePortsFile(const std::string& path, std::uint16_t command, std::uint16_t stream) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::trunc);
    out << "command " << command << "\nstream " << stream << "\n";
    out.flush();
    if (!out) throw ruffini::InputError(path + ": cannot write the ports file");
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) throw ruffini::InputError(path + ": cannot write the ports file: " + ec.message());
}

}  // namespace

int main(int argc, char** argv) {
  spdlog::set_default_logger(spdlog::stderr_color_mt("ruffini-sim"));
  CLI::App app{"ruffini-sim: a simulated Hyperion interrogator (peak stream + command port)"};
  std::string scene_path, scenario_path, replay_path, ports_file;
  ruffini::sim::ServerConfig config;
  app.add_option("--scene", scene_path, "Scene YAML: one channel per patch")->required()->check(CLI::ExistingFile);
  auto* scenario = app.add_option("--scenario", scenario_path, "Scripted presses on the live twin (YAML)")
                       ->check(CLI::ExistingFile);
  auto* replay = app.add_option("--replay", replay_path, "Dataset (HDF5) to replay, looping")->check(CLI::ExistingFile);
  scenario->excludes(replay);
  replay->excludes(scenario);
  app.add_option("--rate-hz", config.rate_hz, "Sample rate")->check(CLI::Range(100.0, 5000.0))->default_val(1000.0);
  app.add_option("--stream-port", config.stream_port, "Peak stream TCP port (0: pick a free one)")->default_val(51972);
  app.add_option("--command-port", config.command_port, "Command TCP port (0: pick a free one)")->default_val(51971);
  app.add_option("--ports-file", ports_file, "Write the chosen ports here ('command P' and 'stream P' lines)");
  app.add_option("--host", config.host, "Address to listen on")->default_val("127.0.0.1");
  app.add_option("--drop-every", config.faults.drop_every, "Fault: skip every N-th sample (serial gaps)");
  app.add_option("--nan-every", config.faults.nan_every, "Fault: a NaN peak on channel 0 every N-th sample");
  app.add_option("--missing-every", config.faults.missing_every,
                 "Fault: every N-th sample leaves one grating out of channel 0 (15 peaks; the grating rotates)");
  app.add_option("--garbage-every", config.faults.garbage_every,
                 "Fault: 16 garbage bytes (a header with content_length 0xDEADBEEF) before every N-th sample's frame");
  app.add_option("--disconnect-after", config.faults.disconnect_after,
                 "Fault: disconnect each stream client after N frames");
  auto* stall_after = app.add_option("--stall-after", config.faults.stall_after,
                                     "Fault: after N samples sent, stall the stream for --stall-ms (held samples go "
                                     "out late in one burst); repeats every N samples");
  auto* stall_ms = app.add_option("--stall-ms", config.faults.stall_ms, "Fault: how long each stall lasts, ms")
                       ->check(CLI::Range(1u, ruffini::sim::kMaxStallMs));
  stall_after->needs(stall_ms);
  stall_ms->needs(stall_after);
  try {
    app.parse(argc, argv);
    if (replay_path.empty() && scenario_path.empty()) throw CLI::RequiredError("--scenario or --replay");
    const auto scene = ruffini::twin::LoadScene(scene_path);
    std::unique_ptr<ruffini::sim::FrameSource> source;
    if (!replay_path.empty()) {
      auto data = ruffini::dataset::ReadDataset(replay_path);
      if (data.info.sample_rate_hz != config.rate_hz) {
        spdlog::warn("{} was sampled at {} Hz; replaying it at --rate-hz {}", replay_path, data.info.sample_rate_hz,
                     config.rate_hz);
      }
      source = std::make_unique<ruffini::sim::ReplaySource>(std::move(data), scene.patches.size());
    } else {
      source = std::make_unique<ruffini::sim::ScriptedSource>(
          scene, ruffini::sim::LoadScenario(scenario_path, scene), config.rate_hz);
    }
    ruffini::sim::SimServer server(config, std::move(source));
    std::printf("ports: command %u stream %u\n", static_cast<unsigned>(server.command_port()),
                static_cast<unsigned>(server.stream_port()));
    std::fflush(stdout);
    if (!ports_file.empty()) WritePortsFile(ports_file, server.command_port(), server.stream_port());
    spdlog::info("serving scene '{}' ({} channel(s)) at {} Hz on {}", scene.name, scene.patches.size(),
                 config.rate_hz, config.host);
    server.Run();
    spdlog::info("stopped");
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
