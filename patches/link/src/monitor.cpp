#include "ruffini/link/monitor.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "ruffini/error.h"

namespace ruffini::link {

std::string_view FaultName(FaultCode c) noexcept {
  switch (c) {
    case FaultCode::kNone: return "none";
    case FaultCode::kInterrogatorSilent: return "interrogator_silent";
    case FaultCode::kInterrogatorDisconnected: return "interrogator_disconnected";
    case FaultCode::kFramesRejected: return "frames_rejected";
    case FaultCode::kFramesLost: return "frames_lost";
    case FaultCode::kBaselineInvalid: return "baseline_invalid";
    case FaultCode::kBaselineStale: return "baseline_stale";
    case FaultCode::kModelMismatch: return "model_mismatch";
    case FaultCode::kOverloaded: return "overloaded";
    case FaultCode::kShuttingDown: return "shutting_down";
    case FaultCode::kInternal: return "internal";
    case FaultCode::kLate: return "late";
  }
  return "unknown";
}

std::string_view BaselineStateName(BaselineState s) noexcept {
  switch (s) {
    case BaselineState::kUnspecified: return "unspecified";
    case BaselineState::kCapturing: return "capturing";
    case BaselineState::kTracking: return "tracking";
    case BaselineState::kFrozen: return "frozen";
    case BaselineState::kStale: return "stale";
  }
  return "unknown";
}

std::uint32_t RejectCode(decode::Reason r) noexcept { return static_cast<std::uint32_t>(r); }

std::uint32_t RejectCode(ingest::Reason r) noexcept {
  using R = ingest::Reason;
  switch (r) {
    case R::kContentTooLong: return 32;
    case R::kContentTooShort: return 33;
    case R::kBadPeaksLength: return 34;
    case R::kNegativeCount: return 35;
    case R::kCountMismatch: return 36;
    case R::kNonFinite: return 40;
    case R::kBadTimestamp: return 41;
    case R::kOutOfWindow: return 42;
    case R::kWrongPeakCount: return 43;
    case R::kUnorderedPeaks: return 44;
    case R::kPeakOutsideBands: return 45;
    case R::kDuplicatePeak: return 46;
    default: return 63;
  }
}

namespace {

template <typename Scalar>
class PipelineRunner final : public FramePipeline {
 public:
  PipelineRunner(const v1::DecoderModel& model, const patch::PatchSpec& spec, const decode::PipelineConfig& config,
                 decode::DecoderOptions options)
      : pipeline_(model, spec, config, std::move(options)), data_(pipeline_) {}
  decode::PipelineOutput Process(const Wavelengths& wl, std::uint32_t flags) noexcept override {
    return pipeline_.Process(wl, flags, data_);
  }
  [[nodiscard]] const decode::BaselineTracker& baseline() const noexcept override { return data_.baseline(); }
  [[nodiscard]] const decode::PipelineCounters& counters() const noexcept override { return data_.counters(); }
  [[nodiscard]] bool calibrated_uncertainty() const noexcept override { return pipeline_.calibrated_uncertainty(); }
  void OnStreamBreak() noexcept override { data_.ForgetTouches(); }
  void Retare(const Wavelengths& baseline_nm) noexcept override { pipeline_.Retare(baseline_nm, data_); }

 private:
  decode::Pipeline<Scalar> pipeline_;
  typename decode::Pipeline<Scalar>::Data data_;
};

float Finite(float v) { return std::isfinite(v) ? v : 0.0f; }

}  // namespace

DecoderChoice ParseDecoderChoice(const std::string& text, const v1::DecoderModel& model) {
  std::string offered = "paper-float, paper-double";
  for (const auto& net : model.location()) offered += ", " + net.grid().name() + "-float, " + net.grid().name() + "-double";
  const auto dash = text.rfind('-');
  const std::string scalar = dash == std::string::npos ? "" : text.substr(dash + 1);
  const std::string what = dash == std::string::npos ? text : text.substr(0, dash);
  if (what == "inversion") {
    throw InputError("--decoder " + text +
                     ": the inversion decoder is measured by `ruffini bench` only; the service does not offer it "
                     "(its response model is not part of the model file and its solver allocates per frame). "
                     "Choose one of: " + offered);
  }
  DecoderChoice c;
  c.name = text;
  if (scalar != "float" && scalar != "double") {
    throw InputError("--decoder " + text + ": expected <paper|GRID>-<float|double>; the model offers: " + offered);
  }
  c.use_double = scalar == "double";
  if (what == "paper") return c;
  for (int i = 0; i < model.location_size(); ++i) {
    if (model.location(i).grid().name() == what) {
      c.grid = i;
      return c;
    }
  }
  throw InputError("--decoder " + text + ": the model has no grid named '" + what + "'; it offers: " + offered);
}

std::unique_ptr<FramePipeline> MakePipeline(const v1::DecoderModel& model, const patch::PatchSpec& spec,
                                            const decode::PipelineConfig& config, const DecoderChoice& choice) {
  decode::DecoderOptions options;
  options.max_missing = config.max_missing;
  options.sample_rate_hz = config.baseline.sample_rate_hz;
  if (choice.grid >= 0) options.grids = {choice.grid};
  if (choice.use_double) return std::make_unique<PipelineRunner<double>>(model, spec, config, options);
  return std::make_unique<PipelineRunner<float>>(model, spec, config, options);
}

MonitorConfig Resolved(MonitorConfig c) {
  if (!(c.sample_rate_hz >= 1.0 && c.sample_rate_hz <= 100000.0)) {
    throw InputError("sample rate " + std::to_string(c.sample_rate_hz) + " Hz: expected 1 to 100000");
  }
  if (c.heartbeat_period_ns <= 0) throw InputError("heartbeat period must be positive");
  if (c.silence_deadline_ns < 0) throw InputError("silence deadline must not be negative");
  if (c.reject_fault_frames < 0) throw InputError("reject_fault_frames must not be negative");
  const double period_ns = 1e9 / c.sample_rate_hz;
  // 3 frame periods, but at least 15 ms: at 5 kHz 3 periods are 0.6 ms, and a general-purpose OS's wake-up
  // jitter tripped that about five times a second (docs/bench/service.md); 5 ms still tripped in the demo on a
  // loaded 2-core machine. Every such fault latches the robot. 15 ms keeps the aggregator's 30 ms patch
  // watchdog and the 50 ms fault budget.
  if (c.silence_deadline_ns == 0) {
    c.silence_deadline_ns = std::max<std::int64_t>(static_cast<std::int64_t>(std::ceil(3.0 * period_ns)), 15'000'000);
  }
  if (c.reject_fault_frames == 0) c.reject_fault_frames = std::max(3, static_cast<int>(std::lround(0.02 * c.sample_rate_hz)));
  if (!(c.capture_deadline_s > 0)) throw InputError("capture deadline must be positive");
  return c;
}

Monitor::Monitor(FramePipeline& pipeline, MonitorConfig config, Now now)
    : pipeline_(pipeline), config_(Resolved(config)) {
  next_heartbeat_mono_ = now.mono_ns;  // the first heartbeat at once
  health_.active_fault = FaultCode::kNone;  // the first Update reports the disconnected start as a fault
  health_.baseline = BaselineState::kCapturing;
}

void Monitor::Stamp(Message& m, Now now) const noexcept {
  m.serial = have_serial_ ? last_serial_ : 0;
  m.t_ns = last_t_ns_;
  m.decoder_t_ns = now.unix_ns;
  m.mono_ns = now.mono_ns;
}

void Monitor::FillHealth() noexcept {
  const auto& b = pipeline_.baseline();
  const auto& c = pipeline_.counters();
  health_.valid_frames = c.valid;
  health_.onsets = c.onsets;
  health_.faint_frames = c.faint;
  health_.release_refused_frames = c.release_refused;
  for (std::size_t i = 0; i < decode::kReasonCount; ++i) health_.decode_rejected[i] = c.invalid[i];
  health_.in_contact = in_contact_;
  switch (b.state()) {
    case decode::BaselineTracker::State::kCapturing: health_.baseline = BaselineState::kCapturing; break;
    case decode::BaselineTracker::State::kTracking: health_.baseline = BaselineState::kTracking; break;
    case decode::BaselineTracker::State::kFrozen: health_.baseline = BaselineState::kFrozen; break;
  }
  if (b.stale()) health_.baseline = BaselineState::kStale;
  health_.drift_pm = b.state() == decode::BaselineTracker::State::kCapturing ? 0.0f : Finite(static_cast<float>(b.drift_pm()));
  health_.common_mode_pm = Finite(b.common_mode_pm());
  health_.frozen_s = static_cast<float>(b.frozen_s());
}

void Monitor::Update(Now now, MessageSink& sink) noexcept {
  FillHealth();
  FaultCode fault = FaultCode::kNone;
  std::uint32_t reason = 0;
  const bool silent = !have_frame_ ? now.mono_ns - connected_mono_ > config_.silence_deadline_ns
                                   : now.mono_ns - last_frame_mono_ > config_.silence_deadline_ns;
  if (shutting_down_) {
    fault = FaultCode::kShuttingDown;
  } else if (!connected_) {
    fault = FaultCode::kInterrogatorDisconnected;
  } else if (silent) {
    fault = FaultCode::kInterrogatorSilent;
  } else if (overload_until_mono_ >= 0 && now.mono_ns < overload_until_mono_) {
    fault = FaultCode::kOverloaded;
  } else if (reject_run_ >= config_.reject_fault_frames) {
    fault = FaultCode::kFramesRejected;
    reason = last_reject_code_;
  } else if (health_.baseline == BaselineState::kStale) {
    fault = FaultCode::kBaselineStale;
  } else if (health_.baseline == BaselineState::kCapturing && first_frame_mono_ >= 0 &&
             static_cast<double>(now.mono_ns - first_frame_mono_) > config_.capture_deadline_s * 1e9) {
    fault = FaultCode::kBaselineInvalid;
  }
  const bool changed = fault != health_.active_fault;
  health_.active_fault = fault;
  health_.healthy = fault == FaultCode::kNone &&
                    (health_.baseline == BaselineState::kTracking || health_.baseline == BaselineState::kFrozen);
  if (changed && fault != FaultCode::kNone) {
    ++faults_[static_cast<std::size_t>(fault)];
    Message& m = scratch_;
    m.kind = Message::Kind::kFault;
    Stamp(m, now);
    m.health = health_;
    m.fault.code = fault;
    m.fault.reason = reason;
    const double ms = static_cast<double>(config_.silence_deadline_ns) / 1e6;
    switch (fault) {
      case FaultCode::kInterrogatorSilent:
        std::snprintf(m.fault.text.data(), m.fault.text.size(), "no frame from the interrogator for %.3f ms", ms);
        break;
      case FaultCode::kFramesRejected:
        std::snprintf(m.fault.text.data(), m.fault.text.size(), "%d frames in a row rejected (last reason %u)",
                      reject_run_, static_cast<unsigned>(reason));
        break;
      case FaultCode::kBaselineInvalid:
        std::snprintf(m.fault.text.data(), m.fault.text.size(), "no baseline %.1f s after the first frame",
                      config_.capture_deadline_s);
        break;
      case FaultCode::kBaselineStale:
        std::snprintf(m.fault.text.data(), m.fault.text.size(), "baseline frozen for %.1f s",
                      static_cast<double>(health_.frozen_s));
        break;
      default:
        std::snprintf(m.fault.text.data(), m.fault.text.size(), "%.*s", static_cast<int>(FaultName(fault).size()),
                      FaultName(fault).data());
    }
    sink.Push(m);
  }
  if (now.mono_ns >= next_heartbeat_mono_) {
    Message& m = scratch_;
    m.kind = Message::Kind::kHeartbeat;
    Stamp(m, now);
    m.health = health_;
    sink.Push(m);
    next_heartbeat_mono_ += config_.heartbeat_period_ns;
    if (next_heartbeat_mono_ <= now.mono_ns) next_heartbeat_mono_ = now.mono_ns + config_.heartbeat_period_ns;
  }
}

void Monitor::OnConnected(Now now, MessageSink& sink) noexcept {
  connected_ = true;
  have_frame_ = false;
  connected_mono_ = now.mono_ns;
  pipeline_.OnStreamBreak();
  InterruptRetare(now, sink);
  reject_run_ = 0;
  Update(now, sink);
}

void Monitor::OnDisconnected(Now now, MessageSink& sink) noexcept {
  connected_ = false;
  InterruptRetare(now, sink);
  Update(now, sink);
}

void Monitor::OnFrame(const FrameIn& f, Now now, MessageSink& sink) noexcept {
  ++health_.frames;
  have_frame_ = true;
  last_frame_mono_ = now.mono_ns;
  if (first_frame_mono_ < 0) first_frame_mono_ = now.mono_ns;
  if (have_serial_ && f.serial > last_serial_ + 1) {
    ++health_.serial_gaps;
    health_.frames_lost += f.serial - last_serial_ - 1;
  }
  if (have_serial_ && f.serial != last_serial_ + 1) {  // lost, repeated or restarted
    pipeline_.OnStreamBreak();
    InterruptRetare(now, sink);
  }
  have_serial_ = true;
  last_serial_ = f.serial;
  last_t_ns_ = f.t_ns;

  const decode::PipelineOutput o = pipeline_.Process(f.wavelength_nm, f.flags);
  if (retare_ && retare_->active()) {
    if (const auto r = retare_->Feed(f.wavelength_nm, o, pipeline_.baseline())) {
      // Accepted: the new baseline holds from the next frame; this frame's output stays as it was decoded.
      if (r->outcome == decode::RetareOutcome::kAccepted) pipeline_.Retare(retare_->baseline_nm());
      ReportRetare(retare_id_, *r, now, sink);
    }
  }
  if (o.over_range) {
    // More load than the model knows: a contact of at least the stated force, never a light one; reported,
    // so not a rejection run.
    reject_run_ = 0;
    Message& m = scratch_;
    m.kind = Message::Kind::kContact;
    Stamp(m, now);
    Contact& c = m.contact;
    c = Contact{};
    c.force_n = Finite(o.force_n);
    c.over_range = true;
    c.force_lower_bound_n = c.force_n;
    c.uncertainty = pipeline_.calibrated_uncertainty();
    c.onset = !in_contact_;
    c.common_mode_pm = Finite(o.common_mode_pm);
    c.missing = o.missing;
    in_contact_ = true;
    sink.Push(m);
  } else if (o.valid) {
    reject_run_ = 0;
    if (o.in_contact || in_contact_) {
      Message& m = scratch_;
      m.kind = Message::Kind::kContact;
      Stamp(m, now);
      Contact& c = m.contact;
      c = Contact{};
      // The frame that ends a contact carries the reading that closed the gate (below its 40 mN off level),
      // which is noise about 0 and reads down to -0.1 N at rest on a field cover. Sent as read, it crossed the
      // aggregator's negative-force doubt (-0.05 N: "decoders clamp at 0, further below is a broken decoder")
      // and fired a STOP on a release about 2 times an hour (ruffini field-hours, docs/experiments/field-hours.md).
      // A release is sent clamped at 0, as the contract says; an open gate never reads below its off level.
      c.force_n = o.in_contact ? Finite(o.force_n) : std::max(0.0f, Finite(o.force_n));
      c.uncertainty = pipeline_.calibrated_uncertainty();
      c.force_sd_n = c.uncertainty ? Finite(o.force_sd_n) : 0.0f;
      // A covariance that is not finite would be sent as 0 (a perfectly confident place): such a frame is sent
      // as force only, not located.
      const bool cov_ok = !c.uncertainty || (std::isfinite(o.cov_yy_mm2) && std::isfinite(o.cov_yr_mm2) &&
                                              std::isfinite(o.cov_rr_mm2));
      c.located = o.located && std::isfinite(o.y_mm) && std::isfinite(o.r_deg) && cov_ok;
      if (c.located) {
        c.y_mm = o.y_mm;
        c.r_deg = o.r_deg;
        c.confidence = Finite(o.confidence);
        if (c.uncertainty) {
          c.cov_yy_mm2 = Finite(o.cov_yy_mm2);
          c.cov_yr_mm2 = Finite(o.cov_yr_mm2);
          c.cov_rr_mm2 = Finite(o.cov_rr_mm2);
        }
        c.multiple = o.multiple;
      }
      c.faint = o.faint;  // information only: the force above stands
      c.onset = o.in_contact && !in_contact_;
      c.released = !o.in_contact;
      c.common_mode_pm = Finite(o.common_mode_pm);
      c.missing = o.missing;
      in_contact_ = o.in_contact;
      sink.Push(m);
    }
  } else if (o.reason != decode::Reason::kCapturing) {
    ++reject_run_;
    last_reject_code_ = RejectCode(o.reason);
    // A stale baseline ends the pipeline's contact; the fault says so, the next contact is a new onset.
    if (o.reason == decode::Reason::kBaselineStale) in_contact_ = false;
  }
  Update(now, sink);
}

void Monitor::OnStreamRejected(ingest::Reason reason, Now now, MessageSink& sink) noexcept {
  const auto i = static_cast<std::size_t>(reason);
  if (i < health_.stream_rejected.size()) ++health_.stream_rejected[i];
  have_frame_ = true;  // the interrogator is talking, if not sense: the reject run judges that
  last_frame_mono_ = now.mono_ns;
  ++reject_run_;
  last_reject_code_ = RejectCode(reason);
  Update(now, sink);
}

void Monitor::OnFramesDropped(std::uint64_t frames, Now now, MessageSink& sink) noexcept {
  if (frames == 0) return;
  health_.frames_dropped += frames;
  overload_until_mono_ = now.mono_ns + config_.overload_hold_ns;
  Update(now, sink);
}

void Monitor::Tick(Now now, MessageSink& sink) noexcept { Update(now, sink); }

void Monitor::Shutdown(Now now, MessageSink& sink) noexcept {
  shutting_down_ = true;
  next_heartbeat_mono_ = now.mono_ns + config_.heartbeat_period_ns;  // the fault is the last word
  Update(now, sink);
}

void Monitor::EnableRetare(const v1::ResponseMap* map, const decode::RetareConfig& config) {
  retare_ = std::make_unique<decode::Retare>(map, pipeline_.baseline().config(), config);
  retare_force_n_ = static_cast<float>(config.min_force_n);
}

void Monitor::ReportRetare(std::uint64_t request_id, const decode::RetareResult& r, Now now, MessageSink& sink) noexcept {
  ++retares_[static_cast<std::size_t>(r.outcome)];
  Message& m = scratch_;
  m.kind = Message::Kind::kRetare;
  Stamp(m, now);
  m.retare = RetareReport{};
  m.retare.request_id = request_id;
  m.retare.outcome = r.outcome;
  m.retare.force_n = Finite(static_cast<float>(r.force_n));
  m.retare.y_mm = Finite(static_cast<float>(r.y_mm));
  m.retare.r_deg = Finite(static_cast<float>(r.r_deg));
  m.retare.motion_pm = Finite(static_cast<float>(r.motion_pm));
  m.retare.min_force_n = retare_force_n_;
  sink.Push(m);
  // The health changes at once when the baseline did (the next heartbeat would say so anyway).
  if (r.outcome == decode::RetareOutcome::kAccepted) Update(now, sink);
}

void Monitor::InterruptRetare(Now now, MessageSink& sink) noexcept {
  if (!retare_) return;
  if (const auto r = retare_->Interrupt()) ReportRetare(retare_id_, *r, now, sink);
}

void Monitor::RequestRetare(std::uint64_t request_id, Now now, MessageSink& sink) noexcept {
  decode::RetareResult refused;
  refused.y_mm = refused.r_deg = 0.0;
  if (!retare_) {
    refused.outcome = decode::RetareOutcome::kNoMap;
    ReportRetare(request_id, refused, now, sink);
    return;
  }
  if (!retare_->Start()) {
    refused.outcome = decode::RetareOutcome::kBusy;  // the one under way goes on and reports its own id
    ReportRetare(request_id, refused, now, sink);
    return;
  }
  retare_id_ = request_id;
}

std::int64_t Monitor::NextDeadlineMono() const noexcept {
  std::int64_t d = next_heartbeat_mono_;
  if (connected_ && !shutting_down_) {
    const std::int64_t since = have_frame_ ? last_frame_mono_ : connected_mono_;
    d = std::min(d, since + config_.silence_deadline_ns + 1);
  }
  return d;  // an overload's end needs no deadline of its own: the next heartbeat notices it
}

}  // namespace ruffini::link
