// The safety layer's receivers: per stream, they detect the eight communication errors of IEC 61784-3
// (corruption, unintended repetition, incorrect sequence, loss, unacceptable delay, insertion, masquerade,
// addressing) and say what the receiver must do. docs/safety-channel.md states each measure and its safe
// reaction; tests/channel/ tests every row.
//
// Everything here is pure and runs on injected steady-clock times (ns). Real-time safe: no allocation, no
// lock, no throw (except the constructors, which validate their configuration).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>

#include "ruffini/v1/aggregator.pb.h"
#include "ruffini/v1/patch.pb.h"

namespace ruffini::channel {

// The eight communication errors; the metric label of every detection is Name(error).
enum class Error : std::uint8_t {
  kCorruption = 0,         // the CRC does not match the fields
  kRepetition = 1,         // the same sequence number again
  kIncorrectSequence = 2,  // an older sequence number than the last accepted (reordered or replayed)
  kLoss = 3,               // a gap in the sequence numbers
  kDelay = 4,              // older than the freshness budget
  kInsertion = 5,          // not from the sender run this stream began with
  kMasquerade = 6,         // claims another sender identity (another patch id)
  kAddressing = 7,         // addressed to another receiver (another aggregator run, another robot)
};
inline constexpr std::size_t kErrorKinds = 8;
[[nodiscard]] std::string_view Name(Error e) noexcept;

// A random nonzero 64-bit run id for this process (std::random_device). Draw once at start.
[[nodiscard]] std::uint64_t DrawRunId();

// Per-stream sequence numbers: the next expected is last + 1.
enum class SeqVerdict : std::uint8_t { kNext, kGap, kRepeat, kOld };
class SequenceCheck {
 public:
  // kNext and kGap advance `last`; kRepeat and kOld leave it. 0 is never valid (kOld). Before any number
  // was seen, the next expected is 1 (a patch stream's hello).
  SeqVerdict Check(std::uint64_t seq) noexcept;
  // For a stream that may begin anywhere (a subscriber's view of a shared counter): the first number seen
  // is taken as kNext.
  SeqVerdict CheckJoining(std::uint64_t seq) noexcept;
  [[nodiscard]] std::uint64_t last() const noexcept { return last_; }
  // How many numbers the last kGap skipped.
  [[nodiscard]] std::uint64_t skipped() const noexcept { return skipped_; }

 private:
  std::uint64_t last_ = 0;
  std::uint64_t skipped_ = 0;
};

// Freshness without synchronised clocks: the sender stamps its steady clock; the receiver learns the offset
// between the two steady clocks as the smallest (arrival - sent) seen on the link (the fastest message
// bounds the offset from above), allowed to creep up by at most max_drift_ppm of the elapsed time (two
// steady clocks may run at slightly different rates). A message's age is how much longer it took than that
// fastest one. The learned offset includes the link's minimum transport delay, so the age measures queueing
// and slowing, not the wire's constant latency.
struct FreshnessConfig {
  std::int64_t budget_ns = 20'000'000;  // older than this is kDelay
  double max_drift_ppm = 200.0;         // stated clock requirement (docs/safety-channel.md)
};
class FreshnessCheck {
 public:
  explicit FreshnessCheck(FreshnessConfig config);  // throws std::invalid_argument on a bad config
  // The age of a message sent at `sent_steady_ns` (sender's clock) arriving at `arrival_steady_ns`
  // (receiver's clock); the first message of a link has age 0. Saturates instead of overflowing.
  std::int64_t Age(std::int64_t sent_steady_ns, std::int64_t arrival_steady_ns) noexcept;
  [[nodiscard]] bool Late(std::int64_t age_ns) const noexcept { return age_ns > config_.budget_ns; }
  [[nodiscard]] const FreshnessConfig& config() const noexcept { return config_; }
  [[nodiscard]] bool learned() const noexcept { return learned_; }
  [[nodiscard]] std::int64_t offset_ns() const noexcept { return offset_ns_; }
  [[nodiscard]] std::int64_t last_arrival_ns() const noexcept { return last_arrival_ns_; }
  // Starts from what an earlier link of the same sender run learned (its offset and its last arrival), instead
  // of taking the first message as on time: a delay that ended the earlier link is still seen on this one.
  void Seed(std::int64_t offset_ns, std::int64_t last_arrival_ns) noexcept {
    learned_ = true;
    offset_ns_ = offset_ns;
    last_arrival_ns_ = last_arrival_ns;
  }

 private:
  FreshnessConfig config_;
  bool learned_ = false;
  std::int64_t offset_ns_ = 0;       // receiver steady - sender steady, fastest message, with creep
  std::int64_t last_arrival_ns_ = 0;
};

// The error-rate rule (OPC UA Safety's SafetyErrorIntervalLimit): `limit` errors within `window_ns` latch.
struct ErrorRateConfig {
  std::int64_t window_ns = 60'000'000'000;  // 1 min
  int limit = 2;                            // 1..8
};
class ErrorRate {
 public:
  explicit ErrorRate(ErrorRateConfig config);  // throws std::invalid_argument on a bad config
  // Records an error at `now_ns`; true when this one makes `limit` within the window.
  bool Record(std::int64_t now_ns) noexcept;
  [[nodiscard]] const ErrorRateConfig& config() const noexcept { return config_; }

 private:
  ErrorRateConfig config_;
  std::array<std::int64_t, 8> times_{};  // ring of the newest errors
  std::size_t count_ = 0;
};

// Detections by reason, for metrics and status.
struct ErrorCounts {
  std::array<std::uint64_t, kErrorKinds> by_error{};
  void Count(Error e) noexcept { ++by_error[static_cast<std::size_t>(e)]; }
  [[nodiscard]] std::uint64_t operator[](Error e) const noexcept { return by_error[static_cast<std::size_t>(e)]; }
  [[nodiscard]] std::uint64_t total() const noexcept;
};

struct LinkConfig {
  FreshnessConfig freshness;
  ErrorRateConfig error_rate;
};

// What the receiver does with one message.
struct Verdict {
  bool use = true;         // act on its content (false: discard it)
  bool error = false;      // an error was detected (`kind` says which; counted already)
  Error kind = Error::kCorruption;
  bool latch = false;      // the link must latch a fault (patch link: FAULT the patch; controller: halt)
  bool rate_latch = false; // the latch comes from the error-rate rule (too many errors in the window)
  std::int64_t age_ns = 0; // the message's age (freshness)
};

// The aggregator's receiver for one decoder stream (PatchMessage). Reactions:
//   corruption, masquerade, insertion, addressing, repetition, incorrect sequence: discard, count; the
//     error-rate rule latches a fault at the limit. A discarded message leaves a gap, so the next one
//     reports kLoss (below) unless it was a repetition.
//   loss: a lost message may have been a contact; the content of this one is used, and the patch latches
//     FAULT (KIND_PATCH_PROTOCOL): a lost contact message is not tolerable.
//   delay: the content is used (a late STOP still stops) and the patch latches FAULT (KIND_PATCH_LATE).
class PatchLinkCheck {
 public:
  PatchLinkCheck(LinkConfig config, std::uint64_t aggregator_run_id, std::string patch_id);
  // What an earlier stream of this patch learned of its sender's clock: used when this stream's sender run is
  // the same (a decoder reconnecting, e.g. after the delay ended its stream), ignored otherwise (a restarted
  // decoder has a new run and a new clock origin). Call before the first Receive.
  void RememberSender(std::uint64_t sender_run_id, std::int64_t offset_ns, std::int64_t last_arrival_ns) noexcept {
    remembered_ = {sender_run_id, offset_ns, last_arrival_ns};
  }
  Verdict Receive(const v1::PatchMessage& m, std::int64_t arrival_steady_ns) noexcept;
  [[nodiscard]] const ErrorCounts& counts() const noexcept { return counts_; }
  [[nodiscard]] const FreshnessCheck& freshness() const noexcept { return freshness_; }
  [[nodiscard]] std::uint64_t sender_run_id() const noexcept { return sender_run_id_; }

 private:
  Verdict Discard(Error e, std::int64_t arrival_steady_ns) noexcept;
  std::uint64_t aggregator_run_id_;
  std::string patch_id_;
  std::uint64_t sender_run_id_ = 0;  // learned from the stream's first message
  struct Remembered {
    std::uint64_t sender_run_id = 0;
    std::int64_t offset_ns = 0, last_arrival_ns = 0;
  } remembered_;
  SequenceCheck seq_;
  FreshnessCheck freshness_;
  ErrorRate rate_;
  ErrorCounts counts_;
};

// The controller's receiver for one WatchSafety stream (SafetyState). Reactions:
//   corruption, addressing (another robot), insertion (another aggregator run within a stream),
//     repetition, incorrect sequence: discard, count; the error-rate rule latches a halt at the limit.
//     A discarded state is as if lost: the watchdog halts if no good state follows in time.
//   loss: tolerable (states are latest-value: a gap means skipped repeats); counted, content used.
//   delay: the state is discarded and the controller halts (latch).
class StateLinkCheck {
 public:
  StateLinkCheck(LinkConfig config, std::string robot_name);
  // What an earlier stream learned of an aggregator run's clock: used when this stream's run is that run (a
  // re-created stream), so that a delay that halted the earlier stream is not this one's "on time". Call
  // before the first Receive.
  void RememberSender(std::uint64_t run_id, std::int64_t offset_ns, std::int64_t last_arrival_ns) noexcept {
    remembered_ = {run_id, offset_ns, last_arrival_ns};
  }
  Verdict Receive(const v1::SafetyState& s, std::int64_t arrival_steady_ns) noexcept;
  [[nodiscard]] const ErrorCounts& counts() const noexcept { return counts_; }
  [[nodiscard]] std::uint64_t aggregator_run_id() const noexcept { return run_id_; }
  [[nodiscard]] const FreshnessCheck& freshness() const noexcept { return freshness_; }

 private:
  Verdict Discard(Error e, std::int64_t arrival_steady_ns) noexcept;
  std::string robot_name_;
  std::uint64_t run_id_ = 0;  // learned from the stream's first good state
  struct Remembered {
    std::uint64_t run_id = 0;
    std::int64_t offset_ns = 0, last_arrival_ns = 0;
  } remembered_;
  SequenceCheck seq_;
  FreshnessCheck freshness_;
  ErrorRate rate_;
  ErrorCounts counts_;
};

}  // namespace ruffini::channel
