#pragma once
// gRPC keepalive for every Ruffini link (docs/aggregator.md, "Keepalive"): a peer that vanished without
// closing its socket (a host that lost power, a dead node, a frozen middlebox) is detected and its transport
// closed within about time + timeout (2 s with the defaults), on the server and on the clients.
//
// gRPC 1.51 (Debian 12's libgrpc++) has no GRPC_ARG_TCP_USER_TIMEOUT_MS; its TCP layer sets the socket's
// TCP_USER_TIMEOUT to GRPC_ARG_KEEPALIVE_TIMEOUT_MS whenever GRPC_ARG_KEEPALIVE_TIME_MS is set (gRPC proposal
// A18), so these arguments also bound how long sent data may stay unacknowledged.
#include <grpcpp/server_builder.h>
#include <grpcpp/support/channel_arguments.h>

#include <chrono>

namespace ruffini::service {

struct Keepalive {
  std::chrono::milliseconds time{1000};     // a ping after this long without one
  std::chrono::milliseconds timeout{1000};  // no ack within this: the transport is closed (and TCP_USER_TIMEOUT)
};

// A client channel's arguments: pings every `time` even with no call open and no data to send.
void AddKeepalive(grpc::ChannelArguments& args, const Keepalive& k = {});
// A server's: pings every `time` on every connection, and accepts its clients' pings at that rate (gRPC's
// default would answer a client pinging more than every 5 minutes with GOAWAY too_many_pings).
void AddKeepalive(grpc::ServerBuilder& builder, const Keepalive& k = {});

}  // namespace ruffini::service
