#include "ruffini/aggregate/core.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "ruffini/error.h"

namespace ruffini::aggregate {

std::string_view JointRejectionName(JointRejection r) noexcept {
  switch (r) {
    case JointRejection::kNone: return "accepted";
    case JointRejection::kNoRobot: return "no_robot";
    case JointRejection::kWrongCount: return "wrong_count";
    case JointRejection::kWrongNames: return "wrong_names";
    case JointRejection::kNotFinite: return "not_finite";
    case JointRejection::kNotMonotonic: return "not_monotonic";
    case JointRejection::kImplausibleTime: return "implausible_time";
  }
  return "unknown";
}

std::string_view BadInputName(BadInput b) noexcept {
  switch (b) {
    case BadInput::kBadPosition: return "bad_position";
    case BadInput::kBadCovariance: return "bad_covariance";
    case BadInput::kImplausibleTime: return "implausible_time";
    case BadInput::kUnknownFaultCode: return "unknown_fault_code";
    case BadInput::kHelloChanged: return "hello_changed";
  }
  return "unknown";
}

namespace {

v1::SafetyState::State ToProto(safety::State s) {
  switch (s) {
    case safety::State::kClear: return v1::SafetyState::STATE_CLEAR;
    case safety::State::kStop: return v1::SafetyState::STATE_STOP;
    case safety::State::kFault: return v1::SafetyState::STATE_FAULT;
  }
  return v1::SafetyState::STATE_UNSPECIFIED;
}

// |a - b| > bound, without overflow for any pair of int64 values.
bool FarApart(std::int64_t a, std::int64_t b, std::int64_t bound) {
  std::int64_t d = 0;
  if (__builtin_sub_overflow(a, b, &d)) return true;  // further apart than any int64 bound
  return d > bound || d < -bound;
}

// A code on the wire (any int32, negative too) -> the policy's enum; nullopt when outside it.
std::optional<safety::PatchFaultCode> FaultCode(int code) {
  if (code < 0 || code >= static_cast<int>(safety::kPatchFaultCodeCount)) return std::nullopt;
  return static_cast<safety::PatchFaultCode>(code);
}

}  // namespace

namespace {

fusion::SurfaceContact SurfaceOf(const v1::PatchContact& c) noexcept {
  fusion::SurfaceContact s;
  s.force_n = c.force_n();
  s.force_sd_n = c.force_sd_n();
  s.located = c.located();
  s.y_mm = c.y_mm();
  s.r_deg = c.r_deg();
  s.cov_yy_mm2 = c.cov_yy_mm2();
  s.cov_ys_mm2 = c.cov_yr_mm2();
  s.cov_ss_mm2 = c.cov_rr_mm2();
  s.uncertainty_calibrated = c.uncertainty_calibrated();
  return s;
}

}  // namespace

Core::Core(Setup setup, std::int64_t now_ns)
    : setup_(std::move(setup)), policy_(setup_.safety), data_(policy_, now_ns), start_ns_(now_ns) {
  if (setup_.patches.size() != setup_.safety.patches.size()) {
    throw InputError("aggregator setup: " + std::to_string(setup_.patches.size()) + " patches but " +
                     std::to_string(setup_.safety.patches.size()) + " in the safety config");
  }
  for (std::size_t i = 0; i < setup_.patches.size(); ++i) {
    if (setup_.patches[i].id != setup_.safety.patches[i].id) {
      throw InputError("aggregator setup: patch " + std::to_string(i) + " is '" + setup_.patches[i].id +
                       "' but the safety config names '" + setup_.safety.patches[i].id + "'");
    }
    if (setup_.patches[i].mount) {
      if (!setup_.robot) throw InputError("patch '" + setup_.patches[i].id + "' has a mount but the scene has no robot");
      robot::ValidateMount(*setup_.robot, *setup_.patches[i].mount, "patch '" + setup_.patches[i].id + "'");
    }
  }
  if (setup_.run_id == 0) throw InputError("aggregator setup: the run id must be nonzero (drawn at start)");
  link_config_.freshness.budget_ns = setup_.safety.link.freshness_budget_ns;
  link_config_.error_rate.window_ns = setup_.safety.link.error_window_ns;
  link_config_.error_rate.limit = setup_.safety.link.error_limit;
  try {
    (void)channel::PatchLinkCheck(link_config_, setup_.run_id, "validate");
  } catch (const std::invalid_argument& e) {
    throw InputError(std::string("aggregator setup: safety.link_layer: ") + e.what());
  }
  link_errors_.resize(setup_.patches.size());
  sender_clock_.resize(setup_.patches.size());
  links_.resize(setup_.patches.size());
  if (setup_.robot) {
    q_scratch_.resize(setup_.robot->num_dof());
    fusion::FusionConfig fc;
    for (const auto& p : setup_.patches) {
      fusion::FusionPatch fp;
      fp.id = p.id;
      if (p.mount) fp.mount = *p.mount;
      fp.extent_y_mm = p.extent_y_mm;
      fp.extent_r_deg = p.extent_r_deg;
      fc.patches.push_back(fp);
    }
    fc.seams = setup_.seams;
    fuser_.emplace(*setup_.robot, std::move(fc));
    fusion_data_ = std::make_unique<fusion::FusionData>();
    fusion_inputs_.reserve(setup_.patches.size());
  }
}

// One probe across a seam loads both patches, and each decoder reads only its share (docs/fusion.md, "Seams"):
// a contact is judged on the sum of both sides' forces when one touch on the seam may explain both
// (fusion::OneTouchOnSeam: each within its band across the seam, and the two agree along it) and the other side's
// newest contact is live: in contact, not a doubt, and received within its patch's silence deadline (arrival
// time, not frame times: two interrogators' clocks may differ, and a side that lags must not end the sum while
// the press goes on). Only the force is raised; the contact's own sd stays (the stop rule never judges the sum
// lower than the contact alone, and a sd it cannot read stays unreadable).
void Core::JudgeOnSeam(std::size_t pi, const v1::PatchContact& c, safety::Contact& sc, std::int64_t now_ns) noexcept {
  if (!setup_.safety.seam_sum.enabled || !fuser_ || !std::isfinite(c.force_n())) return;
  const fusion::FusionConfig& fc = fuser_->config();
  double best = sc.force_n;
  std::size_t best_partner = 0;
  float best_partner_n = 0.0f;
  for (const fusion::FusionConfig::SeamBand& sb : fc.seams) {
    if (sb.seam.a != pi && sb.seam.b != pi) continue;
    const bool mine_is_a = sb.seam.a == pi;
    const std::size_t pj = mine_is_a ? sb.seam.b : sb.seam.a;
    const PatchLink& other = links_[pj];
    if (other.stream < 0 || !other.in_contact || other.doubtful) continue;
    if (now_ns - other.contact_arrival_ns > setup_.safety.patches[pj].silence_deadline_ns) continue;
    const float f_other = other.surface.force_n();
    if (!std::isfinite(f_other) || f_other <= 0) continue;
    const fusion::SurfaceContact mine = SurfaceOf(c), theirs = SurfaceOf(other.surface);
    bool one = false;
    if (mine.located && theirs.located) {
      one = mine_is_a ? fusion::OneTouchOnSeam(fc, sb, mine, theirs) : fusion::OneTouchOnSeam(fc, sb, theirs, mine);
    } else if (mine.located || theirs.located) {
      // A side that does not place its touch (force only) may be anywhere on its patch, the seam included: the
      // located side decides (review 4: an unplaced side must not end the sum while the press goes on).
      one = mine.located ? fusion::SideMayBeOnSeam(sb, mine_is_a, fc.patches[pi], mine, fc.lift)
                         : fusion::SideMayBeOnSeam(sb, !mine_is_a, fc.patches[pj], theirs, fc.lift);
    }
    if (!one) continue;
    // In double, clamped: two huge finite readings must not add up to +inf (a non-finite force is refused).
    const double sum = std::min(static_cast<double>(std::numeric_limits<float>::max()),
                                static_cast<double>(c.force_n()) + static_cast<double>(f_other));
    if (sum > best) {
      best = sum;
      best_partner = pj;
      best_partner_n = f_other;
    }
  }
  if (best > sc.force_n) {
    // The cause's text says the force is a sum, and of what (safety::Describe).
    sc.seam_own_force_n = sc.force_n;
    sc.seam_partner = static_cast<std::int32_t>(best_partner);
    sc.seam_partner_force_n = best_partner_n;
    sc.force_n = static_cast<float>(best);
    ++counters_.seam_sums;
  }
}

v1::AggregatorCommand Core::Command(std::int64_t now_ns) {
  v1::AggregatorCommand c;
  c.set_seq(++command_seq_);
  c.set_t_ns(now_ns);
  return c;
}

void Core::DrainPolicyEvents(const std::string& operator_name) {
  for (const safety::Event& e : data_.events()) {
    Event out;
    out.safety = e;
    out.cause_patch = std::string(policy_.patch_id(e.cause.patch));
    if (e.type == safety::EventType::kResetAccepted || e.type == safety::EventType::kResetRefused) {
      out.operator_name = operator_name;
    }
    events_.push_back(std::move(out));
  }
  data_.ClearEvents();
}

std::vector<Event> Core::TakeEvents() {
  DrainPolicyEvents();
  return std::exchange(events_, {});
}

void Core::Note(const safety::Step& step) {
  if (!data_.events().empty()) DrainPolicyEvents();
  if (!step.publish) return;
  changed_ = true;
  const auto& s = data_.state();
  // Once per STOP (its epoch), when it latches; later publications of the same STOP are not new samples.
  if (s.state == safety::State::kStop && s.cause.kind == safety::CauseKind::kContact && s.cause.t_ns > 0 &&
      s.stop_epoch != latency_epoch_) {
    latency_epoch_ = s.stop_epoch;
    stop_latency_ns_ = data_.now_ns() - s.cause.t_ns;
  }
}

int Core::OpenStream(std::int64_t /*now_ns*/, std::string allowed_patch) {
  const int id = next_stream_++;
  streams_[id] = Stream{};
  streams_[id].allowed_patch = std::move(allowed_patch);
  return id;
}

Core::Reply Core::Refuse(Stream& s, v1::HelloRefusal reason, const std::string& message, std::int64_t now_ns) {
  ++counters_.hellos_refused[static_cast<std::size_t>(reason)];
  Reply r;
  r.command = Command(now_ns);
  r.command->mutable_hello_refused()->set_reason(reason);
  r.command->mutable_hello_refused()->set_message(message);
  r.close = true;
  s.hello_done = true;
  return r;
}

Core::Reply Core::ProtocolError(int /*stream*/, Stream& s, const std::string& why, std::int64_t now_ns,
                                safety::CauseKind kind) {
  ++counters_.protocol_errors;
  if (s.patch >= 0) Note(policy_.OnProtocolError(data_, policy_.patch_id(s.patch), now_ns, kind));
  last_protocol_error_ = why;
  Reply r;
  r.close = true;
  return r;
}

v1::HelloRefusal Core::CheckHello(std::size_t patch, const v1::PatchHello& h, std::string& message) const {
  const PatchExpectation& want = setup_.patches[patch];
  const std::string& id = want.id;
  if (h.patch_name() != want.spec_name || h.patch_fingerprint() != want.spec_fingerprint ||
      h.model_patch_fingerprint() != want.spec_fingerprint) {
    message = "patch '" + id + "': expected spec '" + want.spec_name + "' (" + want.spec_fingerprint +
              "), the decoder has '" + h.patch_name() + "' (" + h.patch_fingerprint() + ", model trained for " +
              h.model_patch_fingerprint() + ")";
    return v1::HELLO_REFUSAL_SPEC_MISMATCH;
  }
  if (!want.model_sha256.empty() && h.model_sha256() != want.model_sha256) {
    message = "patch '" + id + "': expected model sha256 " + want.model_sha256 + ", the decoder runs " +
              h.model_name() + " (" + h.model_sha256() + ")";
    return v1::HELLO_REFUSAL_MODEL_MISMATCH;
  }
  if (h.heartbeat_period_ns() <= 0 || h.heartbeat_period_ns() > setup_.max_heartbeat_period_ns) {
    message = "heartbeat period " + std::to_string(h.heartbeat_period_ns()) + " ns; at most " +
              std::to_string(setup_.max_heartbeat_period_ns) + " ns";
    return v1::HELLO_REFUSAL_RATE_MISMATCH;
  }
  const safety::InputLimits& in = setup_.safety.input;
  if (in.sample_rate_hz > 0 &&
      !(std::isfinite(h.sample_rate_hz()) && std::abs(h.sample_rate_hz() - in.sample_rate_hz) <= 1e-3 * in.sample_rate_hz)) {
    message = "patch '" + id + "': sample rate " + std::to_string(h.sample_rate_hz()) + " Hz; the scene expects " +
              std::to_string(in.sample_rate_hz) + " Hz";
    return v1::HELLO_REFUSAL_RATE_MISMATCH;
  }
  if (!in.decoder_config_sha256.empty() && h.decoder_config().config_sha256() != in.decoder_config_sha256) {
    message = "patch '" + id + "': decoder configuration " + h.decoder_config().config_sha256() +
              "; the scene expects " + in.decoder_config_sha256;
    return v1::HELLO_REFUSAL_CONFIG_MISMATCH;
  }
  // A decoder that refuses faint contacts below some force never lets this aggregator judge them. A scene
  // that pins the model was checked at load (CoverageOfScene: the threshold, the stop rule and the model's sd,
  // seams). Unpinned, only what the hello says is known: refused below the region's threshold with the force
  // alone, and not at all under a raising stop rule (the model's sd is unknown) or on a seam (a seam contact
  // is judged on both sides' sum).
  const float refuse_n = h.decoder_config().faint_refuse_below_n();
  if (!(std::isfinite(refuse_n) && refuse_n >= 0.0f)) {
    message = "patch '" + id + "': faint_refuse_below_n " + std::to_string(refuse_n) + " is not a force";
    return v1::HELLO_REFUSAL_CONFIG_MISMATCH;
  }
  if (refuse_n > 0.0f && want.model_sha256.empty()) {
    float allowed = 0.0f;
    for (const auto& r : setup_.safety.regions) {
      if (r.name == setup_.safety.patches[patch].region) allowed = r.threshold_n;
    }
    if (setup_.safety.stop_rule.sd_k > 0.0f) allowed = 0.0f;
    for (const auto& sb : setup_.seams) {
      if (sb.seam.a == patch || sb.seam.b == patch) allowed = 0.0f;
    }
    if (refuse_n > allowed) {
      message = "patch '" + id + "': the decoder refuses faint contacts below " + std::to_string(refuse_n) +
                " N, but this patch may stop on less (" + std::to_string(allowed) +
                " N: its region's threshold, 0 under a raising stop rule or on a seam); pin the model in the scene or "
                "run a model that does not refuse";
      return v1::HELLO_REFUSAL_CONFIG_MISMATCH;
    }
  }
  return v1::HELLO_REFUSAL_UNSPECIFIED;
}

safety::Rejection Core::CheckContact(std::size_t patch, const v1::PatchMessage& m, std::int64_t now_ns) const {
  const safety::InputLimits& in = setup_.safety.input;
  if (m.t_ns() != 0 && FarApart(m.t_ns(), now_ns, in.max_time_skew_ns)) return safety::Rejection::kImplausibleTime;
  const v1::PatchContact& c = m.contact();
  if (!c.located()) return safety::Rejection::kNone;
  const PatchExpectation& want = setup_.patches[patch];
  const double y = c.y_mm(), r = c.r_deg();
  if (!std::isfinite(y) || !std::isfinite(r) || y < -in.position_tolerance_y_mm ||
      y > want.extent_y_mm + in.position_tolerance_y_mm || r < -in.position_tolerance_r_deg ||
      r > want.extent_r_deg + in.position_tolerance_r_deg) {
    return safety::Rejection::kBadPosition;
  }
  // A 2x2 covariance is PSD when both variances are >= 0 and the determinant is >= 0 (a small relative slack
  // for float rounding). All zero (an uncalibrated model) is PSD.
  const double yy = c.cov_yy_mm2(), yr = c.cov_yr_mm2(), rr = c.cov_rr_mm2();
  if (!std::isfinite(yy) || !std::isfinite(yr) || !std::isfinite(rr) || yy < 0 || rr < 0 ||
      yy * rr - yr * yr < -1e-6 * std::max(1.0, yy * rr)) {
    return safety::Rejection::kBadCovariance;
  }
  return safety::Rejection::kNone;
}

void Core::CountLinkError(const Stream& s, channel::Error e) noexcept {
  if (s.patch >= 0) link_errors_[static_cast<std::size_t>(s.patch)].Count(e);
  else link_errors_unbound_.Count(e);
}

Core::Reply Core::OnPatchMessage(int stream, const v1::PatchMessage& m, std::int64_t now_ns) {
  ++counters_.messages;
  auto it = streams_.find(stream);
  if (it == streams_.end()) return Reply{std::nullopt, true};
  Stream& s = it->second;
  if (s.hello_done && s.patch < 0) return Reply{std::nullopt, true};  // refused earlier: nothing more is read

  // The safety layer first (docs/safety-channel.md): integrity, identity, addressee, sequence, freshness.
  // The stream's first message fixes the patch id it may speak for.
  if (!s.check) {
    s.check.emplace(link_config_, setup_.run_id, m.patch_id());
    // What the patch's earlier streams learned of this sender's clock (review of issue 15, F1: a delay that
    // ended a stream must not become the next stream's "on time").
    const std::int32_t known = policy_.FindPatch(m.patch_id());
    if (known >= 0 && sender_clock_[static_cast<std::size_t>(known)].sender_run_id != 0) {
      const SenderClock& c = sender_clock_[static_cast<std::size_t>(known)];
      s.check->RememberSender(c.sender_run_id, c.offset_ns, c.last_arrival_ns);
    }
  }
  const channel::Verdict v = s.check->Receive(m, now_ns);
  if (s.patch >= 0 && s.check->freshness().learned()) {
    sender_clock_[static_cast<std::size_t>(s.patch)] = {s.check->sender_run_id(), s.check->freshness().offset_ns(),
                                                        s.check->freshness().last_arrival_ns()};
  }
  if (v.error) {
    // The checker counted it per stream; the Core keeps the per-patch totals the metrics show.
    CountLinkError(s, v.kind);
  }
  if (!v.use) {
    const std::string what = "the safety layer discarded a message: " + std::string(channel::Name(v.kind));
    if (!s.hello_done) return Refuse(s, v1::HELLO_REFUSAL_PROTOCOL_ERROR, what, now_ns);
    if (v.latch) {
      return ProtocolError(stream, s, what + ", the second error within the window", now_ns,
                           safety::CauseKind::kLinkErrors);
    }
    return {};  // discarded: the stream goes on (a gap it left is a loss at the next message)
  }
  Reply out = Judge(stream, s, m, now_ns);
  if (v.latch && !out.close && s.patch >= 0) {
    // The content was used (it may be the STOP); now the link answers for what it did.
    const safety::CauseKind kind = v.rate_latch              ? safety::CauseKind::kLinkErrors
                                   : v.kind == channel::Error::kDelay ? safety::CauseKind::kPatchLate
                                                                      : safety::CauseKind::kPatchProtocol;
    const std::string why = v.kind == channel::Error::kDelay
                                ? "a message arrived " + std::to_string(v.age_ns / 1'000'000) + " ms late (budget " +
                                      std::to_string(link_config_.freshness.budget_ns / 1'000'000) + " ms)"
                                : "the safety layer detected " + std::string(channel::Name(v.kind)) +
                                      " (" + std::to_string(s.check->counts()[v.kind]) + " on this stream)";
    Reply fault = ProtocolError(stream, s, why, now_ns, kind);
    fault.command = std::move(out.command);
    fault.end_stream = out.end_stream;
    return fault;
  }
  return out;
}

Core::Reply Core::Judge(int stream, Stream& s, const v1::PatchMessage& m, std::int64_t now_ns) {

  if (!s.hello_done) {
    // The first message: a hello, seq 1, the envelope's id = the scene's patch.
    if (!m.has_hello() || m.seq() != 1) {
      return Refuse(s, v1::HELLO_REFUSAL_PROTOCOL_ERROR, "the first message must be a PatchHello with seq 1", now_ns);
    }
    if (!s.allowed_patch.empty() && m.patch_id() != s.allowed_patch) {
      // Not this caller's patch: refused before anything is looked up, so the patch it names (perhaps live
      // and healthy on another stream) and the safety state are left alone.
      return Refuse(s, v1::HELLO_REFUSAL_UNAUTHORIZED,
                    "this decoder's identity may publish only patch '" + s.allowed_patch + "', not '" + m.patch_id() +
                        "'",
                    now_ns);
    }
    const std::int32_t patch = policy_.FindPatch(m.patch_id());
    if (patch == safety::kNoPatch) {
      // Refused and counted, nothing more: the scene's own patches are judged by their own streams (one that
      // never connects is already missing), so a hello naming a patch the scene does not have -- a decoder
      // configured for another robot, or any caller in --insecure mode -- must not FAULT the robot.
      return Refuse(s, v1::HELLO_REFUSAL_UNKNOWN_PATCH, "the scene names no patch '" + m.patch_id() + "'", now_ns);
    }
    const std::size_t pi = static_cast<std::size_t>(patch);
    // The duplicate check comes first: a hello for a patch with a live stream changes nothing of that stream
    // or of the safety state, whatever it says -- unless the live stream has been silent past
    // kTakeoverWatchdogs watchdogs (a half-open link): then the newcomer may take the patch over.
    int replaced = -1;
    {
      PatchLink& link = links_[pi];
      if (link.stream >= 0 && link.stream != stream) {
        const std::int64_t watchdog_ns = setup_.safety.patches[pi].silence_deadline_ns;
        const bool silent = now_ns - link.last_seen_ns > kTakeoverWatchdogs * watchdog_ns;
        if (!silent) {
          return Refuse(s, v1::HELLO_REFUSAL_DUPLICATE_PATCH,
                        "patch '" + m.patch_id() + "' is held by another live stream (" +
                            link.hello.decoder_instance() + ")",
                        now_ns);
        }
        replaced = link.stream;
      }
    }
    std::string why;
    const v1::HelloRefusal refusal = CheckHello(pi, m.hello(), why);
    if (refusal != v1::HELLO_REFUSAL_UNSPECIFIED) {
      // Only a patch with no stream becomes missing: a silent stream still holding it is already a FAULT
      // (silent), and stays the patch's stream (were it to speak again, it is judged as before).
      if (links_[pi].stream < 0) Note(policy_.OnHelloRefused(data_, m.patch_id(), now_ns));
      return Refuse(s, refusal, why, now_ns);
    }
    Reply r;
    if (replaced >= 0) {
      // The silent stream is forgotten here (its patch goes to the newcomer); the caller ends it.
      auto old = streams_.find(replaced);
      if (old != streams_.end()) streams_.erase(old);
      ++counters_.takeovers;
      Event e;
      e.takeover = true;
      e.replaced_stream = replaced;
      e.cause_patch = m.patch_id();
      e.safety.t_ns = now_ns;
      e.safety.state = data_.state().state;
      e.safety.stop_epoch = data_.state().stop_epoch;
      events_.push_back(std::move(e));
      r.end_stream = replaced;
      // The old stream's end is a disconnect (the patch was silent: the same cause, no new epoch).
      Note(policy_.OnDisconnect(data_, m.patch_id(), now_ns));
    }
    PatchLink& link = links_[pi];
    s.hello_done = true;
    s.patch = patch;
    s.seq = 1;
    link = PatchLink{};
    link.stream = stream;
    link.hello = m.hello();
    link.last_seen_ns = now_ns;
    link.last_seq = 1;
    ++counters_.hellos_accepted;
    Note(policy_.OnHelloAccepted(data_, m.patch_id(), now_ns));
    r.command = Command(now_ns);
    auto* a = r.command->mutable_hello_accepted();
    a->set_patch_id(m.patch_id());
    a->set_watchdog_ns(setup_.safety.patches[pi].silence_deadline_ns);
    a->set_aggregator_instance(setup_.instance);
    a->set_aggregator_run_id(setup_.run_id);
    a->set_robot_name(setup_.robot_name);
    return r;
  }
  if (s.patch < 0) return Reply{std::nullopt, true};  // refused earlier: nothing more is read
  const std::size_t pi = static_cast<std::size_t>(s.patch);
  PatchLink& link = links_[pi];
  const std::string_view id = policy_.patch_id(s.patch);
  // The safety layer has checked seq (a repeat or an older one never gets here; a gap does, as a loss the
  // caller latches after this message is used) and the patch id (a masquerade never gets here).
  if (m.seq() <= s.seq || m.patch_id() != id) {
    return ProtocolError(stream, s, "seq or patch id broken", now_ns);
  }
  s.seq = m.seq();
  link.last_seen_ns = now_ns;
  link.last_seq = m.seq();
  const bool time_plausible = m.t_ns() == 0 || !FarApart(m.t_ns(), now_ns, setup_.safety.input.max_time_skew_ns);
  if (m.t_ns() != 0 && time_plausible) {
    link.last_t_ns = m.t_ns();
    link.clock_offset_ns = m.decoder_t_ns() != 0 ? now_ns - m.decoder_t_ns() : 0;
  }
  switch (m.body_case()) {
    case v1::PatchMessage::kHello: {
      // A hello re-sent on the live stream is checked as the first was; a mismatch ends the stream.
      std::string why;
      if (CheckHello(pi, m.hello(), why) != v1::HELLO_REFUSAL_UNSPECIFIED) {
        Bad(BadInput::kHelloChanged);
        return ProtocolError(stream, s, "a re-sent hello does not match the scene: " + why, now_ns);
      }
      link.hello = m.hello();
      break;
    }
    case v1::PatchMessage::kHeartbeat: {
      link.heartbeat = m.heartbeat();
      safety::Heartbeat hb;
      hb.healthy = m.heartbeat().healthy();
      if (const auto code = FaultCode(m.heartbeat().active_fault())) {
        hb.active_fault = *code;
      } else {
        Bad(BadInput::kUnknownFaultCode);  // outside the contract (negative too): a fault, never "no fault"
        hb.active_fault = safety::PatchFaultCode::kInternal;
      }
      if (!time_plausible) {
        // The frame this heartbeat vouches for is implausibly far from now: the patch's data is not current
        // (a fault of its own unless the decoder already names one).
        Bad(BadInput::kImplausibleTime);
        if (hb.active_fault == safety::PatchFaultCode::kUnspecified) hb.active_fault = safety::PatchFaultCode::kLate;
      }
      hb.in_contact = m.heartbeat().in_contact();
      if (hb.healthy && hb.active_fault == safety::PatchFaultCode::kUnspecified && !hb.in_contact) {
        // The decoder's gate is closed: the contact has ended here too (as in the policy), also a doubt's.
        link.in_contact = false;
        link.doubtful = false;
      }
      Note(policy_.OnHeartbeat(data_, id, hb, now_ns));
      break;
    }
    case v1::PatchMessage::kContact: {
      ++counters_.contacts;
      const v1::PatchContact& c = m.contact();
      const safety::Rejection doubt = CheckContact(pi, m, now_ns);
      const auto& pc = setup_.safety.patches[pi];
      safety::Contact sc;
      sc.force_n = c.force_n();
      sc.force_sd_n = c.uncertainty_calibrated() ? c.force_sd_n() : 0.0f;
      // Lower bounds the stop rule never lowers: an over-range contact, and a two-touch frame (its force may be
      // the stronger fitted touch's lower bound, docs/decoders.md "Two touches").
      sc.over_range = c.over_range() || (c.located() && c.multiple());
      sc.saturated = c.over_range();
      sc.released = c.released();
      sc.t_ns = m.t_ns();
      sc.doubt = doubt;
      // Information only (the cause's text): the force above is judged as read, flagged or not.
      sc.faint = c.faint();
      if (c.faint()) ++counters_.contacts_faint;
      if (doubt != safety::Rejection::kNone) {
        // Not placed, not kept for WatchContacts as it stands: a doubt held as a contact at the patch (no
        // position), so the set still shows that something is there. Never a NaN on the wire.
        Bad(doubt == safety::Rejection::kBadPosition     ? BadInput::kBadPosition
            : doubt == safety::Rejection::kBadCovariance ? BadInput::kBadCovariance
                                                         : BadInput::kImplausibleTime);
        v1::BodyContact body;
        body.set_contact_id(link.in_contact ? link.contact.contact_id() : ++contact_ids_);
        body.set_onset_t_ns(link.in_contact ? link.contact.onset_t_ns() : now_ns);
        body.set_t_ns(doubt == safety::Rejection::kImplausibleTime ? now_ns : m.t_ns());
        body.set_force_n(std::isfinite(c.force_n()) ? c.force_n() : -1.0f);
        body.add_patch_ids(std::string(id));
        body.set_body_region(pc.region);
        if (const auto* mount = setup_.patches[pi].mount ? &*setup_.patches[pi].mount : nullptr) {
          body.set_link(mount->link);
        }
        const std::int32_t region = policy_.FindRegion(pc.region);
        if (region >= 0) body.set_threshold_n(setup_.safety.regions[static_cast<std::size_t>(region)].threshold_n);
        body.set_located(false);
        link.in_contact = true;  // a doubt is held until a good frame says otherwise
        link.contact = body;
        link.surface = v1::PatchContact{};
        link.surface.set_force_n(body.force_n());
        link.doubtful = true;
        Note(policy_.OnContact(data_, id, sc, now_ns));
        break;
      }
      v1::BodyContact body;
      if (c.onset() || !link.in_contact) body.set_contact_id(++contact_ids_);
      else body.set_contact_id(link.contact.contact_id());
      body.set_onset_t_ns(c.onset() || !link.in_contact ? m.t_ns() : link.contact.onset_t_ns());
      const bool placed = PlaceContact(s.patch, m.t_ns(), c, body);
      if (placed) ++counters_.contacts_placed;
      body.set_t_ns(m.t_ns());
      body.set_force_n(std::isfinite(c.force_n()) ? c.force_n() : -1.0f);
      body.set_force_sd_n(std::isfinite(c.force_sd_n()) ? c.force_sd_n() : 0.0f);
      body.set_multiple(c.located() && c.multiple());
      body.set_faint(c.faint());
      body.add_patch_ids(std::string(id));
      body.set_body_region(pc.region);
      const std::int32_t region = policy_.FindRegion(pc.region);
      if (region >= 0) body.set_threshold_n(setup_.safety.regions[static_cast<std::size_t>(region)].threshold_n);
      link.in_contact = !c.released();
      link.contact = body;
      link.surface = c;
      link.doubtful = !std::isfinite(c.force_n()) || c.force_n() < -setup_.safety.input.negative_force_tolerance_n;
      if (placed) sc.p_bc_m = std::array<double, 3>{body.p_bc_m().x(), body.p_bc_m().y(), body.p_bc_m().z()};
      if (!link.doubtful) link.contact_arrival_ns = now_ns;
      if (!link.doubtful && !c.released()) JudgeOnSeam(pi, c, sc, now_ns);
      Note(policy_.OnContact(data_, id, sc, now_ns));
      break;
    }
    case v1::PatchMessage::kFault: {
      link.fault = m.fault();
      const auto code = FaultCode(m.fault().code());
      if (!code) Bad(BadInput::kUnknownFaultCode);
      // An unknown code is still a fault (PatchFaultCode kUnspecified in a PatchFault: "unknown, still a fault").
      Note(policy_.OnPatchFault(data_, id, code.value_or(safety::PatchFaultCode::kInternal), now_ns));
      break;
    }
    case v1::PatchMessage::kRetareResult: {
      // Changes nothing in the safety state: a re-tare only makes the patch able to heal (its heartbeats
      // say so); the latch still needs its reset.
      const v1::RetareResult& r = m.retare_result();
      const auto o = static_cast<std::size_t>(r.outcome());
      ++counters_.retare_results[o < counters_.retare_results.size() ? o : 0];
      link.last_retare = r;
      if (r.request_id() == link.retare_pending) link.retare_pending = 0;
      break;
    }
    case v1::PatchMessage::BODY_NOT_SET:
      return ProtocolError(stream, s, "a message without a body", now_ns);
  }
  return {};
}

void Core::CloseStream(int stream, std::int64_t now_ns) {
  auto it = streams_.find(stream);
  if (it == streams_.end()) return;
  const int patch = it->second.patch;
  streams_.erase(it);
  if (patch < 0) return;
  PatchLink& link = links_[static_cast<std::size_t>(patch)];
  if (link.stream != stream) return;
  link.stream = -1;
  link.in_contact = false;
  Note(policy_.OnDisconnect(data_, policy_.patch_id(patch), now_ns));
}

JointRejection Core::OnJointState(const v1::JointState& js, std::int64_t now_ns, int joint_stream) {
  auto reject = [&](JointRejection r) {
    ++counters_.joint_states[static_cast<std::size_t>(r)];
    return r;
  };
  if (!setup_.robot) return reject(JointRejection::kNoRobot);
  const robot::Model& model = *setup_.robot;
  const std::size_t n = model.num_dof();
  // Names may be left empty: then the positions are in the robot's order (AggregatorStatus.joint_names).
  const bool named = js.names_size() > 0;
  if (static_cast<std::size_t>(js.positions_rad_size()) != n || (named && static_cast<std::size_t>(js.names_size()) != n)) {
    return reject(JointRejection::kWrongCount);
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (named && js.names(static_cast<int>(i)) != model.dof_joint(i).name) return reject(JointRejection::kWrongNames);
    if (!std::isfinite(js.positions_rad(static_cast<int>(i)))) return reject(JointRejection::kNotFinite);
  }
  // Plausible first (so a wild stamp never becomes the monotonic reference), then monotonic on this stream.
  if (FarApart(js.t_ns(), now_ns, setup_.safety.input.max_time_skew_ns)) return reject(JointRejection::kImplausibleTime);
  auto [last, fresh] = joint_stream_last_t_ns_.try_emplace(joint_stream, js.t_ns());
  if (!fresh) {
    if (js.t_ns() <= last->second) return reject(JointRejection::kNotMonotonic);
    last->second = js.t_ns();
  }
  JointSample sample;
  sample.t_ns = js.t_ns();
  sample.q.assign(js.positions_rad().begin(), js.positions_rad().end());
  // In time order (two streams, or a reconnect, may interleave); an equal stamp replaces the older sample.
  auto at = std::lower_bound(joints_.begin(), joints_.end(), sample.t_ns,
                             [](const JointSample& j, std::int64_t t) { return j.t_ns < t; });
  if (at != joints_.end() && at->t_ns == sample.t_ns) *at = std::move(sample);
  else joints_.insert(at, std::move(sample));
  while (joints_.size() > 2 && joints_.back().t_ns - joints_.front().t_ns > setup_.joint_history_ns) joints_.pop_front();
  joint_arrival_ns_ = now_ns;
  ++counters_.joint_states[0];
  Note(policy_.OnJointState(data_, now_ns));
  return JointRejection::kNone;
}

void Core::CloseJointStream(int joint_stream) { joint_stream_last_t_ns_.erase(joint_stream); }

void Core::JointsAt(std::int64_t t_ns, std::vector<double>& q) const {
  // Linear between the two samples around t_ns, else the nearest end.
  const auto after = std::find_if(joints_.begin(), joints_.end(), [&](const JointSample& j) { return j.t_ns >= t_ns; });
  if (after == joints_.begin()) {
    q = after->q;
  } else if (after == joints_.end()) {
    q = joints_.back().q;
  } else {
    const JointSample& b = *after;
    const JointSample& a = *(after - 1);
    const double w = static_cast<double>(t_ns - a.t_ns) / static_cast<double>(b.t_ns - a.t_ns);
    for (std::size_t i = 0; i < q.size(); ++i) q[i] = a.q[i] + w * (b.q[i] - a.q[i]);
  }
}

bool Core::PlaceContact(int patch, std::int64_t t_ns, const v1::PatchContact& c, v1::BodyContact& out) {
  const PatchExpectation& want = setup_.patches[static_cast<std::size_t>(patch)];
  if (!want.mount || !setup_.robot || joints_.empty()) return false;
  const robot::Model& model = *setup_.robot;
  JointsAt(t_ns, q_scratch_);
  if (robot::ForwardKinematics(model, q_scratch_, fk_) != robot::FkStatus::kOk) return false;
  const auto link = model.FindLink(want.mount->link);
  if (!link) return false;
  out.set_link(want.mount->link);
  patch::SurfacePoint sp;
  bool located = c.located();
  // An unlocated contact (force only) is placed at the patch's centre (a doubt about where, not whether).
  sp.y_mm = located ? c.y_mm() : 75.0;
  sp.r_deg = located ? c.r_deg() : 72.5;
  const robot::SurfaceInLink s = robot::PatchToLink(*want.mount, sp);
  out.mutable_p_lc_m()->set_x(s.p_LS_m.x());
  out.mutable_p_lc_m()->set_y(s.p_LS_m.y());
  out.mutable_p_lc_m()->set_z(s.p_LS_m.z());
  const Eigen::Isometry3d& X_BL = fk_.X_BL[*link];
  const Eigen::Vector3d p = X_BL * s.p_LS_m;
  const Eigen::Vector3d n = X_BL.linear() * s.n_L;
  out.mutable_p_bc_m()->set_x(p.x());
  out.mutable_p_bc_m()->set_y(p.y());
  out.mutable_p_bc_m()->set_z(p.z());
  out.mutable_normal_b()->set_x(n.x());
  out.mutable_normal_b()->set_y(n.y());
  out.mutable_normal_b()->set_z(n.z());
  out.set_located(located);
  return true;
}

v1::ResetStopResponse Core::OnReset(const v1::ResetStopRequest& r, bool authorized, std::int64_t now_ns) {
  if (!data_.events().empty()) DrainPolicyEvents();
  safety::ResetRequest req;
  req.stop_epoch = r.stop_epoch();
  req.authorized = authorized;
  req.other_run = r.aggregator_run_id() != setup_.run_id;  // 0 (not named) is never this run's
  const safety::ResetResult res = policy_.Reset(data_, req, now_ns);
  DrainPolicyEvents(r.operator_name());
  if (res.accepted) changed_ = true;
  v1::ResetStopResponse out;
  out.set_accepted(res.accepted);
  out.set_reason(static_cast<v1::ResetRefusal>(res.reason));
  out.set_message(safety::Describe(policy_, res));
  *out.mutable_state() = SafetyState();
  return out;
}

Core::RetareDecision Core::OnRetare(const v1::RetarePatchRequest& r, bool authorized, std::int64_t now_ns) {
  RetareDecision d;
  auto refuse = [&](v1::RetareRefusal why, const std::string& text) {
    ++counters_.retare_requests[static_cast<std::size_t>(why)];
    d.response.set_sent(false);
    d.response.set_reason(why);
    d.response.set_message(text);
    return d;
  };
  if (!authorized) return refuse(v1::RETARE_REFUSAL_UNAUTHORIZED, "only an operator may ask for a re-tare");
  if (r.aggregator_run_id() != setup_.run_id) {
    return refuse(v1::RETARE_REFUSAL_WRONG_RUN, "the request names another aggregator run (this one started since)");
  }
  const std::int32_t pi = policy_.FindPatch(r.patch_id());
  if (pi < 0) return refuse(v1::RETARE_REFUSAL_UNKNOWN_PATCH, "the scene has no patch '" + r.patch_id() + "'");
  const safety::State state = data_.state().state;
  if (state != safety::State::kStop && state != safety::State::kFault) {
    return refuse(v1::RETARE_REFUSAL_NOT_HELD, "the robot is not held (the state is neither STOP nor FAULT)");
  }
  PatchLink& link = links_[static_cast<std::size_t>(pi)];
  auto it = streams_.find(link.stream);
  if (link.stream < 0 || it == streams_.end() || !it->second.hello_done) {
    return refuse(v1::RETARE_REFUSAL_NOT_CONNECTED, "patch '" + r.patch_id() + "' has no live decoder stream");
  }
  if (link.retare_pending != 0 && now_ns - link.retare_sent_ns < kRetareAnswerNs) {
    return refuse(v1::RETARE_REFUSAL_BUSY, "re-tare " + std::to_string(link.retare_pending) + " of patch '" +
                                               r.patch_id() + "' is not answered yet");
  }
  ++counters_.retare_requests[0];
  link.retare_pending = ++retare_ids_;
  link.retare_sent_ns = now_ns;
  d.stream = link.stream;
  d.command = Command(now_ns);
  d.command->mutable_retare()->set_request_id(link.retare_pending);
  d.command->mutable_retare()->set_operator_name(r.operator_name());
  d.response.set_sent(true);
  d.response.set_request_id(link.retare_pending);
  d.response.set_message("re-tare " + std::to_string(link.retare_pending) + " sent to patch '" + r.patch_id() + "'");
  return d;
}

void Core::Tick(std::int64_t now_ns) { Note(policy_.Tick(data_, now_ns)); }

void Core::Publish(std::int64_t now_ns) { Note(policy_.Publish(data_, now_ns)); }

void Core::Shutdown(std::int64_t now_ns) { Note(policy_.Shutdown(data_, now_ns)); }

v1::SafetyState Core::SafetyState() const {
  const safety::SafetyState& s = data_.state();
  v1::SafetyState out;
  out.set_state(ToProto(s.state));
  out.set_stop_epoch(s.stop_epoch);
  out.set_seq(s.seq);
  out.set_changed_t_ns(s.changed_t_ns);
  out.set_published_t_ns(s.published_t_ns);
  out.set_aggregator_start_t_ns(start_ns_);
  out.set_aggregator_run_id(setup_.run_id);
  out.set_robot_name(setup_.robot_name);
  v1::SafetyCause* c = out.mutable_cause();
  c->set_kind(static_cast<v1::SafetyCause::Kind>(s.cause.kind));
  c->set_patch_id(std::string(policy_.patch_id(s.cause.patch)));
  c->set_body_region(std::string(policy_.region_name(s.cause.region)));
  if (s.cause.patch >= 0) {
    const auto& want = setup_.patches[static_cast<std::size_t>(s.cause.patch)];
    if (want.mount) c->set_link(want.mount->link);
  }
  // A NaN force (a doubt) is sent as -1: the wire never carries NaN; the message says what it was.
  c->set_force_n(std::isfinite(s.cause.force_n) ? s.cause.force_n : -1.0f);
  c->set_threshold_n(std::isfinite(s.cause.threshold_n) ? s.cause.threshold_n : -1.0f);
  // Only a finite position is published (the Core refuses non-finite ones before placement; this is the
  // last guard on the wire).
  if (s.cause.p_bc_m && std::isfinite((*s.cause.p_bc_m)[0]) && std::isfinite((*s.cause.p_bc_m)[1]) &&
      std::isfinite((*s.cause.p_bc_m)[2])) {
    c->mutable_p_bc_m()->set_x((*s.cause.p_bc_m)[0]);
    c->mutable_p_bc_m()->set_y((*s.cause.p_bc_m)[1]);
    c->mutable_p_bc_m()->set_z((*s.cause.p_bc_m)[2]);
  }
  c->set_patch_fault(static_cast<v1::PatchFaultCode>(s.cause.patch_fault));
  if (s.cause.kind == safety::CauseKind::kContact && s.cause.seam_partner != safety::kNoPatch) {
    c->set_seam_partner_patch_id(std::string(policy_.patch_id(s.cause.seam_partner)));
  }
  if (s.cause.kind != safety::CauseKind::kNone) c->set_message(safety::Describe(policy_, s.cause));
  c->set_t_ns(s.cause.t_ns);
  return out;
}

v1::ContactSet Core::Contacts(std::int64_t now_ns) {
  v1::ContactSet set;
  set.set_published_t_ns(now_ns);
  set.set_stop_epoch(data_.state().stop_epoch);
  if (!joints_.empty()) set.set_joint_state_t_ns(joints_.back().t_ns);
  // One joint state for the fusion: the one at the newest contact frame's time (the patches' frames lie within
  // a frame period of each other).
  std::int64_t t_fuse = 0;
  for (const PatchLink& link : links_) {
    if (link.stream >= 0 && link.in_contact && !link.doubtful) t_fuse = std::max(t_fuse, link.contact.t_ns());
  }
  // The newest contributing frame's interrogator time (0 when the set is empty), as the contract says.
  std::int64_t t_newest = 0;
  for (const PatchLink& link : links_) {
    if (link.stream >= 0 && link.in_contact) t_newest = std::max(t_newest, link.contact.t_ns());
  }
  set.set_t_ns(t_newest);
  bool can_fuse = fuser_ && !joints_.empty();
  if (can_fuse) {
    JointsAt(t_fuse, q_scratch_);
    can_fuse = robot::ForwardKinematics(*setup_.robot, q_scratch_, fk_latest_) == robot::FkStatus::kOk;
  }
  if (!can_fuse) {
    for (const PatchLink& link : links_) {
      if (link.stream >= 0 && link.in_contact) *set.add_contacts() = link.contact;
    }
    return set;
  }
  fusion_inputs_.clear();
  for (std::size_t i = 0; i < links_.size(); ++i) {
    const PatchLink& link = links_[i];
    if (link.stream < 0 || !link.in_contact || link.doubtful) continue;
    fusion::PatchInput in;
    in.patch = i;
    in.contact = SurfaceOf(link.surface);
    fusion_inputs_.push_back(in);
  }
  fuser_->Update(fusion_inputs_, std::span<const Eigen::Isometry3d>(fk_latest_.X_BL.data(), fk_latest_.X_BL.size()),
                 *fusion_data_);
  for (const fusion::BodyContact& f : fusion_data_->contacts()) {
    v1::BodyContact* b = set.add_contacts();
    b->set_link(setup_.robot->link(f.link).name);
    const Eigen::Vector3d p_L = fk_latest_.X_BL[f.link].inverse() * f.p_BC_m;
    b->mutable_p_lc_m()->set_x(p_L.x());
    b->mutable_p_lc_m()->set_y(p_L.y());
    b->mutable_p_lc_m()->set_z(p_L.z());
    b->mutable_p_bc_m()->set_x(f.p_BC_m.x());
    b->mutable_p_bc_m()->set_y(f.p_BC_m.y());
    b->mutable_p_bc_m()->set_z(f.p_BC_m.z());
    b->mutable_normal_b()->set_x(f.n_B.x());
    b->mutable_normal_b()->set_y(f.n_B.y());
    b->mutable_normal_b()->set_z(f.n_B.z());
    b->set_force_n(static_cast<float>(f.force_n));
    b->set_force_sd_n(static_cast<float>(std::sqrt(std::max(0.0, f.force_var_n2))));
    auto* cov = b->mutable_cov_p_bc_m2();
    cov->set_xx(f.cov_p_BC_m2(0, 0));
    cov->set_xy(f.cov_p_BC_m2(0, 1));
    cov->set_xz(f.cov_p_BC_m2(0, 2));
    cov->set_yy(f.cov_p_BC_m2(1, 1));
    cov->set_yz(f.cov_p_BC_m2(1, 2));
    cov->set_zz(f.cov_p_BC_m2(2, 2));
    b->set_located(f.located);
    std::uint64_t id = 0;
    std::int64_t onset = 0, t = 0;
    bool faint = true;  // every contributor's frame flagged faint (a fused force with one firm side is not)
    for (std::size_t i = 0; i < links_.size(); ++i) {
      if (!f.HasPatch(i)) continue;
      b->add_patch_ids(setup_.patches[i].id);
      const v1::BodyContact& own = links_[i].contact;
      if (own.multiple()) b->set_multiple(true);
      faint = faint && own.faint();
      if (id == 0 || own.contact_id() < id) id = own.contact_id();
      if (onset == 0 || own.onset_t_ns() < onset) onset = own.onset_t_ns();
      t = std::max(t, own.t_ns());
      if (b->body_region().empty()) {
        b->set_body_region(own.body_region());
        b->set_threshold_n(own.threshold_n());
      }
    }
    b->set_contact_id(id);
    b->set_onset_t_ns(onset);
    b->set_t_ns(t);
    b->set_faint(faint && b->patch_ids_size() > 0);
  }
  // A patch in contact that no fused contact covers (a doubt, or a contact the fusion refused) is shown as the
  // Core holds it, never dropped: something touches that patch.
  for (std::size_t i = 0; i < links_.size(); ++i) {
    const PatchLink& link = links_[i];
    if (link.stream < 0 || !link.in_contact) continue;
    bool covered = false;
    for (const fusion::BodyContact& f : fusion_data_->contacts()) covered = covered || f.HasPatch(i);
    if (!covered) *set.add_contacts() = link.contact;
  }
  return set;
}

v1::AggregatorStatus Core::Status(std::int64_t now_ns) const {
  v1::AggregatorStatus st;
  st.set_t_ns(now_ns);
  st.set_aggregator_start_t_ns(start_ns_);
  st.set_aggregator_run_id(setup_.run_id);
  st.set_robot_name(setup_.robot_name);
  *st.mutable_safety() = SafetyState();
  const auto patch_states = data_.patches();
  for (std::size_t i = 0; i < links_.size(); ++i) {
    const PatchLink& l = links_[i];
    v1::PatchStatus* p = st.add_patches();
    p->set_patch_id(setup_.patches[i].id);
    p->set_link_state(static_cast<v1::LinkState>(patch_states[i].link));
    p->set_last_seen_t_ns(l.last_seen_ns);
    p->set_last_t_ns(l.last_t_ns);
    p->set_last_seq(l.last_seq);
    p->set_clock_offset_ns(l.clock_offset_ns);
    if (patch_states[i].healthy_since_t_ns) p->set_healthy_since_t_ns(*patch_states[i].healthy_since_t_ns);
    *p->mutable_hello() = l.hello;
    *p->mutable_last_heartbeat() = l.heartbeat;
    *p->mutable_last_fault() = l.fault;
    *p->mutable_last_retare() = l.last_retare;
    p->set_retare_pending(l.retare_pending);
    for (const v1::SensitivityMap& m : setup_.patches[i].sensitivity) *p->add_sensitivity() = m;
  }
  for (const v1::RegionCoverage& c : setup_.coverage) *st.add_coverage() = c;
  // Age by arrival on the aggregator's own clock (the controller's clock is not this one): never negative.
  st.set_joint_state_age_ns(joint_arrival_ns_ < 0 ? -1 : std::max<std::int64_t>(0, now_ns - joint_arrival_ns_));
  if (!joints_.empty()) st.set_joint_state_t_ns(joints_.back().t_ns);
  if (setup_.robot) {
    for (std::size_t i = 0; i < setup_.robot->num_dof(); ++i) st.add_joint_names(setup_.robot->dof_joint(i).name);
  }
  st.set_aggregator_version("0.1.0");
  return st;
}

}  // namespace ruffini::aggregate
