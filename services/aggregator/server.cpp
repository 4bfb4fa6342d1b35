#include "server.h"

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <spdlog/spdlog.h>

#include <future>

#include "ruffini/error.h"
#include "ruffini/service/keepalive.h"
#include "ruffini/service/process_metrics.h"
#include "server_impl.h"

namespace ruffini::aggregator {

AggregatorServer::AggregatorServer(ServerConfig config, aggregate::Setup setup) : impl_(std::make_unique<Impl>()) {
  Impl& s = *impl_;
  s.config = config;
  s.unix0 = service::UnixNowNs();
  s.mono0 = service::MonoNowNs();
  const std::size_t n = setup.patches.size();
  for (const auto& p : setup.safety.patches) {
    s.stats.patch_ids.push_back(p.id);
    s.stats.patch_regions.push_back(p.region);
  }
  s.stats.contacts = std::make_unique<std::atomic<std::uint64_t>[]>(n);
  s.stats.link_state = std::make_unique<std::atomic<int>[]>(n);
  s.stats.link_errors = std::make_unique<std::array<std::atomic<std::uint64_t>, channel::kErrorKinds>[]>(n + 1);
  s.was_in_contact.assign(n, false);
  s.core = std::make_unique<aggregate::Core>(std::move(setup), s.Now());

  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder builder;
  // Keepalive pings on every connection: a decoder or controller that vanished without closing its socket
  // is dropped within ~2 s (its Connect stream then closes in the Core; docs/aggregator.md).
  service::AddKeepalive(builder);
  // One port, one aggregator: without this gRPC sets SO_REUSEPORT, and a second copy (started by mistake, or a
  // restart while the old one hangs) would listen on the same port and take half of the calls.
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  builder.AddListeningPort(config.listen.str(), service::ServerCredentials(config.tls), &s.port);
  builder.RegisterService(&s);
  s.server = builder.BuildAndStart();
  if (!s.server || s.port == 0) {
    throw InputError("--listen " + config.listen.str() +
                     ": cannot listen there (is another process, perhaps another aggregator, listening on it?)");
  }
  if (config.health_listen) {
    // No service registered: the server carries only gRPC's default health service (enabled above).
    grpc::ServerBuilder health;
    health.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
    health.AddListeningPort(config.health_listen->str(), grpc::InsecureServerCredentials(), &s.health_port);
    s.health_server = health.BuildAndStart();
    if (!s.health_server || s.health_port == 0) {
      throw InputError("--health-listen " + config.health_listen->str() +
                       ": cannot listen there (is another process listening on it?)");
    }
  }
  try {
    s.exposer = std::make_unique<prometheus::Exposer>(config.metrics.str());
  } catch (const std::exception& e) {
    throw InputError("--metrics " + config.metrics.str() + ": cannot listen (" + e.what() + ")");
  }
  s.collectable = MakeStatsCollectable(s.stats);
  s.exposer->RegisterCollectable(s.collectable);
  s.exposer->RegisterCollectable(service::ProcessMetrics());  // process_cpu_seconds_total, memory, fds
}

AggregatorServer::~AggregatorServer() { Stop(); }

std::uint16_t AggregatorServer::port() const noexcept { return static_cast<std::uint16_t>(impl_->port); }

std::uint16_t AggregatorServer::health_port() const noexcept { return static_cast<std::uint16_t>(impl_->health_port); }

std::uint16_t AggregatorServer::metrics_port() const noexcept {
  const auto ports = impl_->exposer->GetListeningPorts();
  return ports.empty() ? 0 : static_cast<std::uint16_t>(ports.front());
}

void AggregatorServer::Start() {
  Impl& s = *impl_;
  s.loop_beat_ns = service::MonoNowNs();
  s.SetServing(true);
  s.loop = std::thread([&s] { s.Loop(); });
  s.health_watch = std::thread([&s] { s.HealthWatch(); });
}

void AggregatorServer::Stop() {
  Impl& s = *impl_;
  if (!s.loop.joinable()) return;
  {
    std::lock_guard lock(s.health_mu);
    s.health_stop = true;
  }
  s.health_cv.notify_one();
  s.health_watch.join();
  s.SetServing(false);
  // Last words: FAULT (shutting down) to every subscriber, then every stream finished.
  std::promise<void> finished;
  s.Post([&s, &finished] {
    s.shut_down = true;
    s.core->Shutdown(s.Now());
    s.LogEvents();
    s.PublishSafety();
    for (const auto& r : s.safety_subs) r->FinishWith(grpc::Status(grpc::StatusCode::UNAVAILABLE, "aggregator shutting down"));
    for (const auto& r : s.contact_subs) r->FinishWith(grpc::Status(grpc::StatusCode::UNAVAILABLE, "aggregator shutting down"));
    finished.set_value();
  });
  finished.get_future().wait_for(std::chrono::seconds(1));
  // Give the last writes a moment, then stop the server (open streams are cancelled at the deadline).
  s.server->Shutdown(std::chrono::system_clock::now() + std::chrono::milliseconds(500));
  {
    std::lock_guard lock(s.mu);
    s.stopping = true;
  }
  s.cv.notify_one();
  s.loop.join();
  s.server->Wait();
  if (s.health_server) {
    s.health_server->Shutdown(std::chrono::system_clock::now() + std::chrono::milliseconds(100));
    s.health_server->Wait();
  }
}

}  // namespace ruffini::aggregator
