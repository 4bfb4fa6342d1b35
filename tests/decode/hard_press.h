#pragma once
// Hard presses through the whole decode path of a live decoder, without sockets: the twin of one patch of
// a scene (its edges as ruffini-sim sets them) -> its InterrogatorSim -> Hyperion bytes (peaks of the channel in ascending order, a missing peak
// left out, as ruffini-sim sends them) -> the ingest codec with the decoder service's default picking
// (NearestGratingBands) -> link::Monitor over the decoder service's default pipeline -> the messages the
// aggregator would get. One press per point: 1.5 s untouched (the baseline capture), a 0.3 s ramp to the
// force, a 0.5 s hold, a 0.3 s release, 0.4 s of rest.
//
// What counts as a stop is what the aggregator's existing rule does with those messages: a contact whose
// force is above the region's threshold (strictly), or a fault (a fault is a STOP/FAULT).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "ruffini/decode/model_io.h"
#include "ruffini/ingest/hyperion.h"
#include "ruffini/link/monitor.h"
#include "ruffini/sim/scenario.h"
#include "ruffini/twin/scene.h"
#include "ruffini/twin/twin.h"

namespace ruffini::testing {

struct PressOutcome {
  bool stop_force = false;  // a contact above the threshold
  bool over_range = false;  // a contact flagged over range
  bool fault = false;       // a fault message during the press
  float max_force_n = 0.0f; // largest contact force reported
  [[nodiscard]] bool stops() const noexcept { return stop_force || over_range || fault; }
  std::vector<link::Contact> hold;  // the contact messages of the hold (the force steady)
  std::vector<std::int64_t> hold_t_ns;  // their frames' times (the same for every rig: one clock)
};

struct ProbeAt {
  double y_mm = 0.0, r_deg = 0.0, force_n = 0.0;
};

class HardPressRig {
 public:
  HardPressRig(const twin::Scene& scene, std::size_t patch, const v1::DecoderModel& model, double rate_hz = 1000.0)
      : scene_(scene), patch_(patch), model_(model), rate_hz_(rate_hz),
        mounts_(sim::LoadMounts(scene)),
        twin_(scene.patches[patch].spec, sim::EffectsFor(scene, mounts_.get(), patch), {scene.probe.radius_mm}) {
    Wavelengths centre{};
    for (std::size_t i = 0; i < kGratings; ++i) centre[i] = scene.patches[patch].spec.gratings[i].wavelength_nm;
    codec_.pick = ingest::NearestGratingBands(0, centre);
    pipeline_config_.baseline = decode::BaselineFor(model, rate_hz);
    monitor_config_.sample_rate_hz = rate_hz;
    monitor_config_ = link::Resolved(monitor_config_);
  }

  [[nodiscard]] const twin::SkinTwin& twin() const noexcept { return twin_; }
  // The decoder's pipeline settings (the service's defaults unless a test changes them).
  decode::PipelineConfig& pipeline_config() noexcept { return pipeline_config_; }
  // A stop rule measured and not shipped (docs/experiments/pair.md, "Stop 33"): a contact flagged `multiple` also
  // stops when force + k x force_sd crosses the threshold (0: off, the aggregator's rule).
  void set_multiple_sd_k(double k) noexcept { multiple_sd_k_ = k; }

  // Several probes pressed together (same ramp, hold and release).
  PressOutcome Press(std::span<const ProbeAt> probes, double threshold_n, std::uint64_t seed = 1) const {
    struct Sink final : link::MessageSink {
      std::vector<link::Message> messages;
      void Push(const link::Message& m) noexcept override { messages.push_back(m); }
    } sink;
    auto pipeline = link::MakePipeline(model_, scene_.patches[patch_].spec, pipeline_config_, link::DecoderChoice{});
    const std::int64_t epoch_ns = 1'700'000'000'000'000'000;
    link::Monitor monitor(*pipeline, monitor_config_, link::Now{0, epoch_ns});
    ingest::StreamDecoder decoder(codec_);
    twin::InterrogatorSim sim(twin_, seed);
    monitor.OnConnected(link::Now{0, epoch_ns}, sink);
    const double t_press = 1.5, ramp = 0.3, hold = 0.5, release = 0.3, rest = 0.4;
    const auto frames = static_cast<std::uint64_t>((t_press + ramp + hold + release + rest) * rate_hz_);
    std::vector<twin::Contact> contacts(probes.size());
    PressOutcome out;
    std::size_t first_message = 0;
    for (std::uint64_t k = 0; k < frames; ++k) {
      const double t = static_cast<double>(k) / rate_hz_;
      const double u = t - t_press;
      double w = 0.0;
      if (u >= 0 && u < ramp) w = u / ramp;
      else if (u >= ramp && u <= ramp + hold) w = 1.0;
      else if (u > ramp + hold && u < ramp + hold + release) w = 1.0 - (u - ramp - hold) / release;
      for (std::size_t i = 0; i < probes.size(); ++i) {
        contacts[i] = twin::Contact{{probes[i].y_mm, probes[i].r_deg}, w * probes[i].force_n, scene_.probe};
      }
      twin::Shifts s{};
      std::uint32_t flags = 0;
      twin_.StrainShiftsPm(contacts, s, flags);
      Wavelengths wl{};
      sim.Read(t, s, wl, flags);
      // What ruffini-sim puts on the wire: the channel's peaks in ascending order, a missing one left out.
      const std::int64_t t_ns = epoch_ns + static_cast<std::int64_t>(t * 1e9);
      const std::vector<std::uint8_t> bytes = ingest::EncodeWavelengths(k, t_ns, 0, wl);
      const link::Now now{static_cast<std::int64_t>(t * 1e9), t_ns};
      if (k == static_cast<std::uint64_t>(t_press * rate_hz_)) first_message = sink.messages.size();
      std::span<const std::uint8_t> rest_bytes(bytes);
      while (!rest_bytes.empty()) {
        const auto r = decoder.Feed(rest_bytes);
        rest_bytes = rest_bytes.subspan(r.consumed);
        if (r.status == ingest::StreamDecoder::Status::kFrame) {
          link::FrameIn f;
          f.serial = k;
          f.t_ns = t_ns;
          f.flags = decoder.flags();
          f.wavelength_nm = decoder.wavelength_nm();
          monitor.OnFrame(f, now, sink);
        } else if (r.status == ingest::StreamDecoder::Status::kRejected) {
          monitor.OnStreamRejected(r.reason, now, sink);
        } else if (r.status == ingest::StreamDecoder::Status::kNeedsResync) {
          monitor.OnStreamRejected(r.reason, now, sink);
          decoder.Reset();
          break;
        }
      }
      monitor.Tick(now, sink);
    }
    for (std::size_t i = first_message; i < sink.messages.size(); ++i) {
      const link::Message& m = sink.messages[i];
      if (m.kind == link::Message::Kind::kFault && m.fault.code != link::FaultCode::kNone) out.fault = true;
      if (m.kind == link::Message::Kind::kContact) {
        const double t = static_cast<double>(m.t_ns - epoch_ns) * 1e-9 - t_press;
        if (t >= ramp && t <= ramp + hold) {
          out.hold.push_back(m.contact);
          out.hold_t_ns.push_back(m.t_ns);
        }
        out.max_force_n = std::max(out.max_force_n, m.contact.force_n);
        if (m.contact.force_n > threshold_n) out.stop_force = true;
        if (multiple_sd_k_ > 0.0 && m.contact.multiple &&
            m.contact.force_n + multiple_sd_k_ * m.contact.force_sd_n > threshold_n) {
          out.stop_force = true;
        }
#ifdef RUFFINI_HAS_OVER_RANGE
        if (m.contact.over_range) out.over_range = true;
#endif
      }
    }
    return out;
  }

 private:
  const twin::Scene& scene_;
  std::size_t patch_;
  const v1::DecoderModel& model_;
  double rate_hz_;
  double multiple_sd_k_ = 0.0;
  std::unique_ptr<sim::MountedScene> mounts_;  // the scene's seams make edges `continued` (sim::EffectsFor)
  twin::SkinTwin twin_;
  ingest::DecoderConfig codec_;
  decode::PipelineConfig pipeline_config_;
  link::MonitorConfig monitor_config_;
};

// The grid of the measurement: every 10 mm along Y and around the arc, plus 2 mm from each edge.
inline std::vector<double> GridMm(double length_mm) {
  std::vector<double> v{2.0};
  for (double x = 10.0; x < length_mm - 2.0 - 1e-9; x += 10.0) v.push_back(x);
  v.push_back(length_mm - 2.0);
  return v;
}

}  // namespace ruffini::testing
