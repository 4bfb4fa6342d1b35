#include "server.h"

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>
#include <prometheus/collectable.h>
#include <prometheus/metric_family.h>
#include <prometheus/metric_type.h>
#include <prometheus/exposer.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <functional>
#include <future>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <thread>

#include "ruffini/error.h"
#include "ruffini/service/keepalive.h"
#include "ruffini/service/process_metrics.h"
#include "ruffini/service/atomic_histogram.h"
#include "ruffini/v1/aggregator.grpc.pb.h"

namespace ruffini::aggregator {

namespace {

constexpr const char* kVersion = "0.1.0";

// Shared between a Connect/Joint reactor and the events it posts: the reactor is deleted in OnDone, after which
// `alive` is false and the posted events do nothing (they hold the Guard, never only the reactor). One
// recursive mutex guards the reactor's state (a reaction may run inline in a call the loop makes).
struct Guard {
  std::recursive_mutex mu;
  bool alive = true;
};

// Latest-value slot writer for WatchSafety / WatchContacts. Owned by shared_ptr, never by `delete this`: the
// reactor holds itself (self_) until OnDone; the loop's subscriber set holds it from the posted insert to the
// posted erase (which OnDone posts), so every call the loop makes is on a live object, and after OnDone
// (done_, checked under mu_) the call does nothing. Every path ends in exactly one Finish: FinishWith (the
// loop), a failed write, or a cancellation with no write in flight.
// What a subscriber asked for (WatchSafetyRequest / WatchContactsRequest), fixed at subscription.
struct WatchOptions {
  std::int64_t period_ns = 0;      // the longest gap wanted, clamped (ClampPeriod)
  std::vector<std::string> links;  // WatchContacts: only these URDF links (empty: all)
  float min_force_n = 0;           // WatchContacts: only contacts at or above this force
  [[nodiscard]] bool filters() const { return !links.empty() || min_force_n > 0; }
};

template <typename Msg>
class WatchReactor final : public grpc::ServerWriteReactor<Msg>, public std::enable_shared_from_this<WatchReactor<Msg>> {
 public:
  using Ptr = std::shared_ptr<WatchReactor>;
  [[nodiscard]] const WatchOptions& options() const noexcept { return options_; }
  // on_done runs once, from OnDone, with the last reference gRPC held; it posts the erase from the loop's set.
  static Ptr Make(grpc::CallbackServerContext* ctx, WatchOptions options, std::function<void(Ptr)> on_done) {
    Ptr r(new WatchReactor(ctx, std::move(options), std::move(on_done)));
    r->self_ = r;
    return r;
  }

  // Loop thread.
  void Offer(const Msg& m, std::int64_t mono_ns) {
    const Ptr keep = this->shared_from_this();  // a reaction run inline may end the call
    std::lock_guard lock(mu_);
    // After Finish (ours, or after a failed write) and before OnDone, nothing may be started on the stream.
    if (done_ || finishing_ || finished_) return;
    if (writing_) {
      pending_ = m;  // replaces an older pending state: the newest wins (seq and stop_epoch tell what was skipped)
      return;
    }
    current_ = m;
    writing_ = true;
    write_started_ns_ = mono_ns;
    this->StartWrite(&current_);
  }
  // A write stuck past the deadline: cancel the call; OnWriteDone(false) / OnDone follow. Returns true when
  // this subscriber was dropped now.
  bool CheckStuck(std::int64_t mono_ns, std::int64_t deadline_ns) {
    const Ptr keep = this->shared_from_this();
    std::lock_guard lock(mu_);
    if (done_ || !writing_ || dropped_ || mono_ns - write_started_ns_ <= deadline_ns) return false;
    dropped_ = true;
    ctx_->TryCancel();
    return true;
  }
  // Ends the stream after the write in flight (if any) with this status.
  void FinishWith(const grpc::Status& status) {
    const Ptr keep = this->shared_from_this();
    std::lock_guard lock(mu_);
    if (done_ || finishing_ || finished_) return;
    finishing_ = true;
    final_ = status;
    if (!writing_) {
      finished_ = true;  // exactly one Finish: OnWriteDone must not finish again
      if (pending_) {
        current_ = *pending_;
        pending_.reset();
        writing_ = true;
        this->StartWriteAndFinish(&current_, grpc::WriteOptions(), final_);
      } else {
        this->Finish(final_);
      }
    }
  }

  void OnWriteDone(bool ok) override {
    const Ptr keep = this->shared_from_this();
    std::lock_guard lock(mu_);
    writing_ = false;
    if (finished_) return;  // the last write went out with StartWriteAndFinish
    if (!ok) {
      finished_ = true;
      this->Finish(grpc::Status(grpc::StatusCode::CANCELLED, "write failed"));
      return;
    }
    if (pending_) {
      current_ = *pending_;
      pending_.reset();
      writing_ = true;
      if (finishing_) {
        finished_ = true;
        this->StartWriteAndFinish(&current_, grpc::WriteOptions(), final_);
      } else {
        this->StartWrite(&current_);
      }
    } else if (finishing_) {
      finished_ = true;
      this->Finish(final_);
    }
  }
  // The client cancelled (or the transport died): with no write in flight nothing else would finish the call
  // until the next Offer; with one, OnWriteDone(false) does.
  void OnCancel() override {
    const Ptr keep = this->shared_from_this();
    std::lock_guard lock(mu_);
    if (finished_ || writing_) return;
    finished_ = true;
    this->Finish(grpc::Status(grpc::StatusCode::CANCELLED, "cancelled"));
  }
  void OnDone() override {
    Ptr self;
    {
      std::lock_guard lock(mu_);
      done_ = true;
      self = std::move(self_);
    }
    on_done_(std::move(self));  // the object lives on in the loop's set until the posted erase
  }

 private:
  WatchReactor(grpc::CallbackServerContext* ctx, WatchOptions options, std::function<void(Ptr)> on_done)
      : ctx_(ctx), options_(std::move(options)), on_done_(std::move(on_done)) {}

  grpc::CallbackServerContext* ctx_;  // valid until OnDone
  const WatchOptions options_;
  std::function<void(Ptr)> on_done_;
  Ptr self_;
  std::recursive_mutex mu_;
  Msg current_;
  std::optional<Msg> pending_;
  bool writing_ = false, finishing_ = false, finished_ = false, dropped_ = false, done_ = false;
  grpc::Status final_;
  std::int64_t write_started_ns_ = 0;
};

using SafetyReactor = WatchReactor<v1::SafetyState>;
using ContactsReactor = WatchReactor<v1::ContactSet>;

struct Stats {
  std::atomic<int> state{3};
  std::atomic<std::uint64_t> stop_epoch{1}, seq{0}, stops{0}, faults{0}, resets_accepted{0}, resets_refused{0};
  std::atomic<std::uint64_t> messages{0}, hellos_accepted{0}, hellos_refused{0}, protocol_errors{0};
  std::atomic<std::uint64_t> joint_accepted{0}, joint_rejected{0};
  std::atomic<std::uint64_t> subscriber_drops{0};
  // Refused for who the caller is (docs/security.md): an RPC its role may not call, a hello for another
  // patch (copied from the core), a ResetStop from a non-operator.
  std::atomic<std::uint64_t> auth_wrong_role{0}, auth_hello_other_patch{0}, auth_reset_not_operator{0};
  std::atomic<std::uint64_t> fusion_updates{0}, fusion_inputs{0}, fusion_merges{0}, fusion_rejected{0};
  std::atomic<int> safety_subscribers{0}, contact_subscribers{0};
  std::vector<std::string> patch_ids, patch_regions;
  std::unique_ptr<std::atomic<std::uint64_t>[]> contacts;   // contact onsets per patch
  std::unique_ptr<std::atomic<int>[]> link_state;            // per patch
  service::AtomicHistogram frame_to_stop;
};

class StatsCollectable final : public prometheus::Collectable {
 public:
  explicit StatsCollectable(const Stats& s) : s_(s) {}
  std::vector<prometheus::MetricFamily> Collect() const override {
    using prometheus::ClientMetric;
    using prometheus::MetricFamily;
    using prometheus::MetricType;
    std::vector<MetricFamily> out;
    auto one = [&](const char* name, const char* help, MetricType type, double v) {
      MetricFamily f{name, help, type, {}};
      ClientMetric m;
      if (type == MetricType::Counter) m.counter.value = v;
      else m.gauge.value = v;
      f.metric.push_back(m);
      out.push_back(std::move(f));
    };
    auto u = [](const std::atomic<std::uint64_t>& a) { return static_cast<double>(a.load(std::memory_order_relaxed)); };
    {
      MetricFamily f{"ruffini_aggregator_safety_state", "1 for the safety state in force (0 for the others).",
                     MetricType::Gauge, {}};
      const int st = s_.state.load();
      const char* names[] = {"clear", "stop", "fault"};
      for (int i = 1; i <= 3; ++i) {
        ClientMetric m;
        m.label.push_back({"state", names[i - 1]});
        m.gauge.value = st == i ? 1.0 : 0.0;
        f.metric.push_back(m);
      }
      out.push_back(std::move(f));
    }
    one("ruffini_aggregator_stop_epoch", "The current stop_epoch.", MetricType::Gauge, u(s_.stop_epoch));
    one("ruffini_aggregator_stops_total", "Entries into STOP.", MetricType::Counter, u(s_.stops));
    one("ruffini_aggregator_faults_total", "Entries into FAULT.", MetricType::Counter, u(s_.faults));
    {
      MetricFamily f{"ruffini_aggregator_resets_total", "ResetStop requests by result.", MetricType::Counter, {}};
      ClientMetric a, r;
      a.label.push_back({"result", "accepted"});
      a.counter.value = u(s_.resets_accepted);
      r.label.push_back({"result", "refused"});
      r.counter.value = u(s_.resets_refused);
      f.metric = {a, r};
      out.push_back(std::move(f));
    }
    one("ruffini_aggregator_patch_messages_total", "PatchMessages received.", MetricType::Counter, u(s_.messages));
    one("ruffini_aggregator_hellos_accepted_total", "Decoder hellos accepted.", MetricType::Counter, u(s_.hellos_accepted));
    one("ruffini_aggregator_hellos_refused_total", "Decoder hellos refused.", MetricType::Counter, u(s_.hellos_refused));
    one("ruffini_aggregator_protocol_errors_total", "Connect streams ended for a protocol error.", MetricType::Counter,
        u(s_.protocol_errors));
    {
      MetricFamily f{"ruffini_aggregator_joint_states_total", "Joint states received, by result.", MetricType::Counter, {}};
      ClientMetric a, r;
      a.label.push_back({"result", "accepted"});
      a.counter.value = u(s_.joint_accepted);
      r.label.push_back({"result", "rejected"});
      r.counter.value = u(s_.joint_rejected);
      f.metric = {a, r};
      out.push_back(std::move(f));
    }
    {
      MetricFamily f{"ruffini_aggregator_contacts_total", "Contact onsets, by patch and body region.",
                     MetricType::Counter, {}};
      MetricFamily g{"ruffini_aggregator_patch_link_state",
                     "Each patch link's state (LinkState number: 1 disconnected, 2 hello pending, 3 refused, 4 healthy, "
                     "5 unhealthy, 6 silent).",
                     MetricType::Gauge, {}};
      for (std::size_t i = 0; i < s_.patch_ids.size(); ++i) {
        ClientMetric m;
        m.label = {{"patch", s_.patch_ids[i]}, {"region", s_.patch_regions[i]}};
        m.counter.value = static_cast<double>(s_.contacts[i].load());
        f.metric.push_back(m);
        ClientMetric l;
        l.label = {{"patch", s_.patch_ids[i]}};
        l.gauge.value = s_.link_state[i].load();
        g.metric.push_back(l);
      }
      out.push_back(std::move(f));
      out.push_back(std::move(g));
    }
    one("ruffini_aggregator_safety_subscribers", "WatchSafety streams open.", MetricType::Gauge, s_.safety_subscribers.load());
    one("ruffini_aggregator_contact_subscribers", "WatchContacts streams open.", MetricType::Gauge,
        s_.contact_subscribers.load());
    one("ruffini_aggregator_fusion_updates_total", "Fusion passes over the patches in contact.", MetricType::Counter,
        u(s_.fusion_updates));
    one("ruffini_aggregator_fusion_inputs_total", "Patch contacts fed to the fusion.", MetricType::Counter,
        u(s_.fusion_inputs));
    one("ruffini_aggregator_fusion_merges_total",
        "Pairs of patch contacts fused into one body contact (a touch across a seam).", MetricType::Counter,
        u(s_.fusion_merges));
    one("ruffini_aggregator_fusion_rejected_total", "Patch contacts the fusion refused (bad input).",
        MetricType::Counter, u(s_.fusion_rejected));
    {
      MetricFamily f{"ruffini_aggregator_auth_refusals_total",
                     "Callers refused for who they are: TLS handshakes refused (no or a bad client certificate), "
                     "an RPC the caller's role may not call, a decoder's hello for another patch, a ResetStop from a "
                     "non-operator.",
                     MetricType::Counter, {}};
      const auto& h = service::handshake_refusals();
      const std::pair<const char*, double> rows[] = {
          {"no_certificate", u(h.no_certificate)},     {"bad_certificate", u(h.bad_certificate)},
          {"handshake_other", u(h.other)},             {"wrong_role", u(s_.auth_wrong_role)},
          {"hello_other_patch", u(s_.auth_hello_other_patch)}, {"reset_not_operator", u(s_.auth_reset_not_operator)}};
      for (const auto& [reason, v] : rows) {
        ClientMetric m;
        m.label.push_back({"reason", reason});
        m.counter.value = v;
        f.metric.push_back(m);
      }
      out.push_back(std::move(f));
    }
    one("ruffini_aggregator_subscriber_drops_total", "Subscribers finished because a write was stuck past its deadline.",
        MetricType::Counter, u(s_.subscriber_drops));
    {
      MetricFamily f{"ruffini_aggregator_frame_to_stop_seconds",
                     "From the contact frame's interrogator timestamp to the STOP latched here, s.", MetricType::Histogram,
                     {}};
      ClientMetric m;
      s_.frame_to_stop.Fill(m);
      f.metric.push_back(m);
      out.push_back(std::move(f));
    }
    return out;
  }

 private:
  const Stats& s_;
};

}  // namespace

struct AggregatorServer::Impl final : v1::Aggregator::CallbackService {
  ServerConfig config;
  std::unique_ptr<aggregate::Core> core;  // owned by the loop thread after Start()
  std::unique_ptr<grpc::Server> server;
  std::unique_ptr<grpc::Server> health_server;  // plaintext, grpc.health.v1 only
  int health_port = 0;
  int port = 0;
  std::unique_ptr<prometheus::Exposer> exposer;
  std::shared_ptr<StatsCollectable> collectable;
  Stats stats;

  // The event queue: callbacks post, the loop runs.
  std::mutex mu;
  std::condition_variable cv;
  std::deque<std::function<void()>> events;
  bool stopping = false;
  std::thread loop;

  // The health service reflects the loop: the loop stamps loop_beat_ns (steady clock) every iteration; the
  // health watcher reports NOT_SERVING while the stamp is older than kLoopStaleNs, SERVING again after.
  static constexpr std::int64_t kLoopStaleNs = 200'000'000;
  static constexpr auto kHealthWatchPeriod = std::chrono::milliseconds(20);
  std::atomic<std::int64_t> loop_beat_ns{0};
  std::thread health_watch;
  std::mutex health_mu;
  std::condition_variable health_cv;
  bool health_stop = false;
  void SetServing(bool serving) {
    server->GetHealthCheckService()->SetServingStatus(serving);
    if (health_server) health_server->GetHealthCheckService()->SetServingStatus(serving);
  }
  void HealthWatch();

  // Loop-thread state.
  // The subscribers: each set owns its reactors (a reference from the posted insert to the posted erase).
  std::set<SafetyReactor::Ptr> safety_subs;
  std::set<ContactsReactor::Ptr> contact_subs;
  bool shut_down = false;  // Stop's last words were sent: a later subscriber is finished at once
  // The publication periods in force: the shortest any subscriber asked for, never longer than the config's
  // (10 ms) nor shorter than kShortestPeriodNs. Every subscriber receives every publication (seq is shared).
  static constexpr std::int64_t kShortestPeriodNs = 2'000'000;
  std::int64_t safety_period_ns = 0, contacts_period_ns = 0;
  bool periods_changed = false;
  // A request's heartbeat_period_ns (0: the longest) clamped to [kShortestPeriodNs, longest].
  static std::int64_t ClampPeriod(std::int64_t requested, std::int64_t longest) {
    if (requested <= 0 || requested > longest) return longest;
    return std::max(requested, std::min(kShortestPeriodNs, longest));
  }
  void RecomputePeriods() {
    std::int64_t safety = config.heartbeat_period_ns, contacts = config.contacts_period_ns;
    for (const auto& r : safety_subs) safety = std::min(safety, r->options().period_ns);
    for (const auto& r : contact_subs) contacts = std::min(contacts, r->options().period_ns);
    periods_changed = periods_changed || safety != safety_period_ns || contacts != contacts_period_ns;
    safety_period_ns = safety;
    contacts_period_ns = contacts;
  }
  std::int64_t unix0 = 0, mono0 = 0;
  std::vector<bool> was_in_contact;

  std::int64_t Now() const { return unix0 + (service::MonoNowNs() - mono0); }
  void Post(std::function<void()> f) {
    {
      std::lock_guard lock(mu);
      events.push_back(std::move(f));
    }
    cv.notify_one();
  }
  void Loop();
  void PublishSafety();
  void PublishContacts();
  void CopyStats();
  // The caller's identity; true when its role is one of `allowed` (kAny, a plaintext server, always is).
  // Otherwise counts and logs the refusal.
  bool Allowed(const grpc::CallbackServerContext* ctx, std::string_view rpc, std::initializer_list<service::Role> allowed,
               service::Identity* who = nullptr);

  // --- RPCs (callbacks only enqueue) ---
  grpc::ServerBidiReactor<v1::PatchMessage, v1::AggregatorCommand>* Connect(grpc::CallbackServerContext* ctx) override;
  grpc::ServerReadReactor<v1::JointState>* PublishJointStates(grpc::CallbackServerContext* ctx,
                                                              v1::PublishJointStatesResponse* response) override;
  grpc::ServerWriteReactor<v1::SafetyState>* WatchSafety(grpc::CallbackServerContext* ctx,
                                                         const v1::WatchSafetyRequest* request) override;
  grpc::ServerWriteReactor<v1::ContactSet>* WatchContacts(grpc::CallbackServerContext* ctx,
                                                          const v1::WatchContactsRequest* request) override;
  grpc::ServerUnaryReactor* ResetStop(grpc::CallbackServerContext* ctx, const v1::ResetStopRequest* request,
                                      v1::ResetStopResponse* response) override;
  grpc::ServerUnaryReactor* GetStatus(grpc::CallbackServerContext* ctx, const v1::GetStatusRequest* request,
                                      v1::AggregatorStatus* response) override;
};

namespace {

// A decoder's Connect stream.
class ConnectReactor final : public grpc::ServerBidiReactor<v1::PatchMessage, v1::AggregatorCommand> {
 public:
  ConnectReactor(AggregatorServer::Impl* impl, std::string peer, std::string allowed_patch)
      : impl_(impl), guard_(std::make_shared<Guard>()), peer_(std::move(peer)) {
    auto self = this;
    auto guard = guard_;
    impl_->Post([self, guard, impl, allowed = std::move(allowed_patch)] {
      std::lock_guard lock(guard->mu);
      if (!guard->alive) return;
      self->stream_ = impl->core->OpenStream(impl->Now(), allowed);
    });
    StartRead(&in_);
  }

  void OnReadDone(bool ok) override {
    auto guard = guard_;
    auto impl = impl_;
    auto self = this;
    if (!ok) {
      // The decoder closed its side (or the call broke): end the stream.
      impl_->Post([self, guard, impl] {
        std::lock_guard lock(guard->mu);
        if (!guard->alive) return;
        impl->core->CloseStream(self->stream_, impl->Now());
        self->FinishOnce(grpc::Status::OK);
      });
      return;
    }
    impl_->Post([self, guard, impl, m = in_] {
      std::lock_guard lock(guard->mu);
      if (!guard->alive) return;
      const auto reply = impl->core->OnPatchMessage(self->stream_, m, impl->Now());
      if (reply.command) self->Send(*reply.command);
      if (reply.close) {
        if (!reply.command) {
          spdlog::warn("patch stream from {}: protocol error ({}); ending it", self->peer_, impl->core->last_protocol_error());
        } else if (reply.command->has_hello_refused()) {
          spdlog::warn("patch stream from {}: hello refused ({}): {}", self->peer_,
                       v1::HelloRefusal_Name(reply.command->hello_refused().reason()),
                       reply.command->hello_refused().message());
        }
        impl->core->CloseStream(self->stream_, impl->Now());
        self->FinishOnce(grpc::Status(grpc::StatusCode::FAILED_PRECONDITION,
                                      reply.command && reply.command->has_hello_refused()
                                          ? reply.command->hello_refused().message()
                                          : "protocol error"));
      } else if (reply.command && reply.command->has_hello_accepted()) {
        spdlog::info("patch {} connected from {} ({})", reply.command->hello_accepted().patch_id(), self->peer_,
                     m.hello().decoder_instance());
      }
    });
    StartRead(&in_);
  }
  void OnWriteDone(bool ok) override {
    std::lock_guard lock(guard_->mu);
    out_.pop_front();
    if (ok && !out_.empty()) {
      StartWrite(&out_.front());
      return;
    }
    if (!ok) {
      // The client is gone or the call was cancelled (a refusal whose decoder vanished): nothing more can be
      // written. If the loop already asked to finish, this is the last chance to; otherwise the read side's
      // failure (OnReadDone(false), which always follows) finishes the call.
      write_failed_ = true;
      out_.clear();
    }
    if (finish_pending_ && !finished_) {
      finished_ = true;
      Finish(final_);
    }
  }
  void OnDone() override {
    auto impl = impl_;
    int stream = -1;
    {
      std::lock_guard lock(guard_->mu);  // stream_ is written by the loop under the guard
      guard_->alive = false;
      stream = stream_;
    }
    impl->Post([impl, stream] { impl->core->CloseStream(stream, impl->Now()); });
    delete this;
  }

  // Loop thread, guard held.
  void Send(const v1::AggregatorCommand& c) {
    if (finish_pending_ || write_failed_) return;
    out_.push_back(c);
    if (out_.size() == 1) StartWrite(&out_.front());
  }
  void FinishOnce(const grpc::Status& s) {
    if (finish_pending_) return;
    finish_pending_ = true;
    final_ = s;
    if (out_.empty()) {
      finished_ = true;
      Finish(final_);
    }
  }

 private:
  AggregatorServer::Impl* impl_;
  std::shared_ptr<Guard> guard_;
  std::string peer_;
  int stream_ = -1;
  v1::PatchMessage in_;
  std::deque<v1::AggregatorCommand> out_;
  // Exactly one Finish: FinishOnce when nothing is queued, else the last OnWriteDone (ok or not).
  bool finish_pending_ = false, finished_ = false, write_failed_ = false;
  grpc::Status final_;
};

// A controller's joint-state stream.
class JointReactor final : public grpc::ServerReadReactor<v1::JointState> {
 public:
  JointReactor(AggregatorServer::Impl* impl, v1::PublishJointStatesResponse* response)
      : impl_(impl), guard_(std::make_shared<Guard>()), response_(response) {
    StartRead(&in_);
  }
  void OnReadDone(bool ok) override {
    auto guard = guard_;
    auto impl = impl_;
    auto self = this;
    if (!ok) {
      // Queued behind every state this stream sent: the counts are complete when the loop gets here.
      impl_->Post([self, guard] {
        std::lock_guard lock(guard->mu);
        if (guard->alive) self->Finish(grpc::Status::OK);
      });
      return;
    }
    impl_->Post([self, guard, impl, js = in_] {
      const auto r = impl->core->OnJointState(js, impl->Now());
      std::lock_guard lock(guard->mu);
      if (!guard->alive) return;
      auto* resp = self->response_;
      resp->set_received(resp->received() + 1);
      if (r == aggregate::JointRejection::kNone) {
        resp->set_accepted(resp->accepted() + 1);
      } else {
        resp->set_rejected(resp->rejected() + 1);
        resp->set_last_rejection(std::string(aggregate::JointRejectionName(r)));
        if (resp->rejected() == 1 || resp->rejected() % 1000 == 0) {
          spdlog::warn("joint state rejected ({}); {} so far on this stream", aggregate::JointRejectionName(r),
                       resp->rejected());
        }
      }
    });
    StartRead(&in_);
  }
  void OnDone() override {
    {
      std::lock_guard lock(guard_->mu);
      guard_->alive = false;
    }
    delete this;
  }

 private:
  AggregatorServer::Impl* impl_;
  std::shared_ptr<Guard> guard_;
  v1::PublishJointStatesResponse* response_;
  v1::JointState in_;
};

// A streaming call refused at once (PERMISSION_DENIED: the caller's role may not call it).
template <typename Base>
class DeniedReactor final : public Base {
 public:
  explicit DeniedReactor(const grpc::Status& status) { this->Finish(status); }
  void OnDone() override { delete this; }
};

grpc::Status Denied(std::string_view rpc) {
  return grpc::Status(grpc::StatusCode::PERMISSION_DENIED,
                      "this caller's identity (its TLS client certificate) may not call " + std::string(rpc));
}

}  // namespace

bool AggregatorServer::Impl::Allowed(const grpc::CallbackServerContext* ctx, std::string_view rpc,
                                     std::initializer_list<service::Role> allowed, service::Identity* who) {
  service::Identity id = service::CallerIdentity(*ctx, config.tls.insecure);
  bool ok = id.role == service::Role::kAny;
  for (auto r : allowed) ok = ok || id.role == r;
  if (!ok) {
    stats.auth_wrong_role.fetch_add(1);
    spdlog::warn("{} refused (PERMISSION_DENIED) for {} '{}' from {}", rpc, service::RoleName(id.role), id.id,
                 ctx->peer());
  }
  if (who) *who = std::move(id);
  return ok;
}

grpc::ServerBidiReactor<v1::PatchMessage, v1::AggregatorCommand>* AggregatorServer::Impl::Connect(
    grpc::CallbackServerContext* ctx) {
  service::Identity who;
  if (!Allowed(ctx, "Connect", {service::Role::kDecoder}, &who)) {
    return new DeniedReactor<grpc::ServerBidiReactor<v1::PatchMessage, v1::AggregatorCommand>>(Denied("Connect"));
  }
  return new ConnectReactor(this, ctx->peer(), who.patch);
}

grpc::ServerReadReactor<v1::JointState>* AggregatorServer::Impl::PublishJointStates(
    grpc::CallbackServerContext* ctx, v1::PublishJointStatesResponse* response) {
  if (!Allowed(ctx, "PublishJointStates", {service::Role::kController})) {
    return new DeniedReactor<grpc::ServerReadReactor<v1::JointState>>(Denied("PublishJointStates"));
  }
  return new JointReactor(this, response);
}

grpc::ServerWriteReactor<v1::SafetyState>* AggregatorServer::Impl::WatchSafety(grpc::CallbackServerContext* ctx,
                                                                               const v1::WatchSafetyRequest* request) {
  if (!Allowed(ctx, "WatchSafety", {service::Role::kController, service::Role::kOperator})) {
    return new DeniedReactor<grpc::ServerWriteReactor<v1::SafetyState>>(Denied("WatchSafety"));
  }
  if (request->heartbeat_period_ns() < 0) {
    return new DeniedReactor<grpc::ServerWriteReactor<v1::SafetyState>>(grpc::Status(
        grpc::StatusCode::INVALID_ARGUMENT,
        "heartbeat_period_ns (" + std::to_string(request->heartbeat_period_ns()) + ") must be 0 or positive"));
  }
  WatchOptions options;
  options.period_ns = ClampPeriod(request->heartbeat_period_ns(), config.heartbeat_period_ns);
  auto r = SafetyReactor::Make(ctx, std::move(options), [this](SafetyReactor::Ptr gone) {
    Post([this, gone = std::move(gone)] {
      safety_subs.erase(gone);
      stats.safety_subscribers = static_cast<int>(safety_subs.size());
      RecomputePeriods();
    });
  });
  const std::string who = request->subscriber().empty() ? ctx->peer() : request->subscriber();
  Post([this, r, who] {
    if (shut_down) {
      r->FinishWith(grpc::Status(grpc::StatusCode::UNAVAILABLE, "aggregator shutting down"));
      return;
    }
    safety_subs.insert(r);  // erased by the event its OnDone posts, which comes after this one
    stats.safety_subscribers = static_cast<int>(safety_subs.size());
    RecomputePeriods();
    // Debug level: a controller that reconnects in a loop would otherwise write a line per attempt.
    spdlog::debug("safety subscriber {} ({} now)", who, safety_subs.size());
    r->Offer(core->SafetyState(), service::MonoNowNs());  // the state in force at once
  });
  return r.get();
}

grpc::ServerWriteReactor<v1::ContactSet>* AggregatorServer::Impl::WatchContacts(grpc::CallbackServerContext* ctx,
                                                                                const v1::WatchContactsRequest* request) {
  if (!Allowed(ctx, "WatchContacts", {service::Role::kController, service::Role::kOperator})) {
    return new DeniedReactor<grpc::ServerWriteReactor<v1::ContactSet>>(Denied("WatchContacts"));
  }
  if (request->heartbeat_period_ns() < 0 || !(request->min_force_n() >= 0.0F)) {
    return new DeniedReactor<grpc::ServerWriteReactor<v1::ContactSet>>(grpc::Status(
        grpc::StatusCode::INVALID_ARGUMENT, "heartbeat_period_ns (" + std::to_string(request->heartbeat_period_ns()) +
                                                ") and min_force_n (" + std::to_string(request->min_force_n()) +
                                                " N) must be 0 or positive"));
  }
  WatchOptions options;
  options.period_ns = ClampPeriod(request->heartbeat_period_ns(), config.contacts_period_ns);
  options.links.assign(request->links().begin(), request->links().end());
  options.min_force_n = request->min_force_n();
  auto r = ContactsReactor::Make(ctx, std::move(options), [this](ContactsReactor::Ptr gone) {
    Post([this, gone = std::move(gone)] {
      contact_subs.erase(gone);
      stats.contact_subscribers = static_cast<int>(contact_subs.size());
      RecomputePeriods();
    });
  });
  Post([this, r] {
    if (shut_down) {
      r->FinishWith(grpc::Status(grpc::StatusCode::UNAVAILABLE, "aggregator shutting down"));
      return;
    }
    contact_subs.insert(r);
    stats.contact_subscribers = static_cast<int>(contact_subs.size());
    RecomputePeriods();
  });
  return r.get();
}

grpc::ServerUnaryReactor* AggregatorServer::Impl::ResetStop(grpc::CallbackServerContext* ctx,
                                                            const v1::ResetStopRequest* request,
                                                            v1::ResetStopResponse* response) {
  auto* reactor = ctx->DefaultReactor();
  const std::string peer = ctx->peer();
  // Only an operator may reset (a plaintext server treats every caller as one, and says so at start). Anyone
  // else gets the policy's answer for an unauthorized caller: refused, UNAUTHORIZED, nothing changed.
  const service::Identity who = service::CallerIdentity(*ctx, config.tls.insecure);
  const bool authorized = who.role == service::Role::kOperator || who.role == service::Role::kAny;
  Post([this, reactor, request, response, peer, authorized, who] {
    *response = core->OnReset(*request, authorized, Now());
    if (!authorized) {
      stats.auth_reset_not_operator.fetch_add(1);
      spdlog::warn("ResetStop refused (UNAUTHORIZED) for {} '{}' from {}: only an operator may reset",
                   service::RoleName(who.role), who.id, peer);
    }
    if (response->accepted()) {
      stats.resets_accepted.fetch_add(1);
      spdlog::warn("ResetStop accepted from {} ({}): epoch {}", peer, request->operator_name(), request->stop_epoch());
    } else {
      stats.resets_refused.fetch_add(1);
      spdlog::warn("ResetStop refused from {} ({}): {}", peer, request->operator_name(), response->message());
    }
    reactor->Finish(grpc::Status::OK);
  });
  return reactor;
}

grpc::ServerUnaryReactor* AggregatorServer::Impl::GetStatus(grpc::CallbackServerContext* ctx,
                                                            const v1::GetStatusRequest* /*request*/,
                                                            v1::AggregatorStatus* response) {
  auto* reactor = ctx->DefaultReactor();
  if (!Allowed(ctx, "GetStatus", {service::Role::kController, service::Role::kOperator})) {
    reactor->Finish(Denied("GetStatus"));
    return reactor;
  }
  Post([this, reactor, response] {
    *response = core->Status(Now());
    response->set_safety_subscribers(static_cast<std::uint32_t>(safety_subs.size()));
    response->set_contact_subscribers(static_cast<std::uint32_t>(contact_subs.size()));
    reactor->Finish(grpc::Status::OK);
  });
  return reactor;
}

void AggregatorServer::Impl::PublishSafety() {
  const v1::SafetyState s = core->SafetyState();
  const std::int64_t mono = service::MonoNowNs();
  for (const auto& r : safety_subs) r->Offer(s, mono);
}

namespace {

// ContactSet.t_ns as the contract has it: the newest contributing frame's interrogator time, 0 when empty.
void SetNewestFrameTime(v1::ContactSet& set) {
  std::int64_t t = 0;
  for (const auto& c : set.contacts()) t = std::max(t, c.t_ns());
  set.set_t_ns(t);
}

bool Wanted(const v1::BodyContact& c, const WatchOptions& o) {
  if (c.force_n() < o.min_force_n) return false;  // a NaN force (never published) would be kept
  return o.links.empty() || std::find(o.links.begin(), o.links.end(), c.link()) != o.links.end();
}

}  // namespace

void AggregatorServer::Impl::PublishContacts() {
  v1::ContactSet c = core->Contacts(Now());
  SetNewestFrameTime(c);
  const std::int64_t mono = service::MonoNowNs();
  v1::ContactSet filtered;
  for (const auto& r : contact_subs) {
    const WatchOptions& o = r->options();
    if (!o.filters()) {
      r->Offer(c, mono);
      continue;
    }
    filtered = c;
    filtered.clear_contacts();
    for (const auto& contact : c.contacts()) {
      if (Wanted(contact, o)) *filtered.add_contacts() = contact;
    }
    SetNewestFrameTime(filtered);
    r->Offer(filtered, mono);
  }
}

void AggregatorServer::Impl::CopyStats() {
  const v1::SafetyState s = core->SafetyState();
  stats.state = static_cast<int>(s.state());
  stats.stop_epoch = s.stop_epoch();
  stats.seq = s.seq();
  const auto& sc = core->safety_counters();
  stats.stops = sc.stops;
  stats.faults = sc.faults;
  const auto& c = core->counters();
  stats.messages = c.messages;
  stats.hellos_accepted = c.hellos_accepted;
  std::uint64_t refused = 0;
  for (auto v : c.hellos_refused) refused += v;
  stats.hellos_refused = refused;
  stats.protocol_errors = c.protocol_errors;
  stats.auth_hello_other_patch = c.hellos_refused[v1::HELLO_REFUSAL_UNAUTHORIZED];
  stats.joint_accepted = c.joint_states[0];
  std::uint64_t rejected = 0;
  for (std::size_t i = 1; i < c.joint_states.size(); ++i) rejected += c.joint_states[i];
  stats.joint_rejected = rejected;
  if (const auto* f = core->fusion_counters()) {
    stats.fusion_updates = f->updates;
    stats.fusion_inputs = f->inputs;
    stats.fusion_merges = f->merges;
    stats.fusion_rejected = f->rejected_total();
  }
  const auto status_patches = core->policy().config().patches.size();
  const auto patches = core->Status(Now());
  for (std::size_t i = 0; i < status_patches; ++i) {
    stats.link_state[i] = patches.patches(static_cast<int>(i)).link_state();
  }
}

void AggregatorServer::Impl::HealthWatch() {
  bool serving = true;
  std::unique_lock lock(health_mu);
  while (!health_cv.wait_for(lock, kHealthWatchPeriod, [&] { return health_stop; })) {
    const std::int64_t stale_ns = service::MonoNowNs() - loop_beat_ns.load(std::memory_order_relaxed);
    const bool ok = stale_ns <= kLoopStaleNs;
    if (ok == serving) continue;
    serving = ok;
    SetServing(ok);
    if (!ok) {
      spdlog::error("the loop has not run for {:.0f} ms: health NOT_SERVING", static_cast<double>(stale_ns) / 1e6);
    } else {
      spdlog::warn("the loop runs again: health SERVING");
    }
  }
}

void AggregatorServer::Impl::Loop() {
  safety_period_ns = config.heartbeat_period_ns;
  contacts_period_ns = config.contacts_period_ns;
  std::int64_t next_heartbeat = Now() + safety_period_ns;
  std::int64_t next_contacts = Now() + contacts_period_ns;
  std::int64_t next_stats = 0;
  std::deque<std::function<void()>> batch;
  std::int64_t wedge_at = config.test_wedge_for_ns > 0 ? service::MonoNowNs() + config.test_wedge_after_ns : 0;
  for (;;) {
    loop_beat_ns.store(service::MonoNowNs(), std::memory_order_relaxed);
    if (wedge_at != 0 && service::MonoNowNs() >= wedge_at) {
      spdlog::warn("--test-wedge-loop: the loop sleeps {} ms", static_cast<double>(config.test_wedge_for_ns) / 1e6);
      std::this_thread::sleep_for(std::chrono::nanoseconds(config.test_wedge_for_ns));
      wedge_at = 0;
    }
    {
      std::unique_lock lock(mu);
      cv.wait_for(lock, std::chrono::milliseconds(1), [&] { return !events.empty() || stopping; });
      batch.swap(events);
      if (stopping && batch.empty()) break;
    }
    bool contacts_changed = false;
    const std::uint64_t contacts_before = core->counters().contacts;
    for (auto& f : batch) f();
    batch.clear();
    contacts_changed = core->counters().contacts != contacts_before;
    const std::int64_t now = Now();
    if (periods_changed) {  // a subscriber asking for a shorter period gets it from now on
      next_heartbeat = std::min(next_heartbeat, now + safety_period_ns);
      next_contacts = std::min(next_contacts, now + contacts_period_ns);
      periods_changed = false;
    }
    core->Tick(now);
    if (now >= next_heartbeat) {
      core->Publish(now);
      next_heartbeat += safety_period_ns;
      if (next_heartbeat <= now) next_heartbeat = now + safety_period_ns;
    }
    const std::int64_t latency = core->TakeStopLatencyNs();
    if (latency >= 0) stats.frame_to_stop.ObserveNs(latency);
    if (core->TakeChanged()) PublishSafety();
    if (contacts_changed || now >= next_contacts) {
      PublishContacts();
      if (now >= next_contacts) next_contacts += contacts_period_ns;  // phase-locked, like the safety heartbeat
      if (next_contacts <= now) next_contacts = now + contacts_period_ns;
    }
    const std::int64_t mono = service::MonoNowNs();
    for (const auto& r : safety_subs) {
      if (r->CheckStuck(mono, config.write_deadline_ns)) {
        stats.subscriber_drops.fetch_add(1);
        spdlog::warn("safety subscriber dropped: a write was stuck for more than {} ms",
                     static_cast<double>(config.write_deadline_ns) / 1e6);
      }
    }
    for (const auto& r : contact_subs) {
      if (r->CheckStuck(mono, config.write_deadline_ns)) stats.subscriber_drops.fetch_add(1);
    }
    // Contact onsets per patch (for the contact-rate dashboards); no allocation per iteration.
    for (std::size_t i = 0; i < was_in_contact.size(); ++i) {
      const bool in_contact = core->in_contact(i);
      if (in_contact && !was_in_contact[i]) stats.contacts[i].fetch_add(1);
      was_in_contact[i] = in_contact;
    }
    if (now >= next_stats) {
      CopyStats();
      next_stats = now + 5'000'000;
    }
  }
}

AggregatorServer::AggregatorServer(ServerConfig config, aggregate::Setup setup) : impl_(std::make_unique<Impl>()) {
  Impl& s = *impl_;
  s.config = config;
  s.unix0 = service::UnixNowNs();
  s.mono0 = service::MonoNowNs();
  const std::size_t n = setup.patches.size();
  for (const auto& p : setup.safety.patches) {
    s.stats.patch_ids.push_back(p.id);
    s.stats.patch_regions.push_back(p.region);
  }
  s.stats.contacts = std::make_unique<std::atomic<std::uint64_t>[]>(n);
  s.stats.link_state = std::make_unique<std::atomic<int>[]>(n);
  s.was_in_contact.assign(n, false);
  s.core = std::make_unique<aggregate::Core>(std::move(setup), s.Now());

  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder builder;
  // Keepalive pings on every connection: a decoder or controller that vanished without closing its socket
  // is dropped within ~2 s (its Connect stream then closes in the Core; docs/aggregator.md).
  service::AddKeepalive(builder);
  // One port, one aggregator: without this gRPC sets SO_REUSEPORT, and a second copy (started by mistake, or a
  // restart while the old one hangs) would listen on the same port and take half of the calls.
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  builder.AddListeningPort(config.listen.str(), service::ServerCredentials(config.tls), &s.port);
  builder.RegisterService(&s);
  s.server = builder.BuildAndStart();
  if (!s.server || s.port == 0) {
    throw InputError("--listen " + config.listen.str() +
                     ": cannot listen there (is another process, perhaps another aggregator, listening on it?)");
  }
  if (config.health_listen) {
    // No service registered: the server carries only gRPC's default health service (enabled above).
    grpc::ServerBuilder health;
    health.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
    health.AddListeningPort(config.health_listen->str(), grpc::InsecureServerCredentials(), &s.health_port);
    s.health_server = health.BuildAndStart();
    if (!s.health_server || s.health_port == 0) {
      throw InputError("--health-listen " + config.health_listen->str() +
                       ": cannot listen there (is another process listening on it?)");
    }
  }
  try {
    s.exposer = std::make_unique<prometheus::Exposer>(config.metrics.str());
  } catch (const std::exception& e) {
    throw InputError("--metrics " + config.metrics.str() + ": cannot listen (" + e.what() + ")");
  }
  s.collectable = std::make_shared<StatsCollectable>(s.stats);
  s.exposer->RegisterCollectable(s.collectable);
  s.exposer->RegisterCollectable(service::ProcessMetrics());  // process_cpu_seconds_total, memory, fds
}

AggregatorServer::~AggregatorServer() { Stop(); }

std::uint16_t AggregatorServer::port() const noexcept { return static_cast<std::uint16_t>(impl_->port); }

std::uint16_t AggregatorServer::health_port() const noexcept { return static_cast<std::uint16_t>(impl_->health_port); }

std::uint16_t AggregatorServer::metrics_port() const noexcept {
  const auto ports = impl_->exposer->GetListeningPorts();
  return ports.empty() ? 0 : static_cast<std::uint16_t>(ports.front());
}

void AggregatorServer::Start() {
  Impl& s = *impl_;
  s.loop_beat_ns = service::MonoNowNs();
  s.SetServing(true);
  s.loop = std::thread([&s] { s.Loop(); });
  s.health_watch = std::thread([&s] { s.HealthWatch(); });
}

void AggregatorServer::Stop() {
  Impl& s = *impl_;
  if (!s.loop.joinable()) return;
  {
    std::lock_guard lock(s.health_mu);
    s.health_stop = true;
  }
  s.health_cv.notify_one();
  s.health_watch.join();
  s.SetServing(false);
  // Last words: FAULT (shutting down) to every subscriber, then every stream finished.
  std::promise<void> finished;
  s.Post([&s, &finished] {
    s.shut_down = true;
    s.core->Shutdown(s.Now());
    s.PublishSafety();
    for (const auto& r : s.safety_subs) r->FinishWith(grpc::Status(grpc::StatusCode::UNAVAILABLE, "aggregator shutting down"));
    for (const auto& r : s.contact_subs) r->FinishWith(grpc::Status(grpc::StatusCode::UNAVAILABLE, "aggregator shutting down"));
    finished.set_value();
  });
  finished.get_future().wait_for(std::chrono::seconds(1));
  // Give the last writes a moment, then stop the server (open streams are cancelled at the deadline).
  s.server->Shutdown(std::chrono::system_clock::now() + std::chrono::milliseconds(500));
  {
    std::lock_guard lock(s.mu);
    s.stopping = true;
  }
  s.cv.notify_one();
  s.loop.join();
  s.server->Wait();
  if (s.health_server) {
    s.health_server->Shutdown(std::chrono::system_clock::now() + std::chrono::milliseconds(100));
    s.health_server->Wait();
  }
}

}  // namespace ruffini::aggregator
