#pragma once
// What a decoder service sends to the aggregator, as plain fixed-size structs: the real-time decode thread
// fills them without allocating and hands them through a lock-free ring to the publisher thread, which
// turns them into ruffini.v1.PatchMessage (to_proto.h). Numbers of the enums are those of patch.proto.
#include <array>
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "ruffini/decode/pipeline.h"
#include "ruffini/decode/retare.h"
#include "ruffini/ingest/hyperion.h"

namespace ruffini::link {

// v1::PatchFaultCode, same numbers.
enum class FaultCode : std::uint8_t {
  kNone = 0,
  kInterrogatorSilent = 1,
  kInterrogatorDisconnected = 2,
  kFramesRejected = 3,
  kFramesLost = 4,
  kBaselineInvalid = 5,
  kBaselineStale = 6,
  kModelMismatch = 7,
  kOverloaded = 8,
  kShuttingDown = 9,
  kInternal = 10,
  kLate = 11,  // sent by the publisher (a message waited past the freshness budget), never by the monitor
};
inline constexpr std::size_t kFaultCodeCount = 12;
// snake_case, stable (metric label values).
std::string_view FaultName(FaultCode c) noexcept;

// v1::BaselineState, same numbers.
enum class BaselineState : std::uint8_t { kUnspecified = 0, kCapturing = 1, kTracking = 2, kFrozen = 3, kStale = 4 };
std::string_view BaselineStateName(BaselineState s) noexcept;

// v1::FrameRejectReason numbers: decode::Reason keeps its own (1..8); the interrogator stream's start at 32.
std::uint32_t RejectCode(decode::Reason r) noexcept;
std::uint32_t RejectCode(ingest::Reason r) noexcept;

// The decoder's health, as a Heartbeat carries it. Counters are cumulative since the decoder process started.
struct Health {
  bool healthy = false;
  FaultCode active_fault = FaultCode::kNone;
  std::uint64_t frames = 0;        // interrogator frames delivered by the codec
  std::uint64_t valid_frames = 0;  // decoded
  std::uint64_t serial_gaps = 0;
  std::uint64_t frames_lost = 0;
  std::uint64_t onsets = 0;
  std::uint64_t faint_frames = 0;  // contact frames flagged faint (decode::PipelineCounters::faint)
  std::uint64_t release_refused_frames = 0;  // refused after a release (decode::PipelineCounters::release_refused)
  std::uint64_t messages_dropped = 0;  // heartbeats and mid-contact frames dropped on a full ring
  std::uint64_t frames_dropped = 0;    // frames the ingest thread dropped on a full ring (overload)
  std::array<std::uint64_t, decode::kReasonCount> decode_rejected{};  // by decode::Reason
  std::array<std::uint64_t, ingest::kReasonCount> stream_rejected{};  // by ingest::Reason
  bool in_contact = false;
  BaselineState baseline = BaselineState::kUnspecified;
  float drift_pm = 0.0f;
  float common_mode_pm = 0.0f;
  float frozen_s = 0.0f;
};

// One decoded frame of a contact (patch frame). Never NaN: position and covariance are 0 when not located,
// uncertainty fields 0 when the model has none (uncertainty = false).
struct Contact {
  float force_n = 0.0f;
  float force_sd_n = 0.0f;
  bool uncertainty = false;
  bool located = false;
  float y_mm = 0.0f, r_deg = 0.0f;
  float cov_yy_mm2 = 0.0f, cov_yr_mm2 = 0.0f, cov_rr_mm2 = 0.0f;
  float confidence = 0.0f;
  bool onset = false;
  bool released = false;
  float common_mode_pm = 0.0f;
  std::uint8_t missing = 0;
  bool over_range = false;          // more load than the model knows: force_n is a lower bound
  float force_lower_bound_n = 0.0f;  // with over_range
  bool multiple = false;            // located, and more than one touch (the covariance holds them)
  bool faint = false;               // shifts a baseline error gives as well (decode::PipelineOutput::faint)
};

struct Fault {
  FaultCode code = FaultCode::kNone;
  std::uint32_t reason = 0;    // v1::FrameRejectReason number, for kFramesRejected
  std::array<char, 120> text{};  // NUL-terminated
};

// The outcome of a re-tare the aggregator asked for (decode/retare.h).
struct RetareReport {
  std::uint64_t request_id = 0;
  decode::RetareOutcome outcome = decode::RetareOutcome::kInterrupted;
  float force_n = 0.0f;           // the largest force one touch on the map explains (0: not judged)
  float y_mm = 0.0f, r_deg = 0.0f;  // where (0: none)
  float motion_pm = 0.0f;
  float min_force_n = 0.0f;       // the decoder's re-tare force
};

struct Message {
  enum class Kind : std::uint8_t { kContact, kHeartbeat, kFault, kRetare };
  Kind kind = Kind::kHeartbeat;
  std::uint64_t serial = 0;     // interrogator serial of the newest frame (0: none yet)
  std::int64_t t_ns = 0;        // its interrogator timestamp, Unix ns
  std::int64_t decoder_t_ns = 0;  // when the decoder made this message, Unix ns
  std::int64_t mono_ns = 0;     // the same instant on the decoder's steady clock (never sent)
  Contact contact;
  Health health;
  Fault fault;
  RetareReport retare;

  // Never dropped on a full ring: faults, re-tare results, contact onsets and releases.
  [[nodiscard]] bool critical() const noexcept {
    return kind == Kind::kFault || kind == Kind::kRetare || (kind == Kind::kContact && (contact.onset || contact.released));
  }
};

}  // namespace ruffini::link
