#pragma once
// Ruffini safety client: the one file pair (safety_client.h + safety_client.cpp) a cobot integrator copies
// into a robot controller. It depends only on gRPC (grpc++), the stubs generated from
// proto/ruffini/v1/aggregator.proto (package ruffini.v1) and the C++20 standard library: no other Ruffini
// code, no logging library. docs/controller.md shows how to integrate it.
//
// The contract it keeps (docs/contracts.md, "WatchSafety"): the aggregator sends a SafetyState at least every
// 10 ms. The robot must stop whenever
//   - the state is STOP, FAULT or anything else than CLEAR (an unknown value counts as STOP),
//   - no state arrived for heartbeat_timeout (30 ms by default: silence is a stop),
//   - the stream ended, or could not be opened,
//   - a CLEAR carries a new stop_epoch (a stop/clear cycle happened in states this client skipped).
// It may move again only after states_before_clear CLEAR states in a row on one live stream (each within
// heartbeat_timeout of the one before). The client starts halted.
//
// How to use it: the control loop reads `halted()` every cycle (one atomic load: real-time safe) and holds
// the robot while it is true; the halt and clear callbacks say why, for logs and the HMI. The callbacks run
// on the client's own threads (its stream reader and its watchdog), one at a time and in the order the
// decisions were made, with the client's lock held: keep them short, never block in them, and never call
// Stop() or destroy the client from them.
#include <grpcpp/grpcpp.h>

#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "ruffini/v1/aggregator.grpc.pb.h"

namespace ruffini::controller {

using SteadyClock = std::chrono::steady_clock;

// Why the robot must stop.
enum class HaltReason : int {
  kNotStarted = 0,   // no state received yet (the client starts halted)
  kStop = 1,         // STATE_STOP: a contact above its body region's threshold
  kFault = 2,        // STATE_FAULT: the skin cannot be trusted (start-up, a silent patch, shutdown, ...)
  kUnknownState = 3, // STATE_UNSPECIFIED or a value this client does not know: treated as STOP
  kMissedStop = 4,   // a CLEAR with a new stop_epoch: a stop and its reset happened in skipped states
  kNoHeartbeat = 5,  // no state within heartbeat_timeout on an open stream
  kStreamEnded = 6,  // the WatchSafety stream ended after it had delivered states
  kConnectFailed = 7,// the WatchSafety stream ended before its first state (nothing listening, refused, ...)
};
inline constexpr int kHaltReasonCount = 8;
// "NOT_STARTED", "STOP", "FAULT", "UNKNOWN_STATE", "MISSED_STOP", "NO_HEARTBEAT", "STREAM_ENDED",
// "CONNECT_FAILED".
std::string_view HaltReasonName(HaltReason reason) noexcept;

// A decision to stop the robot.
struct HaltEvent {
  HaltReason reason = HaltReason::kNotStarted;
  ruffini::v1::SafetyState state;  // the newest state received (the one that halted, for STOP/FAULT)
  std::string detail;              // e.g. "no state for 31.0 ms", "stream ended: UNAVAILABLE: aggregator shutting down"
  SteadyClock::time_point t{};     // when the client decided (its steady clock)
  std::chrono::nanoseconds silence{0};  // kNoHeartbeat: time since the last state (or since the stream opened)
};

// A decision that the robot may move again.
struct ClearEvent {
  ruffini::v1::SafetyState state;   // the CLEAR that released it
  SteadyClock::time_point t{};
  std::chrono::nanoseconds halted_for{0};  // how long the robot was halted
};

// What the client has seen since it was made.
struct SafetyStats {
  std::uint64_t states = 0;           // SafetyStates received
  std::uint64_t skipped_states = 0;   // seq gaps within one aggregator run (latest-value slots skip states)
  std::uint64_t streams_opened = 0;   // WatchSafety calls started
  std::uint64_t clears = 0;           // clear decisions
  std::array<std::uint64_t, kHaltReasonCount> halts{};  // halt decisions by HaltReason
  std::chrono::nanoseconds max_state_gap{0};  // longest gap between two states on one stream
  std::chrono::nanoseconds time_halted{0};    // total time halted, up to the moment of the query
  bool halted = true;
  HaltReason reason = HaltReason::kNotStarted;  // meaningful while halted
  ruffini::v1::SafetyState last_state;        // the newest state (empty before the first)
};

struct MonitorConfig {
  std::chrono::nanoseconds heartbeat_timeout = std::chrono::milliseconds(30);  // silence longer than this halts
  int states_before_clear = 3;  // CLEAR states in a row on one live stream before a clear (>= 1)
};

// The pure state machine of the client: no threads, no I/O, no clock of its own (every event carries the
// time), so it is tested without a network. SafetyClient drives it. Not thread-safe by itself.
class SafetyMonitor {
 public:
  struct Action {
    enum class Kind { kNone, kHalt, kClear } kind = Kind::kNone;
    HaltEvent halt;    // when kind == kHalt
    ClearEvent clear;  // when kind == kClear
  };

  SafetyMonitor(MonitorConfig config, SteadyClock::time_point now);

  // A WatchSafety call was started.
  Action OnStreamOpened(SteadyClock::time_point now);
  // A SafetyState arrived on the open stream.
  Action OnState(const ruffini::v1::SafetyState& state, SteadyClock::time_point now);
  // The stream ended (detail: the gRPC status, for the halt's detail).
  Action OnStreamEnded(const std::string& detail, SteadyClock::time_point now);
  // The watchdog's tick: halts once when an open stream has been silent for longer than heartbeat_timeout.
  Action OnTick(SteadyClock::time_point now);

  [[nodiscard]] bool halted() const noexcept { return halted_; }
  [[nodiscard]] HaltReason reason() const noexcept { return reason_; }
  [[nodiscard]] bool stream_open() const noexcept { return stream_open_; }
  // Time since the last state on the open stream (or since it opened, before its first state); 0 when no
  // stream is open.
  [[nodiscard]] std::chrono::nanoseconds Silence(SteadyClock::time_point now) const noexcept;
  [[nodiscard]] SafetyStats Stats(SteadyClock::time_point now) const;
  [[nodiscard]] const MonitorConfig& config() const noexcept { return config_; }

 private:
  Action Halt(HaltReason reason, std::string detail, SteadyClock::time_point now,
              std::chrono::nanoseconds silence = std::chrono::nanoseconds(0));

  MonitorConfig config_;
  bool halted_ = true;
  HaltReason reason_ = HaltReason::kNotStarted;
  std::uint64_t halt_epoch_ = 0;           // stop_epoch of the state behind the current halt
  std::int64_t halt_run_ = 0;              // aggregator_start_t_ns of that state
  SteadyClock::time_point halted_since_;
  bool stream_open_ = false;
  bool stream_has_state_ = false;
  SteadyClock::time_point last_evidence_;  // the last state on this stream, or the stream's start
  int clear_streak_ = 0;
  bool have_clear_epoch_ = false;          // last_clear_epoch_ is known (within the current aggregator run)
  std::uint64_t last_clear_epoch_ = 0;
  SafetyStats stats_;
};

struct SafetyClientConfig {
  std::string subscriber = "ruffini-safety-client";  // WatchSafetyRequest.subscriber (logs, metrics)
  MonitorConfig monitor;
  std::chrono::milliseconds watchdog_tick{1};           // how often the watchdog looks (steady clock)
  std::chrono::milliseconds reconnect_initial{100};     // first pause before a new WatchSafety call
  std::chrono::milliseconds reconnect_max{1000};        // the pause doubles up to this
  // An open stream silent for this long is cancelled and opened again (a dead peer can keep a TCP
  // connection looking open for minutes). The robot halted long before (heartbeat_timeout).
  std::chrono::milliseconds cancel_silent_stream_after{500};
};

// A channel to the aggregator with reconnect backoff fit for a safety client: 100 ms initial and minimum,
// 1 s maximum (gRPC's defaults are 1 s growing to 120 s). credentials: nullptr means plaintext.
std::shared_ptr<grpc::Channel> MakeAggregatorChannel(const std::string& target,
                                                     std::shared_ptr<grpc::ChannelCredentials> credentials = nullptr,
                                                     std::chrono::milliseconds initial_backoff = std::chrono::milliseconds(100),
                                                     std::chrono::milliseconds max_backoff = std::chrono::milliseconds(1000));

// Subscribes to WatchSafety, keeps the watchdog and reconnects; see the top of this file. Thread-safe.
class SafetyClient {
 public:
  using HaltCallback = std::function<void(const HaltEvent&)>;
  using ClearCallback = std::function<void(const ClearEvent&)>;

  // Does not connect yet: Start() does. on_halt is called on every halt decision: the first one, and
  // again while halted whenever the reason or the stop_epoch changes (it must be idempotent). on_clear is
  // called when the robot may move again. Either may be empty.
  SafetyClient(std::shared_ptr<grpc::Channel> channel, SafetyClientConfig config, HaltCallback on_halt,
               ClearCallback on_clear);
  ~SafetyClient();  // Stop()
  SafetyClient(const SafetyClient&) = delete;
  SafetyClient& operator=(const SafetyClient&) = delete;

  // Starts the stream reader and the watchdog threads. Call once.
  void Start();
  // Cancels the stream, joins both threads; no callback runs after it returns, and halted() is true from
  // then on (nothing supervises the robot any more). Idempotent; not from a callback.
  void Stop();

  // Real-time safe: one atomic load, no lock, no allocation, no throw.
  [[nodiscard]] bool halted() const noexcept { return halted_.load(std::memory_order_acquire); }
  // A snapshot (takes a small lock of its own; callable from the callbacks).
  [[nodiscard]] SafetyStats Stats() const;

 private:
  void ReadLoop();
  void WatchdogLoop();
  void Apply(const SafetyMonitor::Action& action);  // mu_ held

  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<ruffini::v1::Aggregator::Stub> stub_;
  SafetyClientConfig config_;
  HaltCallback on_halt_;
  ClearCallback on_clear_;

  mutable std::mutex mu_;  // the monitor and the callbacks
  SafetyMonitor monitor_;
  std::atomic<bool> halted_{true};

  mutable std::mutex stats_mu_;  // a copy of the monitor's stats, refreshed after every event
  SafetyStats stats_;

  std::mutex ctx_mu_;  // the open call's context, for cancelling it
  grpc::ClientContext* ctx_ = nullptr;
  std::condition_variable stop_cv_;  // wakes the reader out of its reconnect pause
  std::atomic<bool> stopping_{false};
  bool started_ = false;
  std::thread reader_, watchdog_;
};

// A client-streaming PublishJointStates writer. Every message carries the joint names; seq counts from 1 per
// stream. A failed write ends the stream; the next Publish opens a new one, at most
// every retry_pause. Not real-time safe (a gRPC write may block and allocate): call it from a publishing
// thread, not from the servo loop of a real robot. Not thread-safe: one thread publishes.
class JointStatePublisher {
 public:
  JointStatePublisher(std::shared_ptr<grpc::Channel> channel, std::vector<std::string> joint_names,
                      std::chrono::milliseconds retry_pause = std::chrono::milliseconds(100));
  ~JointStatePublisher();  // Finish()
  JointStatePublisher(const JointStatePublisher&) = delete;
  JointStatePublisher& operator=(const JointStatePublisher&) = delete;

  // One joint state (positions in rad, velocities in rad/s or empty, t_ns Unix ns of the measurement).
  // Returns false when it could not be written (no stream, or the write failed).
  bool Publish(std::span<const double> positions_rad, std::span<const double> velocities_rad_s, std::int64_t t_ns);
  // Ends the open stream (if any) and returns the aggregator's counts for it, added to those of the streams
  // before it. The status is the last stream's.
  grpc::Status Finish(ruffini::v1::PublishJointStatesResponse* totals);
  // Unblocks a Publish stuck in a write (from another thread), e.g. on shutdown.
  void Cancel();

  [[nodiscard]] std::uint64_t written() const noexcept { return written_; }
  [[nodiscard]] std::uint64_t failed() const noexcept { return failed_; }

 private:
  grpc::Status EndStream();

  std::unique_ptr<ruffini::v1::Aggregator::Stub> stub_;
  std::vector<std::string> names_;
  std::chrono::milliseconds retry_pause_;
  std::mutex ctx_mu_;
  std::unique_ptr<grpc::ClientContext> ctx_;
  std::unique_ptr<grpc::ClientWriter<ruffini::v1::JointState>> writer_;
  ruffini::v1::PublishJointStatesResponse response_, totals_;
  ruffini::v1::JointState msg_;
  std::uint64_t seq_ = 0, written_ = 0, failed_ = 0;
  SteadyClock::time_point next_try_{};
  std::atomic<bool> cancelled_{false};
};

// ResetStop naming `stop_epoch` (the epoch the operator saw). Returns the gRPC status; *response holds
// the aggregator's answer (accepted, or the refusal and why) when the status is OK.
grpc::Status ResetStop(ruffini::v1::Aggregator::Stub& stub, std::uint64_t stop_epoch, const std::string& operator_name,
                       const std::string& operator_note, ruffini::v1::ResetStopResponse* response,
                       std::chrono::milliseconds timeout = std::chrono::seconds(2));

// One line for a state, e.g. "STOP epoch 3 cause contact upper_arm_a 1.60 N" or "FAULT epoch 1 cause
// startup".
std::string DescribeState(const ruffini::v1::SafetyState& state);

}  // namespace ruffini::controller
