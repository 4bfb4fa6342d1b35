#include "ruffini/service/keepalive.h"

#include <grpc/grpc.h>

namespace ruffini::service {

namespace {

// The same arguments on both sides; `set` is ChannelArguments::SetInt or ServerBuilder::AddChannelArgument.
template <typename Set>
void Apply(const Keepalive& k, Set&& set) {
  const int time_ms = static_cast<int>(k.time.count()), timeout_ms = static_cast<int>(k.timeout.count());
  set(GRPC_ARG_KEEPALIVE_TIME_MS, time_ms);
  set(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, timeout_ms);  // also the socket's TCP_USER_TIMEOUT (keepalive.h)
  set(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
  // A watch subscriber and a decoder's Connect stream each send no data one way: keep pinging anyway
  // (gRPC's default stops after 2 pings without data and spaces them 5 minutes apart).
  set(GRPC_ARG_HTTP2_MAX_PINGS_WITHOUT_DATA, 0);
  set(GRPC_ARG_HTTP2_MIN_SENT_PING_INTERVAL_WITHOUT_DATA_MS, time_ms);
  // Accept the peer's pings at this rate (half the period, for timer jitter) without a ping strike.
  set(GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS, time_ms / 2);
}

}  // namespace

void AddKeepalive(grpc::ChannelArguments& args, const Keepalive& k) {
  Apply(k, [&](const char* key, int v) { args.SetInt(key, v); });
}

void AddKeepalive(grpc::ServerBuilder& builder, const Keepalive& k) {
  Apply(k, [&](const char* key, int v) { builder.AddChannelArgument(key, v); });
}

}  // namespace ruffini::service
