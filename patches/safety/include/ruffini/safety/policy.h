#pragma once
// The aggregator's safety policy: CLEAR, STOP, FAULT, latching under a stop_epoch, and resets. A pure state
// machine: no threads, no sockets, no protobuf, no clock of its own. Every call carries `now_ns`, the
// aggregator's clock (Unix ns, never going backwards), so a test replays any sequence exactly. The rules,
// the event x state table and why a cause is a STOP or a FAULT are in docs/safety.md.
//
// Shape (Pinocchio's Model/Data, like decode::NetworkDecoder): a const `Policy` holds what the scene fixes
// (patch ids, body regions and their thresholds, deadlines); a `Data` sized once from it holds what changes
// (the state, the epoch, every patch's link and health, counters). Every event is a const method of the
// Policy taking the Data:
//
//   safety::Policy policy(config);                 // validates; throws InputError naming the field
//   safety::Data data(policy, start_ns);           // FAULT, cause STARTUP, stop_epoch 1, seq 1
//   policy.OnHelloAccepted(data, "forearm", now);  // ... heartbeats, contacts, faults, Tick, Publish
//   if (policy.OnContact(data, "forearm", {.force_n = 180}, now).publish) Send(data.state());
//   auto r = policy.Reset(data, {.stop_epoch = data.state().stop_epoch, .authorized = true}, now);
//
// Real-time safe: every event (On*, Tick, Publish, Reset, Shutdown) is noexcept and allocates nothing; the
// Describe* and *Name helpers at the end allocate or not as noted and are for logs, off the hot path.
//
// The enums mirror ruffini.v1 (aggregator.proto, patch.proto) value for value, with the same numbers, and
// their *Name() is the wire name's suffix in lower case (tests/safety/proto_mirror_test.cpp checks both), so
// a service converts with a cast.
#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace ruffini::safety {

// ruffini.v1.SafetyState.State. STATE_UNSPECIFIED (0) never comes out of the policy.
enum class State : std::uint8_t { kClear = 1, kStop = 2, kFault = 3 };

// ruffini.v1.SafetyCause.Kind.
enum class CauseKind : std::uint8_t {
  kNone = 0,              // KIND_UNSPECIFIED: no cause (the state is CLEAR)
  kContact = 1,           // a contact above its region's threshold, or a contact the policy cannot trust: STOP
  kPatchFault = 2,        // a PatchFault, or a heartbeat that is not healthy: FAULT
  kPatchSilent = 3,       // no message within the patch's deadline, or its stream ended: FAULT
  kPatchMissing = 4,      // a scene patch never connected, or its hello was refused: FAULT
  kPatchProtocol = 5,     // the patch broke the stream protocol (the service detects it): FAULT
  kJointStatesStale = 6,  // no joint state within the limit (or none yet) while the scene needs them: FAULT
  kStartup = 7,           // the start-up latch (epoch 1): FAULT
  kShuttingDown = 8,      // Shutdown(): FAULT, never reset
  kInternal = 9,          // the caller fed something impossible (time backwards, an unknown patch): FAULT
  kPatchLate = 10,        // a patch's messages arrived older than the freshness budget: FAULT (the channel layer's)
  kLinkErrors = 11,       // too many errors on a link's safety layer within its window: FAULT (the channel layer's)
};
inline constexpr std::size_t kCauseKindCount = 12;

// ruffini.v1.ResetRefusal. kNone (RESET_REFUSAL_UNSPECIFIED) when accepted.
enum class ResetRefusal : std::uint8_t {
  kNone = 0,
  kWrongEpoch = 1,            // not the current stop_epoch
  kNotLatched = 2,            // the state is CLEAR
  kCausePresent = 3,          // some cause is still there (ResetResult.blocking says which)
  kNotHealthyLongEnough = 4,  // some patch not healthy for Config.healthy_before_reset_ns yet
  kUnauthorized = 5,          // ResetRequest.authorized is false
  kShuttingDown = 6,          // after Shutdown(): nothing is ever reset
  kInvalidRequest = 7,        // the request cannot be trusted (now_ns went backwards)
  kWrongRun = 8,              // the request names another aggregator run (ResetRequest.other_run)
};
inline constexpr std::size_t kResetRefusalCount = 9;

// ruffini.v1.LinkState. kHelloPending is the service's (a stream open, no hello yet): the policy never sets it.
enum class LinkState : std::uint8_t {
  kUnspecified = 0,
  kDisconnected = 1,
  kHelloPending = 2,
  kRefused = 3,
  kHealthy = 4,
  kUnhealthy = 5,
  kSilent = 6,
};
inline constexpr std::size_t kLinkStateCount = 7;

// ruffini.v1.PatchFaultCode.
enum class PatchFaultCode : std::uint8_t {
  kUnspecified = 0,  // in a heartbeat: no fault; in a PatchFault: unknown, still a fault
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
  kLate = 11,        // frames or messages waited past the freshness budget (or carry an implausible time)
};
inline constexpr std::size_t kPatchFaultCodeCount = 12;

// Why an event was refused as input. A refused event is never applied as it stands, and it is a doubt, never
// a reason to clear: time going backwards latches FAULT (kInternal) whatever the event; otherwise a refused
// contact latches STOP (and counts as above threshold on its patch), any other refused event FAULT (kInternal).
// Reset is the exception: a refused reset changes nothing (ResetRefusal::kInvalidRequest for time backwards).
enum class Rejection : std::uint8_t {
  kNone = 0,
  kTimeBackwards,   // now_ns below the newest now_ns seen (any event): FAULT, the deadlines cannot be trusted
  kUnknownPatch,    // a patch id the scene does not name
  kUnknownRegion,   // a contact naming a body region the config does not have (its threshold is unknown)
  kNonFiniteForce,  // a contact's force_n is NaN or infinite
  kNegativeForce,   // a contact's force_n is below 0 (the decoder clamps at 0: a broken decoder)
  kNotConnected,    // a heartbeat or contact from a patch whose hello is not accepted (or that went silent)
  // Found by the caller (aggregate::Core) before the policy judges a contact, passed in Contact.doubt:
  kBadPosition,     // a located contact whose position is not finite or lies off the patch (beyond the tolerance)
  kBadCovariance,   // a located contact whose covariance is not finite or not positive semi-definite
  kImplausibleTime, // a contact frame whose t_ns is further from its arrival than InputLimits.max_time_skew_ns
};
inline constexpr std::size_t kRejectionCount = 10;

inline constexpr std::int32_t kNoPatch = -1;
inline constexpr std::int32_t kNoRegion = -1;

// --- Configuration (the scene's safety section; the scene loader fills it) ----------------------------------

// When a contact cause ends (hysteresis): a contact that went above its threshold stays a present cause until
// its force has stayed below threshold x (1 - fraction) for hold_ns (on the aggregator's clock), or the decoder
// released it (a released frame, or a healthy heartbeat out of contact). A contact hovering at the threshold is
// therefore one cause (one epoch), not one per crossing. It never delays a STOP: only the end of a cause.
struct ContactRelease {
  float fraction = 0.1f;                   // 0 <= fraction < 1
  std::int64_t hold_ns = 100'000'000;      // 0 .. 60 s
  std::string source;                      // why these numbers (the scene's `source:`; empty: the defaults)
};

struct RegionConfig {
  std::string name;         // e.g. "forearm"
  float threshold_n = 0;    // a contact above this stops (at or below never does); > 0 and finite
  std::string source;       // where the number comes from (FACTS.md: ISO/TS 15066 values vary by source)
  ContactRelease release{};  // the scene's safety.contact_release, or the region's own `release:`
};

// What the aggregator checks of its input before the policy judges it (docs/safety.md, "Bad input"). The
// policy uses negative_force_tolerance_n; aggregate::Core applies the rest.
struct InputLimits {
  // A force in [-tolerance, 0) is decoder noise around zero and is judged as 0 N; below -tolerance it is a
  // doubt (Rejection::kNegativeForce: STOP).
  float negative_force_tolerance_n = 0.05f;
  // A contact frame's or joint state's t_ns further than this from its arrival (either way) is refused
  // (frames: a doubt, STOP; joint states: rejected and counted, never used).
  std::int64_t max_time_skew_ns = 2'000'000'000;
  // A located position this far outside the spec's Y / R extents is off the patch (a doubt, STOP).
  double position_tolerance_y_mm = 5.0;
  double position_tolerance_r_deg = 5.0;
  // Hello expectations (0 / empty: the scene states none, and nothing is checked).
  double sample_rate_hz = 0;              // PatchHello.sample_rate_hz must match within 0.1 %
  std::string decoder_config_sha256;      // PatchHello.decoder_config.config_sha256 must equal it
  std::string source;                     // why these numbers (the scene's `source:` fields, joined)
};

struct PatchConfig {
  std::string id;                                // the scene's patch id
  std::string region;                            // the region its contacts are judged in (a RegionConfig name)
  std::int64_t silence_deadline_ns = 30'000'000;  // silent longer than this (strictly) is a fault: 3 heartbeats
};

// What the scene requires of its patches' sensitivity maps (the scene's `safety.coverage`; docs/coverage.md):
// a press of press_factor x a region's threshold must stop anywhere on the region's covered surface, which is
// its patches' surface less the accepted uncovered bands. Checked at load, never per frame.
struct CoverageConfig {
  double press_factor = 1.5;  // the issue 16 target: grid presses at 1.5x the threshold stop
  std::string source;         // the scene's `source:` (empty: the default)
  struct Band {
    std::string name, patch;  // unique name; the scene's patch id (empty: every patch of the scene)
    double y_min_mm = 0, y_max_mm = 0, r_min_deg = 0, r_max_deg = 0;  // patch frame, inclusive
    std::string source;       // why the scene accepts it
  };
  std::vector<Band> accepted_uncovered;
};

struct Config {
  std::vector<RegionConfig> regions;
  std::vector<PatchConfig> patches;             // at least one; ids unique
  bool joint_states_required = true;             // false: a scene without a robot (joint states are ignored)
  std::int64_t joint_state_max_age_ns = 50'000'000;  // older than this (strictly, by arrival) is stale
  // Before a reset: every patch continuously healthy for at least this long (200 ms = 20 heartbeats).
  std::int64_t healthy_before_reset_ns = 200'000'000;
  // true (the default, the contract in docs/contracts.md): every new cause while latched also takes
  //   epoch + 1 and becomes the published cause, so a reset naming the epoch an operator saw is refused once
  //   anything new has happened (the more cautious reading: the operator must see the newest cause).
  // false: a new cause while latched (same or lower severity) is recorded and keeps the epoch; only a new
  //   latch (CLEAR -> STOP/FAULT, the STOP -> FAULT escalation, Shutdown) takes epoch + 1.
  bool new_epoch_per_cause = true;
  InputLimits input{};
  // The safety layer on the decoder links (docs/safety-channel.md; the scene's `link_layer`).
  struct LinkLayer {
    std::int64_t freshness_budget_ns = 20'000'000;  // a patch message older than this: FAULT kPatchLate
    std::int64_t error_window_ns = 60'000'000'000;  // the error-rate rule's window ...
    int error_limit = 2;                            // ... and how many errors in it latch FAULT kLinkErrors
    std::string source;                             // the scene's `source:` (empty: these defaults)
  } link{};
  CoverageConfig coverage{};
  // The stop rule (the scene's `stop_rule`; docs/safety.md, "The stop rule"): a contact is judged at
  // force + sd_k x force_sd (JudgedForce), so sd_k > 0 stops earlier on an uncertain reading and sd_k < 0 asks
  // the reading to clear the threshold by |sd_k| sigma. 0 (the default): the force alone, as always.
  struct StopRule {
    float sd_k = 0.0f;         // -3 .. 3
    float max_sd_n = 0.5f;     // sd_k < 0: an sd above this is not trusted and never lowers (a broken sd)
    std::string source;        // the scene's `source:` (empty: the default)
  } stop_rule{};
  // `safety.seam_sum`: judge a contact that one touch on its seam may explain on the sum of both sides' forces
  // (aggregate::Core::JudgeOnSeam, docs/fusion.md "The stop on a seam"). Off by default: it stops more seam
  // probes but also two separate light touches near the seam (docs/experiments/seam.md).
  struct SeamSum {
    bool enabled = false;
    std::string source;
  } seam_sum{};
};

// The force a contact is judged at against its threshold: force_n + sd_k x sd. A non-finite or negative sd
// counts as infinite when sd_k > 0 (a doubt stops). When sd_k < 0 it never lowers: an sd that is not finite,
// negative or above max_sd_n, and a force that is a lower bound (an over-range contact, a raised two-touch
// force), are judged as the force; otherwise it lowers by at most |sd_k| x max_sd_n (Validate keeps that at
// most half of every threshold). The result is never below 0. The end of a cause is judged on the larger of
// the force and this (a lowering rule never ends a STOP early).
float JudgedForce(float force_n, float force_sd_n, bool over_range, const Config::StopRule& rule) noexcept;

// Throws InputError naming the field and the value: "safety.patches[2].id ('forearm') is a duplicate".
void Validate(const Config& c);

// --- Events ---------------------------------------------------------------------------------------------------

// A heartbeat's safety content (ruffini.v1.Heartbeat).
struct Heartbeat {
  bool healthy = false;                                   // false by default: not healthy
  PatchFaultCode active_fault = PatchFaultCode::kUnspecified;  // healthy with a fault in force reads as unhealthy
  bool in_contact = false;                                // false ends a contact the policy still holds
};

// One patch contact frame (ruffini.v1.PatchContact, plus where the aggregator placed it).
struct Contact {
  float force_n = 0;              // >= 0 and finite, else refused (and a STOP)
  std::string_view region{};      // the body region to judge it in; empty: the patch's configured region
  bool released = false;          // the frame that ends the contact
  std::int64_t t_ns = 0;          // when the frame was measured (interrogator clock); 0: now_ns
  std::optional<std::array<double, 3>> p_bc_m{};  // where on the body (base frame B, m), when placed
  float force_sd_n = 0;           // the decoder's 1-sigma (0: not calibrated); used by Config::stop_rule only
  bool over_range = false;        // force_n is a lower bound: over range, or a two-touch frame's raised force
                                  // (never lowered by the stop rule)
  bool saturated = false;         // PatchContact.over_range: more load than the decoder can read; a STOP at any
                                  // threshold (force_n is only its lower bound)
  // The caller found the frame untrustworthy (kBadPosition, kBadCovariance, kImplausibleTime): refused as a
  // doubt (STOP), counted under that rejection; p_bc_m is then ignored.
  Rejection doubt = Rejection::kNone;
  // Information for the cause's text only (never judged): force_n is the sum of this patch's reading
  // (seam_own_force_n) and the newest one of patch seam_partner across their seam (seam_partner_force_n;
  // aggregate::Core::JudgeOnSeam); kNoPatch: force_n is this patch's own. faint: the decoder flagged the frame
  // faint (PatchContact.faint).
  std::int32_t seam_partner = kNoPatch;
  float seam_own_force_n = 0, seam_partner_force_n = 0;
  bool faint = false;
};

struct ResetRequest {
  std::uint64_t stop_epoch = 0;  // the epoch the operator saw
  bool authorized = false;        // the service checked the caller's identity (TLS client certificate)
  bool other_run = false;         // the request names another aggregator run (or none): kWrongRun
};

// --- Outputs --------------------------------------------------------------------------------------------------

// ruffini.v1.SafetyCause. Indices name the Policy's config (Policy::patch_id, Policy::region_name).
struct Cause {
  CauseKind kind = CauseKind::kNone;
  std::int32_t patch = kNoPatch;      // index into Config.patches (kNoPatch: none)
  std::int32_t region = kNoRegion;    // index into Config.regions (kContact with a known region)
  float force_n = 0;                  // kContact: the force as received (NaN stays NaN: a doubt)
  float threshold_n = 0;              // kContact: the threshold it was judged against (0: none known)
  float judged_n = 0;                 // kContact: what was judged (Config::stop_rule: force + sd_k x sd)
  std::optional<std::array<double, 3>> p_bc_m{};  // kContact: where, when placed
  PatchFaultCode patch_fault = PatchFaultCode::kUnspecified;  // kPatchFault
  Rejection doubt = Rejection::kNone;  // set when the cause is a refused input (a doubt, not a measurement)
  std::int64_t t_ns = 0;               // the evidence: the contact frame's t_ns, else now_ns when detected
  // kContact, from Contact (information, in Describe's text): force_n was a seam sum of this patch's reading
  // and seam_partner's; the frame was flagged faint.
  std::int32_t seam_partner = kNoPatch;
  float seam_own_force_n = 0, seam_partner_force_n = 0;
  bool faint = false;
  // Field by field, a NaN force equal to a NaN force (a state compared with its copy is equal).
  bool operator==(const Cause& o) const noexcept;
};

// ruffini.v1.SafetyState without aggregator_start_t_ns (the service's).
struct SafetyState {
  State state = State::kFault;
  std::uint64_t stop_epoch = 1;   // only grows; the start-up latch is 1
  std::uint64_t seq = 1;          // +1 per publication: every change, every Publish()
  Cause cause{};                  // what latched the current epoch (kNone when CLEAR)
  std::int64_t changed_t_ns = 0;  // when `state` last changed
  std::int64_t published_t_ns = 0;
  bool operator==(const SafetyState&) const = default;
};

// One scene patch as the policy sees it (the safety part of ruffini.v1.PatchStatus).
struct PatchState {
  LinkState link = LinkState::kDisconnected;
  bool ever_connected = false;          // false: missing (never connected); true: silent after a disconnect
  std::int64_t last_seen_t_ns = 0;      // newest accepted message (now_ns); 0: never
  std::optional<std::int64_t> healthy_since_t_ns{};  // continuously healthy since (empty: not healthy)
  bool fault_in_force = false;          // a PatchFault or an unhealthy heartbeat, until a healthy heartbeat
  PatchFaultCode fault = PatchFaultCode::kUnspecified;  // the newest fault code
  bool protocol_fault = false;          // until the next accepted hello
  CauseKind protocol_kind = CauseKind::kPatchProtocol;  // which: protocol, late, or link errors
  bool contact_over = false;            // a contact above threshold (or doubtful) and not released yet
  float contact_force_n = 0;            // the newest contact's force (NaN when it was NaN)
  // While contact_over: since when the force has stayed below the region's release level (empty: it has
  // not); the cause ends once this is ContactRelease.hold_ns old.
  std::optional<std::int64_t> contact_below_since_t_ns{};
  bool operator==(const PatchState& o) const noexcept;  // NaN equals NaN, as for Cause
};

// Plain counters; a service copies them into its metric handles off the hot thread.
struct Counters {
  std::uint64_t stops = 0;        // entries into STOP (from CLEAR)
  std::uint64_t faults = 0;       // entries into FAULT (start-up, from CLEAR, escalations from STOP)
  std::uint64_t escalations = 0;  // STOP -> FAULT (also in faults)
  std::uint64_t epochs = 0;       // stop_epoch increments (start-up excluded)
  std::uint64_t causes_while_latched = 0;   // new causes that arrived while already latched
  std::array<std::uint64_t, kCauseKindCount> causes{};  // new causes by kind (latching or not)
  std::uint64_t resets_accepted = 0;
  std::array<std::uint64_t, kResetRefusalCount> resets_refused{};  // by ResetRefusal ([0] unused)
  std::array<std::uint64_t, kRejectionCount> rejections{};         // by Rejection ([0] unused)
  std::uint64_t publications = 0;  // seq increments (state changes and Publish)
  std::uint64_t events_dropped = 0;  // events not taken before kEventCapacity more arrived
  bool operator==(const Counters&) const = default;
};

// A change worth one log line (docs/safety.md, "Events"): every latch, escalation, new epoch while latched,
// shutdown and reset (accepted or refused). The Data keeps the newest kEventCapacity until the caller takes
// them (Data::ClearEvents); older ones are counted in Counters.events_dropped, never blocking an event.
enum class EventType : std::uint8_t {
  kLatch,          // CLEAR -> STOP or FAULT (a new epoch)
  kEscalation,     // STOP -> FAULT (a new epoch)
  kNewEpoch,       // a new cause while latched took a new epoch (Config.new_epoch_per_cause)
  kShutdown,       // FAULT shutting down (a new epoch)
  kResetAccepted,  // -> CLEAR
  kResetRefused,   // nothing changed; `reset_refusal` says why
};
std::string_view EventTypeName(EventType t) noexcept;

struct Event {
  EventType type = EventType::kLatch;
  State state = State::kFault;         // the state after the event
  std::uint64_t stop_epoch = 0;        // the epoch after the event
  Cause cause{};                       // the cause latched (latches), or the cause that blocked a reset
  ResetRefusal reset_refusal = ResetRefusal::kNone;
  std::uint64_t reset_epoch = 0;       // resets: the epoch the request named
  std::int64_t t_ns = 0;               // now_ns of the event
  bool operator==(const Event&) const = default;
};
inline constexpr std::size_t kEventCapacity = 16;

// What one event did.
struct Step {
  bool publish = false;                   // state() changed (seq +1): publish it now
  Rejection rejection = Rejection::kNone;  // the event was refused as input (and latched a doubt)
};

struct ResetResult {
  bool accepted = false;
  ResetRefusal reason = ResetRefusal::kNone;
  Cause blocking{};                    // kCausePresent: the first cause found (scene order); kNotHealthyLongEnough:
                                       // the patch (kind kNone) or the joint states (kJointStatesStale)
  std::int64_t healthy_for_ns = 0;     // kNotHealthyLongEnough: how long that patch has been healthy
  std::uint64_t current_epoch = 0;     // the epoch in force after the request
};

class Policy;

// What changes. Sized once from the Policy (the only allocation); holds no reference to it.
class Data {
 public:
  // Start-up: FAULT, cause kStartup (patch: the first scene patch), stop_epoch 1, seq 1, at start_ns.
  Data(const Policy& policy, std::int64_t start_ns);

  [[nodiscard]] const SafetyState& state() const noexcept { return state_; }
  [[nodiscard]] const Counters& counters() const noexcept { return counters_; }
  [[nodiscard]] std::span<const PatchState> patches() const noexcept { return patches_; }
  // The newest cause, latching or only recorded (the start-up cause at first).
  [[nodiscard]] const Cause& latest_cause() const noexcept { return latest_cause_; }
  [[nodiscard]] bool shutting_down() const noexcept { return shutting_down_; }
  [[nodiscard]] std::optional<std::int64_t> joint_state_t_ns() const noexcept { return joint_last_ns_; }
  // The newest now_ns accepted: time never goes backwards below it.
  [[nodiscard]] std::int64_t now_ns() const noexcept { return now_ns_; }
  // The events since the last ClearEvents (oldest first), for the caller's log.
  [[nodiscard]] std::span<const Event> events() const noexcept { return {events_.data(), event_count_}; }
  void ClearEvents() noexcept { event_count_ = 0; }

  bool operator==(const Data&) const = default;

 private:
  friend class Policy;
  SafetyState state_{};
  Cause latest_cause_{};
  Counters counters_{};
  std::vector<PatchState> patches_;
  std::optional<std::int64_t> joint_last_ns_{};
  bool joint_stale_ = false;      // latched once per staleness (a fresh state re-arms it)
  bool shutting_down_ = false;
  bool dirty_ = false;            // the current event changed state_ (one seq per event)
  std::int64_t now_ns_ = 0;
  Cause last_rejection_{};        // the newest refused input's cause, until a reset clears the latch
  std::array<Event, kEventCapacity> events_{};
  std::size_t event_count_ = 0;
  void Record(const Event& e) noexcept;
};

// What the scene fixes. Immutable after construction.
class Policy {
 public:
  explicit Policy(Config config);  // Validate()s; throws InputError

  [[nodiscard]] const Config& config() const noexcept { return config_; }
  [[nodiscard]] std::size_t patch_count() const noexcept { return config_.patches.size(); }
  // kNoPatch / kNoRegion when not found. No allocation.
  [[nodiscard]] std::int32_t FindPatch(std::string_view id) const noexcept;
  [[nodiscard]] std::int32_t FindRegion(std::string_view name) const noexcept;
  [[nodiscard]] std::string_view patch_id(std::int32_t patch) const noexcept;    // "" for kNoPatch
  [[nodiscard]] std::string_view region_name(std::int32_t region) const noexcept;  // "" for kNoRegion

  // Every event first refuses time going backwards, then checks every deadline (as Tick does), then
  // applies itself. All: real-time safe (no allocation, no lock, no throw).

  // The service accepted the patch's hello: live, not yet healthy (a healthy heartbeat makes it so).
  // Clears a protocol fault. A second hello on a live link (ResendHello) keeps its health.
  Step OnHelloAccepted(Data& d, std::string_view patch_id, std::int64_t now_ns) const noexcept;
  // The service refused the patch's hello: the patch stays (or becomes) missing: FAULT kPatchMissing.
  Step OnHelloRefused(Data& d, std::string_view patch_id, std::int64_t now_ns) const noexcept;
  // Liveness. Not healthy (or healthy with a fault in force): FAULT kPatchFault, and health restarts.
  Step OnHeartbeat(Data& d, std::string_view patch_id, const Heartbeat& hb, std::int64_t now_ns) const noexcept;
  // Liveness. Above its region's threshold (strictly): STOP kContact, whatever else is going on.
  Step OnContact(Data& d, std::string_view patch_id, const Contact& c, std::int64_t now_ns) const noexcept;
  // FAULT kPatchFault; the fault is in force until a healthy heartbeat.
  Step OnPatchFault(Data& d, std::string_view patch_id, PatchFaultCode code, std::int64_t now_ns) const noexcept;
  // FAULT kPatchProtocol (or the safety layer's kPatchLate / kLinkErrors, as `kind` says); in force until the
  // next accepted hello.
  Step OnProtocolError(Data& d, std::string_view patch_id, std::int64_t now_ns,
                       CauseKind kind = CauseKind::kPatchProtocol) const noexcept;
  // The patch's stream ended: FAULT kPatchSilent.
  Step OnDisconnect(Data& d, std::string_view patch_id, std::int64_t now_ns) const noexcept;
  // An accepted joint state arrived (staleness is measured by arrival, on the aggregator's clock).
  Step OnJointState(Data& d, std::int64_t now_ns) const noexcept;
  // Deadlines only: a patch silent past its deadline, joint states older than the limit.
  Step Tick(Data& d, std::int64_t now_ns) const noexcept;
  // A periodic publication: Tick, then seq +1 (once: a change found by the Tick is that publication).
  // Always returns publish = true, also when now_ns went backwards (the FAULT it latches is that publication,
  // published at the newest good time).
  Step Publish(Data& d, std::int64_t now_ns) const noexcept;
  // Clear the latch named by r.stop_epoch. Checks in this order: now_ns not backwards (kInvalidRequest),
  // authorized, this run (kWrongRun), not shutting down, latched, the epoch, every cause gone (a patch past its deadline counts as
  // silent), every patch healthy long enough. A refused reset changes nothing but the refusal counter; an
  // accepted one makes the state CLEAR (same epoch; the next latch takes epoch + 1).
  ResetResult Reset(Data& d, const ResetRequest& r, std::int64_t now_ns) const noexcept;
  // The aggregator is shutting down: FAULT kShuttingDown under a new epoch, forever. Idempotent.
  Step Shutdown(Data& d, std::int64_t now_ns) const noexcept;

 private:
  enum class Severity : std::uint8_t { kStop, kFault };
  bool Advance(Data& d, std::int64_t now_ns) const noexcept;
  Rejection Backwards(Data& d) const noexcept;
  Rejection Reject(Data& d, Rejection why, Cause cause, Severity severity) const noexcept;
  void CheckDeadlines(Data& d) const noexcept;
  void Seen(Data& d, std::size_t patch) const noexcept;
  void Latch(Data& d, const Cause& cause, Severity severity, bool is_new) const noexcept;
  Step Finish(Data& d, Step step) const noexcept;
  Step Refuse(Data& d, Rejection why, Cause cause, Severity severity) const noexcept;
  [[nodiscard]] Cause FirstCausePresent(const Data& d, std::int64_t now_ns) const noexcept;
  [[nodiscard]] bool ContactPresent(const PatchState& p, std::size_t patch, std::int64_t now_ns) const noexcept;
  [[nodiscard]] const ContactRelease& ReleaseOf(std::size_t patch) const noexcept;

  Config config_;
};

// --- Names (stable snake_case: metric label values; the proto's names in lower case without the prefix) -----
std::string_view StateName(State s) noexcept;
std::string_view CauseKindName(CauseKind k) noexcept;
std::string_view ResetRefusalName(ResetRefusal r) noexcept;
std::string_view LinkStateName(LinkState l) noexcept;
std::string_view PatchFaultCodeName(PatchFaultCode c) noexcept;
std::string_view RejectionName(Rejection r) noexcept;

// For logs and the ResetStop response's message (allocate; not for the hot path).
std::string Describe(const Policy& p, const Cause& c);
std::string Describe(const Policy& p, const ResetResult& r);

}  // namespace ruffini::safety
