// ruffini-decoder: one fibre, one service (service.h). Exit codes as the other tools: 0 ok (stopped by SIGINT
// or SIGTERM), 1 bad input (the message names what is wrong), 2 usage. stdout carries one line, the metrics
// port ("ports: metrics P"); logs go to stderr.
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>

#include "ruffini/error.h"
#include "ruffini/service/tls.h"
#include "service.h"

int main(int argc, char** argv) {
  spdlog::set_default_logger(spdlog::stderr_color_mt("ruffini-decoder"));
  CLI::App app{"ruffini-decoder: decodes one patch's interrogator stream and streams contacts to the aggregator"};
  ruffini::decoder::ServiceConfig config;
  std::string interrogator, aggregator, metrics = "127.0.0.1:9464", ports_file;
  app.add_option("--scene", config.scene_path, "Scene YAML (names the patch, its spec and its model)")
      ->required()->check(CLI::ExistingFile);
  app.add_option("--patch", config.patch, "The scene's patch this decoder serves (default: the only one)");
  app.add_option("--interrogator", interrogator, "The interrogator's peak-stream port, HOST:PORT")->required();
  app.add_option("--channel", config.channel,
                 "Interrogator channel of the fibre, 1 to 16 as the instrument's panel and its vendor's API count "
                 "(default: the patch's place in the scene, the first patch on channel 1)")
      ->check(CLI::Range(1, 16));
  app.add_option("--aggregator", aggregator, "The aggregator's gRPC address, HOST:PORT")->required();
  app.add_option("--metrics", metrics, "Where to serve Prometheus metrics, HOST:PORT (port 0: pick a free one)")
      ->capture_default_str();
  app.add_option("--model", config.model_path, "Decoder model file (default: the scene's `model:` for the patch)");
  app.add_option("--decoder", config.decoder,
                 "Decoder configuration: paper-float, paper-double, or one grid, <GRID>-float / <GRID>-double "
                 "(docs/bench has each one's cost and error)")
      ->capture_default_str();
  app.add_option("--rate-hz", config.rate_hz, "The interrogator's frame rate, Hz")->capture_default_str();
  app.add_option("--heartbeat-ms", config.heartbeat_ms, "Heartbeat period to the aggregator, ms")->capture_default_str();
  app.add_option("--silence-ms", config.silence_ms,
                 "Interrogator silence before a fault, ms (default: 3 frame periods, at least 15 ms)");
  app.add_option("--reject-fault-frames", config.reject_fault_frames,
                 "Frames rejected in a row before a fault (default: 20 ms of frames, at least 3)");
  app.add_option("--freshness-budget-ms", config.freshness_budget_ms,
                 "A frame or message older than this in the decoder's own queues is dropped and reported, ms "
                 "(docs/safety-channel.md)")
      ->capture_default_str();
  app.add_option("--retare-force-n", config.retare_force_n,
                 "Re-tare: refuse when one touch explains the shifts with at least this force, N (0: half the "
                 "patch's region threshold; docs/safety.md \"Re-tare\")")
      ->capture_default_str();
  app.add_option("--max-frozen-s", config.max_frozen_s,
                 "The baseline's staleness limit, s (0: the default, 300 s). For tests: a stale baseline in seconds")
      ->capture_default_str();
  app.add_option("--rest-file", config.rest_file,
                 "The patch's rest baseline, written while at rest and checked at start-up: a capture under a press "
                 "held through a restart is refused (docs/decoder-service.md \"Rest file\"; default: none)");
  app.add_option("--ports-file", ports_file, "Write the chosen metrics port here ('metrics P')");
  auto* tls_opt = app.add_option("--tls-dir", config.tls_dir,
                                 "Mutual TLS: DIR/ca.crt, DIR/decoder-PATCH.crt and DIR/decoder-PATCH.key (docs/security.md)")
                      ->check(CLI::ExistingDirectory);
  app.add_flag("--insecure", config.insecure, "Plaintext gRPC to the aggregator (logged as a warning)")->excludes(tls_opt);
  CLI11_PARSE(app, argc, argv);

  ruffini::service::BlockStopSignals();  // in every thread; main waits for them
  ruffini::service::CountHandshakeRefusals();

  try {
    config.interrogator = ruffini::service::ParseHostPort(interrogator, "--interrogator");
    config.aggregator = ruffini::service::ParseHostPort(aggregator, "--aggregator");
    config.metrics = ruffini::service::ParseHostPort(metrics, "--metrics", /*allow_zero=*/true);
    ruffini::decoder::DecoderService service(config);
    spdlog::info("{}", service.Describe());
    ruffini::service::AnnouncePorts(ports_file, {{"metrics", service.metrics_port()}});
    service.Start();
    const int sig = ruffini::service::WaitForStopSignal();
    spdlog::info("signal {}: stopping", sig);
    service.Stop();
    spdlog::info("stopped");
    ruffini::service::ExitAfterCleanStop();
  } catch (const ruffini::InputError& e) {
    spdlog::error("{}", e.what());
    return 1;
  } catch (const std::exception& e) {
    spdlog::error("unexpected error: {}", e.what());
    return 1;
  }
}
