#pragma once
// Ruffini safety client: the one file pair (safety_client.h + safety_client.cpp) a cobot integrator copies
// into a robot controller. It depends only on gRPC (grpc++), the stubs generated from
// proto/ruffini/v1/aggregator.proto (package ruffini.v1) and the C++20 standard library: no other Ruffini
// code, no logging library. docs/controller.md shows how to integrate it.
//
// The contract it keeps (docs/contracts.md, "WatchSafety"): the aggregator sends a SafetyState at least every
// 10 ms. The robot must stop whenever
//   - the state is STOP, FAULT or anything else than CLEAR (an unknown value counts as STOP),
//   - the state is not for this robot (SafetyState.robot_name differs from the configured name; an empty
//     name differs too): the state is discarded and counted,
//   - no state arrived for heartbeat_timeout (30 ms by default: silence is a stop),
//   - the stream ended, or could not be opened,
//   - a CLEAR carries another stop_epoch than the state before it in the same aggregator run (a stop/clear
//     cycle happened in states this client skipped),
//   - a CLEAR comes from a new aggregator run (aggregator_run_id or aggregator_start_t_ns changed: a restart,
//     or another aggregator answering at this address),
//   - the safety layer discards the state (CheckState: CRC, run, sequence, freshness; docs/safety-channel.md),
//     and, once two such errors fall within the error-rate window, every state until an operator calls
//     AcknowledgeLinkErrors().
// After every halt, whatever its reason, it may move again only after states_before_clear CLEAR states in a
// row of one aggregator run on one live stream, each within heartbeat_timeout of the state before it. The
// client starts halted.
//
// How to use it: the control loop reads `halted()` every cycle (one atomic load: real-time safe) and holds
// the robot while it is true; the halt and clear callbacks say why, for logs and the HMI. The watchdog is a
// thread of its own that reads the time of the last state from an atomic and stores `halted()` itself, so a
// halt for silence never waits for a lock or a callback. The callbacks run on a notifier thread of the
// client, one at a time and in the order the decisions were made, with no lock of the client held: a slow
// callback delays only the callbacks after it, never a decision. Never call Stop() or destroy the client
// from a callback (Stop() waits for a running callback to return).
#include <grpcpp/grpcpp.h>

#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <span>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "ruffini/channel/checkers.h"
#include "ruffini/v1/aggregator.grpc.pb.h"

namespace ruffini::controller {

using SteadyClock = std::chrono::steady_clock;

// Why the robot must stop.
enum class HaltReason : int {
  kNotStarted = 0,   // no state received yet (the client starts halted)
  kStop = 1,         // STATE_STOP: a contact above its body region's threshold
  kFault = 2,        // STATE_FAULT: the skin cannot be trusted (start-up, a silent patch, shutdown, ...)
  kUnknownState = 3, // STATE_UNSPECIFIED or a value this client does not know: treated as STOP
  kMissedStop = 4,   // a CLEAR under another stop_epoch than the state before it: a stop and its reset were skipped
  kNoHeartbeat = 5,  // no state within heartbeat_timeout on an open stream
  kStreamEnded = 6,  // the WatchSafety stream ended after it had delivered states
  kConnectFailed = 7,// the WatchSafety stream ended before its first state (nothing listening, refused, ...)
  kWrongRobot = 8,   // a state for another robot (robot_name is not MonitorConfig::robot_name): discarded
  kNewRun = 9,       // a CLEAR from a new aggregator run (a restart, or another aggregator): clean states again
  kLinkError = 10,   // the safety layer discarded a state (corruption, repetition, incorrect sequence, insertion;
                     // docs/safety-channel.md); after the error-rate limit, every state until a new stream
  kLate = 11,        // a state older than the freshness budget (unacceptable delay): discarded
};
inline constexpr int kHaltReasonCount = 12;
// "NOT_STARTED", "STOP", "FAULT", "UNKNOWN_STATE", "MISSED_STOP", "NO_HEARTBEAT", "STREAM_ENDED",
// "CONNECT_FAILED", "WRONG_ROBOT", "NEW_RUN", "LINK_ERROR", "LATE".
std::string_view HaltReasonName(HaltReason reason) noexcept;

// A decision to stop the robot.
struct HaltEvent {
  HaltReason reason = HaltReason::kNotStarted;
  ruffini::v1::SafetyState state;  // the state behind it (the discarded one for WRONG_ROBOT), else the newest
  std::string detail;              // e.g. "no state for 31.0 ms", "stream ended: UNAVAILABLE: aggregator shutting down"
  SteadyClock::time_point t{};     // when the client decided (its steady clock)
  std::chrono::nanoseconds silence{0};  // kNoHeartbeat: time since the last state (or since the stream opened)
  bool link_errors_latched = false;     // the error-rate latch holds: no state is used until AcknowledgeLinkErrors
};

// A decision that the robot may move again.
struct ClearEvent {
  ruffini::v1::SafetyState state;   // the CLEAR that released it
  SteadyClock::time_point t{};
  std::chrono::nanoseconds halted_for{0};  // how long the robot was halted
};

// What the client has seen since it was made.
struct SafetyStats {
  std::uint64_t states = 0;           // SafetyStates received (accepted and discarded)
  std::uint64_t discarded = 0;        // of those, discarded by CheckState (each one also halts)
  std::array<std::uint64_t, kHaltReasonCount> discarded_by{};  // discarded states by the HaltReason they caused
  std::uint64_t skipped_states = 0;   // seq gaps within one aggregator run (latest-value slots skip states)
  ruffini::channel::ErrorCounts link_errors;  // the safety layer's detections by error (loss included)
  std::uint64_t streams_opened = 0;   // WatchSafety calls started
  std::uint64_t channels_created = 0; // gRPC channels made (SafetyClient: the first and every re-creation)
  std::uint64_t clears = 0;           // clear decisions
  std::array<std::uint64_t, kHaltReasonCount> halts{};  // halt decisions by HaltReason
  std::chrono::nanoseconds max_state_gap{0};  // longest gap between two accepted states on one stream
  std::chrono::nanoseconds time_halted{0};    // total time halted, up to the moment of the query
  bool halted = true;
  HaltReason reason = HaltReason::kNotStarted;  // meaningful while halted
  bool link_errors_latched = false;   // the error-rate latch holds (until AcknowledgeLinkErrors)
  std::uint64_t link_acknowledgements = 0;  // AcknowledgeLinkErrors calls that released a latch
  ruffini::v1::SafetyState last_state;        // the newest accepted state (empty before the first)
};

struct MonitorConfig {
  // The robot this controller drives: the scene's robot name, as the aggregator puts it in every
  // SafetyState.robot_name (e.g. "cobot" for config/scenes/cobot.yaml). Required (the constructors throw
  // std::invalid_argument when it is empty): a state for any other name, or with none, is discarded and halts.
  std::string robot_name;
  std::chrono::nanoseconds heartbeat_timeout = std::chrono::milliseconds(30);  // silence longer than this halts
  int states_before_clear = 3;  // clean CLEAR states in a row before a clear (>= 1)
  // The safety layer (docs/safety-channel.md): the freshness budget of a state (its sender steady time against
  // its arrival, the offset learned per stream) and the error-rate rule (errors within a window, per stream).
  ruffini::channel::LinkConfig link{};
};

// The verdict of SafetyMonitor::CheckState on one received state.
struct StateVerdict {
  bool accept = true;
  HaltReason halt = HaltReason::kNotStarted;  // when discarded: the halt it causes (a discarded state always halts)
  std::string detail;                          // when discarded: why (the halt's detail)
  static StateVerdict Accept() { return {}; }
  static StateVerdict Discard(HaltReason halt, std::string detail) { return {false, halt, std::move(detail)}; }
};

// The pure state machine of the client: no threads, no I/O, no clock of its own (every event carries the
// time), so it is tested (and fuzzed) without a network. SafetyClient drives it. Not thread-safe by itself.
class SafetyMonitor {
 public:
  struct Action {
    enum class Kind { kNone, kHalt, kClear } kind = Kind::kNone;
    HaltEvent halt;    // when kind == kHalt
    ClearEvent clear;  // when kind == kClear
  };

  // Throws std::invalid_argument when config.robot_name is empty.
  SafetyMonitor(MonitorConfig config, SteadyClock::time_point now);

  // A WatchSafety call was started.
  Action OnStreamOpened(SteadyClock::time_point now);
  // A SafetyState arrived on the open stream at `arrival` (this client's steady clock). Every received state
  // goes through CheckState first: a discarded one is counted, halts, and is no evidence of a live link.
  Action OnState(const ruffini::v1::SafetyState& state, SteadyClock::time_point arrival);
  // The stream ended (detail: the gRPC status, for the halt's detail).
  Action OnStreamEnded(const std::string& detail, SteadyClock::time_point now);
  // The watchdog's tick: OnSilence(Silence(now), now).
  Action OnTick(SteadyClock::time_point now);
  // A watchdog saw `silence` on the open stream: longer than heartbeat_timeout ends the clear streak and
  // halts (NO_HEARTBEAT; told once, and not while already halted for the link itself).
  Action OnSilence(std::chrono::nanoseconds silence, SteadyClock::time_point now);

  // The safety layer's check of one received state (docs/safety-channel.md), the single place every
  // SafetyState passes through with its arrival time before the rules above see it: CRC, robot (addressing),
  // aggregator run, sequence (within the stream, and across streams of the same run: never an older state),
  // freshness. Accept, or discard with the halt it causes.
  StateVerdict CheckState(const ruffini::v1::SafetyState& state, SteadyClock::time_point arrival);

  // The error-rate rule's latch (docs/safety-channel.md): `limit` errors of the safety layer within its window,
  // counted over the client's lifetime (a new stream does not forget them), and no state is used until an
  // operator acknowledges it here. The robot still needs three clean states afterwards.
  [[nodiscard]] bool link_errors_latched() const noexcept { return link_latched_; }
  // Returns whether a latch was held (and is now released).
  bool AcknowledgeLinkErrors() noexcept {
    const bool was = link_latched_;
    link_latched_ = false;
    if (was) ++stats_.link_acknowledgements;
    return was;
  }

  [[nodiscard]] bool halted() const noexcept { return halted_; }
  [[nodiscard]] HaltReason reason() const noexcept { return reason_; }
  [[nodiscard]] bool stream_open() const noexcept { return stream_open_; }
  // The last accepted state on the open stream, or the stream's start before its first state.
  [[nodiscard]] SteadyClock::time_point last_evidence() const noexcept { return last_evidence_; }
  // Time since last_evidence() while a stream is open; 0 when none is.
  [[nodiscard]] std::chrono::nanoseconds Silence(SteadyClock::time_point now) const noexcept;
  [[nodiscard]] SafetyStats Stats(SteadyClock::time_point now) const;
  [[nodiscard]] const MonitorConfig& config() const noexcept { return config_; }

 private:
  struct Run {
    std::uint64_t id = 0;        // SafetyState.aggregator_run_id
    std::int64_t start_ns = 0;   // SafetyState.aggregator_start_t_ns
    bool operator==(const Run&) const = default;
  };
  static Run RunOf(const ruffini::v1::SafetyState& s) { return {s.aggregator_run_id(), s.aggregator_start_t_ns()}; }
  Action OnAcceptedState(const ruffini::v1::SafetyState& s, bool new_run, bool new_epoch, bool late,
                         SteadyClock::time_point now);
  Action Halt(HaltReason reason, std::string detail, SteadyClock::time_point now,
              std::chrono::nanoseconds silence = std::chrono::nanoseconds(0),
              const ruffini::v1::SafetyState* state = nullptr);

  MonitorConfig config_;
  bool halted_ = true;
  HaltReason reason_ = HaltReason::kNotStarted;
  std::uint64_t halt_epoch_ = 0;           // stop_epoch of the state behind the current halt
  Run halt_run_;                           // and its run
  SteadyClock::time_point halted_since_;
  bool stream_open_ = false;
  bool stream_has_state_ = false;
  SteadyClock::time_point last_evidence_;  // the last accepted state on this stream, or the stream's start
  int clear_streak_ = 0;
  bool have_run_ = false;                  // run_ is known
  Run run_;                                // the aggregator run of the newest accepted state
  bool have_epoch_ = false;                // last_epoch_ is known (within run_)
  std::uint64_t last_epoch_ = 0;           // stop_epoch of the newest accepted state
  std::array<bool, kHaltReasonCount> discard_reason_{};  // halt reasons CheckState has used
  std::optional<ruffini::channel::StateLinkCheck> link_;  // this stream's safety-layer receiver
  std::optional<ruffini::channel::ErrorRate> rate_;       // the error-rate rule over the client's lifetime
  bool link_latched_ = false;              // the error-rate limit was reached (until AcknowledgeLinkErrors)
  bool halt_latched_ = false;              // link_latched_ when the current halt was told (a new latch is told)
  std::uint64_t seq_run_ = 0;              // the aggregator run of seq_last_ ...
  std::uint64_t seq_last_ = 0;             // ... and the newest seq accepted from it, on any stream
  std::vector<std::uint64_t> dead_runs_;   // runs a newer run replaced (the newest 64): their states are refused
  struct RememberedClock {
    std::uint64_t run_id = 0;
    std::int64_t offset_ns = 0, last_arrival_ns = 0;
  } remembered_clock_;                     // the newest run's clock offset, kept across streams
  SafetyStats stats_;
};

// Makes the channel a SafetyClient reads from; called again to re-create it after a dead transport.
using ChannelFactory = std::function<std::shared_ptr<grpc::Channel>()>;

struct SafetyClientConfig {
  std::string subscriber = "ruffini-safety-client";  // WatchSafetyRequest.subscriber (logs, metrics)
  MonitorConfig monitor;                               // monitor.robot_name is required
  std::chrono::milliseconds watchdog_tick{1};           // how often the watchdog looks (steady clock)
  std::chrono::milliseconds reconnect_initial{100};     // first pause before a new WatchSafety call
  std::chrono::milliseconds reconnect_max{1000};        // the pause doubles up to this
  // An open stream silent for this long is cancelled, and the channel is made again (a new TCP connection):
  // a dead peer can keep a connection looking open for minutes, and a new call on the old channel would
  // ride the same dead transport. The robot halted long before (heartbeat_timeout). The channel is also made
  // again after a stream ends UNAVAILABLE (a transport the keepalive found dead, a refused connect).
  std::chrono::milliseconds cancel_silent_stream_after{500};
};

// A channel to the aggregator fit for a safety client. Reconnect backoff 100 ms initial and minimum, 1 s
// maximum (gRPC's defaults are 1 s growing to 120 s). HTTP/2 keepalive: a ping every 1 s, also without
// calls and without data, and a transport whose ping is not answered within 1 s is closed (gRPC clients
// send none by default, so a peer that vanished without closing its socket went unnoticed). Its own
// subchannel pool, so a channel made again dials a new connection instead of sharing the old one.
// credentials: nullptr means plaintext. The aggregator must allow pings every 1 s
// (GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS, GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS).
std::shared_ptr<grpc::Channel> MakeAggregatorChannel(const std::string& target,
                                                     std::shared_ptr<grpc::ChannelCredentials> credentials = nullptr,
                                                     std::chrono::milliseconds initial_backoff = std::chrono::milliseconds(100),
                                                     std::chrono::milliseconds max_backoff = std::chrono::milliseconds(1000));
// A ChannelFactory that calls MakeAggregatorChannel(target, credentials).
ChannelFactory AggregatorChannelFactory(std::string target, std::shared_ptr<grpc::ChannelCredentials> credentials = nullptr);

// Subscribes to WatchSafety, keeps the watchdog and reconnects; see the top of this file. Thread-safe.
class SafetyClient {
 public:
  using HaltCallback = std::function<void(const HaltEvent&)>;
  using ClearCallback = std::function<void(const ClearEvent&)>;

  // Does not connect yet: Start() does. on_halt is called on every halt decision: the first one, and
  // again while halted whenever the reason or the stop_epoch changes or the error-rate latch begins (it must
  // be idempotent). on_clear is
  // called when the robot may move again. Either may be empty. Throws std::invalid_argument when
  // config.monitor.robot_name is empty.
  SafetyClient(ChannelFactory make_channel, SafetyClientConfig config, HaltCallback on_halt, ClearCallback on_clear);
  ~SafetyClient();  // Stop()
  SafetyClient(const SafetyClient&) = delete;
  SafetyClient& operator=(const SafetyClient&) = delete;

  // Starts the stream reader, the watchdog and the notifier threads. Call once.
  void Start();
  // Cancels the stream, joins the threads (waiting for a callback that is running to return); no callback
  // runs after it returns (decisions not yet told are dropped), and halted() is true from then on (nothing
  // supervises the robot any more). Idempotent; not from a callback.
  void Stop();

  // Real-time safe: one atomic load, no lock, no allocation, no throw.
  [[nodiscard]] bool halted() const noexcept { return halted_.load(std::memory_order_acquire); }
  // A snapshot (takes the client's lock for a moment; callable from the callbacks).
  [[nodiscard]] SafetyStats Stats() const;
  // The operator's acknowledgement of the safety layer's error-rate latch (SafetyMonitor::AcknowledgeLinkErrors):
  // the robot then still needs three clean states. Returns whether a latch was held (false: nothing to
  // acknowledge). Takes the client's lock for a moment; callable from any thread, not from a callback.
  bool AcknowledgeLinkErrors();

 private:
  void ReadLoop();
  void WatchdogLoop();
  void NotifyLoop();
  void Apply(SafetyMonitor::Action action);  // mu_ held
  void Mirror();                             // mu_ held: the monitor's link view into the watchdog's atomics

  ChannelFactory make_channel_;
  std::shared_ptr<grpc::Channel> channel_;  // the reader's
  std::unique_ptr<ruffini::v1::Aggregator::Stub> stub_;
  SafetyClientConfig config_;
  HaltCallback on_halt_;
  ClearCallback on_clear_;

  mutable std::mutex mu_;  // the monitor; never held while user code runs
  SafetyMonitor monitor_;
  std::uint64_t channels_created_ = 0;  // mu_

  // The watchdog's own view, written under mu_ after every event and read without a lock.
  std::atomic<bool> halted_{true};
  std::atomic<bool> stream_open_{false};
  std::atomic<std::int64_t> evidence_ns_{0};  // last_evidence() on the steady clock, ns since its epoch
  std::atomic<bool> cancelled_for_silence_{false};

  std::mutex notify_mu_;  // the decisions waiting for their callback
  std::condition_variable notify_cv_;
  std::deque<SafetyMonitor::Action> pending_;

  std::mutex ctx_mu_;  // the open call's context, for cancelling it
  grpc::ClientContext* ctx_ = nullptr;
  std::condition_variable stop_cv_;  // wakes the reader out of its reconnect pause
  std::atomic<bool> stopping_{false};
  bool started_ = false;
  std::thread reader_, watchdog_, notifier_;
};

// A client-streaming PublishJointStates writer. Every message carries the joint names; seq counts from 1 per
// stream. A failed write ends the stream; the next Publish opens a new one, at most every retry_pause. Not
// real-time safe (a gRPC write may block and allocate: on a frozen link it blocks until Cancel()): call it
// from a publishing thread, never from the servo loop of a real robot. Not thread-safe: one thread
// publishes; Cancel() may come from any thread.
class JointStatePublisher {
 public:
  JointStatePublisher(std::shared_ptr<grpc::Channel> channel, std::vector<std::string> joint_names,
                      std::chrono::milliseconds retry_pause = std::chrono::milliseconds(100));
  ~JointStatePublisher();  // Finish() with its default deadline
  JointStatePublisher(const JointStatePublisher&) = delete;
  JointStatePublisher& operator=(const JointStatePublisher&) = delete;

  // One joint state (positions in rad, velocities in rad/s or empty, t_ns Unix ns of the measurement).
  // Returns false when it could not be written (no stream, or the write failed).
  bool Publish(std::span<const double> positions_rad, std::span<const double> velocities_rad_s, std::int64_t t_ns);
  // Ends the open stream (if any) and returns the aggregator's counts for it, added to those of the streams
  // before it. The status is the last stream's. If the aggregator has not answered within `deadline` (a
  // frozen link), the stream is cancelled (status CANCELLED) and Finish returns.
  grpc::Status Finish(ruffini::v1::PublishJointStatesResponse* totals,
                      std::chrono::milliseconds deadline = std::chrono::milliseconds(500));
  // Unblocks a Publish stuck in a write (from another thread), e.g. on shutdown; later Publish calls fail.
  void Cancel();

  [[nodiscard]] std::uint64_t written() const noexcept { return written_; }
  [[nodiscard]] std::uint64_t failed() const noexcept { return failed_; }

 private:
  grpc::Status EndStream(std::chrono::milliseconds deadline);

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

// ResetStop naming the aggregator run and the stop_epoch the operator saw (SafetyState.aggregator_run_id
// and stop_epoch): a reset for another run is refused (RESET_REFUSAL_WRONG_RUN), so a stale reset cannot
// clear a STOP of a restarted aggregator. Returns the gRPC status; *response holds the aggregator's answer
// (accepted, or the refusal and why) when the status is OK.
grpc::Status ResetStop(ruffini::v1::Aggregator::Stub& stub, std::uint64_t aggregator_run_id, std::uint64_t stop_epoch,
                       const std::string& operator_name, const std::string& operator_note,
                       ruffini::v1::ResetStopResponse* response,
                       std::chrono::milliseconds timeout = std::chrono::seconds(2));

// One line for a state, e.g. "STOP epoch 3 cause contact upper_arm_a 1.60 N" or "FAULT epoch 1 cause
// startup".
std::string DescribeState(const ruffini::v1::SafetyState& state);

}  // namespace ruffini::controller
