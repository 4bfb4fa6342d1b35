// ruffini-aggregator: one per robot (server.h). Exit codes: 0 ok (stopped by SIGINT or SIGTERM), 1 bad input
// (the message names what is wrong), 2 usage. stdout carries one line, the ports ("ports: grpc P metrics P").
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "ruffini/error.h"
#include "scene_setup.h"
#include "server.h"

int main(int argc, char** argv) {
  spdlog::set_default_logger(spdlog::stderr_color_mt("ruffini-aggregator"));
  CLI::App app{"ruffini-aggregator: patch contacts -> body-frame contacts and safety stops for one robot"};
  std::string scene_path, listen = "127.0.0.1:50051", metrics = "127.0.0.1:9465", ports_file;
  app.add_option("--scene", scene_path, "Scene YAML (robot, patches and mounts, safety regions)")
      ->required()->check(CLI::ExistingFile);
  app.add_option("--listen", listen, "gRPC address, HOST:PORT (port 0: pick a free one)")->capture_default_str();
  std::string health_listen;
  app.add_option("--health-listen", health_listen,
                 "Also serve grpc.health.v1 (only) in plaintext here, HOST:PORT, for probes that cannot present a "
                 "client certificate (Kubernetes' gRPC probe)");
  app.add_option("--metrics", metrics, "Prometheus metrics address, HOST:PORT (port 0: pick a free one)")
      ->capture_default_str();
  app.add_option("--ports-file", ports_file, "Write the chosen ports here ('grpc P' and 'metrics P' lines)");
  std::string tls_dir;
  bool insecure = false;
  auto* tls_opt = app.add_option("--tls-dir", tls_dir,
                                 "Mutual TLS: DIR/ca.crt, DIR/aggregator.crt and DIR/aggregator.key (docs/security.md)")
                      ->check(CLI::ExistingDirectory);
  app.add_flag("--insecure", insecure, "Plaintext gRPC, no identities: every caller may do everything (logged)")
      ->excludes(tls_opt);
  double silence_ms = 0, joint_age_ms = 0, freshness_ms = 0;
  app.add_option("--patch-silence-ms", silence_ms,
                 "Override every patch's silence deadline (default: the scene's `safety:` values); for slow links "
                 "or loaded test machines, never shorter than 3 heartbeats")
      ->check(CLI::Range(30.0, 10000.0));
  app.add_option("--joint-max-age-ms", joint_age_ms, "Override the scene's joint-state max age")
      ->check(CLI::Range(1.0, 10000.0));
  app.add_option("--patch-freshness-ms", freshness_ms,
                 "Override the scene's patch freshness budget (safety.link_layer.freshness_budget_ms, default 20 ms: "
                 "a patch message older than this faults the patch; docs/safety-channel.md)")
      ->check(CLI::Range(1.0, 10000.0));
  std::vector<double> wedge_ms;  // tests only: AT_MS FOR_MS
  app.add_option("--test-wedge-loop", wedge_ms, "Tests only: the loop sleeps FOR_MS once, AT_MS after start")
      ->expected(2)
      ->check(CLI::Range(0.0, 60000.0))
      ->group("");  // hidden
  CLI11_PARSE(app, argc, argv);

  ruffini::service::BlockStopSignals();
  ruffini::service::CountHandshakeRefusals();
  try {
    ruffini::aggregator::ServerConfig config;
    config.tls = ruffini::service::LoadTls(tls_dir, insecure, "aggregator");
    config.listen = ruffini::service::ParseHostPort(listen, "--listen", /*allow_zero=*/true);
    config.metrics = ruffini::service::ParseHostPort(metrics, "--metrics", /*allow_zero=*/true);
    if (!health_listen.empty()) {
      config.health_listen = ruffini::service::ParseHostPort(health_listen, "--health-listen", /*allow_zero=*/true);
    }
    if (wedge_ms.size() == 2) {
      config.test_wedge_after_ns = static_cast<std::int64_t>(wedge_ms[0] * 1e6);
      config.test_wedge_for_ns = static_cast<std::int64_t>(wedge_ms[1] * 1e6);
      spdlog::warn("--test-wedge-loop: the loop will sleep {} ms, {} ms after start (a test's fault injection)",
                   wedge_ms[1], wedge_ms[0]);
    }
    ruffini::aggregate::Setup setup = ruffini::aggregator::SetupFromScene(scene_path);
    if (silence_ms > 0) {
      for (auto& p : setup.safety.patches) p.silence_deadline_ns = static_cast<std::int64_t>(silence_ms * 1e6);
      spdlog::warn("--patch-silence-ms {}: the scene's patch silence deadlines are overridden", silence_ms);
    }
    if (freshness_ms > 0) {
      setup.safety.link.freshness_budget_ns = static_cast<std::int64_t>(freshness_ms * 1e6);
      spdlog::warn("--patch-freshness-ms {}: the scene's patch freshness budget is overridden", freshness_ms);
    }
    if (joint_age_ms > 0) {
      setup.safety.joint_state_max_age_ns = static_cast<std::int64_t>(joint_age_ms * 1e6);
      spdlog::warn("--joint-max-age-ms {}: the scene's joint-state max age is overridden", joint_age_ms);
    }
    spdlog::info("{}", ruffini::aggregator::Describe(setup));
    ruffini::service::LogTls(config.tls, "every caller is treated as every role (decoder of any patch, controller, "
                                         "operator: any caller may ResetStop)");
    ruffini::aggregator::AggregatorServer server(config, std::move(setup));
    std::vector<std::pair<std::string, int>> ports = {{"grpc", server.port()}, {"metrics", server.metrics_port()}};
    if (server.health_port() != 0) ports.emplace_back("health", server.health_port());
    ruffini::service::AnnouncePorts(ports_file, ports);
    server.Start();
    const int sig = ruffini::service::WaitForStopSignal();
    spdlog::info("signal {}: sending FAULT to every subscriber and stopping", sig);
    server.Stop();
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
