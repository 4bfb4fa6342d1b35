// `ruffini bench-service`, part 1: the decoder's "parse to message" throughput on one thread, and the
// report (service_bench.h). The end-to-end part is service_bench_e2e.cpp.
#include "ruffini/harness/service_bench.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <span>
#include <sstream>
#include <string_view>

#include "ruffini/decode/model_io.h"
#include "ruffini/decode/pipeline.h"
#include "ruffini/error.h"
#include "ruffini/ingest/hyperion.h"
#include "ruffini/link/monitor.h"
#include "ruffini/link/to_proto.h"
#include "ruffini/plot/svg.h"
#include "ruffini/sim/scenario.h"
#include "ruffini/twin/scene.h"
#include "ruffini/v1/patch.pb.h"

namespace ruffini::harness {
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

double ThreadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + static_cast<double>(ts.tv_nsec) * 1e-9;
}

// The publisher's half: every message to a PatchMessage, serialized into one reused string.
class ProtoSink final : public link::MessageSink {
 public:
  explicit ProtoSink(std::string patch_id) : patch_id_(std::move(patch_id)) { bytes_.reserve(4096); }
  void Push(const link::Message& m) noexcept override {
    link::ToProto(m, patch_id_, ++seq_, out_);
    out_.SerializeToString(&bytes_);
    bytes_total_ += bytes_.size();
    Count(m);
  }
  void Count(const link::Message& m) noexcept {
    ++messages_;
    switch (m.kind) {
      case link::Message::Kind::kContact: ++contacts_; break;
      case link::Message::Kind::kHeartbeat: ++heartbeats_; break;
      case link::Message::Kind::kFault: ++faults_; break;
      case link::Message::Kind::kRetare: break;  // only on an operator's request: none in a bench
    }
  }
  std::string patch_id_;
  std::uint64_t seq_ = 0;
  v1::PatchMessage out_;
  std::string bytes_;
  std::uint64_t bytes_total_ = 0, messages_ = 0, contacts_ = 0, heartbeats_ = 0, faults_ = 0;
};

// Counts only (the monitor without the publisher's conversion).
class CountSink final : public link::MessageSink {
 public:
  void Push(const link::Message& m) noexcept override {
    ++messages_;
    if (m.kind == link::Message::Kind::kContact) ++contacts_;
    if (m.kind == link::Message::Kind::kHeartbeat) ++heartbeats_;
    if (m.kind == link::Message::Kind::kFault) ++faults_;
  }
  std::uint64_t messages_ = 0, contacts_ = 0, heartbeats_ = 0, faults_ = 0;
};

struct Prepared {
  twin::Scene scene;
  const twin::ScenePatch* patch = nullptr;
  std::size_t channel = 0;
  v1::DecoderModel model;
  std::vector<std::uint8_t> bytes;
  std::int64_t t0_ns = 0;
};

ingest::DecoderConfig CodecFor(const Prepared& p) {
  // As the service with allow_missing (its default): grating bands halfway between the nominal centres.
  Wavelengths centre{};
  for (std::size_t i = 0; i < kGratings; ++i) centre[i] = p.patch->spec.gratings.at(i).wavelength_nm;
  ingest::DecoderConfig codec;
  codec.pick = ingest::NearestGratingBands(p.channel, centre);
  return codec;
}

enum class Stage { kCodec, kMonitor, kFull };

struct PassResult {
  double seconds = 0.0;      // wall (steady clock)
  double cpu_seconds = 0.0;  // this thread's CPU time (CLOCK_THREAD_CPUTIME_ID): no time spent descheduled
  std::uint64_t frames = 0, in_contact = 0, capturing = 0;
  std::uint64_t messages = 0, contacts = 0, heartbeats = 0, faults = 0, bytes = 0;
};

// One timed pass over the whole buffer, with a fresh codec, pipeline and monitor (the stream from frame 0).
PassResult Pass(const Prepared& p, const ServiceBenchOptions& o, const std::string& choice_text, Stage stage) {
  decode::PipelineConfig pc;
  pc.baseline = decode::BaselineFor(p.model, o.stream_rate_hz);
  const link::DecoderChoice choice = link::ParseDecoderChoice(choice_text, p.model);
  auto pipeline = link::MakePipeline(p.model, p.patch->spec, pc, choice);
  link::MonitorConfig mc;
  mc.sample_rate_hz = o.stream_rate_hz;
  mc = link::Resolved(mc);
  // The injected clock is the stream's own: frame k arrives at t0 + k / rate, so heartbeats come as often as
  // in the live service at that rate.
  const link::Now start{0, p.t0_ns};
  link::Monitor monitor(*pipeline, mc, start);
  ingest::StreamDecoder codec(CodecFor(p));
  ProtoSink proto_sink(p.patch->name);
  CountSink count_sink;
  link::MessageSink& sink = stage == Stage::kFull ? static_cast<link::MessageSink&>(proto_sink) : count_sink;
  monitor.OnConnected(start, sink);

  PassResult r;
  std::uint64_t checksum = 0;
  std::span<const std::uint8_t> rest(p.bytes);
  const double cpu0 = ThreadCpuSeconds();
  const auto t0 = Clock::now();
  while (!rest.empty()) {
    const auto fr = codec.Feed(rest);
    rest = rest.subspan(fr.consumed);
    if (fr.status != ingest::StreamDecoder::Status::kFrame) continue;
    ++r.frames;
    if (stage == Stage::kCodec) {
      checksum += codec.frame().serial_number + static_cast<std::uint64_t>(codec.wavelength_nm()[0] > 1550.0);
      continue;
    }
    link::FrameIn f;
    f.serial = codec.frame().serial_number;
    f.t_ns = codec.frame().timestamp_ns;
    f.flags = codec.flags();
    f.wavelength_nm = codec.wavelength_nm();
    const link::Now now{f.t_ns - p.t0_ns, f.t_ns};
    monitor.OnFrame(f, now, sink);
    monitor.Tick(now, sink);
    r.in_contact += monitor.health().in_contact ? 1 : 0;
    r.capturing += monitor.health().baseline == link::BaselineState::kCapturing ? 1 : 0;
  }
  r.seconds = SecondsSince(t0);
  r.cpu_seconds = ThreadCpuSeconds() - cpu0;
  if (stage == Stage::kCodec && checksum == 0) r.frames = 0;  // never true; keeps the loop's work observable
  if (stage == Stage::kFull) {
    r.messages = proto_sink.messages_;
    r.contacts = proto_sink.contacts_;
    r.heartbeats = proto_sink.heartbeats_;
    r.faults = proto_sink.faults_;
    r.bytes = proto_sink.bytes_total_;
  } else {
    r.messages = count_sink.messages_;
    r.contacts = count_sink.contacts_;
    r.heartbeats = count_sink.heartbeats_;
    r.faults = count_sink.faults_;
  }
  return r;
}

std::string Fixed(double v, int digits) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}
std::string Thousands(double v) {
  // Groups of three digits, space-separated (built forwards: GCC 12 warns falsely on string::insert here).
  const std::string digits = std::to_string(static_cast<long long>(std::llround(v)));
  std::string out;
  for (std::size_t i = 0; i < digits.size(); ++i) {
    const std::size_t left = digits.size() - i;
    if (i > 0 && left % 3 == 0 && digits[i - 1] != '-') out += ' ';
    out += digits[i];
  }
  return out;
}

}  // namespace

ThroughputResult RunThroughput(const ServiceBenchOptions& o, const std::function<void(const std::string&)>& log) {
  Prepared p;
  p.scene = twin::LoadScene(o.scene_path);
  p.patch = &p.scene.Patch(o.patch);
  p.channel = static_cast<std::size_t>(p.patch - p.scene.patches.data());
  if (p.patch->model_path.empty()) throw InputError(o.scene_path + ": patch '" + p.patch->name + "' names no model");
  p.model = decode::LoadModel(p.patch->model_path);
  decode::CheckModelMatchesPatch(p.model, p.patch->spec, p.patch->model_path);
  const sim::Scenario scenario = sim::LoadScenario(o.scenario_path, p.scene);

  ThroughputResult result;
  result.frames = o.frames;
  {
    log("throughput: encoding " + std::to_string(o.frames) + " frames from the live twin (" + o.scenario_path + ")");
    const auto t0 = Clock::now();
    sim::ScriptedSource source(p.scene, scenario, o.stream_rate_hz);
    std::vector<Wavelengths> channels(source.channels());
    p.t0_ns = 1'700'000'000'000'000'000;  // a fixed Unix time: the buffer is the same on every run
    const double period_ns = 1e9 / o.stream_rate_hz;
    std::vector<std::uint8_t> frame;
    for (std::size_t k = 0; k < o.frames; ++k) {
      source.Sample(k, channels);
      const auto t_ns = p.t0_ns + static_cast<std::int64_t>(std::llround(static_cast<double>(k) * period_ns));
      frame = ingest::EncodeWavelengths(k, t_ns, p.channel, channels[p.channel]);
      p.bytes.insert(p.bytes.end(), frame.begin(), frame.end());
    }
    result.encode_s = SecondsSince(t0);
    result.buffer_bytes = p.bytes.size();
  }

  std::vector<std::string> choices = {"paper-float", "paper-double"};
  if (p.model.location_size() > 0) choices.push_back(p.model.location(0).grid().name() + "-float");
  struct Job {
    std::string config;
    Stage stage;
    std::string what;
  };
  std::vector<Job> jobs;
  for (const auto& c : choices) jobs.push_back({c, Stage::kFull, "Feed -> Monitor::OnFrame + Tick -> ToProto + SerializeToString"});
  jobs.push_back({"paper-float", Stage::kMonitor, "Feed -> Monitor::OnFrame + Tick (messages counted, not converted)"});
  jobs.push_back({"(none)", Stage::kCodec, "Feed only (parse + pick the channel)"});
  // Round robin: repeat r of every row runs before repeat r + 1 of any, so a burst of other work on the
  // machine falls on all rows alike.
  result.rows.resize(jobs.size());
  for (int rep = 0; rep < std::max(1, o.repeats); ++rep) {
    for (std::size_t j = 0; j < jobs.size(); ++j) {
      const Job& job = jobs[j];
      ThroughputRow& row = result.rows[j];
      row.config = job.config;
      row.stage = job.what;
      const PassResult r = Pass(p, o, job.config == "(none)" ? "paper-float" : job.config, job.stage);
      if (r.frames != o.frames) {
        throw InputError("throughput: the codec delivered " + std::to_string(r.frames) + " of " +
                         std::to_string(o.frames) + " frames (a rejected frame in the twin's stream?)");
      }
      row.frames_per_s.push_back(static_cast<double>(r.frames) / r.seconds);
      row.frames_per_cpu_s.push_back(static_cast<double>(r.frames) / r.cpu_seconds);
      row.messages = r.messages;
      row.contact_messages = r.contacts;
      row.heartbeats = r.heartbeats;
      row.faults = r.faults;
      row.bytes_serialized = r.bytes;
      if (job.config == "paper-float" && job.stage == Stage::kFull) {
        result.frames_in_contact = r.in_contact;
        result.capturing_frames = r.capturing;
      }
    }
  }
  auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  for (auto& row : result.rows) {
    row.median_fps = median(row.frames_per_s);
    row.best_fps = *std::max_element(row.frames_per_s.begin(), row.frames_per_s.end());
    row.median_cpu_fps = median(row.frames_per_cpu_s);
    log("throughput: " + row.config + ", " + row.stage + ": median " + Thousands(row.median_fps) +
        " frames/s (wall), " + Thousands(row.median_cpu_fps) + " frames per CPU second");
  }
  return result;
}

Quantiles QuantilesOf(std::vector<double> us) {
  Quantiles q;
  q.count = us.size();
  if (us.empty()) return q;
  std::sort(us.begin(), us.end());
  // Nearest rank: the smallest value with at least p of the samples at or below it.
  auto at = [&](double p) {
    const auto rank = static_cast<std::size_t>(std::ceil(p * static_cast<double>(us.size())));
    return us[std::clamp<std::size_t>(rank, 1, us.size()) - 1];
  };
  q.p50_us = at(0.50);
  q.p90_us = at(0.90);
  q.p99_us = at(0.99);
  q.p999_us = at(0.999);
  q.min_us = us.front();
  q.max_us = us.back();
  double sum = 0.0;
  for (double v : us) sum += v;
  q.mean_us = sum / static_cast<double>(us.size());
  return q;
}

std::string LoadAverage() {
  std::ifstream in("/proc/loadavg");
  std::string a, b, c;
  in >> a >> b >> c;
  return a + " " + b + " " + c;
}

Machine MachineNow() {
  Machine m;
  m.nproc = static_cast<int>(sysconf(_SC_NPROCESSORS_ONLN));
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("model name", 0) == 0) {
      const auto colon = line.find(':');
      if (colon != std::string::npos) m.cpu_model = line.substr(colon + 2);
      break;
    }
  }
  m.load_before = LoadAverage();
  return m;
}

namespace {

std::string Us(double v) { return v >= 1000.0 ? Fixed(v, 0) : Fixed(v, 1); }
std::string FaultList(const EndToEndRun& r) {
  if (r.faults == 0) return "0";
  std::string s = std::to_string(r.faults) + " (";
  bool first = true;
  for (const auto& [name, n] : r.fault_counts) {
    s += (first ? "" : ", ") + name + " " + std::to_string(n);
    first = false;
  }
  return s + ")";
}
// A path relative to the working folder when it lies inside it (the repository root, as a rule).
std::string Shown(const std::string& path) {
  std::error_code ec;
  const auto rel = std::filesystem::relative(path, std::filesystem::current_path(), ec);
  return ec || rel.empty() || rel.string().rfind("..", 0) == 0 ? path : rel.string();
}
std::string Met(bool met) { return met ? "**met**" : "**not met**"; }

// A histogram of the latency samples as fractions per log-spaced bin, one line per rate.
void WriteHistogram(const std::vector<EndToEndRun>& runs, const std::string& path) {
  plot::Figure fig("Decoder service: contact message latency (arrival at the aggregator - frame t_ns)",
                   "latency (us, log scale)", "share of contact messages per bin", 720, 440);
  fig.SetLogX();
  constexpr double kLo = 10.0, kHi = 100000.0;
  constexpr int kBinsPerDecade = 20;
  const int bins = 4 * kBinsPerDecade;
  const std::vector<std::string> colours = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd"};
  for (std::size_t r = 0; r < runs.size(); ++r) {
    const auto& run = runs[r];
    if (run.latency_us.empty()) continue;
    std::vector<double> counts(static_cast<std::size_t>(bins), 0.0);
    for (double v : run.latency_us) {
      const double x = std::log10(std::clamp(v, kLo, kHi * 0.999999) / kLo) * kBinsPerDecade;
      counts[static_cast<std::size_t>(std::clamp(static_cast<int>(x), 0, bins - 1))] += 1.0;
    }
    plot::Series s;
    s.label = Fixed(run.rate_hz / 1000.0, 0) + " kHz: p50 " + Us(run.latency.p50_us) + " us, p99 " +
              Us(run.latency.p99_us) + " us (" + std::to_string(run.latency.count) + " messages)";
    s.colour = colours[r % colours.size()];
    s.style = plot::Series::Style::kLine;
    for (int b = 0; b < bins; ++b) {
      s.x.push_back(kLo * std::pow(10.0, (b + 0.5) / kBinsPerDecade));
      s.y.push_back(counts[static_cast<std::size_t>(b)] / static_cast<double>(run.latency_us.size()));
    }
    fig.Add(std::move(s));
  }
  fig.SetXRange(kLo, kHi);
  fig.AddVLine(200.0, "goal: p99 <= 200 us");
  try {
    fig.Save(path);
  } catch (const std::exception& e) {
    throw InputError(path + ": cannot write the histogram (" + e.what() + ")");
  }
}

}  // namespace

void WriteServiceReport(const ServiceBenchOptions& o, const Machine& m, const ThroughputResult& t,
                        const std::vector<EndToEndRun>& runs) {
  namespace fs = std::filesystem;
  const fs::path dir(o.out_dir);
  const std::string md_path = (dir / "service.md").string(), svg_path = (dir / "service-latency.svg").string();
  std::ostringstream md;
  md << "# Decoder service bench (`ruffini bench-service`)\n\n"
     << "Written by `" << o.command << "` (docs/bench/README.md says how to rerun it). Numbers are from one run on "
     << "the machine below; nothing here is a test (speed goals never are).\n\n";

  md << "## Machine\n\n"
     << "| | |\n| --- | --- |\n"
     << "| cores (`nproc`) | " << m.nproc << " |\n"
     << "| CPU | " << (m.cpu_model.empty() ? "unknown" : m.cpu_model) << " |\n"
     << "| load average (1, 5, 15 min) before | " << m.load_before << " |\n"
     << "| load average (1, 5, 15 min) after | " << m.load_after << " |\n"
     << "| scene, scenario | `" << Shown(o.scene_path) << "`, `" << Shown(o.scenario_path) << "` |\n\n";

  // --- Throughput.
  md << "## Decoder pipeline throughput (one thread, parse to message)\n\n"
     << t.frames << " Hyperion frames (" << t.buffer_bytes << " bytes) of the live twin (`sim::ScriptedSource`, "
     << "scenario above, " << Fixed(o.stream_rate_hz, 0) << " Hz stream clock) were encoded into one buffer ("
     << Fixed(t.encode_s, 1) << " s, untimed). Each timed pass starts a fresh codec, pipeline and monitor on "
     << "the buffer: `ingest::StreamDecoder::Feed` (the service's codec config: the patch's channel, missing peaks "
     << "allowed with grating bands) -> `link::Monitor::OnFrame` + `Tick` (the shipped model, "
     << "`decode::BaselineFor` at the stream rate, the stream's own clock injected) -> a sink that runs "
     << "`link::ToProto` and `SerializeToString` into a reused string for every message. "
     << o.repeats << (o.repeats == 1 ? " pass" : " passes") << " per row; frames/s = frames / wall time of the pass (steady clock); frames per CPU second = frames / the thread's CPU time in the pass. Rows run round robin (every row's first pass, then every row's second, ...).\n\n";
  const double share = t.frames ? 100.0 * static_cast<double>(t.frames_in_contact) / static_cast<double>(t.frames) : 0.0;
  md << "Frames in contact (the monitor's `in_contact` after the frame, paper-float): " << t.frames_in_contact << " of "
     << t.frames << " (" << Fixed(share, 1) << " %); frames before the baseline was captured: " << t.capturing_frames
     << ".\n\n";
  md << "| configuration | timed loop | frames per CPU second (median) | frames/s wall (median) | frames/s wall (best) | us of CPU per frame (median) | messages (contact / heartbeat / fault) | bytes serialized |\n"
     << "| --- | --- | --- | --- | --- | --- | --- | --- |\n";
  for (const auto& r : t.rows) {
    md << "| " << r.config << " | " << r.stage << " | " << Thousands(r.median_cpu_fps) << " | "
       << Thousands(r.median_fps) << " | " << Thousands(r.best_fps) << " | " << Fixed(1e6 / r.median_cpu_fps, 2) << " | "
       << (r.config == "(none)" ? std::string("-")
                                : std::to_string(r.contact_messages) + " / " + std::to_string(r.heartbeats) + " / " +
                                      std::to_string(r.faults))
       << " | " << (r.bytes_serialized ? Thousands(static_cast<double>(r.bytes_serialized)) : "-")
       << " |\n";
  }
  const double goal_fps = 100000.0;
  const double paper_fps = t.rows.empty() ? 0.0 : t.rows.front().median_cpu_fps;
  const double paper_wall = t.rows.empty() ? 0.0 : t.rows.front().median_fps;
  md << "\nGoal: paper-float >= 100 000 frames/s on one core: " << Met(paper_fps >= goal_fps) << " ("
     << Thousands(paper_fps) << " frames per CPU second, " << Fixed(100.0 * paper_fps / goal_fps, 0)
     << " % of the goal; by wall time " << Thousands(paper_wall) << " frames/s, "
     << Fixed(100.0 * paper_wall / goal_fps, 0) << " %). \"On one core\" is judged by the thread's CPU time "
     << "(`CLOCK_THREAD_CPUTIME_ID`), which leaves out the time the thread waited for a core on a shared "
     << "machine; the wall columns include it.\n\n";

  // --- End to end.
  md << "## End-to-end latency (real processes)\n\n"
     << "`ruffini-sim --scenario` and `ruffini-decoder` (defaults: paper-float, 10 ms heartbeats) run as "
     << "processes on 127.0.0.1 with port 0 and ports files; the decoder publishes to a recording Aggregator "
     << "(a gRPC server inside the bench process). For each contact message arriving in the window, latency = "
     << "arrival at the recording server (`system_clock`, Unix ns) - the message's `t_ns` (the sim's timestamp "
     << "of the frame = its scheduled send time, docs/sim.md). The window opens " << Fixed(o.warmup_s, 1)
     << " s after the decoder's first healthy heartbeat (baseline captured) and lasts " << Fixed(o.seconds, 1)
     << " s. The split: `decoder_t_ns - t_ns` (sim write lag, loopback TCP, ingest, ring A, decode) and "
     << "arrival - `decoder_t_ns` (ring B, `ToProto`, gRPC, the recording server's read). All clocks are the "
     << "same host's `system_clock`.\n\n";
  md << "| rate | contact messages | p50 (us) | p90 (us) | p99 (us) | p99.9 (us) | max (us) | mean (us) | goal p99 <= 200 us |\n"
     << "| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n";
  for (const auto& r : runs) {
    const auto& q = r.latency;
    md << "| " << Fixed(r.rate_hz / 1000.0, 0) << " kHz | " << q.count << " | " << Us(q.p50_us) << " | "
       << Us(q.p90_us) << " | " << Us(q.p99_us) << " | " << Us(q.p999_us) << " | " << Us(q.max_us) << " | "
       << Us(q.mean_us) << " | " << Met(q.count > 0 && q.p99_us <= 200.0)
       << (q.count > 0 && q.p99_us > 200.0 ? " (" + Fixed(q.p99_us / 200.0, 1) + "x)" : "") << " |\n";
  }
  md << "\nWhere the time goes (same messages):\n\n"
     << "| rate | `decoder_t_ns - t_ns` p50 / p99 / max (us) | arrival - `decoder_t_ns` p50 / p99 / max (us) |\n"
     << "| --- | --- | --- |\n";
  for (const auto& r : runs) {
    md << "| " << Fixed(r.rate_hz / 1000.0, 0) << " kHz | " << Us(r.to_decoder.p50_us) << " / "
       << Us(r.to_decoder.p99_us) << " / " << Us(r.to_decoder.max_us) << " | " << Us(r.to_aggregator.p50_us)
       << " / " << Us(r.to_aggregator.p99_us) << " / " << Us(r.to_aggregator.max_us) << " |\n";
  }
  for (const auto& r : runs) {
    if (r.latency.count == 0) continue;
    const bool decoder_side = r.to_decoder.p99_us >= r.to_aggregator.p99_us;
    md << "\n- " << Fixed(r.rate_hz / 1000.0, 0) << " kHz: the larger p99 is on the "
       << (decoder_side ? "way in (sim write, TCP, ingest, decode: " + Us(r.to_decoder.p99_us) + " us)"
                        : "way out (ring B, publisher, gRPC: " + Us(r.to_aggregator.p99_us) + " us)")
       << "; medians " << Us(r.to_decoder.p50_us) << " us in, " << Us(r.to_aggregator.p50_us) << " us out.";
  }
  md << "\n";
  md << "\nThe sim's own write lag (`system_clock` at the write - the frame's `t_ns`, its log line at shutdown; "
     << "the whole run, capture included, not only the window):\n\n";
  for (const auto& r : runs) {
    md << "- " << Fixed(r.rate_hz / 1000.0, 0) << " kHz: "
       << (r.sim_write_lag.empty() ? std::string("(not logged)") : "`" + r.sim_write_lag + "`") << "\n";
  }
  md << "\nRun details:\n\n"
     << "| rate | window (s) | messages (all) | heartbeats | faults | serial span of contacts | decoder: messages dropped / serial gaps (last heartbeat) | baseline ready after (s) | exit codes sim / decoder |\n"
     << "| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n";
  for (const auto& r : runs) {
    md << "| " << Fixed(r.rate_hz / 1000.0, 0) << " kHz | " << Fixed(r.window_s, 2) << " | " << r.messages << " | "
       << r.heartbeats << " | " << FaultList(r) << " | " << r.serial_span << " | " << r.messages_dropped << " / "
       << r.serial_gaps << " | " << Fixed(r.capture_wait_s, 2) << " | " << r.sim_exit << (r.sim_killed ? " (killed)" : "")
       << " / " << r.decoder_exit << (r.decoder_killed ? " (killed)" : "") << " |\n";
  }
  md << "\n![latency histogram](service-latency.svg)\n\n";

  // --- CPU.
  md << "## CPU share\n\n"
     << "utime + stime from `/proc/<pid>/stat` (clock ticks of " << Fixed(1000.0 / static_cast<double>(sysconf(_SC_CLK_TCK)), 0)
     << " ms) over the same window, divided by the window's wall time: percent of one core.\n\n"
     << "| rate | decoder (% of one core) | goal | sim (% of one core, context) |\n| --- | --- | --- | --- |\n";
  for (const auto& r : runs) {
    const double goal = r.rate_hz <= 1000.0 ? 5.0 : 25.0;
    md << "| " << Fixed(r.rate_hz / 1000.0, 0) << " kHz | " << Fixed(r.decoder_cpu_pct, 1) << " | <= " << Fixed(goal, 0)
       << " %: " << Met(r.decoder_cpu_pct <= goal) << " | " << Fixed(r.sim_cpu_pct, 1) << " |\n";
  }
  md << "\nThe decoder's CPU by thread name (threads of one name summed): `dec-ingest` (socket reads, the "
     << "codec, ring A), `dec-decode` (link::Monitor: the pipeline, health, ring B), `dec-publish` (ToProto, "
     << "the gRPC stream writes); `ruffini-decoder` is the main thread and gRPC's unnamed threads, other names "
     << "are gRPC's own:\n\n";
  for (const auto& r : runs) {
    std::vector<std::pair<double, std::string>> threads;
    for (const auto& [name, pct] : r.decoder_threads_cpu_pct) threads.emplace_back(pct, name);
    std::sort(threads.rbegin(), threads.rend());
    md << "- " << Fixed(r.rate_hz / 1000.0, 0) << " kHz:";
    bool first = true;
    for (const auto& [pct, name] : threads) {
      if (pct <= 0.0) continue;
      md << (first ? " " : ", ") << "`" << name << "` " << Fixed(pct, 1) << " %";
      first = false;
    }
    md << (first ? " (no thread used a clock tick)" : "") << "\n";
  }
  md << "\n";

  std::error_code ec;
  fs::create_directories(dir, ec);
  {
    std::ofstream out(md_path, std::ios::trunc);
    out << md.str();
    out.flush();
    if (!out) throw InputError(md_path + ": cannot write the report");
  }
  WriteHistogram(runs, svg_path);
}

}  // namespace ruffini::harness
