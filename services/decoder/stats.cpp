#include "stats.h"

#include <string_view>

namespace ruffini::decoder {

StatsCollectable::StatsCollectable(const Stats& stats, std::string patch,
                                   std::vector<std::pair<std::string, std::string>> info)
    : stats_(stats), patch_(std::move(patch)), info_(std::move(info)) {}

namespace {

using prometheus::ClientMetric;
using prometheus::MetricFamily;
using prometheus::MetricType;

double Load(const std::atomic<std::uint64_t>& a) { return static_cast<double>(a.load(std::memory_order_relaxed)); }

}  // namespace

std::vector<MetricFamily> StatsCollectable::Collect() const {
  std::vector<MetricFamily> out;
  const ClientMetric::Label patch{"patch", patch_};
  auto family = [&](std::string name, std::string help, MetricType type) -> MetricFamily& {
    out.push_back(MetricFamily{std::move(name), std::move(help), type, {}});
    return out.back();
  };
  auto add = [&](MetricFamily& f, double v, std::vector<ClientMetric::Label> extra = {}) {
    ClientMetric m;
    m.label.push_back(patch);
    for (auto& l : extra) m.label.push_back(std::move(l));
    if (f.type == MetricType::Counter) m.counter.value = v;
    else m.gauge.value = v;
    f.metric.push_back(std::move(m));
  };
  auto counter = [&](std::string name, std::string help, const std::atomic<std::uint64_t>& a) {
    add(family(std::move(name), std::move(help), MetricType::Counter), Load(a));
  };
  auto gauge = [&](std::string name, std::string help, double v) {
    add(family(std::move(name), std::move(help), MetricType::Gauge), v);
  };
  const Stats& s = stats_;

  {
    auto& f = family("ruffini_decoder_info", "The decoder's configuration (value 1; labels name it).", MetricType::Gauge);
    ClientMetric m;
    m.label.push_back(patch);
    for (const auto& [k, v] : info_) m.label.push_back({k, v});
    m.gauge.value = 1;
    f.metric.push_back(std::move(m));
  }
  counter("ruffini_decoder_frames_total", "Interrogator frames delivered by the stream codec.", s.frames);
  counter("ruffini_decoder_frames_valid_total", "Frames decoded (valid).", s.valid_frames);
  {
    auto& f = family("ruffini_decoder_frames_rejected_total",
                     "Frames rejected, by reason (the codec's and the decoding pipeline's).", MetricType::Counter);
    for (std::size_t i = 1; i < s.decode_rejected.size(); ++i) {
      add(f, Load(s.decode_rejected[i]), {{"reason", std::string(decode::ReasonName(static_cast<decode::Reason>(i)))}});
    }
    for (std::size_t i = 1; i < s.stream_rejected.size(); ++i) {
      add(f, Load(s.stream_rejected[i]),
          {{"reason", "stream_" + std::string(ingest::ReasonName(static_cast<ingest::Reason>(i)))}});
    }
  }
  counter("ruffini_decoder_serial_gaps_total", "Breaks in the interrogator's serial numbers.", s.serial_gaps);
  counter("ruffini_decoder_frames_lost_total", "Frames missing from serial gaps.", s.frames_lost);
  counter("ruffini_decoder_frames_dropped_total",
          "Frames dropped before decoding because the decode thread fell behind (ingest ring full).", s.ingest_dropped);
  counter("ruffini_decoder_contacts_total", "Contacts reported (onsets).", s.onsets);
  counter("ruffini_decoder_frames_faint_total",
          "Contact frames flagged faint: every shift below the faint level, which a baseline error gives as well.",
          s.faint_frames);
  counter("ruffini_decoder_captures_refused_total",
          "Start-up baseline captures refused because they were not the patch's rest (--rest-file): a press held "
          "through a restart.",
          s.captures_refused);
  counter("ruffini_decoder_rest_file_errors_total",
          "Writes of the rest file (--rest-file) that failed: until one succeeds, a restart trusts its first capture.",
          s.rest_file_errors);
  counter("ruffini_decoder_frames_release_refused_total",
          "Gate-open frames reported as no contact after a release: below the release force while a press is recent "
          "(PipelineConfig::release_*; models that refuse faint frames).",
          s.release_refused_frames);
  {
    auto& f = family("ruffini_decoder_faults_total", "Faults begun, by code.", MetricType::Counter);
    for (std::size_t i = 1; i < s.faults.size(); ++i) {
      add(f, Load(s.faults[i]), {{"code", std::string(link::FaultName(static_cast<link::FaultCode>(i)))}});
    }
  }
  {
    auto& f = family("ruffini_decoder_fault_active", "1 for the fault in force (0 for the others).", MetricType::Gauge);
    const int active = s.active_fault.load(std::memory_order_relaxed);
    for (std::size_t i = 1; i < s.faults.size(); ++i) {
      add(f, static_cast<int>(i) == active ? 1.0 : 0.0,
          {{"code", std::string(link::FaultName(static_cast<link::FaultCode>(i)))}});
    }
  }
  gauge("ruffini_decoder_healthy", "1 when the decoder is fit to report touches.", s.healthy.load() ? 1.0 : 0.0);
  gauge("ruffini_decoder_in_contact", "1 while a contact is on.", s.in_contact.load() ? 1.0 : 0.0);
  {
    auto& f = family("ruffini_decoder_baseline_state", "1 for the baseline's state (0 for the others).", MetricType::Gauge);
    const int st = s.baseline_state.load(std::memory_order_relaxed);
    for (int i = 1; i <= 4; ++i) {
      add(f, i == st ? 1.0 : 0.0, {{"state", std::string(link::BaselineStateName(static_cast<link::BaselineState>(i)))}});
    }
  }
  gauge("ruffini_decoder_baseline_drift_meters", "Baseline drift since capture (mean over gratings), m.",
        s.drift_pm.load() * 1e-12);
  gauge("ruffini_decoder_common_mode_meters", "The newest frame's common-mode shift (temperature), m.",
        s.common_mode_pm.load() * 1e-12);
  {
    auto& f = family("ruffini_decoder_decode_seconds",
                     "Time to decode one frame on the decode thread (pipeline, health, message), s.",
                     MetricType::Histogram);
    ClientMetric m;
    m.label.push_back(patch);
    s.decode_seconds.Fill(m);
    f.metric.push_back(std::move(m));
  }
  {
    auto& f = family("ruffini_decoder_frame_age_seconds",
                     "From the frame's socket read to its message handed to the publisher, s.", MetricType::Histogram);
    ClientMetric m;
    m.label.push_back(patch);
    s.frame_age_seconds.Fill(m);
    f.metric.push_back(std::move(m));
  }
  gauge("ruffini_decoder_interrogator_connected", "1 while the interrogator's stream is connected.",
        s.interrogator_connected.load() ? 1.0 : 0.0);
  counter("ruffini_decoder_interrogator_connects_total", "Connections made to the interrogator.", s.interrogator_connects);
  counter("ruffini_decoder_interrogator_received_bytes_total", "Bytes read from the interrogator.", s.interrogator_bytes);
  counter("ruffini_decoder_interrogator_resyncs_total",
          "Framing errors in the interrogator stream (each dropped the connection to resync).", s.resyncs);
  gauge("ruffini_decoder_aggregator_connected", "1 while the Connect stream to the aggregator is up.",
        s.aggregator_connected.load() ? 1.0 : 0.0);
  counter("ruffini_decoder_aggregator_connects_total", "Connect streams opened to the aggregator.", s.aggregator_connects);
  counter("ruffini_decoder_hello_refused_total", "Hellos the aggregator refused.", s.hello_refused);
  counter("ruffini_decoder_hello_timeouts_total", "Connect streams given up because the hello got no answer in time.",
          s.hello_timeouts);
  counter("ruffini_decoder_hello_wrong_robot_total",
          "Hellos accepted by an aggregator guarding another robot than the scene's (stream ended, retried).",
          s.hello_wrong_robot);
  counter("ruffini_decoder_late_frames_total",
          "Interrogator frames that waited past the freshness budget before decoding (dropped; an overload fault).",
          s.late_frames);
  {
    auto& f = family("ruffini_decoder_messages_sent_total", "Messages sent to the aggregator, by kind.", MetricType::Counter);
    static constexpr std::array<std::string_view, 4> kKinds = {"contact", "heartbeat", "fault", "retare_result"};
    for (std::size_t i = 0; i < kKinds.size(); ++i) add(f, Load(s.messages_sent[i]), {{"kind", std::string(kKinds[i])}});
  }
  {
    auto& f = family("ruffini_decoder_retare_requests_total",
                     "Re-tare requests from the aggregator: taken (judged on the next capture window) or repeated "
                     "(an id already seen from this aggregator run; ignored).",
                     MetricType::Counter);
    add(f, Load(s.retare_requests), {{"result", "taken"}});
    add(f, Load(s.retare_repeated), {{"result", "repeated"}});
  }
  {
    auto& f = family("ruffini_decoder_retares_total",
                     "Re-tares ended, by outcome (accepted: the baseline was replaced; the others: refused, named).",
                     MetricType::Counter);
    for (std::size_t i = 0; i < s.retares.size(); ++i) {
      add(f, Load(s.retares[i]), {{"outcome", std::string(decode::RetareOutcomeName(static_cast<decode::RetareOutcome>(i)))}});
    }
  }
  {
    auto& f = family("ruffini_decoder_messages_dropped_total",
                     "Messages not sent: ring_full (heartbeats and mid-contact frames on a full ring), critical "
                     "(onsets, releases, faults lost on an overflowing ring), stale (made before the current "
                     "aggregator stream began), late (waited past the freshness budget in the decoder's queue; "
                     "reported to the aggregator as a `late` fault).",
                     MetricType::Counter);
    add(f, Load(s.messages_dropped), {{"cause", "ring_full"}});
    add(f, Load(s.critical_dropped), {{"cause", "critical"}});
    add(f, Load(s.stale_discarded), {{"cause", "stale"}});
    add(f, Load(s.late_messages), {{"cause", "late"}});
  }
  return out;
}

}  // namespace ruffini::decoder
