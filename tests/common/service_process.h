#pragma once
// Test helpers for tests that start the real services (on top of process.h): start an executable that writes
// a ports file and wait for its port, and ask a gRPC server's grpc.health.v1 service. Header-only; link
// ruffini::grpc.
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <future>
#include <string>
#include <vector>

#include "process.h"

namespace ruffini::testing {

// Starts an executable with `--ports-file DIR/ports` appended; waits (15 s) for `key` in that file and sets
// port (0, with a test failure, when the process exited or never wrote it).
inline Process StartWithPorts(std::vector<std::string> args, const std::string& dir, const std::string& key, int& port) {
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  args.push_back("--ports-file");
  args.push_back(dir + "/ports");
  Process p(args, dir);
  EXPECT_TRUE(WaitFor([&] { return ReadPorts(dir + "/ports").count(key) > 0 || !p.Running(); },
                      std::chrono::seconds(15)));
  port = ReadPorts(dir + "/ports")[key];
  EXPECT_GT(port, 0) << p.stderr_text();
  return p;
}

// grpc.health.v1.Health/Check for the whole server (service ""), plaintext: the reply's status (1 SERVING,
// 2 NOT_SERVING), or -1 on an error.
inline int HealthCheck(const std::string& address, std::chrono::milliseconds timeout = std::chrono::seconds(3)) {
  grpc::GenericStub stub(grpc::CreateChannel(address, grpc::InsecureChannelCredentials()));
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + timeout);
  grpc::Slice empty("");  // HealthCheckRequest{service: ""} serialises to no bytes
  grpc::ByteBuffer request(&empty, 1), response;
  std::promise<grpc::Status> done;
  stub.UnaryCall(&ctx, "/grpc.health.v1.Health/Check", grpc::StubOptions(), &request, &response,
                 [&](grpc::Status st) { done.set_value(st); });
  if (!done.get_future().get().ok()) return -1;
  std::vector<grpc::Slice> slices;
  response.Dump(&slices);
  std::string bytes;
  for (const auto& sl : slices) bytes.append(reinterpret_cast<const char*>(sl.begin()), sl.size());
  // HealthCheckResponse{status = N}: field 1, varint -> 0x08 N.
  return bytes.size() == 2 && bytes[0] == 0x08 ? bytes[1] : -1;
}

}  // namespace ruffini::testing
