#pragma once
// ruffini-aggregator: the gRPC callback service around aggregate::Core. Callbacks only enqueue events; one
// loop thread owns the Core and runs every event in arrival order, ticks every millisecond (patch silence,
// joint staleness), publishes a SafetyState heartbeat every 10 ms, and hands states to subscribers through
// per-subscriber latest-value slots (at most one write in flight each). A subscriber whose write is stuck
// past its deadline is finished with an error, so its controller stops (silence is a stop). The health
// service (grpc.health.v1, on the main port and --health-listen) is NOT_SERVING while the loop has not run
// for 200 ms, SERVING again once it runs.
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "ruffini/aggregate/core.h"
#include "ruffini/service/common.h"
#include "ruffini/service/tls.h"

namespace ruffini::aggregator {

struct ServerConfig {
  service::HostPort listen;             // port 0: pick a free one
  service::HostPort metrics;            // port 0: pick a free one
  service::TlsConfig tls;               // insecure: plaintext, every caller has every role
  // A plaintext listener serving only grpc.health.v1 (the kubelet's gRPC probe cannot present a client
  // certificate); none when unset.
  std::optional<service::HostPort> health_listen;
  // SafetyState heartbeat to every subscriber: this period, or the shortest a subscriber asked for
  // (WatchSafetyRequest.heartbeat_period_ns, at least 2 ms).
  std::int64_t heartbeat_period_ns = 10'000'000;
  std::int64_t write_deadline_ns = 50'000'000;     // a subscriber's write stuck longer is finished with an error
  std::int64_t contacts_period_ns = 10'000'000;    // ContactSet heartbeat (the same rule as heartbeat_period_ns)
  // Tests only (the hidden --test-wedge-loop flag): the loop sleeps test_wedge_for_ns once,
  // test_wedge_after_ns after Start(), as a wedged loop would (0: never).
  std::int64_t test_wedge_after_ns = 0, test_wedge_for_ns = 0;
};

class AggregatorServer {
 public:
  // Binds both ports; throws InputError naming the address when it cannot.
  AggregatorServer(ServerConfig config, aggregate::Setup setup);
  ~AggregatorServer();
  AggregatorServer(const AggregatorServer&) = delete;
  AggregatorServer& operator=(const AggregatorServer&) = delete;

  [[nodiscard]] std::uint16_t port() const noexcept;
  [[nodiscard]] std::uint16_t metrics_port() const noexcept;
  [[nodiscard]] std::uint16_t health_port() const noexcept;  // 0 without --health-listen
  void Start();
  // Publishes FAULT (shutting down) to every subscriber, finishes every stream, stops the server within
  // about a second.
  void Stop();

  struct Impl;  // the service's internals (server.cpp); public only so its reactors can name it

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace ruffini::aggregator
