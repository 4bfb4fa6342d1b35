#pragma once
// An in-test Aggregator: a real gRPC server on 127.0.0.1 (port 0) implementing Connect only. It records every
// PatchMessage with its arrival time (Unix ns, the host clock the sim stamps frames with), answers a hello
// with HelloAccepted (or the refusal a test sets), and lets a test wait on conditions with a deadline.
// Header-only; link ruffini::grpc.
#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "ruffini/v1/aggregator.grpc.pb.h"

namespace ruffini::testing {

struct Received {
  v1::PatchMessage message;
  std::int64_t arrival_unix_ns = 0;
  int stream = 0;  // 1 for the first Connect stream, 2 for the next, ...
};

class AggregatorStub final : public v1::Aggregator::Service {
 public:
  // port 0: pick a free one (port() says which); else that port (an aggregator coming back where it was).
  explicit AggregatorStub(int port = 0) {
    grpc::ServerBuilder builder;
    // Accept the decoder's keepalive pings (one a second) as the real aggregator does
    // (ruffini/service/keepalive.h); gRPC's default would answer them with GOAWAY too_many_pings after a few
    // seconds, and the decoder would reconnect.
    builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
    builder.AddChannelArgument(GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS, 500);
    builder.AddListeningPort("127.0.0.1:" + std::to_string(port), grpc::InsecureServerCredentials(), &port_);
    builder.RegisterService(this);
    server_ = builder.BuildAndStart();
  }
  ~AggregatorStub() override { Shutdown(); }
  AggregatorStub(const AggregatorStub&) = delete;
  AggregatorStub& operator=(const AggregatorStub&) = delete;

  [[nodiscard]] int port() const noexcept { return port_; }
  [[nodiscard]] std::string address() const { return "127.0.0.1:" + std::to_string(port_); }

  // The robot named in HelloAccepted.robot_name from now on. By default "forearm-bench", the name of
  // config/scenes/forearm.yaml, the scene the decoder tests run: a decoder refuses an aggregator of another robot.
  void SetRobotName(std::string name) {
    std::lock_guard lock(mutex_);
    robot_name_ = std::move(name);
  }

  // Refuse every hello from now on with this reason (nullopt: accept).
  void RefuseHellos(std::optional<v1::HelloRefusal> reason) {
    std::lock_guard lock(mutex_);
    refusal_ = reason;
  }

  // Ends every open stream (the decoder sees its stream end) and stops serving.
  void Shutdown() {
    if (!server_) return;
    {
      std::lock_guard lock(mutex_);
      closing_ = true;
    }
    server_->Shutdown(std::chrono::system_clock::now() + std::chrono::milliseconds(500));
    server_->Wait();
    server_.reset();
  }

  // Waits until pred(messages) holds or the timeout passes.
  bool WaitFor(const std::function<bool(const std::vector<Received>&)>& pred, std::chrono::milliseconds timeout) {
    std::unique_lock lock(mutex_);
    return cv_.wait_for(lock, timeout, [&] { return pred(received_); });
  }
  std::vector<Received> Snapshot() const {
    std::lock_guard lock(mutex_);
    return received_;
  }
  // Lock-free, so a WaitFor predicate may call them.
  int streams_opened() const { return streams_.load(); }
  int streams_open() const { return open_.load(); }

  grpc::Status Connect(grpc::ServerContext* /*ctx*/,
                       grpc::ServerReaderWriter<v1::AggregatorCommand, v1::PatchMessage>* stream) override {
    int id = 0;
    {
      std::lock_guard lock(mutex_);
      id = ++streams_;
      ++open_;
    }
    cv_.notify_all();
    v1::PatchMessage m;
    std::uint64_t seq = 0;
    while (stream->Read(&m)) {
      const auto now = std::chrono::duration_cast<std::chrono::nanoseconds>(
                           std::chrono::system_clock::now().time_since_epoch()).count();
      std::optional<v1::HelloRefusal> refusal;
      std::string robot;
      {
        std::lock_guard lock(mutex_);
        received_.push_back({m, now, id});
        refusal = refusal_;
        robot = robot_name_;
      }
      cv_.notify_all();
      if (m.has_hello()) {
        v1::AggregatorCommand c;
        c.set_seq(++seq);
        c.set_t_ns(now);
        if (refusal) {
          c.mutable_hello_refused()->set_reason(*refusal);
          c.mutable_hello_refused()->set_message("refused by the test");
          stream->Write(c);
          break;
        }
        c.mutable_hello_accepted()->set_patch_id(m.patch_id());
        c.mutable_hello_accepted()->set_watchdog_ns(30'000'000);
        c.mutable_hello_accepted()->set_aggregator_instance("aggregator-stub");
        c.mutable_hello_accepted()->set_robot_name(robot);
        stream->Write(c);
      }
    }
    {
      std::lock_guard lock(mutex_);
      --open_;
    }
    cv_.notify_all();
    return grpc::Status::OK;
  }

 private:
  int port_ = 0;
  std::unique_ptr<grpc::Server> server_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  std::vector<Received> received_;
  std::optional<v1::HelloRefusal> refusal_;
  std::string robot_name_ = "forearm-bench";
  std::atomic<int> streams_{0}, open_{0};
  bool closing_ = false;
};

}  // namespace ruffini::testing
