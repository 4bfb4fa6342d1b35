// Ruffini safety client (safety_client.h). Depends only on gRPC, the ruffini.v1 stubs and the standard library.
#include "safety_client.h"

#include <algorithm>
#include <cstdio>
#include <stdexcept>
#include <utility>

namespace ruffini::controller {

namespace v1 = ruffini::v1;
using std::chrono::nanoseconds;

namespace {

std::string Ms(nanoseconds d) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f ms", static_cast<double>(d.count()) / 1e6);
  return buf;
}

std::string StatusText(const grpc::Status& s) {
  static constexpr const char* kCodes[] = {"OK", "CANCELLED", "UNKNOWN", "INVALID_ARGUMENT", "DEADLINE_EXCEEDED",
                                           "NOT_FOUND", "ALREADY_EXISTS", "PERMISSION_DENIED", "RESOURCE_EXHAUSTED",
                                           "FAILED_PRECONDITION", "ABORTED", "OUT_OF_RANGE", "UNIMPLEMENTED",
                                           "INTERNAL", "UNAVAILABLE", "DATA_LOSS", "UNAUTHENTICATED"};
  const int code = static_cast<int>(s.error_code());
  std::string text = code >= 0 && code <= 16 ? kCodes[code] : "code " + std::to_string(code);
  if (!s.error_message().empty()) text += ": " + s.error_message();
  return text;
}

std::string CauseKindName(v1::SafetyCause::Kind kind) {
  switch (kind) {
    case v1::SafetyCause::KIND_CONTACT: return "contact";
    case v1::SafetyCause::KIND_PATCH_FAULT: return "patch fault";
    case v1::SafetyCause::KIND_PATCH_SILENT: return "patch silent";
    case v1::SafetyCause::KIND_PATCH_MISSING: return "patch missing";
    case v1::SafetyCause::KIND_PATCH_PROTOCOL: return "patch protocol";
    case v1::SafetyCause::KIND_JOINT_STATES_STALE: return "joint states stale";
    case v1::SafetyCause::KIND_STARTUP: return "startup";
    case v1::SafetyCause::KIND_SHUTTING_DOWN: return "shutting down";
    case v1::SafetyCause::KIND_INTERNAL: return "internal";
    default: return "unknown";
  }
}

}  // namespace

std::string_view HaltReasonName(HaltReason reason) noexcept {
  switch (reason) {
    case HaltReason::kNotStarted: return "NOT_STARTED";
    case HaltReason::kStop: return "STOP";
    case HaltReason::kFault: return "FAULT";
    case HaltReason::kUnknownState: return "UNKNOWN_STATE";
    case HaltReason::kMissedStop: return "MISSED_STOP";
    case HaltReason::kNoHeartbeat: return "NO_HEARTBEAT";
    case HaltReason::kStreamEnded: return "STREAM_ENDED";
    case HaltReason::kConnectFailed: return "CONNECT_FAILED";
    case HaltReason::kWrongRobot: return "WRONG_ROBOT";
    case HaltReason::kNewRun: return "NEW_RUN";
    case HaltReason::kLinkError: return "LINK_ERROR";
    case HaltReason::kLate: return "LATE";
  }
  return "?";
}

std::string DescribeState(const v1::SafetyState& s) {
  std::string out;
  switch (s.state()) {
    case v1::SafetyState::STATE_CLEAR: out = "CLEAR"; break;
    case v1::SafetyState::STATE_STOP: out = "STOP"; break;
    case v1::SafetyState::STATE_FAULT: out = "FAULT"; break;
    default: out = "UNKNOWN(" + std::to_string(static_cast<int>(s.state())) + ")"; break;
  }
  out += " epoch " + std::to_string(s.stop_epoch());
  if (s.state() == v1::SafetyState::STATE_CLEAR || !s.has_cause()) return out;
  const auto& c = s.cause();
  out += " cause " + CauseKindName(c.kind());
  if (!c.patch_id().empty()) out += " " + c.patch_id();
  if (c.kind() == v1::SafetyCause::KIND_CONTACT) {
    char buf[48];
    std::snprintf(buf, sizeof buf, " %.2f N > %.2f N", static_cast<double>(c.force_n()),
                  static_cast<double>(c.threshold_n()));
    out += buf;
    if (!c.body_region().empty()) out += " (" + c.body_region() + ")";
  }
  return out;
}

// --- SafetyMonitor ---

namespace {
bool LinkReason(HaltReason r) {
  return r == HaltReason::kNoHeartbeat || r == HaltReason::kStreamEnded || r == HaltReason::kConnectFailed;
}
bool StateReason(HaltReason r) {
  return r == HaltReason::kStop || r == HaltReason::kFault || r == HaltReason::kUnknownState ||
         r == HaltReason::kMissedStop || r == HaltReason::kNewRun;
}
}  // namespace

SafetyMonitor::SafetyMonitor(MonitorConfig config, SteadyClock::time_point now)
    : config_(std::move(config)), halted_since_(now), last_evidence_(now) {
  if (config_.robot_name.empty()) {
    throw std::invalid_argument("safety client: MonitorConfig::robot_name is required (the scene's robot name)");
  }
  config_.states_before_clear = std::max(1, config_.states_before_clear);
  stats_.halted = true;
}

nanoseconds SafetyMonitor::Silence(SteadyClock::time_point now) const noexcept {
  return stream_open_ ? std::chrono::duration_cast<nanoseconds>(now - last_evidence_) : nanoseconds(0);
}

SafetyMonitor::Action SafetyMonitor::Halt(HaltReason reason, std::string detail, SteadyClock::time_point now,
                                          nanoseconds silence, const v1::SafetyState* state) {
  clear_streak_ = 0;  // every halt, told or not, ends the streak
  const v1::SafetyState& s = state ? *state : stats_.last_state;
  const std::uint64_t epoch = s.stop_epoch();
  const Run run = RunOf(s);
  if (halted_ && reason == reason_ && link_latched_ == halt_latched_ &&
      (!StateReason(reason) || (epoch == halt_epoch_ && run == halt_run_))) {
    return {};
  }
  if (!halted_) halted_since_ = now;
  halted_ = true;
  halt_latched_ = link_latched_;
  reason_ = reason;
  halt_epoch_ = epoch;
  halt_run_ = run;
  ++stats_.halts[static_cast<std::size_t>(reason)];
  Action a;
  a.kind = Action::Kind::kHalt;
  a.halt.reason = reason;
  a.halt.state = s;
  a.halt.detail = std::move(detail);
  a.halt.t = now;
  a.halt.silence = silence;
  a.halt.link_errors_latched = link_latched_;
  return a;
}

SafetyMonitor::Action SafetyMonitor::OnStreamOpened(SteadyClock::time_point now) {
  stream_open_ = true;
  stream_has_state_ = false;
  last_evidence_ = now;
  clear_streak_ = 0;
  ++stats_.streams_opened;
  // A new stream keeps what the client knows: the error-rate latch, the run's newest seq (a re-created stream
  // must not accept a replay of older states of the same run), the runs a newer run replaced, and the
  // aggregator run's clock offset (a delay that halted the old stream is not the new stream's "on time":
  // review of issue 15, F2). Only a new run's first state starts a clock anew.
  if (link_ && link_->aggregator_run_id() != 0 && link_->freshness().learned()) {
    remembered_clock_ = {link_->aggregator_run_id(), link_->freshness().offset_ns(), link_->freshness().last_arrival_ns()};
  }
  link_.reset();
  return {};
}

// Every received state passes here first: the safety layer (patches/channel: CRC, addressee, run, sequence,
// freshness; docs/safety-channel.md), then nothing else. A discarded state halts.
StateVerdict SafetyMonitor::CheckState(const v1::SafetyState& s, SteadyClock::time_point arrival) {
  if (!link_) {
    link_.emplace(config_.link, config_.robot_name);
    if (remembered_clock_.run_id != 0) {
      link_->RememberSender(remembered_clock_.run_id, remembered_clock_.offset_ns, remembered_clock_.last_arrival_ns);
    }
  }
  if (!rate_) rate_.emplace(config_.link.error_rate);
  const std::int64_t arrival_ns =
      std::chrono::duration_cast<std::chrono::nanoseconds>(arrival.time_since_epoch()).count();
  channel::Verdict v = link_->Receive(s, arrival_ns);
  const bool dead_run =
      std::find(dead_runs_.begin(), dead_runs_.end(), s.aggregator_run_id()) != dead_runs_.end();
  if (v.use && dead_run) {
    // A state of an aggregator run a newer run has replaced (a recording replayed after a restart: review of
    // issue 15, F3): no live aggregator sends it. An insertion.
    stats_.link_errors.Count(channel::Error::kInsertion);
    v.use = false;
    v.error = true;
    v.kind = channel::Error::kInsertion;
  } else if (v.use && s.aggregator_run_id() == seq_run_ && s.seq() < seq_last_) {
    // An older state of the same run on a new stream (a replay): an incorrect sequence. The same seq is
    // allowed: a new subscription's first state repeats the one in force.
    stats_.link_errors.Count(channel::Error::kIncorrectSequence);
    v.use = false;
    v.error = true;
    v.kind = channel::Error::kIncorrectSequence;
  } else if (v.error) {
    stats_.link_errors.Count(v.kind);
  }
  // Every error but a tolerated loss counts toward the latch, over the client's lifetime.
  if (v.error && v.kind != channel::Error::kLoss && rate_->Record(arrival_ns)) link_latched_ = true;
  if (v.use && !link_latched_) {
    if (s.aggregator_run_id() != seq_run_) {
      if (seq_run_ != 0) {
        dead_runs_.push_back(seq_run_);  // replaced by a newer run: never believed again
        if (dead_runs_.size() > 64) dead_runs_.erase(dead_runs_.begin());
      }
      seq_run_ = s.aggregator_run_id();
      seq_last_ = s.seq();
    } else {
      seq_last_ = std::max(seq_last_, s.seq());
    }
  }
  if (!v.use) {
    if (v.kind == channel::Error::kAddressing) {
      return StateVerdict::Discard(HaltReason::kWrongRobot, "a state for robot '" + s.robot_name() +
                                                                "', not this controller's '" + config_.robot_name + "'");
    }
    if (v.kind == channel::Error::kDelay) {
      return StateVerdict::Discard(HaltReason::kLate,
                                   "a state " + std::to_string(v.age_ns / 1'000'000) + " ms old (budget " +
                                       std::to_string(config_.link.freshness.budget_ns / 1'000'000) + " ms)");
    }
    return StateVerdict::Discard(HaltReason::kLinkError,
                                 "the safety layer discarded a state: " + std::string(channel::Name(v.kind)) +
                                     (link_latched_ ? " (error-rate limit reached: no state is used until acknowledged)" : ""));
  }
  if (link_latched_) {
    return StateVerdict::Discard(HaltReason::kLinkError,
                                 "the error-rate limit was reached: no state is used until an operator acknowledges it");
  }
  return StateVerdict::Accept();
}

SafetyMonitor::Action SafetyMonitor::OnState(const v1::SafetyState& s, SteadyClock::time_point now) {
  if (!stream_open_) OnStreamOpened(now);  // tolerate a driver that did not say so
  ++stats_.states;
  StateVerdict verdict = CheckState(s, now);
  if (!verdict.accept) {
    ++stats_.discarded;
    ++stats_.discarded_by[static_cast<std::size_t>(verdict.halt)];
    discard_reason_[static_cast<std::size_t>(verdict.halt)] = true;
    return Halt(verdict.halt, std::move(verdict.detail), now, nanoseconds(0), &s);
  }
  const Run run = RunOf(s);
  const bool new_run = have_run_ && run != run_;
  const nanoseconds gap = std::chrono::duration_cast<nanoseconds>(now - last_evidence_);
  if (stream_has_state_) stats_.max_state_gap = std::max(stats_.max_state_gap, gap);
  // A clean state follows the one before it (or the stream's start) within the watchdog: a late one means a
  // silence, whether or not a watchdog tick saw it (a starved watchdog thread): halt and start the streak again.
  const bool late = gap > config_.heartbeat_timeout;
  if (late) clear_streak_ = 0;
  if (have_run_ && !new_run && s.seq() > stats_.last_state.seq() + 1) {
    stats_.skipped_states += s.seq() - stats_.last_state.seq() - 1;
  }
  if (!have_run_ || new_run) have_epoch_ = false;  // a restarted aggregator counts epochs from 1 again
  have_run_ = true;
  run_ = run;
  const bool new_epoch = have_epoch_ && s.stop_epoch() != last_epoch_;
  have_epoch_ = true;
  last_epoch_ = s.stop_epoch();
  stats_.last_state = s;
  stream_has_state_ = true;
  last_evidence_ = now;

  Action a = OnAcceptedState(s, new_run, new_epoch, late, now);
  // A decision on the state itself says more than the silence before it; else the silence is told (one
  // decision per event, as the callbacks see them).
  if (a.kind == Action::Kind::kNone && late) return OnSilence(gap, now);
  return a;
}

SafetyMonitor::Action SafetyMonitor::OnAcceptedState(const v1::SafetyState& s, bool new_run, bool new_epoch,
                                                     bool late, SteadyClock::time_point now) {
  switch (s.state()) {
    case v1::SafetyState::STATE_CLEAR: {
      if (new_run) {  // the streak starts after it: three clean states of the new run
        return Halt(HaltReason::kNewRun,
                    "CLEAR from a new aggregator run (restarted, or another aggregator): clean states again", now);
      }
      if (new_epoch) {
        return Halt(HaltReason::kMissedStop,
                    "CLEAR with a new stop_epoch: a stop and its reset happened in states not received", now);
      }
      if (!halted_) return {};
      if (late) return {};  // it ends a silence: not within the watchdog of the state before, so not clean
      if (++clear_streak_ < config_.states_before_clear) return {};
      Action a;
      a.kind = Action::Kind::kClear;
      a.clear.state = s;
      a.clear.t = now;
      a.clear.halted_for = std::chrono::duration_cast<nanoseconds>(now - halted_since_);
      stats_.time_halted += a.clear.halted_for;
      ++stats_.clears;
      halted_ = false;
      clear_streak_ = 0;
      return a;
    }
    case v1::SafetyState::STATE_STOP: return Halt(HaltReason::kStop, DescribeState(s), now);
    case v1::SafetyState::STATE_FAULT: return Halt(HaltReason::kFault, DescribeState(s), now);
    default: return Halt(HaltReason::kUnknownState, DescribeState(s) + " (treated as STOP)", now);
  }
}

SafetyMonitor::Action SafetyMonitor::OnStreamEnded(const std::string& detail, SteadyClock::time_point now) {
  const bool had_state = stream_has_state_;
  stream_open_ = false;
  stream_has_state_ = false;
  return had_state ? Halt(HaltReason::kStreamEnded, "stream ended: " + detail, now)
                   : Halt(HaltReason::kConnectFailed, "no stream: " + detail, now);
}

SafetyMonitor::Action SafetyMonitor::OnTick(SteadyClock::time_point now) { return OnSilence(Silence(now), now); }

SafetyMonitor::Action SafetyMonitor::OnSilence(nanoseconds silence, SteadyClock::time_point now) {
  if (!stream_open_ || silence <= config_.heartbeat_timeout) return {};
  clear_streak_ = 0;  // the three-clean-states rule holds after this silence too
  // Once halted for the link itself, or for states the safety layer discards (they are no heartbeat either),
  // only an accepted state (or the stream's end) changes the reason.
  if (halted_ && (LinkReason(reason_) || discard_reason_[static_cast<std::size_t>(reason_)])) return {};
  return Halt(HaltReason::kNoHeartbeat,
              "no state for " + Ms(silence) + " (limit " + Ms(config_.heartbeat_timeout) + ")", now, silence);
}

SafetyStats SafetyMonitor::Stats(SteadyClock::time_point now) const {
  SafetyStats s = stats_;
  s.halted = halted_;
  s.reason = reason_;
  s.link_errors_latched = link_latched_;
  if (halted_) s.time_halted += std::chrono::duration_cast<nanoseconds>(now - halted_since_);
  return s;
}

// --- channel ---

std::shared_ptr<grpc::Channel> MakeAggregatorChannel(const std::string& target,
                                                     std::shared_ptr<grpc::ChannelCredentials> credentials,
                                                     std::chrono::milliseconds initial_backoff,
                                                     std::chrono::milliseconds max_backoff) {
  grpc::ChannelArguments args;
  args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, static_cast<int>(initial_backoff.count()));
  args.SetInt(GRPC_ARG_MIN_RECONNECT_BACKOFF_MS, static_cast<int>(initial_backoff.count()));
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, static_cast<int>(max_backoff.count()));
  args.SetInt(GRPC_ARG_KEEPALIVE_TIME_MS, 1000);
  args.SetInt(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, 1000);
  args.SetInt(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
  args.SetInt(GRPC_ARG_HTTP2_MAX_PINGS_WITHOUT_DATA, 0);  // WatchSafety sends no data after its request
  args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);     // a channel made again dials anew
  if (!credentials) credentials = grpc::InsecureChannelCredentials();
  return grpc::CreateCustomChannel(target, credentials, args);
}

ChannelFactory AggregatorChannelFactory(std::string target, std::shared_ptr<grpc::ChannelCredentials> credentials) {
  return [target = std::move(target), credentials = std::move(credentials)] {
    return MakeAggregatorChannel(target, credentials);
  };
}

// --- SafetyClient ---

SafetyClient::SafetyClient(ChannelFactory make_channel, SafetyClientConfig config, HaltCallback on_halt,
                           ClearCallback on_clear)
    : make_channel_(std::move(make_channel)),
      config_(std::move(config)),
      on_halt_(std::move(on_halt)),
      on_clear_(std::move(on_clear)),
      monitor_(config_.monitor, SteadyClock::now()) {
  if (!make_channel_) throw std::invalid_argument("safety client: no channel factory");
  Mirror();
}

SafetyClient::~SafetyClient() { Stop(); }

void SafetyClient::Start() {
  std::lock_guard lock(mu_);
  if (started_) return;
  started_ = true;
  notifier_ = std::thread([this] { NotifyLoop(); });
  reader_ = std::thread([this] { ReadLoop(); });
  watchdog_ = std::thread([this] { WatchdogLoop(); });
}

void SafetyClient::Stop() {
  {
    std::lock_guard lock(ctx_mu_);
    if (stopping_.exchange(true)) return;
    if (ctx_) ctx_->TryCancel();
  }
  halted_.store(true, std::memory_order_release);
  stop_cv_.notify_all();
  {
    std::lock_guard lock(notify_mu_);
  }
  notify_cv_.notify_all();
  if (reader_.joinable()) reader_.join();
  if (watchdog_.joinable()) watchdog_.join();
  if (notifier_.joinable()) notifier_.join();
  halted_.store(true, std::memory_order_release);
}

bool SafetyClient::AcknowledgeLinkErrors() {
  std::lock_guard lock(mu_);
  return monitor_.AcknowledgeLinkErrors();
}

SafetyStats SafetyClient::Stats() const {
  std::lock_guard lock(mu_);
  SafetyStats s = monitor_.Stats(SteadyClock::now());
  s.channels_created = channels_created_;
  return s;
}

void SafetyClient::Mirror() {
  evidence_ns_.store(monitor_.last_evidence().time_since_epoch().count(), std::memory_order_release);
  stream_open_.store(monitor_.stream_open(), std::memory_order_release);
}

void SafetyClient::Apply(SafetyMonitor::Action a) {
  Mirror();
  if (a.kind == SafetyMonitor::Action::Kind::kNone) return;
  if (a.kind == SafetyMonitor::Action::Kind::kHalt) {
    halted_.store(true, std::memory_order_release);
  } else if (!stopping_) {
    halted_.store(false, std::memory_order_release);
  }
  if (stopping_) return;
  if (a.kind == SafetyMonitor::Action::Kind::kHalt ? !on_halt_ : !on_clear_) return;
  {
    std::lock_guard lock(notify_mu_);
    pending_.push_back(std::move(a));
  }
  notify_cv_.notify_one();
}

void SafetyClient::NotifyLoop() {
  std::unique_lock lock(notify_mu_);
  for (;;) {
    notify_cv_.wait(lock, [this] { return stopping_.load() || !pending_.empty(); });
    if (stopping_) return;
    SafetyMonitor::Action a = std::move(pending_.front());
    pending_.pop_front();
    lock.unlock();
    // No lock of the client is held here: a slow callback delays only the callbacks after it.
    if (a.kind == SafetyMonitor::Action::Kind::kHalt) {
      on_halt_(a.halt);
    } else {
      on_clear_(a.clear);
    }
    lock.lock();
  }
}

void SafetyClient::ReadLoop() {
  auto pause = config_.reconnect_initial;
  v1::WatchSafetyRequest request;
  request.set_subscriber(config_.subscriber);
  bool remake = true;
  while (!stopping_) {
    if (remake) {
      channel_ = make_channel_();
      stub_ = v1::Aggregator::NewStub(channel_);
      std::lock_guard lock(mu_);
      ++channels_created_;
    }
    grpc::ClientContext ctx;
    {
      std::lock_guard lock(ctx_mu_);
      if (stopping_) break;
      ctx_ = &ctx;
    }
    cancelled_for_silence_.store(false);
    auto reader = stub_->WatchSafety(&ctx, request);
    {
      std::lock_guard lock(mu_);
      Apply(monitor_.OnStreamOpened(SteadyClock::now()));
    }
    bool any = false;
    v1::SafetyState state;
    while (reader->Read(&state)) {
      any = true;
      const auto arrival = SteadyClock::now();
      std::lock_guard lock(mu_);
      Apply(monitor_.OnState(state, arrival));
    }
    const grpc::Status status = reader->Finish();
    {
      std::lock_guard lock(ctx_mu_);
      ctx_ = nullptr;
    }
    if (stopping_) break;  // our own cancel: not a decision to report
    {
      std::lock_guard lock(mu_);
      const std::string detail =
          cancelled_for_silence_.load()
              ? "cancelled after " + std::to_string(config_.cancel_silent_stream_after.count()) +
                    " ms without an accepted state (a new connection follows)"
              : StatusText(status);
      Apply(monitor_.OnStreamEnded(detail, SteadyClock::now()));
    }
    // A silent stream we cancelled, or a dead transport: a new channel, so the next call dials a new
    // connection instead of riding the old one.
    remake = cancelled_for_silence_.load() || status.error_code() == grpc::StatusCode::UNAVAILABLE;
    pause = any ? config_.reconnect_initial : std::min(pause * 2, config_.reconnect_max);
    // At least reconnect_initial; after that, go as soon as the channel is connected again (the channel
    // retries on its own backoff), or when the pause is over.
    const auto until = SteadyClock::now() + pause;
    {
      std::unique_lock lock(ctx_mu_);
      if (stop_cv_.wait_for(lock, config_.reconnect_initial, [this] { return stopping_.load(); })) break;
      // A new channel connects on the call itself, after the whole pause (no channel state to wait on).
      if (remake && stop_cv_.wait_until(lock, until, [this] { return stopping_.load(); })) break;
    }
    if (remake) continue;
    while (!stopping_ && SteadyClock::now() < until) {
      const auto slice = std::min<SteadyClock::duration>(until - SteadyClock::now(), std::chrono::milliseconds(20));
      if (channel_->WaitForConnected(std::chrono::system_clock::now() + slice)) break;
    }
  }
}

void SafetyClient::WatchdogLoop() {
  // Its own clock and the atomics the reader mirrors: a halt for silence takes no lock before halted()
  // is true, so nothing the reader or a callback does can delay it.
  const auto timeout = config_.monitor.heartbeat_timeout;
  auto next = SteadyClock::now();
  while (!stopping_) {
    next += config_.watchdog_tick;
    std::this_thread::sleep_until(next);
    const auto now = SteadyClock::now();
    if (next < now - config_.watchdog_tick * 10) next = now;  // the thread was not scheduled: do not catch up
    if (!stream_open_.load(std::memory_order_acquire)) continue;
    const SteadyClock::time_point evidence{SteadyClock::duration(evidence_ns_.load(std::memory_order_acquire))};
    const auto silence = std::chrono::duration_cast<nanoseconds>(now - evidence);
    if (silence <= timeout) continue;
    halted_.store(true, std::memory_order_release);
    {
      std::lock_guard lock(mu_);
      // The monitor agrees with what was stored: the silence seen, even if a state is being handled now.
      Apply(monitor_.OnSilence(std::max(silence, monitor_.Silence(now)), now));
    }
    if (silence > config_.cancel_silent_stream_after) {
      std::lock_guard lock(ctx_mu_);
      if (ctx_ && !cancelled_for_silence_.exchange(true)) ctx_->TryCancel();
    }
  }
}

// --- JointStatePublisher ---

JointStatePublisher::JointStatePublisher(std::shared_ptr<grpc::Channel> channel, std::vector<std::string> joint_names,
                                         std::chrono::milliseconds retry_pause)
    : stub_(v1::Aggregator::NewStub(std::move(channel))), names_(std::move(joint_names)), retry_pause_(retry_pause) {}

JointStatePublisher::~JointStatePublisher() {
  v1::PublishJointStatesResponse ignored;
  Finish(&ignored);
}

bool JointStatePublisher::Publish(std::span<const double> positions_rad, std::span<const double> velocities_rad_s,
                                  std::int64_t t_ns) {
  if (cancelled_) return false;
  if (!writer_) {
    const auto now = SteadyClock::now();
    if (now < next_try_) {
      ++failed_;
      return false;
    }
    next_try_ = now + retry_pause_;
    auto ctx = std::make_unique<grpc::ClientContext>();
    response_.Clear();
    auto writer = stub_->PublishJointStates(ctx.get(), &response_);
    std::lock_guard lock(ctx_mu_);
    if (cancelled_) return false;
    ctx_ = std::move(ctx);
    writer_ = std::move(writer);
    seq_ = 0;
  }
  msg_.Clear();
  // Names on every message: the aggregator accepts a state without them (the positions are then in its robot's
  // joint order) and checks them when present, so named states turn a joint list in another order into a
  // counted rejection (wrong_names) instead of a wrong pose; seven short strings a message are cheap.
  for (const auto& n : names_) msg_.add_names(n);
  for (double q : positions_rad) msg_.add_positions_rad(q);
  for (double v : velocities_rad_s) msg_.add_velocities_rad_s(v);
  msg_.set_t_ns(t_ns);
  msg_.set_seq(++seq_);
  if (!writer_->Write(msg_)) {
    ++failed_;
    EndStream(std::chrono::milliseconds(100));  // the write failed: the call is over, Finish returns at once
    return false;
  }
  ++written_;
  return true;
}

grpc::Status JointStatePublisher::EndStream(std::chrono::milliseconds deadline) {
  if (!writer_) return grpc::Status::OK;
  // WritesDone and Finish wait for the aggregator; on a frozen link they would wait forever. A helper
  // thread cancels the call when the deadline passes (a call's own deadline cannot be set after it began).
  std::mutex m;
  std::condition_variable cv;
  bool done = false;
  std::thread canceller([&] {
    std::unique_lock lock(m);
    if (!cv.wait_for(lock, deadline, [&] { return done; })) {
      std::lock_guard ctx_lock(ctx_mu_);
      if (ctx_) ctx_->TryCancel();
    }
  });
  writer_->WritesDone();
  const grpc::Status status = writer_->Finish();
  {
    std::lock_guard lock(m);
    done = true;
  }
  cv.notify_one();
  canceller.join();
  totals_.set_received(totals_.received() + response_.received());
  totals_.set_accepted(totals_.accepted() + response_.accepted());
  totals_.set_rejected(totals_.rejected() + response_.rejected());
  if (!response_.last_rejection().empty()) totals_.set_last_rejection(response_.last_rejection());
  response_.Clear();
  std::lock_guard lock(ctx_mu_);
  writer_.reset();
  ctx_.reset();
  return status;
}

grpc::Status JointStatePublisher::Finish(v1::PublishJointStatesResponse* totals, std::chrono::milliseconds deadline) {
  const grpc::Status status = EndStream(deadline);
  if (totals) *totals = totals_;
  return status;
}

void JointStatePublisher::Cancel() {
  std::lock_guard lock(ctx_mu_);
  cancelled_ = true;
  if (ctx_) ctx_->TryCancel();
}

// --- ResetStop ---

grpc::Status ResetStop(v1::Aggregator::Stub& stub, std::uint64_t aggregator_run_id, std::uint64_t stop_epoch,
                       const std::string& operator_name, const std::string& operator_note,
                       v1::ResetStopResponse* response, std::chrono::milliseconds timeout) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + timeout);
  v1::ResetStopRequest request;
  request.set_aggregator_run_id(aggregator_run_id);
  request.set_stop_epoch(stop_epoch);
  request.set_operator_name(operator_name);
  request.set_operator_note(operator_note);
  return stub.ResetStop(&ctx, request, response);
}

}  // namespace ruffini::controller
