#include "ruffini/safety/policy.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <utility>

#include "ruffini/error.h"

namespace ruffini::safety {
namespace {

bool HasStream(LinkState l) noexcept {
  return l == LinkState::kHealthy || l == LinkState::kUnhealthy || l == LinkState::kSilent;
}
bool Live(LinkState l) noexcept { return l == LinkState::kHealthy || l == LinkState::kUnhealthy; }

bool SameForce(float a, float b) noexcept { return a == b || (std::isnan(a) && std::isnan(b)); }

std::string Quoted(std::string_view s) { return "('" + std::string(s) + "')"; }

}  // namespace

bool Cause::operator==(const Cause& o) const noexcept {
  return kind == o.kind && patch == o.patch && region == o.region && SameForce(force_n, o.force_n) &&
         threshold_n == o.threshold_n && SameForce(judged_n, o.judged_n) && p_bc_m == o.p_bc_m && patch_fault == o.patch_fault && doubt == o.doubt &&
         t_ns == o.t_ns && seam_partner == o.seam_partner && SameForce(seam_own_force_n, o.seam_own_force_n) &&
         SameForce(seam_partner_force_n, o.seam_partner_force_n) && faint == o.faint;
}

bool PatchState::operator==(const PatchState& o) const noexcept {
  return link == o.link && ever_connected == o.ever_connected && last_seen_t_ns == o.last_seen_t_ns &&
         healthy_since_t_ns == o.healthy_since_t_ns && fault_in_force == o.fault_in_force && fault == o.fault &&
         protocol_fault == o.protocol_fault && protocol_kind == o.protocol_kind && contact_over == o.contact_over &&
         SameForce(contact_force_n, o.contact_force_n) && contact_below_since_t_ns == o.contact_below_since_t_ns;
}

// --- Config ---------------------------------------------------------------------------------------------------

void Validate(const Config& c) {
  auto fail = [](const std::string& what) { throw InputError("safety." + what); };
  if (c.regions.empty()) fail("regions is empty: every patch's contacts are judged in a body region");
  if (!(c.stop_rule.sd_k >= -3.0f && c.stop_rule.sd_k <= 3.0f) ||
      !(c.stop_rule.max_sd_n > 0.0f && c.stop_rule.max_sd_n <= 10.0f)) {
    fail("stop_rule: sd_k must be -3..3 and max_sd_n above 0 and at most 10 N");
  }
  if (c.stop_rule.sd_k < 0.0f) {
    const float lowering = -c.stop_rule.sd_k * c.stop_rule.max_sd_n;
    for (const RegionConfig& r : c.regions) {
      if (lowering > 0.5f * r.threshold_n) {
        std::ostringstream s;
        s << "stop_rule: the largest lowering |sd_k| x max_sd_n (" << lowering << " N) must be at most half of every "
          << "region's threshold (region " << Quoted(r.name) << ": " << r.threshold_n << " N)";
        fail(s.str());
      }
    }
  }
  for (std::size_t i = 0; i < c.regions.size(); ++i) {
    const RegionConfig& r = c.regions[i];
    const std::string at = "regions[" + std::to_string(i) + "]";
    if (r.name.empty()) fail(at + ".name is empty");
    for (std::size_t j = 0; j < i; ++j) {
      if (c.regions[j].name == r.name) fail(at + ".name " + Quoted(r.name) + " is a duplicate");
    }
    if (!std::isfinite(r.threshold_n) || r.threshold_n <= 0.0f) {
      std::ostringstream s;
      s << at << ".threshold_n (" << r.threshold_n << ") must be a finite force above 0 N";
      fail(s.str());
    }
    if (!(r.release.fraction >= 0.0f && r.release.fraction < 1.0f)) {
      std::ostringstream s;
      s << at << ".release.fraction (" << r.release.fraction << ") must lie in 0..1 (1 excluded)";
      fail(s.str());
    }
    if (r.release.hold_ns < 0 || r.release.hold_ns > 60'000'000'000) {
      fail(at + ".release.hold_ns (" + std::to_string(r.release.hold_ns) + ") must lie in 0..60 s");
    }
  }
  const InputLimits& in = c.input;
  if (!(in.negative_force_tolerance_n >= 0.0f && in.negative_force_tolerance_n <= 1.0f)) {
    std::ostringstream s;
    s << "input.negative_force_tolerance_n (" << in.negative_force_tolerance_n << ") must lie in 0..1 N";
    fail(s.str());
  }
  if (in.max_time_skew_ns <= 0 || in.max_time_skew_ns > 3'600'000'000'000) {
    fail("input.max_time_skew_ns (" + std::to_string(in.max_time_skew_ns) + ") must lie in 1 ns..1 h");
  }
  if (!(in.position_tolerance_y_mm >= 0.0 && in.position_tolerance_y_mm <= 100.0) ||
      !(in.position_tolerance_r_deg >= 0.0 && in.position_tolerance_r_deg <= 90.0)) {
    std::ostringstream s;
    s << "input.position_tolerance (" << in.position_tolerance_y_mm << " mm, " << in.position_tolerance_r_deg
      << " deg) must lie in 0..100 mm and 0..90 deg";
    fail(s.str());
  }
  if (!(in.sample_rate_hz == 0.0 || (in.sample_rate_hz >= 1.0 && in.sample_rate_hz <= 1e6))) {
    std::ostringstream s;
    s << "input.sample_rate_hz (" << in.sample_rate_hz << ") must be 0 (not checked) or 1..1e6 Hz";
    fail(s.str());
  }
  if (c.patches.empty()) fail("patches is empty: a scene names at least one patch");
  for (std::size_t i = 0; i < c.patches.size(); ++i) {
    const PatchConfig& p = c.patches[i];
    const std::string at = "patches[" + std::to_string(i) + "]";
    if (p.id.empty()) fail(at + ".id is empty");
    for (std::size_t j = 0; j < i; ++j) {
      if (c.patches[j].id == p.id) fail(at + ".id " + Quoted(p.id) + " is a duplicate");
    }
    bool known = false;
    for (const RegionConfig& r : c.regions) known = known || r.name == p.region;
    if (!known) fail(at + ".region " + Quoted(p.region) + " names no region in safety.regions");
    if (p.silence_deadline_ns <= 0) {
      fail(at + ".silence_deadline_ns (" + std::to_string(p.silence_deadline_ns) + ") must be above 0");
    }
  }
  if (c.joint_state_max_age_ns <= 0) {
    fail("joint_state_max_age_ns (" + std::to_string(c.joint_state_max_age_ns) + ") must be above 0");
  }
  if (c.healthy_before_reset_ns < 0) {
    fail("healthy_before_reset_ns (" + std::to_string(c.healthy_before_reset_ns) + ") must be 0 or more");
  }
}

// --- Data -----------------------------------------------------------------------------------------------------

Data::Data(const Policy& policy, std::int64_t start_ns) : patches_(policy.patch_count()), now_ns_(start_ns) {
  const Cause startup{.kind = CauseKind::kStartup, .t_ns = start_ns};
  state_ = SafetyState{.state = State::kFault,
                       .stop_epoch = 1,
                       .seq = 1,
                       .cause = startup,
                       .changed_t_ns = start_ns,
                       .published_t_ns = start_ns};
  latest_cause_ = startup;
  counters_.faults = 1;
  counters_.causes[static_cast<std::size_t>(CauseKind::kStartup)] = 1;
  counters_.publications = 1;
}

void Data::Record(const Event& e) noexcept {
  if (event_count_ == events_.size()) {
    // Full: the oldest is dropped (counted), so the newest (the one in force) is always there.
    for (std::size_t i = 1; i < events_.size(); ++i) events_[i - 1] = events_[i];
    --event_count_;
    ++counters_.events_dropped;
  }
  events_[event_count_++] = e;
}

// --- Policy: lookups --------------------------------------------------------------------------------------------

Policy::Policy(Config config) : config_(std::move(config)) { Validate(config_); }

std::int32_t Policy::FindPatch(std::string_view id) const noexcept {
  for (std::size_t i = 0; i < config_.patches.size(); ++i) {
    if (config_.patches[i].id == id) return static_cast<std::int32_t>(i);
  }
  return kNoPatch;
}

std::int32_t Policy::FindRegion(std::string_view name) const noexcept {
  for (std::size_t i = 0; i < config_.regions.size(); ++i) {
    if (config_.regions[i].name == name) return static_cast<std::int32_t>(i);
  }
  return kNoRegion;
}

std::string_view Policy::patch_id(std::int32_t patch) const noexcept {
  if (patch < 0 || static_cast<std::size_t>(patch) >= config_.patches.size()) return {};
  return config_.patches[static_cast<std::size_t>(patch)].id;
}

std::string_view Policy::region_name(std::int32_t region) const noexcept {
  if (region < 0 || static_cast<std::size_t>(region) >= config_.regions.size()) return {};
  return config_.regions[static_cast<std::size_t>(region)].name;
}

// --- Policy: the latch ------------------------------------------------------------------------------------------

// A cause arrived. is_new: it was not already present (a contact still above threshold frame after frame,
// an unhealthy heartbeat after an unhealthy heartbeat, are one cause). While CLEAR every cause latches,
// new or not, so a bookkeeping slip can never leave a present cause unlatched.
void Policy::Latch(Data& d, const Cause& cause, Severity severity, bool is_new) const noexcept {
  SafetyState& s = d.state_;
  if (!is_new && s.state != State::kClear) return;
  Counters& n = d.counters_;
  ++n.causes[static_cast<std::size_t>(cause.kind)];
  d.latest_cause_ = cause;
  if (d.shutting_down_) {  // FAULT for good; the published cause stays kShuttingDown
    ++n.causes_while_latched;
    return;
  }
  EventType type = EventType::kLatch;
  if (s.state == State::kClear) {
    s.state = severity == Severity::kStop ? State::kStop : State::kFault;
    ++(severity == Severity::kStop ? n.stops : n.faults);
  } else if (s.state == State::kStop && severity == Severity::kFault) {
    s.state = State::kFault;  // escalation: a new latch, never the other way
    ++n.faults;
    ++n.escalations;
    type = EventType::kEscalation;
  } else {
    ++n.causes_while_latched;
    if (!config_.new_epoch_per_cause) return;  // recorded (counters, latest_cause); the epoch stays
    ++s.stop_epoch;
    ++n.epochs;
    s.cause = cause;
    d.dirty_ = true;
    d.Record({.type = EventType::kNewEpoch, .state = s.state, .stop_epoch = s.stop_epoch, .cause = cause,
              .t_ns = d.now_ns_});
    return;
  }
  ++s.stop_epoch;
  ++n.epochs;
  s.cause = cause;
  s.changed_t_ns = d.now_ns_;
  d.dirty_ = true;
  d.Record({.type = type, .state = s.state, .stop_epoch = s.stop_epoch, .cause = cause, .t_ns = d.now_ns_});
}

Step Policy::Finish(Data& d, Step step) const noexcept {
  if (d.dirty_) {
    d.dirty_ = false;
    ++d.state_.seq;
    ++d.counters_.publications;
    d.state_.published_t_ns = d.now_ns_;
    step.publish = true;
  }
  return step;
}

// Counts the rejection and latches the doubt; the caller publishes (Finish) once.
// The same rejection again (same kind, patch and reason as the previous refused input since the last reset)
// is the same cause: counted, no new epoch (a stream of refused heartbeats must not take an epoch each).
// While CLEAR it latches whatever (Latch), so a doubt is never ignored.
Rejection Policy::Reject(Data& d, Rejection why, Cause cause, Severity severity) const noexcept {
  ++d.counters_.rejections[static_cast<std::size_t>(why)];
  cause.doubt = why;
  if (cause.t_ns == 0) cause.t_ns = d.now_ns_;
  const Cause& last = d.last_rejection_;
  const bool same = last.doubt == why && last.kind == cause.kind && last.patch == cause.patch;
  d.last_rejection_ = cause;
  Latch(d, cause, severity, !same);
  return why;
}

Step Policy::Refuse(Data& d, Rejection why, Cause cause, Severity severity) const noexcept {
  return Finish(d, Step{.rejection = Reject(d, why, cause, severity)});
}

// Time first: an event from the past is refused (the deadlines cannot be judged on it) and is a FAULT;
// it is not applied. Then every deadline at the new now.
bool Policy::Advance(Data& d, std::int64_t now_ns) const noexcept {
  if (now_ns < d.now_ns_) return false;
  d.now_ns_ = now_ns;
  CheckDeadlines(d);
  return true;
}

Rejection Policy::Backwards(Data& d) const noexcept {
  return Reject(d, Rejection::kTimeBackwards, Cause{.kind = CauseKind::kInternal}, Severity::kFault);
}

void Policy::CheckDeadlines(Data& d) const noexcept {
  const std::int64_t now = d.now_ns_;
  for (std::size_t i = 0; i < d.patches_.size(); ++i) {
    PatchState& p = d.patches_[i];
    if (Live(p.link) && now - p.last_seen_t_ns > config_.patches[i].silence_deadline_ns) {
      p.link = LinkState::kSilent;
      p.healthy_since_t_ns.reset();
      Latch(d, Cause{.kind = CauseKind::kPatchSilent, .patch = static_cast<std::int32_t>(i), .t_ns = now},
            Severity::kFault, true);
    }
  }
  if (config_.joint_states_required && d.joint_last_ns_ && !d.joint_stale_ &&
      now - *d.joint_last_ns_ > config_.joint_state_max_age_ns) {
    d.joint_stale_ = true;
    Latch(d, Cause{.kind = CauseKind::kJointStatesStale, .t_ns = now}, Severity::kFault, true);
  }
}

// Any message on a stream is liveness; a silent link that speaks again is live again (not healthy until
// a healthy heartbeat, and the latch it caused stays).
void Policy::Seen(Data& d, std::size_t patch) const noexcept {
  PatchState& p = d.patches_[patch];
  p.last_seen_t_ns = d.now_ns_;
  if (p.link == LinkState::kSilent) p.link = LinkState::kUnhealthy;
}

// --- Policy: events ---------------------------------------------------------------------------------------------

Step Policy::OnHelloAccepted(Data& d, std::string_view patch_id, std::int64_t now_ns) const noexcept {
  if (!Advance(d, now_ns)) return Finish(d, {.rejection = Backwards(d)});
  const std::int32_t i = FindPatch(patch_id);
  if (i == kNoPatch) return Refuse(d, Rejection::kUnknownPatch, Cause{.kind = CauseKind::kInternal}, Severity::kFault);
  PatchState& p = d.patches_[static_cast<std::size_t>(i)];
  p.ever_connected = true;
  p.protocol_fault = false;  // a fresh hello starts a trustworthy stream
  if (!Live(p.link)) {
    p.link = LinkState::kUnhealthy;  // live, not healthy until a healthy heartbeat
    p.healthy_since_t_ns.reset();
  }
  Seen(d, static_cast<std::size_t>(i));
  return Finish(d, {});
}

Step Policy::OnHelloRefused(Data& d, std::string_view patch_id, std::int64_t now_ns) const noexcept {
  if (!Advance(d, now_ns)) return Finish(d, {.rejection = Backwards(d)});
  const std::int32_t i = FindPatch(patch_id);
  if (i == kNoPatch) return Refuse(d, Rejection::kUnknownPatch, Cause{.kind = CauseKind::kInternal}, Severity::kFault);
  PatchState& p = d.patches_[static_cast<std::size_t>(i)];
  const bool is_new = p.link != LinkState::kRefused;
  p.link = LinkState::kRefused;
  p.healthy_since_t_ns.reset();
  Latch(d, Cause{.kind = CauseKind::kPatchMissing, .patch = i, .t_ns = now_ns}, Severity::kFault, is_new);
  return Finish(d, {});
}

Step Policy::OnHeartbeat(Data& d, std::string_view patch_id, const Heartbeat& hb,
                         std::int64_t now_ns) const noexcept {
  if (!Advance(d, now_ns)) return Finish(d, {.rejection = Backwards(d)});
  const std::int32_t i = FindPatch(patch_id);
  if (i == kNoPatch) return Refuse(d, Rejection::kUnknownPatch, Cause{.kind = CauseKind::kInternal}, Severity::kFault);
  PatchState& p = d.patches_[static_cast<std::size_t>(i)];
  if (!HasStream(p.link)) {
    return Refuse(d, Rejection::kNotConnected, Cause{.kind = CauseKind::kInternal, .patch = i}, Severity::kFault);
  }
  Seen(d, static_cast<std::size_t>(i));
  const bool healthy = hb.healthy && hb.active_fault == PatchFaultCode::kUnspecified;
  if (healthy) {
    p.fault_in_force = false;
    if (!hb.in_contact) {  // the decoder's gate is closed: the contact has ended
      p.contact_over = false;
      p.contact_below_since_t_ns.reset();
    }
    if (p.protocol_fault) {
      p.link = LinkState::kUnhealthy;
    } else {
      p.link = LinkState::kHealthy;
      if (!p.healthy_since_t_ns) p.healthy_since_t_ns = now_ns;
    }
    return Finish(d, {});
  }
  const bool is_new = !p.fault_in_force;
  p.fault_in_force = true;
  p.fault = hb.active_fault;
  p.link = LinkState::kUnhealthy;
  p.healthy_since_t_ns.reset();
  Latch(d, Cause{.kind = CauseKind::kPatchFault, .patch = i, .patch_fault = hb.active_fault, .t_ns = now_ns},
        Severity::kFault, is_new);
  return Finish(d, {});
}

float JudgedForce(float force_n, float force_sd_n, bool over_range, const Config::StopRule& rule) noexcept {
  if (rule.sd_k == 0.0f) return force_n;
  const bool sd_ok = std::isfinite(force_sd_n) && force_sd_n >= 0.0f;
  if (rule.sd_k > 0.0f) {
    if (!sd_ok) return std::numeric_limits<float>::infinity();  // an sd that cannot be read: a doubt, above
    return force_n + rule.sd_k * force_sd_n;
  }
  // An sd above max_sd_n is no reading this rule trusts (a broken or forged sd): it never lowers.
  if (!sd_ok || over_range || force_sd_n > rule.max_sd_n) return force_n;
  return std::max(0.0f, force_n + rule.sd_k * force_sd_n);
}

Step Policy::OnContact(Data& d, std::string_view patch_id, const Contact& c, std::int64_t now_ns) const noexcept {
  if (!Advance(d, now_ns)) return Finish(d, {.rejection = Backwards(d)});
  Cause cause{.kind = CauseKind::kContact,
              .force_n = c.force_n,
              .p_bc_m = c.doubt == Rejection::kNone ? c.p_bc_m : std::nullopt,
              .t_ns = c.t_ns != 0 && c.doubt != Rejection::kImplausibleTime ? c.t_ns : now_ns,
              .seam_partner = c.seam_partner,
              .seam_own_force_n = c.seam_own_force_n,
              .seam_partner_force_n = c.seam_partner_force_n,
              .faint = c.faint};
  const std::int32_t i = FindPatch(patch_id);
  if (i == kNoPatch) return Refuse(d, Rejection::kUnknownPatch, cause, Severity::kStop);
  cause.patch = i;
  PatchState& p = d.patches_[static_cast<std::size_t>(i)];
  const std::int32_t region =
      c.region.empty() ? FindRegion(config_.patches[static_cast<std::size_t>(i)].region) : FindRegion(c.region);
  Rejection why = Rejection::kNone;
  if (region == kNoRegion) {
    why = Rejection::kUnknownRegion;
  } else {
    cause.region = region;
    cause.threshold_n = config_.regions[static_cast<std::size_t>(region)].threshold_n;
    if (!std::isfinite(c.force_n)) {
      why = Rejection::kNonFiniteForce;
    } else if (c.force_n < -config_.input.negative_force_tolerance_n) {
      why = Rejection::kNegativeForce;
    } else if (c.doubt != Rejection::kNone) {
      why = c.doubt;
    } else if (!HasStream(p.link)) {
      why = Rejection::kNotConnected;
    }
  }
  if (why != Rejection::kNone) {
    // A contact the policy cannot judge counts as one above its threshold until a good frame (and the
    // release hold), a release or a healthy heartbeat out of contact says otherwise. A doubt while the
    // contact is already held is the same cause (no new epoch).
    const bool was_over = p.contact_over;
    p.contact_over = true;
    p.contact_below_since_t_ns.reset();
    p.contact_force_n = c.force_n;
    ++d.counters_.rejections[static_cast<std::size_t>(why)];
    cause.doubt = why;
    d.last_rejection_ = cause;
    Latch(d, cause, Severity::kStop, !was_over);
    return Finish(d, {.rejection = why});
  }
  Seen(d, static_cast<std::size_t>(i));
  // Within the noise tolerance below 0: judged as 0 N; then the scene's stop rule (the sd, JudgedForce).
  const float force_n = JudgedForce(std::max(c.force_n, 0.0f), c.force_sd_n, c.over_range, config_.stop_rule);
  cause.judged_n = force_n;
  // The end of a cause is judged on the larger of the force and what was judged: a rule that lowers the
  // force (sd_k < 0) may delay a STOP's start, never end one while the reading is above the release level.
  const float release_force_n = std::max(force_n, std::max(c.force_n, 0.0f));
  const RegionConfig& rc = config_.regions[static_cast<std::size_t>(region)];
  // At the threshold never stops. An over-range contact always does, whatever the threshold: its force is only
  // the decoder's lower bound (the skin cannot say how far above it the press is), so a region whose threshold
  // is above that bound would otherwise never stop on a saturated press (review 10, finding 8).
  const bool over = force_n > cause.threshold_n || c.saturated;
  const bool was_over = p.contact_over;
  p.contact_force_n = c.force_n;
  if (c.released) {
    p.contact_over = false;  // the decoder's gate closed: the contact has ended
    p.contact_below_since_t_ns.reset();
  } else if (over) {
    p.contact_over = true;
    p.contact_below_since_t_ns.reset();
  } else if (was_over) {
    // Hysteresis: the cause ends once the force has stayed below the release level for the hold time.
    if (release_force_n < cause.threshold_n * (1.0f - rc.release.fraction)) {
      if (!p.contact_below_since_t_ns) p.contact_below_since_t_ns = now_ns;
      if (now_ns - *p.contact_below_since_t_ns >= rc.release.hold_ns) {
        p.contact_over = false;
        p.contact_below_since_t_ns.reset();
      }
    } else {
      p.contact_below_since_t_ns.reset();  // between the release level and the threshold: still held
    }
  }
  if (over) Latch(d, cause, Severity::kStop, !was_over);
  return Finish(d, {});
}

Step Policy::OnPatchFault(Data& d, std::string_view patch_id, PatchFaultCode code,
                          std::int64_t now_ns) const noexcept {
  if (!Advance(d, now_ns)) return Finish(d, {.rejection = Backwards(d)});
  const std::int32_t i = FindPatch(patch_id);
  if (i == kNoPatch) return Refuse(d, Rejection::kUnknownPatch, Cause{.kind = CauseKind::kInternal}, Severity::kFault);
  PatchState& p = d.patches_[static_cast<std::size_t>(i)];
  // A fault only makes things worse: applied whatever the link (liveness only when there is a stream).
  if (HasStream(p.link)) {
    Seen(d, static_cast<std::size_t>(i));
    p.link = LinkState::kUnhealthy;
  }
  const bool is_new = !p.fault_in_force;
  p.fault_in_force = true;
  p.fault = code;
  p.healthy_since_t_ns.reset();
  Latch(d, Cause{.kind = CauseKind::kPatchFault, .patch = i, .patch_fault = code, .t_ns = now_ns}, Severity::kFault,
        is_new);
  return Finish(d, {});
}

Step Policy::OnProtocolError(Data& d, std::string_view patch_id, std::int64_t now_ns,
                             CauseKind kind) const noexcept {
  if (!Advance(d, now_ns)) return Finish(d, {.rejection = Backwards(d)});
  const std::int32_t i = FindPatch(patch_id);
  if (i == kNoPatch) return Refuse(d, Rejection::kUnknownPatch, Cause{.kind = CauseKind::kInternal}, Severity::kFault);
  if (kind != CauseKind::kPatchLate && kind != CauseKind::kLinkErrors) kind = CauseKind::kPatchProtocol;
  PatchState& p = d.patches_[static_cast<std::size_t>(i)];
  const bool is_new = !p.protocol_fault || p.protocol_kind != kind;
  p.protocol_fault = true;
  p.protocol_kind = kind;
  if (Live(p.link)) p.link = LinkState::kUnhealthy;
  p.healthy_since_t_ns.reset();
  Latch(d, Cause{.kind = kind, .patch = i, .t_ns = now_ns}, Severity::kFault, is_new);
  return Finish(d, {});
}

Step Policy::OnDisconnect(Data& d, std::string_view patch_id, std::int64_t now_ns) const noexcept {
  if (!Advance(d, now_ns)) return Finish(d, {.rejection = Backwards(d)});
  const std::int32_t i = FindPatch(patch_id);
  if (i == kNoPatch) return Refuse(d, Rejection::kUnknownPatch, Cause{.kind = CauseKind::kInternal}, Severity::kFault);
  PatchState& p = d.patches_[static_cast<std::size_t>(i)];
  // A silent link ending, a second disconnect, or the end of a stream the aggregator ended for a protocol or
  // link-layer fault, is the same cause (the patch stays a present cause until a new hello is accepted).
  const bool is_new = Live(p.link) && !p.protocol_fault;
  if (p.link != LinkState::kRefused) p.link = LinkState::kDisconnected;
  p.healthy_since_t_ns.reset();
  Latch(d, Cause{.kind = CauseKind::kPatchSilent, .patch = i, .t_ns = now_ns}, Severity::kFault, is_new);
  return Finish(d, {});
}

Step Policy::OnJointState(Data& d, std::int64_t now_ns) const noexcept {
  if (!Advance(d, now_ns)) return Finish(d, {.rejection = Backwards(d)});
  d.joint_last_ns_ = now_ns;
  d.joint_stale_ = false;
  return Finish(d, {});
}

Step Policy::Tick(Data& d, std::int64_t now_ns) const noexcept {
  if (!Advance(d, now_ns)) return Finish(d, {.rejection = Backwards(d)});
  return Finish(d, {});
}

Step Policy::Publish(Data& d, std::int64_t now_ns) const noexcept {
  const Step step{.rejection = Advance(d, now_ns) ? Rejection::kNone : Backwards(d)};
  d.dirty_ = true;  // a change found just now is this publication: one seq either way
  return Finish(d, step);
}

Step Policy::Shutdown(Data& d, std::int64_t now_ns) const noexcept {
  const Step step{.rejection = Advance(d, now_ns) ? Rejection::kNone : Backwards(d)};
  if (d.shutting_down_) return Finish(d, step);
  SafetyState& s = d.state_;
  Counters& n = d.counters_;
  const Cause cause{.kind = CauseKind::kShuttingDown, .t_ns = d.now_ns_};
  ++n.causes[static_cast<std::size_t>(CauseKind::kShuttingDown)];
  if (s.state != State::kFault) {
    ++n.faults;
    if (s.state == State::kStop) ++n.escalations;
    s.state = State::kFault;
    s.changed_t_ns = d.now_ns_;
  } else {
    ++n.causes_while_latched;
  }
  // Always a new epoch: shutdown supersedes every other cause, and a reset in flight names an older epoch.
  ++s.stop_epoch;
  ++n.epochs;
  s.cause = cause;
  d.latest_cause_ = cause;
  d.shutting_down_ = true;
  d.dirty_ = true;
  d.Record({.type = EventType::kShutdown, .state = State::kFault, .stop_epoch = s.stop_epoch, .cause = cause,
            .t_ns = d.now_ns_});
  return Finish(d, step);
}

// --- Policy: reset ----------------------------------------------------------------------------------------------

Cause Policy::FirstCausePresent(const Data& d, std::int64_t now_ns) const noexcept {
  for (std::size_t k = 0; k < d.patches_.size(); ++k) {
    const PatchState& p = d.patches_[k];
    const auto i = static_cast<std::int32_t>(k);
    if (p.link == LinkState::kRefused || (!HasStream(p.link) && !p.ever_connected)) {
      return {.kind = CauseKind::kPatchMissing, .patch = i, .t_ns = now_ns};
    }
    if (!HasStream(p.link) || p.link == LinkState::kSilent ||
        now_ns - p.last_seen_t_ns > config_.patches[k].silence_deadline_ns) {
      return {.kind = CauseKind::kPatchSilent, .patch = i, .t_ns = now_ns};
    }
    if (p.protocol_fault) return {.kind = p.protocol_kind, .patch = i, .t_ns = now_ns};
    if (p.fault_in_force) {
      return {.kind = CauseKind::kPatchFault, .patch = i, .patch_fault = p.fault, .t_ns = now_ns};
    }
    if (ContactPresent(p, k, now_ns)) {
      const std::int32_t region = FindRegion(config_.patches[k].region);
      return {.kind = CauseKind::kContact,
              .patch = i,
              .region = region,
              .force_n = p.contact_force_n,
              .threshold_n = config_.regions[static_cast<std::size_t>(region)].threshold_n,
              .t_ns = now_ns};
    }
  }
  if (config_.joint_states_required &&
      (!d.joint_last_ns_ || now_ns - *d.joint_last_ns_ > config_.joint_state_max_age_ns)) {
    return {.kind = CauseKind::kJointStatesStale, .t_ns = now_ns};
  }
  return {};
}

const ContactRelease& Policy::ReleaseOf(std::size_t patch) const noexcept {
  const std::int32_t region = FindRegion(config_.patches[patch].region);
  return config_.regions[static_cast<std::size_t>(region)].release;  // Validate(): every patch's region exists
}

// contact_over, with the release hold judged at now_ns (no frame needs to arrive for the hold to run out).
bool Policy::ContactPresent(const PatchState& p, std::size_t patch, std::int64_t now_ns) const noexcept {
  if (!p.contact_over) return false;
  return !p.contact_below_since_t_ns || now_ns - *p.contact_below_since_t_ns < ReleaseOf(patch).hold_ns;
}

ResetResult Policy::Reset(Data& d, const ResetRequest& r, std::int64_t now_ns) const noexcept {
  ResetResult out;
  auto refuse = [&](ResetRefusal why) {
    ++d.counters_.resets_refused[static_cast<std::size_t>(why)];
    out.reason = why;
    out.current_epoch = d.state_.stop_epoch;
    d.Record({.type = EventType::kResetRefused,
              .state = d.state_.state,
              .stop_epoch = d.state_.stop_epoch,
              .cause = out.blocking,
              .reset_refusal = why,
              .reset_epoch = r.stop_epoch,
              .t_ns = now_ns});
    return out;
  };
  if (now_ns < d.now_ns_) {
    ++d.counters_.rejections[static_cast<std::size_t>(Rejection::kTimeBackwards)];
    return refuse(ResetRefusal::kInvalidRequest);
  }
  if (!r.authorized) return refuse(ResetRefusal::kUnauthorized);
  if (r.other_run) return refuse(ResetRefusal::kWrongRun);
  if (d.shutting_down_) return refuse(ResetRefusal::kShuttingDown);
  if (d.state_.state == State::kClear) return refuse(ResetRefusal::kNotLatched);
  if (r.stop_epoch != d.state_.stop_epoch) return refuse(ResetRefusal::kWrongEpoch);
  out.blocking = FirstCausePresent(d, now_ns);
  if (out.blocking.kind != CauseKind::kNone) return refuse(ResetRefusal::kCausePresent);
  for (std::size_t k = 0; k < d.patches_.size(); ++k) {
    const PatchState& p = d.patches_[k];
    const std::int64_t healthy_for = p.healthy_since_t_ns ? now_ns - *p.healthy_since_t_ns : 0;
    if (!p.healthy_since_t_ns || healthy_for < config_.healthy_before_reset_ns) {
      out.blocking = Cause{.patch = static_cast<std::int32_t>(k), .t_ns = now_ns};
      out.healthy_for_ns = healthy_for;
      return refuse(ResetRefusal::kNotHealthyLongEnough);
    }
  }
  // Accepted. Nothing was due at now_ns (FirstCausePresent judged every deadline at it), so none is skipped;
  // a contact whose release hold ran out by now_ns is over.
  for (PatchState& p : d.patches_) {
    p.contact_over = false;
    p.contact_below_since_t_ns.reset();
  }
  d.last_rejection_ = Cause{};
  d.now_ns_ = now_ns;
  d.state_.state = State::kClear;
  d.state_.cause = Cause{};
  d.state_.changed_t_ns = now_ns;
  d.dirty_ = true;
  ++d.counters_.resets_accepted;
  Finish(d, {});
  out.accepted = true;
  out.current_epoch = d.state_.stop_epoch;
  d.Record({.type = EventType::kResetAccepted,
            .state = State::kClear,
            .stop_epoch = d.state_.stop_epoch,
            .reset_epoch = r.stop_epoch,
            .t_ns = now_ns});
  return out;
}

// --- Names and descriptions -------------------------------------------------------------------------------------

std::string_view StateName(State s) noexcept {
  switch (s) {
    case State::kClear: return "clear";
    case State::kStop: return "stop";
    case State::kFault: return "fault";
  }
  return "unspecified";
}

std::string_view CauseKindName(CauseKind k) noexcept {
  switch (k) {
    case CauseKind::kNone: return "unspecified";
    case CauseKind::kContact: return "contact";
    case CauseKind::kPatchFault: return "patch_fault";
    case CauseKind::kPatchSilent: return "patch_silent";
    case CauseKind::kPatchMissing: return "patch_missing";
    case CauseKind::kPatchProtocol: return "patch_protocol";
    case CauseKind::kJointStatesStale: return "joint_states_stale";
    case CauseKind::kStartup: return "startup";
    case CauseKind::kShuttingDown: return "shutting_down";
    case CauseKind::kInternal: return "internal";
    case CauseKind::kPatchLate: return "patch_late";
    case CauseKind::kLinkErrors: return "link_errors";
  }
  return "unspecified";
}

std::string_view ResetRefusalName(ResetRefusal r) noexcept {
  switch (r) {
    case ResetRefusal::kNone: return "unspecified";
    case ResetRefusal::kWrongEpoch: return "wrong_epoch";
    case ResetRefusal::kNotLatched: return "not_latched";
    case ResetRefusal::kCausePresent: return "cause_present";
    case ResetRefusal::kNotHealthyLongEnough: return "not_healthy_long_enough";
    case ResetRefusal::kUnauthorized: return "unauthorized";
    case ResetRefusal::kShuttingDown: return "shutting_down";
    case ResetRefusal::kInvalidRequest: return "invalid_request";
    case ResetRefusal::kWrongRun: return "wrong_run";
  }
  return "unspecified";
}

std::string_view LinkStateName(LinkState l) noexcept {
  switch (l) {
    case LinkState::kUnspecified: return "unspecified";
    case LinkState::kDisconnected: return "disconnected";
    case LinkState::kHelloPending: return "hello_pending";
    case LinkState::kRefused: return "refused";
    case LinkState::kHealthy: return "healthy";
    case LinkState::kUnhealthy: return "unhealthy";
    case LinkState::kSilent: return "silent";
  }
  return "unspecified";
}

std::string_view PatchFaultCodeName(PatchFaultCode c) noexcept {
  switch (c) {
    case PatchFaultCode::kUnspecified: return "unspecified";
    case PatchFaultCode::kInterrogatorSilent: return "interrogator_silent";
    case PatchFaultCode::kInterrogatorDisconnected: return "interrogator_disconnected";
    case PatchFaultCode::kFramesRejected: return "frames_rejected";
    case PatchFaultCode::kFramesLost: return "frames_lost";
    case PatchFaultCode::kBaselineInvalid: return "baseline_invalid";
    case PatchFaultCode::kBaselineStale: return "baseline_stale";
    case PatchFaultCode::kModelMismatch: return "model_mismatch";
    case PatchFaultCode::kOverloaded: return "overloaded";
    case PatchFaultCode::kShuttingDown: return "shutting_down";
    case PatchFaultCode::kInternal: return "internal";
    case PatchFaultCode::kLate: return "late";
  }
  return "unspecified";
}

std::string_view RejectionName(Rejection r) noexcept {
  switch (r) {
    case Rejection::kNone: return "none";
    case Rejection::kTimeBackwards: return "time_backwards";
    case Rejection::kUnknownPatch: return "unknown_patch";
    case Rejection::kUnknownRegion: return "unknown_region";
    case Rejection::kNonFiniteForce: return "non_finite_force";
    case Rejection::kNegativeForce: return "negative_force";
    case Rejection::kNotConnected: return "not_connected";
    case Rejection::kBadPosition: return "bad_position";
    case Rejection::kBadCovariance: return "bad_covariance";
    case Rejection::kImplausibleTime: return "implausible_time";
  }
  return "none";
}

std::string_view EventTypeName(EventType t) noexcept {
  switch (t) {
    case EventType::kLatch: return "latch";
    case EventType::kEscalation: return "escalation";
    case EventType::kNewEpoch: return "new_epoch";
    case EventType::kShutdown: return "shutdown";
    case EventType::kResetAccepted: return "reset_accepted";
    case EventType::kResetRefused: return "reset_refused";
  }
  return "unknown";
}

std::string Describe(const Policy& p, const Cause& c) {
  std::ostringstream s;
  s << CauseKindName(c.kind);
  if (c.patch != kNoPatch) s << " patch '" << p.patch_id(c.patch) << "'";
  if (c.kind == CauseKind::kContact) {
    s << " force " << c.force_n << " N";
    if (c.seam_partner != kNoPatch) {
      s << " (seam sum of '" << p.patch_id(c.patch) << "' " << c.seam_own_force_n << " N and '"
        << p.patch_id(c.seam_partner) << "' " << c.seam_partner_force_n << " N)";
    }
    if (c.faint) s << " [faint: shifts within a baseline error, force judged as read]";
    if (p.config().stop_rule.sd_k != 0.0f && c.judged_n != c.force_n && c.doubt == Rejection::kNone) {
      s << " (judged " << c.judged_n << " N with its sd)";
    }
    if (c.region != kNoRegion) s << " above region '" << p.region_name(c.region) << "' threshold " << c.threshold_n << " N";
    if (c.p_bc_m) s << " at (" << (*c.p_bc_m)[0] << ", " << (*c.p_bc_m)[1] << ", " << (*c.p_bc_m)[2] << ") m";
  }
  if (c.kind == CauseKind::kPatchFault) s << " (" << PatchFaultCodeName(c.patch_fault) << ")";
  if (c.doubt != Rejection::kNone) s << " [doubt: " << RejectionName(c.doubt) << "]";
  s << " at t_ns " << c.t_ns;
  return s.str();
}

std::string Describe(const Policy& p, const ResetResult& r) {
  std::ostringstream s;
  if (r.accepted) {
    s << "reset accepted: stop_epoch " << r.current_epoch << " cleared";
    return s.str();
  }
  s << "reset refused (" << ResetRefusalName(r.reason) << "): ";
  switch (r.reason) {
    case ResetRefusal::kWrongEpoch: s << "the current stop_epoch is " << r.current_epoch; break;
    case ResetRefusal::kNotLatched: s << "the state is CLEAR"; break;
    case ResetRefusal::kCausePresent: s << "cause still present: " << Describe(p, r.blocking); break;
    case ResetRefusal::kNotHealthyLongEnough:
      s << "patch '" << p.patch_id(r.blocking.patch) << "' healthy for " << r.healthy_for_ns << " ns of the "
        << p.config().healthy_before_reset_ns << " ns required";
      break;
    case ResetRefusal::kUnauthorized: s << "the caller may not reset"; break;
    case ResetRefusal::kShuttingDown: s << "the aggregator is shutting down"; break;
    case ResetRefusal::kInvalidRequest: s << "the aggregator's clock went backwards"; break;
    case ResetRefusal::kWrongRun: s << "the request names another aggregator run (aggregator_run_id)"; break;
    case ResetRefusal::kNone: break;
  }
  return s.str();
}

}  // namespace ruffini::safety
