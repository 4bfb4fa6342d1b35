#pragma once
// The decode thread of a decoder service, without the thread: interrogator frames in (already parsed and
// picked by the ingest codec), decode::Pipeline on each, and the messages for the aggregator out (contacts,
// heartbeats, faults), with the patch's health and faults worked out here. Pure: no sockets, no threads, no
// allocation per call; the clock is injected (every call carries Now), so tests replay any sequence.
//
// What is sent (the rules of docs/contracts.md):
// - Contact: every valid frame while the pipeline reports a contact, the first one flagged onset, plus the
//   first valid frame after it, flagged released. Invalid frames send nothing (they are counted); a contact
//   is never ended by an invalid frame, and one that persists becomes a fault. An over-range frame (the
//   pipeline's over_range: more load than the model knows) is sent as a contact flagged over_range with
//   force_n = its lower bound (onset if no contact was open) and is not a rejection.
// - Heartbeat: every heartbeat period of the steady clock, whatever else happens (also while silent), with
//   the health: healthy only when connected, frames arriving, the baseline tracking or frozen, and no fault.
// - Fault: when a fault begins, or a different one takes over. Faults in priority order:
//   shutting_down > interrogator_disconnected > interrogator_silent (no frame for silence_deadline_ns) >
//   overloaded (frames dropped before decoding within the last second) > frames_rejected (reject_fault_frames
//   frames in a row rejected, by the codec or the pipeline; the last reason is named) > baseline_stale >
//   baseline_invalid (still capturing capture_deadline_s after the first frame). A fault ends by itself when
//   its condition does (the heartbeat says healthy again); the aggregator's latch decides what that means.
#include <cstdint>
#include <memory>
#include <string>

#include "ruffini/decode/pipeline.h"
#include "ruffini/decode/retare.h"
#include "ruffini/link/messages.h"
#include "ruffini/patch/spec.h"
#include "ruffini/v1/model.pb.h"

namespace ruffini::link {

// The two clocks of one instant: steady (deadlines) and Unix (what goes on the wire).
struct Now {
  std::int64_t mono_ns = 0;
  std::int64_t unix_ns = 0;
};

// Where the monitor's messages go (the service: a lock-free ring; tests: a vector). Must not block.
class MessageSink {
 public:
  virtual ~MessageSink() = default;
  virtual void Push(const Message& m) noexcept = 0;
};

// decode::Pipeline<float or double> with its per-stream Data, behind one interface (the decoder
// configuration is a run-time choice).
class FramePipeline {
 public:
  virtual ~FramePipeline() = default;
  virtual decode::PipelineOutput Process(const Wavelengths& wavelength_nm, std::uint32_t flags) noexcept = 0;
  [[nodiscard]] virtual const decode::BaselineTracker& baseline() const noexcept = 0;
  [[nodiscard]] virtual const decode::PipelineCounters& counters() const noexcept = 0;
  [[nodiscard]] virtual bool calibrated_uncertainty() const noexcept = 0;
  // The interrogator stream broke (a serial gap or a reconnect): state that assumes consecutive frames (the
  // two-touch fit's cached places) starts afresh.
  virtual void OnStreamBreak() noexcept {}
  // An accepted re-tare: the pipeline's baseline becomes baseline_nm (decode::Pipeline::Retare).
  virtual void Retare(const Wavelengths& baseline_nm) noexcept = 0;
};

// A decoder configuration users pick at deployment (a point of the bench's speed/accuracy table): the
// paper's fusion of every grid or one grid alone, in float or double. Written `paper-float` (default),
// `paper-double`, `<GRID>-float`, `<GRID>-double` (GRID: a location net's grid name in the model, e.g. SG).
struct DecoderChoice {
  std::string name = "paper-float";
  bool use_double = false;
  int grid = -1;  // -1: every grid (the paper's NIP); else the location net's index
};
// Throws InputError naming the value and listing the choices the model offers.
DecoderChoice ParseDecoderChoice(const std::string& text, const v1::DecoderModel& model);

// Builds the pipeline the choice names. Throws InputError when the model does not fit the spec.
std::unique_ptr<FramePipeline> MakePipeline(const v1::DecoderModel& model, const patch::PatchSpec& spec,
                                            const decode::PipelineConfig& config, const DecoderChoice& choice);

struct MonitorConfig {
  double sample_rate_hz = 1000.0;
  std::int64_t heartbeat_period_ns = 10'000'000;  // 10 ms
  std::int64_t silence_deadline_ns = 0;           // 0: 3 frame periods, at least 15 ms
  int reject_fault_frames = 0;                    // 0: 20 ms of frames, at least 3
  double capture_deadline_s = 10.0;
  std::int64_t overload_hold_ns = 1'000'000'000;  // an overload fault lasts this long after the last drop
};
// Fills the 0 defaults from the rate; throws InputError naming the field when a value is unusable.
MonitorConfig Resolved(MonitorConfig c);

// One frame from the interrogator, as the ingest codec delivered it.
struct FrameIn {
  std::uint64_t serial = 0;
  std::int64_t t_ns = 0;     // interrogator timestamp, Unix ns
  std::uint32_t flags = 0;   // ruffini/frame.h flags (kFlagPeakMissing, kFlagSaturated)
  Wavelengths wavelength_nm{};
};

class Monitor {
 public:
  // The pipeline must outlive the monitor. Throws InputError on a bad config.
  Monitor(FramePipeline& pipeline, MonitorConfig config, Now now);

  void OnConnected(Now now, MessageSink& sink) noexcept;
  void OnDisconnected(Now now, MessageSink& sink) noexcept;
  void OnFrame(const FrameIn& frame, Now now, MessageSink& sink) noexcept;
  // A frame the codec refused (the stream stays aligned, or a framing error before a reconnect).
  void OnStreamRejected(ingest::Reason reason, Now now, MessageSink& sink) noexcept;
  // Frames lost before decoding (the ingest ring was full): an overload.
  void OnFramesDropped(std::uint64_t frames, Now now, MessageSink& sink) noexcept;
  // Messages the sink could not take (it counts them into the next heartbeats).
  void OnMessagesDropped(std::uint64_t messages) noexcept { health_.messages_dropped += messages; }
  // Deadlines: silence, heartbeat. Call at least by NextDeadlineMono().
  void Tick(Now now, MessageSink& sink) noexcept;
  // The last fault (shutting_down), then nothing healthy ever again.
  void Shutdown(Now now, MessageSink& sink) noexcept;
  // Re-tare (decode/retare.h, docs/safety.md "Re-tare"). EnableRetare gives the model's response map (nullptr:
  // none; every request is then refused no_map) and the settings; call once before the first request. Throws
  // InputError on a bad map or settings.
  void EnableRetare(const v1::ResponseMap* map, const decode::RetareConfig& config);
  // The aggregator asked (request_id from its command): the next capture window of frames is judged, and a
  // kRetare message reports the outcome (busy at once when one is under way; no_map without EnableRetare's
  // map). While it runs, and until an accepted one replaces the baseline, the patch's health is what it was
  // (a stale baseline stays a fault): nothing can heal early.
  void RequestRetare(std::uint64_t request_id, Now now, MessageSink& sink) noexcept;
  // Re-tares by outcome (cumulative).
  [[nodiscard]] const std::array<std::uint64_t, decode::kRetareOutcomeCount>& retares() const noexcept { return retares_; }

  // Steady-clock time (ns) by which Tick must run next.
  [[nodiscard]] std::int64_t NextDeadlineMono() const noexcept;
  [[nodiscard]] const Health& health() const noexcept { return health_; }
  [[nodiscard]] const MonitorConfig& config() const noexcept { return config_; }
  // Faults begun, by code (cumulative).
  [[nodiscard]] const std::array<std::uint64_t, kFaultCodeCount>& faults() const noexcept { return faults_; }

 private:
  void Update(Now now, MessageSink& sink) noexcept;
  void Stamp(Message& m, Now now) const noexcept;
  void FillHealth() noexcept;

  FramePipeline& pipeline_;
  MonitorConfig config_;
  Health health_;
  std::array<std::uint64_t, kFaultCodeCount> faults_{};
  bool connected_ = false;
  bool shutting_down_ = false;
  bool have_frame_ = false;        // a frame (valid or rejected) since the last connect
  std::int64_t last_frame_mono_ = 0;
  std::int64_t connected_mono_ = 0;
  std::int64_t first_frame_mono_ = -1;
  std::int64_t overload_until_mono_ = -1;
  std::int64_t next_heartbeat_mono_ = 0;
  bool have_serial_ = false;
  std::uint64_t last_serial_ = 0;
  std::int64_t last_t_ns_ = 0;
  int reject_run_ = 0;
  std::uint32_t last_reject_code_ = 0;
  bool in_contact_ = false;
  Message scratch_;                // built in place, pushed by reference
  std::unique_ptr<decode::Retare> retare_;
  std::uint64_t retare_id_ = 0;    // the request under way
  float retare_force_n_ = 0.0f;
  std::array<std::uint64_t, decode::kRetareOutcomeCount> retares_{};
  void ReportRetare(std::uint64_t request_id, const decode::RetareResult& r, Now now, MessageSink& sink) noexcept;
  void InterruptRetare(Now now, MessageSink& sink) noexcept;
};

}  // namespace ruffini::link
