#pragma once
// A scripted Aggregator for the controller tests: a real gRPC server on 127.0.0.1 (port 0) in the test's
// process. WatchSafety sends the test's current SafetyState every 10 ms (seq counting per run, robot_name
// and run id filled as the safety layer's aggregator does), or nothing while `silent`; GetStatus names the
// joints, the robot and the run; PublishJointStates counts. Header-only; link ruffini::grpc.
#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "ruffini/channel/crc.h"
#include "ruffini/v1/aggregator.grpc.pb.h"

namespace ruffini::testing {

class ScriptedAggregator final : public v1::Aggregator::Service {
 public:
  explicit ScriptedAggregator(std::string robot_name = "cobot", std::uint64_t run_id = 0x5eed0001)
      : robot_(std::move(robot_name)), run_id_(run_id) {
    state_.set_state(v1::SafetyState::STATE_FAULT);
    state_.set_stop_epoch(1);
    state_.mutable_cause()->set_kind(v1::SafetyCause::KIND_STARTUP);
    grpc::ServerBuilder builder;
    builder.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port_);
    // Allow the clients' 1 s keepalive pings (gRPC servers refuse pings more often than every 5 min).
    builder.AddChannelArgument(GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS, 100);
    builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
    builder.AddChannelArgument(GRPC_ARG_HTTP2_MAX_PING_STRIKES, 0);
    builder.RegisterService(this);
    server_ = builder.BuildAndStart();
  }
  ~ScriptedAggregator() override { Shutdown(); }
  ScriptedAggregator(const ScriptedAggregator&) = delete;
  ScriptedAggregator& operator=(const ScriptedAggregator&) = delete;

  [[nodiscard]] int port() const noexcept { return port_; }
  [[nodiscard]] std::string address() const { return "127.0.0.1:" + std::to_string(port_); }

  void Shutdown() {
    if (!server_) return;
    closing_ = true;
    server_->Shutdown(std::chrono::system_clock::now() + std::chrono::milliseconds(500));
    server_->Wait();
    server_.reset();
  }

  // The state sent from now on (robot_name, run id, seq and start time are filled in when sent).
  void Set(v1::SafetyState::State state, std::uint64_t epoch) {
    std::lock_guard lock(mu_);
    state_.set_state(state);
    state_.set_stop_epoch(epoch);
    if (state == v1::SafetyState::STATE_CLEAR) {
      state_.clear_cause();
    } else {
      state_.mutable_cause()->set_kind(state == v1::SafetyState::STATE_STOP ? v1::SafetyCause::KIND_CONTACT
                                                                            : v1::SafetyCause::KIND_PATCH_SILENT);
    }
  }
  void SetRobot(std::string name) {
    std::lock_guard lock(mu_);
    robot_ = std::move(name);
  }
  void SetRun(std::uint64_t run_id) {
    std::lock_guard lock(mu_);
    run_id_ = run_id;
    seq_ = 0;
  }
  // While silent, open streams stay open and send nothing.
  void SetSilent(bool silent) { silent_ = silent; }

  [[nodiscard]] std::uint64_t states_sent() const { return sent_.load(); }
  [[nodiscard]] int watch_calls() const { return watch_calls_.load(); }
  [[nodiscard]] std::uint64_t joint_states() const { return joint_states_.load(); }
  // Steady time of the last state written to any stream.
  [[nodiscard]] std::chrono::steady_clock::time_point last_sent() const {
    return std::chrono::steady_clock::time_point(std::chrono::steady_clock::duration(last_sent_ns_.load()));
  }

  grpc::Status WatchSafety(grpc::ServerContext* ctx, const v1::WatchSafetyRequest* /*request*/,
                           grpc::ServerWriter<v1::SafetyState>* writer) override {
    ++watch_calls_;
    auto next = std::chrono::steady_clock::now();
    while (!ctx->IsCancelled() && !closing_) {
      if (!silent_) {
        v1::SafetyState s;
        {
          std::lock_guard lock(mu_);
          s = state_;
          s.set_robot_name(robot_);
          s.set_aggregator_run_id(run_id_);
          s.set_aggregator_start_t_ns(static_cast<std::int64_t>(run_id_));
          s.set_seq(++seq_);
        }
        // The aggregator's part of the safety layer (docs/safety-channel.md): send time and CRC, last.
        s.set_sender_steady_ns(
            std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count());
        ruffini::channel::Seal(s);
        if (!writer->Write(s)) break;
        ++sent_;
        last_sent_ns_ = std::chrono::steady_clock::now().time_since_epoch().count();
      }
      next += std::chrono::milliseconds(10);
      std::this_thread::sleep_until(next);
      const auto now = std::chrono::steady_clock::now();
      if (next < now - std::chrono::milliseconds(100)) next = now;
    }
    return grpc::Status(grpc::StatusCode::UNAVAILABLE, "scripted aggregator: stream ends");
  }

  grpc::Status GetStatus(grpc::ServerContext* /*ctx*/, const v1::GetStatusRequest* /*request*/,
                         v1::AggregatorStatus* status) override {
    std::lock_guard lock(mu_);
    for (const char* j : {"j1", "j2", "j3"}) status->add_joint_names(j);
    status->set_robot_name(robot_);
    status->set_aggregator_run_id(run_id_);
    *status->mutable_safety() = state_;
    status->set_aggregator_version("scripted");
    return grpc::Status::OK;
  }

  // Records the request; accepts it when it names this run and the current epoch, else refuses WRONG_RUN or
  // WRONG_EPOCH.
  grpc::Status ResetStop(grpc::ServerContext* /*ctx*/, const v1::ResetStopRequest* request,
                         v1::ResetStopResponse* response) override {
    std::lock_guard lock(mu_);
    last_reset_ = *request;
    if (request->aggregator_run_id() != run_id_) {
      response->set_reason(v1::RESET_REFUSAL_WRONG_RUN);
    } else if (request->stop_epoch() != state_.stop_epoch()) {
      response->set_reason(v1::RESET_REFUSAL_WRONG_EPOCH);
    } else {
      response->set_accepted(true);
    }
    return grpc::Status::OK;
  }
  v1::ResetStopRequest last_reset() {
    std::lock_guard lock(mu_);
    return last_reset_;
  }

  grpc::Status PublishJointStates(grpc::ServerContext* /*ctx*/, grpc::ServerReader<v1::JointState>* reader,
                                  v1::PublishJointStatesResponse* response) override {
    v1::JointState js;
    while (reader->Read(&js)) {
      ++joint_states_;
      response->set_received(response->received() + 1);
      response->set_accepted(response->accepted() + 1);
    }
    return grpc::Status::OK;
  }

 private:
  std::unique_ptr<grpc::Server> server_;
  int port_ = 0;
  std::mutex mu_;
  v1::SafetyState state_;
  v1::ResetStopRequest last_reset_;
  std::string robot_;
  std::uint64_t run_id_;
  std::uint64_t seq_ = 0;
  std::atomic<bool> silent_{false}, closing_{false};
  std::atomic<std::uint64_t> sent_{0}, joint_states_{0};
  std::atomic<std::int64_t> last_sent_ns_{0};
  std::atomic<int> watch_calls_{0};
};

}  // namespace ruffini::testing
