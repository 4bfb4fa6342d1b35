// The aggregator's Prometheus metrics: a collectable that reads Stats (atomics the loop updates) at scrape time.
#include <prometheus/metric_family.h>
#include <prometheus/metric_type.h>

#include <cctype>

#include "server_impl.h"

namespace ruffini::aggregator {

namespace {

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
    {
      // One series per refusal reason (the contract's HelloRefusal, lower case without its prefix).
      MetricFamily f{"ruffini_aggregator_hellos_refused_total", "Decoder hellos refused, by reason.",
                     MetricType::Counter, {}};
      for (int r = v1::HelloRefusal_MIN + 1; r <= v1::HelloRefusal_MAX; ++r) {
        if (!v1::HelloRefusal_IsValid(r)) continue;
        std::string reason = v1::HelloRefusal_Name(static_cast<v1::HelloRefusal>(r)).substr(sizeof("HELLO_REFUSAL_") - 1);
        for (char& ch : reason) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
        ClientMetric m;
        m.label.push_back({"reason", reason});
        m.counter.value = u(s_.hellos_refused[static_cast<std::size_t>(r)]);
        f.metric.push_back(std::move(m));
      }
      out.push_back(std::move(f));
    }
    {
      // RetarePatch requests: sent, or refused by reason (the contract's RetareRefusal, lower case); and the
      // decoders' results by outcome (RetareOutcome, lower case).
      auto lower = [](std::string text, std::size_t prefix) {
        text = text.substr(prefix);
        for (char& ch : text) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
        return text;
      };
      MetricFamily f{"ruffini_aggregator_retare_requests_total", "RetarePatch requests: sent, or refused by reason.",
                     MetricType::Counter, {}};
      for (int r = v1::RetareRefusal_MIN; r <= v1::RetareRefusal_MAX; ++r) {
        if (!v1::RetareRefusal_IsValid(r)) continue;
        ClientMetric m;
        m.label.push_back({"result", r == 0 ? std::string("sent")
                                            : lower(v1::RetareRefusal_Name(static_cast<v1::RetareRefusal>(r)),
                                                    sizeof("RETARE_REFUSAL_") - 1)});
        m.counter.value = u(s_.retare_requests[static_cast<std::size_t>(r)]);
        f.metric.push_back(std::move(m));
      }
      out.push_back(std::move(f));
      MetricFamily g{"ruffini_aggregator_retare_results_total", "Re-tare results from the decoders, by outcome.",
                     MetricType::Counter, {}};
      for (int o = v1::RetareOutcome_MIN + 1; o <= v1::RetareOutcome_MAX; ++o) {
        if (!v1::RetareOutcome_IsValid(o)) continue;
        ClientMetric m;
        m.label.push_back({"outcome", lower(v1::RetareOutcome_Name(static_cast<v1::RetareOutcome>(o)), sizeof("RETARE_OUTCOME_") - 1)});
        m.counter.value = u(s_.retare_results[static_cast<std::size_t>(o)]);
        g.metric.push_back(std::move(m));
      }
      out.push_back(std::move(g));
    }
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
    {
      MetricFamily f{"ruffini_aggregator_link_errors_total",
                     "Communication errors the safety layer detected on the decoder links, by patch ('-': a stream "
                     "refused before it had one) and reason (docs/safety-channel.md).",
                     MetricType::Counter, {}};
      for (std::size_t i = 0; i <= s_.patch_ids.size(); ++i) {
        for (std::size_t e = 0; e < channel::kErrorKinds; ++e) {
          ClientMetric m;
          m.label = {{"patch", i < s_.patch_ids.size() ? s_.patch_ids[i] : "-"},
                     {"reason", std::string(channel::Name(static_cast<channel::Error>(e)))}};
          m.counter.value = u(s_.link_errors[i][e]);
          f.metric.push_back(m);
        }
      }
      out.push_back(std::move(f));
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
    one("ruffini_aggregator_seam_pairs_total",
        "Pairs of patch contacts the fusion placed on their seam (docs/fusion.md, Seams).", MetricType::Counter,
        u(s_.seam_pairs));
    one("ruffini_aggregator_seam_mixtures_total",
        "Of the seam pairs, those at two places along the seam made one covering contact.", MetricType::Counter,
        u(s_.seam_mixtures));
    one("ruffini_aggregator_seam_sums_total",
        "Contact frames judged on the sum of both sides of their seam (safety.seam_sum; it was larger).",
        MetricType::Counter, u(s_.seam_sums));
    one("ruffini_aggregator_contacts_faint_total",
        "Contact frames the decoder flagged faint (shifts a baseline error gives as well); judged as read.",
        MetricType::Counter, u(s_.contacts_faint));
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

std::shared_ptr<prometheus::Collectable> MakeStatsCollectable(const Stats& stats) {
  return std::make_shared<StatsCollectable>(stats);
}

}  // namespace ruffini::aggregator
