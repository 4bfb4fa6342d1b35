// The aggregator's loop thread: runs the queued events in order, ticks the Core, publishes SafetyStates and
// ContactSets to the subscribers, drops stuck subscribers, copies counters for the metrics; and the health
// watcher that reports NOT_SERVING while the loop does not run.
#include <spdlog/spdlog.h>

#include "ruffini/channel/crc.h"
#include "server_impl.h"

namespace ruffini::aggregator {

v1::SafetyState AggregatorServer::Impl::SealedState(std::int64_t mono_ns) const {
  v1::SafetyState s = core->SafetyState();
  s.set_sender_steady_ns(mono_ns);
  channel::Seal(s);
  return s;
}

void AggregatorServer::Impl::LogEvents() {
  for (const aggregate::Event& e : core->TakeEvents()) {
    if (e.takeover) {
      spdlog::warn("safety_event type=takeover patch={} replaced_stream={} epoch={}", e.cause_patch, e.replaced_stream,
                   e.safety.stop_epoch);
      continue;
    }
    const auto& c = e.safety.cause;
    spdlog::warn("safety_event type={} state={} epoch={} cause={} patch={} force_n={} threshold_n={} doubt={} "
                 "reset_epoch={} refusal={} operator={}",
                 safety::EventTypeName(e.safety.type), safety::StateName(e.safety.state), e.safety.stop_epoch,
                 safety::CauseKindName(c.kind), e.cause_patch.empty() ? "-" : e.cause_patch, c.force_n, c.threshold_n,
                 safety::RejectionName(c.doubt), e.safety.reset_epoch, safety::ResetRefusalName(e.safety.reset_refusal),
                 e.operator_name.empty() ? "-" : e.operator_name);
  }
}

void AggregatorServer::Impl::PublishSafety() {
  const std::int64_t mono = service::MonoNowNs();
  const v1::SafetyState s = SealedState(mono);
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
  for (std::size_t r = 0; r < stats.hellos_refused.size() && r < c.hellos_refused.size(); ++r) {
    stats.hellos_refused[r].store(c.hellos_refused[r], std::memory_order_relaxed);
  }
  stats.protocol_errors = c.protocol_errors;
  stats.seam_sums = c.seam_sums;
  stats.contacts_faint = c.contacts_faint;
  for (std::size_t r = 0; r < stats.retare_results.size() && r < c.retare_results.size(); ++r) {
    stats.retare_results[r].store(c.retare_results[r], std::memory_order_relaxed);
  }
  for (std::size_t i = 0; i <= stats.patch_ids.size(); ++i) {
    const channel::ErrorCounts& ec = i < stats.patch_ids.size() ? core->link_errors()[i] : core->link_errors_unbound();
    for (std::size_t e = 0; e < channel::kErrorKinds; ++e) {
      stats.link_errors[i][e].store(ec.by_error[e], std::memory_order_relaxed);
    }
  }
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
    stats.seam_pairs = f->seam_pairs;
    stats.seam_mixtures = f->seam_mixtures;
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
    LogEvents();
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

}  // namespace ruffini::aggregator
