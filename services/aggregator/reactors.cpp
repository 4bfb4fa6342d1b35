// The aggregator's gRPC reactors and RPC handlers. They only enqueue events for the loop (loop.cpp), which
// owns aggregate::Core; every path of every reactor ends in exactly one Finish (docs/aggregator.md).
#include <spdlog/spdlog.h>

#include "server_impl.h"

namespace ruffini::aggregator {

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
      impl->stream_enders[self->stream_] = [self, guard] {
        std::lock_guard ender_lock(guard->mu);
        if (guard->alive) self->FinishOnce(grpc::Status(grpc::StatusCode::ABORTED, "replaced by a new stream for its patch"));
      };
      impl->stream_senders[self->stream_] = [self, guard](const v1::AggregatorCommand& c) {
        std::lock_guard sender_lock(guard->mu);
        if (guard->alive) self->Send(c);
      };
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
      if (reply.end_stream >= 0) impl->EndStream(reply.end_stream);
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
      if (m.has_retare_result()) {
        const v1::RetareResult& r = m.retare_result();
        spdlog::warn("patch {}: re-tare {} {} (one touch explains {:.2f} N at ({:.1f} mm, {:.1f} deg); re-tare force "
                     "{:.2f} N; motion {:.2f} pm)",
                     m.patch_id(), r.request_id(), v1::RetareOutcome_Name(r.outcome()), r.force_n(), r.y_mm(), r.r_deg(),
                     r.min_force_n(), r.motion_pm());
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
    impl->Post([impl, stream] {
      impl->stream_enders.erase(stream);
      impl->stream_senders.erase(stream);
      impl->core->CloseStream(stream, impl->Now());
    });
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
      : impl_(impl), guard_(std::make_shared<Guard>()), response_(response), stream_(NextId()) {
    StartRead(&in_);
  }
  // Each joint-state stream has its own monotonic reference in the Core.
  static int NextId() {
    static std::atomic<int> next{1};
    return next.fetch_add(1);
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
    impl_->Post([self, guard, impl, js = in_, stream = stream_] {
      const auto r = impl->core->OnJointState(js, impl->Now(), stream);
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
    impl_->Post([impl = impl_, stream = stream_] { impl->core->CloseJointStream(stream); });
    delete this;
  }

 private:
  AggregatorServer::Impl* impl_;
  std::shared_ptr<Guard> guard_;
  v1::PublishJointStatesResponse* response_;
  int stream_;
  v1::JointState in_;
};

// A streaming call refused at once (PERMISSION_DENIED: the caller's role may not call it).
template <typename Base>
class DeniedReactor final : public Base {
 public:
  explicit DeniedReactor(const grpc::Status& status) { this->Finish(status); }
  void OnDone() override { delete this; }
};

}  // namespace

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
    const std::int64_t mono = service::MonoNowNs();
    r->Offer(SealedState(mono), mono);  // the state in force at once
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
    LogEvents();
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

grpc::ServerUnaryReactor* AggregatorServer::Impl::RetarePatch(grpc::CallbackServerContext* ctx,
                                                              const v1::RetarePatchRequest* request,
                                                              v1::RetarePatchResponse* response) {
  auto* reactor = ctx->DefaultReactor();
  const std::string peer = ctx->peer();
  // Authorised like ResetStop: only an operator (a plaintext server treats every caller as one).
  const service::Identity who = service::CallerIdentity(*ctx, config.tls.insecure);
  const bool authorized = who.role == service::Role::kOperator || who.role == service::Role::kAny;
  Post([this, reactor, request, response, peer, authorized, who] {
    if (shut_down) {
      response->set_sent(false);
      response->set_reason(v1::RETARE_REFUSAL_SHUTTING_DOWN);
      response->set_message("the aggregator is shutting down");
    } else {
      auto d = core->OnRetare(*request, authorized, Now());
      if (d.command) {
        auto it = stream_senders.find(d.stream);
        if (it != stream_senders.end()) it->second(*d.command);
      }
      *response = std::move(d.response);
    }
    stats.retare_requests[static_cast<std::size_t>(response->reason())].fetch_add(1);
    if (!authorized) {  // counted in ruffini_aggregator_retare_requests_total{result="unauthorized"}
      spdlog::warn("RetarePatch refused (UNAUTHORIZED) for {} '{}' from {}: only an operator may ask", service::RoleName(who.role),
                   who.id, peer);
    }
    spdlog::warn("RetarePatch {} from {} ({}, \"{}\"): {}", response->sent() ? "sent" : "refused", peer,
                 request->operator_name(), request->operator_note(), response->message());
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

}  // namespace ruffini::aggregator
