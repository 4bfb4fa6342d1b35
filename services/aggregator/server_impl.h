#pragma once
// ruffini-aggregator's internals, shared by its parts (private to services/aggregator):
//   reactors.cpp       the gRPC reactors and RPC handlers: they only enqueue events for the loop
//   loop.cpp           the loop thread, which owns aggregate::Core, publishes and sweeps subscribers; the
//                      health watcher
//   authorization.cpp  who may call what (roles from the TLS identity)
//   metrics.cpp        the Prometheus view of Stats
//   server.cpp         construction (ports, keepalive), Start, Stop
#include <grpcpp/grpcpp.h>

#include <functional>
#include <map>
#include <prometheus/collectable.h>
#include <prometheus/exposer.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <functional>
#include <initializer_list>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "ruffini/service/atomic_histogram.h"
#include "ruffini/service/common.h"
#include "ruffini/service/tls.h"
#include "ruffini/v1/aggregator.grpc.pb.h"
#include "server.h"

namespace ruffini::aggregator {

// Shared between a Connect/Joint reactor and the events it posts: the reactor is deleted in OnDone, after which
// `alive` is false and the posted events do nothing (they hold the Guard, never only the reactor). One
// recursive mutex guards the reactor's state (a reaction may run inline in a call the loop makes).
struct Guard {
  std::recursive_mutex mu;
  bool alive = true;
};

// What a subscriber asked for (WatchSafetyRequest / WatchContactsRequest), fixed at subscription.
struct WatchOptions {
  std::int64_t period_ns = 0;      // the longest gap wanted, clamped (ClampPeriod)
  std::vector<std::string> links;  // WatchContacts: only these URDF links (empty: all)
  float min_force_n = 0;           // WatchContacts: only contacts at or above this force
  [[nodiscard]] bool filters() const { return !links.empty() || min_force_n > 0; }
};

// Latest-value slot writer for WatchSafety / WatchContacts. Owned by shared_ptr, never by `delete this`: the
// reactor holds itself (self_) until OnDone; the loop's subscriber set holds it from the posted insert to the
// posted erase (which OnDone posts), so every call the loop makes is on a live object, and after OnDone
// (done_, checked under mu_) the call does nothing. Every path ends in exactly one Finish: FinishWith (the
// loop), a failed write, or a cancellation with no write in flight.
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
  std::atomic<std::uint64_t> messages{0}, hellos_accepted{0}, protocol_errors{0};
  std::array<std::atomic<std::uint64_t>, v1::HelloRefusal_ARRAYSIZE> hellos_refused{};  // by v1::HelloRefusal
  // RetarePatch: [0] sent, else refused by v1::RetareRefusal; the decoders' results by v1::RetareOutcome.
  std::array<std::atomic<std::uint64_t>, v1::RetareRefusal_ARRAYSIZE> retare_requests{};
  std::array<std::atomic<std::uint64_t>, v1::RetareOutcome_ARRAYSIZE> retare_results{};
  std::atomic<std::uint64_t> joint_accepted{0}, joint_rejected{0};
  std::atomic<std::uint64_t> subscriber_drops{0};
  // Refused for who the caller is (docs/security.md): an RPC its role may not call, a hello for another
  // patch (copied from the core), a ResetStop from a non-operator.
  std::atomic<std::uint64_t> auth_wrong_role{0}, auth_hello_other_patch{0}, auth_reset_not_operator{0};
  std::atomic<std::uint64_t> fusion_updates{0}, fusion_inputs{0}, fusion_merges{0}, fusion_rejected{0};
  // Seams (docs/fusion.md "Seams"): the fusion's pairs placed on their seam and, of them, the mixtures; the
  // core's contacts judged on a seam sum. Contact messages flagged faint (the core's).
  std::atomic<std::uint64_t> seam_pairs{0}, seam_mixtures{0}, seam_sums{0}, contacts_faint{0};
  std::atomic<int> safety_subscribers{0}, contact_subscribers{0};
  std::vector<std::string> patch_ids, patch_regions;
  std::unique_ptr<std::atomic<std::uint64_t>[]> contacts;   // contact onsets per patch
  std::unique_ptr<std::atomic<int>[]> link_state;            // per patch
  // The safety layer's detections (docs/safety-channel.md): per patch (then one row for streams that never
  // got a patch, "-"), per error.
  std::unique_ptr<std::array<std::atomic<std::uint64_t>, channel::kErrorKinds>[]> link_errors;
  service::AtomicHistogram frame_to_stop;
};

// The Prometheus collectable over Stats (metrics.cpp).
std::shared_ptr<prometheus::Collectable> MakeStatsCollectable(const Stats& stats);

// PERMISSION_DENIED for an RPC the caller's role may not call (authorization.cpp).
grpc::Status Denied(std::string_view rpc);

struct AggregatorServer::Impl final : v1::Aggregator::CallbackService {
  ServerConfig config;
  std::unique_ptr<aggregate::Core> core;  // owned by the loop thread after Start()
  std::unique_ptr<grpc::Server> server;
  std::unique_ptr<grpc::Server> health_server;  // plaintext, grpc.health.v1 only
  int health_port = 0;
  int port = 0;
  std::unique_ptr<prometheus::Exposer> exposer;
  std::shared_ptr<prometheus::Collectable> collectable;
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
  // The Core's takeover: Finish the replaced stream's call (its reactor, if still there). Loop thread.
  std::map<int, std::function<void()>> stream_enders;
  // A command on a live Connect stream (RetarePatch): its reactor's Send, while the reactor lives. Loop thread.
  std::map<int, std::function<void(const v1::AggregatorCommand&)>> stream_senders;
  void EndStream(int stream) {
    auto it = stream_enders.find(stream);
    if (it == stream_enders.end()) return;
    auto end = std::move(it->second);
    stream_enders.erase(it);
    end();
  }
  // Every latch, escalation, new epoch, shutdown, reset and takeover: one structured line each (loop.cpp).
  void LogEvents();
  void PublishSafety();
  // The state as it goes on the wire: the safety layer's send time and CRC set last (docs/safety-channel.md).
  v1::SafetyState SealedState(std::int64_t mono_ns) const;
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
  grpc::ServerUnaryReactor* RetarePatch(grpc::CallbackServerContext* ctx, const v1::RetarePatchRequest* request,
                                        v1::RetarePatchResponse* response) override;
  grpc::ServerUnaryReactor* GetStatus(grpc::CallbackServerContext* ctx, const v1::GetStatusRequest* request,
                                      v1::AggregatorStatus* response) override;
};

}  // namespace ruffini::aggregator
