#pragma once
// The aggregator's state, without the network: one object owns the patch links, the joint-state history,
// the body-frame placement of contacts and the safety policy, and runs on an injected clock (every call
// carries now_ns, Unix ns of the aggregator's clock). The service's gRPC callbacks only enqueue; one loop
// thread calls these methods (DESIGN.md, "Threads and time"), so a test can replay any sequence.
//
// A Connect stream's rules (docs/contracts.md): the first message is a PatchHello with seq 1 naming a scene
// patch. If another live stream holds that patch the hello is refused DUPLICATE_PATCH first, before anything
// else is looked at, and nothing else changes (the live stream keeps its health, no epoch is taken) -- unless
// that stream has been silent for more than kTakeoverWatchdogs watchdogs: then the old stream is ended
// (Reply.end_stream) and the newcomer takes the patch (a restarted decoder after a half-open link). Then the
// spec fingerprint, model SHA-256, heartbeat period, sample rate and decoder configuration must be the
// scene's; otherwise the hello is refused (the stream ends, and a patch with no live stream stays or becomes
// missing: FAULT). After it, seq rises by exactly 1 and the patch id never changes; a break is a protocol
// error (the stream ends, FAULT). A hello re-sent on the live stream is checked like the first; a mismatch is
// a protocol error of that stream. Heartbeats, contacts and faults go to the safety policy (ruffini::safety);
// contacts are placed in the base frame with the joint state interpolated at the contact's timestamp.
//
// Bad input is a doubt, never passed on (docs/safety.md, "Bad input"): a located contact with a non-finite or
// off-patch position or a non-finite / non-PSD covariance, a contact frame whose t_ns is implausibly far from
// its arrival (safety::InputLimits), are refused as a STOP; a heartbeat's active_fault outside the contract's
// enum is a fault (kInternal), counted. No NaN reaches SafetyState or ContactSet.
//
// Identity (docs/contracts.md): every SafetyState, AggregatorStatus and HelloAccepted carries Setup.run_id
// (random, nonzero, drawn by the service at start) and Setup.robot_name; a ResetStop naming another run (or
// none) is refused WRONG_RUN and changes nothing else.
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "ruffini/channel/checkers.h"
#include "ruffini/fusion/fuser.h"
#include "ruffini/robot/kinematics.h"
#include "ruffini/robot/model.h"
#include "ruffini/robot/mount.h"
#include "ruffini/safety/policy.h"
#include "ruffini/v1/aggregator.pb.h"

namespace ruffini::aggregate {

// What the aggregator expects of each scene patch.
struct PatchExpectation {
  std::string id;
  std::string spec_name;
  std::string spec_fingerprint;
  std::string model_sha256;      // "": any model trained for the spec
  std::optional<robot::PatchMount> mount;  // where it sits on the robot (none: not placed)
  double extent_y_mm = 150.0;    // the spec's surface: Y in 0..extent_y_mm, R in 0..extent_r_deg
  double extent_r_deg = 145.0;
  // The sensitivity maps of the model the scene names (GetStatus shows them; empty: none or no model).
  std::vector<v1::SensitivityMap> sensitivity;
};

// A live stream silent for more than this many watchdogs (its patch's silence deadline) is replaced by a
// new hello for its patch.
inline constexpr std::int64_t kTakeoverWatchdogs = 3;

struct Setup {
  safety::Config safety;
  std::vector<PatchExpectation> patches;   // the same ids, in the same order, as safety.patches
  std::optional<robot::Model> robot;       // none: a scene without a robot (contacts are not placed)
  std::int64_t max_heartbeat_period_ns = 10'000'000;  // a decoder announcing a slower heartbeat is refused
  std::int64_t joint_history_ns = 1'000'000'000;      // how much joint-state history is kept for placement
  std::string instance = "aggregator";
  std::uint64_t run_id = 0;        // this aggregator run (nonzero; the service draws it with std::random_device)
  std::string robot_name;          // the scene's `name`
  // Per region, what its patches' sensitivity maps guarantee (computed at load; GetStatus shows it).
  std::vector<v1::RegionCoverage> coverage;
  // The seams between the patches' covers and their bands (indices into `patches`; from the mounts and the
  // sensitivity maps at load, docs/fusion.md "Seams"). Used by the fusion when there is a robot.
  std::vector<fusion::FusionConfig::SeamBand> seams;
};

// Joint-state rejections (counted, logged by the service; a rejected state is not used).
enum class JointRejection : std::uint8_t {
  kNone = 0,
  kNoRobot,          // the scene has no robot
  kWrongCount,       // names / positions do not match the robot's joints
  kWrongNames,       // a name differs from the robot's joint (in the robot's order)
  kNotFinite,        // a NaN or infinite position
  kNotMonotonic,     // t_ns not after the previous state's on the same stream
  kImplausibleTime,  // t_ns further than InputLimits.max_time_skew_ns from its arrival
};
inline constexpr std::size_t kJointRejectionCount = 7;
std::string_view JointRejectionName(JointRejection r) noexcept;

// Input refused or corrected before the policy saw it (counted; the policy counts its own rejections too).
enum class BadInput : std::uint8_t {
  kBadPosition = 0,     // a located contact's position is not finite or off the patch: STOP
  kBadCovariance,       // a located contact's covariance is not finite or not PSD: STOP
  kImplausibleTime,     // a contact frame (STOP) or another message (its t_ns not used) far from arrival
  kUnknownFaultCode,    // a heartbeat's or PatchFault's code outside the enum: a fault (kInternal)
  kHelloChanged,        // a hello re-sent on a live stream differs from what the scene expects: protocol error
};
inline constexpr std::size_t kBadInputCount = 5;
std::string_view BadInputName(BadInput b) noexcept;

// One line of the service's log (docs/safety.md, "Events"): the policy's latches, escalations, new epochs,
// shutdown and resets, with who asked for a reset; and a stream replaced by a takeover.
struct Event {
  safety::Event safety{};          // type, state, epoch, cause (patch index, force) as the policy recorded it
  std::string operator_name;       // resets: ResetStopRequest.operator_name
  std::string cause_patch;         // the cause's patch id ("" none)
  bool takeover = false;           // true: not a policy event; `replaced_stream` was ended for `cause_patch`
  int replaced_stream = -1;
};

struct Counters {
  std::uint64_t messages = 0;
  std::uint64_t hellos_accepted = 0;
  std::array<std::uint64_t, v1::HelloRefusal_ARRAYSIZE> hellos_refused{};  // by v1::HelloRefusal
  std::uint64_t protocol_errors = 0;
  std::uint64_t contacts = 0;                     // contact messages
  std::uint64_t contacts_placed = 0;              // placed in the base frame
  std::uint64_t contacts_faint = 0;               // contact messages flagged faint (judged as read all the same)
  std::array<std::uint64_t, kJointRejectionCount> joint_states{};  // [0]: accepted
  std::array<std::uint64_t, kBadInputCount> bad_input{};          // by BadInput
  std::uint64_t takeovers = 0;                                    // silent streams replaced by a new hello
  std::uint64_t seam_sums = 0;  // contacts judged on the sum of both sides of their seam (it was larger)
  std::array<std::uint64_t, v1::RetareRefusal_ARRAYSIZE> retare_requests{};  // [0]: sent; else by refusal
  std::array<std::uint64_t, v1::RetareOutcome_ARRAYSIZE> retare_results{};   // by v1::RetareOutcome
};

class Core {
 public:
  // Throws InputError when the setup is inconsistent (patch lists differ, a mount's link is unknown).
  Core(Setup setup, std::int64_t now_ns);

  // --- Connect streams ---
  // A new stream; returns its id. allowed_patch: the only patch id its caller may publish (its certificate's
  // identity); empty: any (a plaintext service). A hello for another patch is refused UNAUTHORIZED and
  // leaves every patch's state, and the safety state, as they were.
  int OpenStream(std::int64_t now_ns, std::string allowed_patch = {});
  struct Reply {
    std::optional<v1::AggregatorCommand> command;  // to send on the stream
    bool close = false;                            // end the stream (after the command, if any)
    // Another stream the caller must end now (Finish it; the Core has already forgotten it): the silent
    // stream this hello took its patch from. -1: none.
    int end_stream = -1;
  };
  Reply OnPatchMessage(int stream, const v1::PatchMessage& m, std::int64_t now_ns);
  void CloseStream(int stream, std::int64_t now_ns);

  // --- Joint states (PublishJointStates) ---
  // joint_stream: which PublishJointStates call this came on (the monotonic rule is per stream, so one bad
  // stamp cannot lock out a controller that reconnects); 0 for a caller that has only one.
  JointRejection OnJointState(const v1::JointState& js, std::int64_t now_ns, int joint_stream = 0);
  // That joint-state stream ended (its monotonic reference is dropped).
  void CloseJointStream(int joint_stream);

  // --- ResetStop ---
  v1::ResetStopResponse OnReset(const v1::ResetStopRequest& r, bool authorized, std::int64_t now_ns);

  // --- RetarePatch (docs/safety.md "Re-tare") ---
  // Sent only when authorized, for this run, to a known patch whose decoder is connected, while the safety
  // state is STOP or FAULT, and when no earlier request of that patch is still unanswered (within
  // kRetareAnswerNs). A sent request is a command on the patch's stream: `stream` and `command`.
  static constexpr std::int64_t kRetareAnswerNs = 5'000'000'000;
  struct RetareDecision {
    v1::RetarePatchResponse response;
    int stream = -1;
    std::optional<v1::AggregatorCommand> command;
  };
  RetareDecision OnRetare(const v1::RetarePatchRequest& r, bool authorized, std::int64_t now_ns);

  // Deadlines (patch silence, joint staleness); call every few ms.
  void Tick(std::int64_t now_ns);
  // A periodic publication (the 10 ms heartbeat to subscribers): seq + 1.
  void Publish(std::int64_t now_ns);
  void Shutdown(std::int64_t now_ns);

  // --- Outputs ---
  // The current safety state as sent to subscribers.
  [[nodiscard]] v1::SafetyState SafetyState() const;
  // True once after each change of the safety state (the service publishes it at once).
  bool TakeChanged() noexcept { return std::exchange(changed_, false); }
  // The body-frame contacts now: every patch in contact, lifted into the base frame with the newest joint
  // state and fused across patches on the same or adjacent links (ruffini::fusion: a touch straddling a seam
  // is one contact, forces summed). Without a robot: one unplaced contact per patch.
  [[nodiscard]] v1::ContactSet Contacts(std::int64_t now_ns);
  [[nodiscard]] const fusion::FusionCounters* fusion_counters() const noexcept {
    return fuser_ ? &fusion_data_->counters : nullptr;
  }
  [[nodiscard]] v1::AggregatorStatus Status(std::int64_t now_ns) const;
  [[nodiscard]] const Counters& counters() const noexcept { return counters_; }
  // Whether patch i (scene order) is in contact now.
  [[nodiscard]] bool in_contact(std::size_t i) const noexcept { return links_[i].stream >= 0 && links_[i].in_contact; }
  [[nodiscard]] const safety::Counters& safety_counters() const noexcept { return data_.counters(); }
  [[nodiscard]] const safety::Policy& policy() const noexcept { return policy_; }
  [[nodiscard]] std::int64_t start_ns() const noexcept { return start_ns_; }
  // Why the newest protocol error ended its stream (for the service's log).
  [[nodiscard]] const std::string& last_protocol_error() const noexcept { return last_protocol_error_; }
  // Frame-to-stop latency of the newest STOP: now_ns when it latched minus the contact frame's t_ns; -1 none.
  [[nodiscard]] std::int64_t TakeStopLatencyNs() noexcept { return std::exchange(stop_latency_ns_, -1); }
  // The events since the last call, oldest first: one log line each (the service logs them in one place).
  [[nodiscard]] std::vector<Event> TakeEvents();
  [[nodiscard]] std::uint64_t run_id() const noexcept { return setup_.run_id; }
  // The safety layer's detections on the decoder links, by patch (scene order) and by error; a stream that
  // never got a patch counts under `unbound` (a corrupted or forged first message).
  [[nodiscard]] const std::vector<channel::ErrorCounts>& link_errors() const noexcept { return link_errors_; }
  [[nodiscard]] const channel::ErrorCounts& link_errors_unbound() const noexcept { return link_errors_unbound_; }

 private:
  struct Stream {
    int patch = -1;        // after an accepted hello
    std::string allowed_patch;  // empty: any
    std::uint64_t seq = 0;
    bool hello_done = false;
    // The safety layer's receiver (docs/safety-channel.md), made at the stream's first message for the patch
    // id it names: every message passes it before anything in it is believed.
    std::optional<channel::PatchLinkCheck> check;
  };
  struct PatchLink {
    int stream = -1;                      // the live stream holding the patch
    std::int64_t last_seen_ns = 0, last_t_ns = 0, clock_offset_ns = 0;
    std::uint64_t last_seq = 0;
    v1::PatchHello hello;
    v1::Heartbeat heartbeat;
    v1::PatchFault fault;
    bool in_contact = false;
    bool doubtful = false;                // the newest contact was refused as a doubt: shown unplaced, not fused
    v1::BodyContact contact;              // the newest contact, placed when possible
    v1::PatchContact surface;             // the newest contact as the decoder sent it (patch frame)
    std::int64_t contact_arrival_ns = 0;  // when the newest good contact arrived (aggregator clock)
    v1::RetareResult last_retare;         // the newest re-tare result
    std::uint64_t retare_pending = 0;     // the request sent and not answered yet
    std::int64_t retare_sent_ns = 0;
  };
  struct JointSample {
    std::int64_t t_ns = 0;
    std::vector<double> q;
  };

  Reply Refuse(Stream& s, v1::HelloRefusal reason, const std::string& message, std::int64_t now_ns);
  // The scene's expectations of a hello (spec, model, rate, configuration): HELLO_REFUSAL_UNSPECIFIED when met.
  v1::HelloRefusal CheckHello(std::size_t patch, const v1::PatchHello& h, std::string& message) const;
  void Bad(BadInput b) noexcept { ++counters_.bad_input[static_cast<std::size_t>(b)]; }
  safety::Rejection CheckContact(std::size_t patch, const v1::PatchMessage& m, std::int64_t now_ns) const;
  void JudgeOnSeam(std::size_t patch, const v1::PatchContact& c, safety::Contact& sc, std::int64_t now_ns) noexcept;
  void DrainPolicyEvents(const std::string& operator_name = {});
  Reply ProtocolError(int stream, Stream& s, const std::string& why, std::int64_t now_ns,
                      safety::CauseKind kind = safety::CauseKind::kPatchProtocol);
  void CountLinkError(const Stream& s, channel::Error e) noexcept;
  // The message's content, after the safety layer let it through.
  Reply Judge(int stream, Stream& s, const v1::PatchMessage& m, std::int64_t now_ns);
  void Note(const safety::Step& step);
  void JointsAt(std::int64_t t_ns, std::vector<double>& q) const;
  bool PlaceContact(int patch, std::int64_t t_ns, const v1::PatchContact& c, v1::BodyContact& out);
  v1::AggregatorCommand Command(std::int64_t now_ns);

  Setup setup_;
  channel::LinkConfig link_config_;
  std::vector<channel::ErrorCounts> link_errors_;
  // Per patch: the newest sender clock its streams learned (sender run, offset, last arrival), kept across
  // streams so that a reconnecting decoder of the same run is held to the same clock.
  struct SenderClock {
    std::uint64_t sender_run_id = 0;
    std::int64_t offset_ns = 0, last_arrival_ns = 0;
  };
  std::vector<SenderClock> sender_clock_;
  channel::ErrorCounts link_errors_unbound_;
  safety::Policy policy_;
  safety::Data data_;
  std::int64_t start_ns_;
  std::map<int, Stream> streams_;
  int next_stream_ = 1;
  std::vector<PatchLink> links_;
  std::deque<JointSample> joints_;        // sorted by t_ns
  std::int64_t joint_arrival_ns_ = -1;    // when the newest accepted joint state arrived (aggregator clock)
  std::map<int, std::int64_t> joint_stream_last_t_ns_;  // the monotonic reference, per joint-state stream
  std::vector<Event> events_;
  robot::Data fk_;
  std::optional<fusion::Fuser> fuser_;
  std::unique_ptr<fusion::FusionData> fusion_data_;  // fixed-size (about 29 kB): on the heap once
  std::vector<fusion::PatchInput> fusion_inputs_;
  robot::Data fk_latest_;
  std::vector<double> q_scratch_;
  Counters counters_;
  std::uint64_t command_seq_ = 0;
  std::uint64_t contact_ids_ = 0;
  std::uint64_t retare_ids_ = 0;  // RetarePatch request ids (per run, from 1)
  bool changed_ = true;
  std::int64_t stop_latency_ns_ = -1;
  std::uint64_t latency_epoch_ = 0;  // the STOP whose latency was taken
  std::string last_protocol_error_;
};

}  // namespace ruffini::aggregate
