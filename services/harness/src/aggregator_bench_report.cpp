// `ruffini bench-aggregator`: the report (aggregator_bench.h): docs/bench/aggregator.md and
// aggregator-latency.svg.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "ruffini/harness/aggregator_bench.h"
#include "ruffini/error.h"
#include "ruffini/plot/svg.h"

namespace ruffini::harness {
namespace {

std::string Fixed(double v, int digits) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}
std::string Us(double v) { return v >= 1000.0 ? Fixed(v, 0) : Fixed(v, 1); }
std::string Met(bool met) { return met ? "**met**" : "**not met**"; }
std::string Shown(const std::string& path) {
  std::error_code ec;
  const auto rel = std::filesystem::relative(path, std::filesystem::current_path(), ec);
  return ec || rel.empty() || rel.string().rfind("..", 0) == 0 ? path : rel.string();
}
// "met" or "not met (2.3x)" against an upper bound.
std::string Against(double value, double goal, bool have) {
  if (!have) return "no samples";
  return Met(value <= goal) + (value > goal ? " (" + Fixed(value / goal, 1) + "x the goal)" : "");
}

// The latency distribution per configuration (empirical CDF, log x).
void WriteCdf(const std::vector<LatencyRun>& runs, const std::string& path) {
  plot::Figure fig("Aggregator: frame-to-stop latency (STOP at the subscriber - the cause frame's t_ns)",
                   "latency (us, log scale)", "share of STOPs at or below", 720, 440);
  fig.SetLogX();
  const std::vector<std::string> colours = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd"};
  double lo = 1e9, hi = 0;
  for (std::size_t r = 0; r < runs.size(); ++r) {
    std::vector<double> v = runs[r].latency_us;
    if (v.empty()) continue;
    std::sort(v.begin(), v.end());
    plot::Series s;
    s.label = std::to_string(runs[r].patches) + " patches: p50 " + Us(runs[r].latency.p50_us) + " us, p99 " +
              Us(runs[r].latency.p99_us) + " us (" + std::to_string(v.size()) + " STOPs)";
    s.colour = colours[r % colours.size()];
    s.style = plot::Series::Style::kLine;
    for (std::size_t i = 0; i < v.size(); ++i) {
      s.x.push_back(v[i]);
      s.y.push_back(static_cast<double>(i + 1) / static_cast<double>(v.size()));
    }
    lo = std::min(lo, v.front());
    hi = std::max(hi, v.back());
    fig.Add(std::move(s));
  }
  if (hi <= 0) {
    lo = 10;
    hi = 10000;
  }
  fig.SetXRange(std::min(lo * 0.8, 100.0), std::max(hi * 1.25, 2000.0));
  fig.SetYRange(0.0, 1.0);
  fig.AddVLine(200.0, "goal: p50 <= 200 us");
  fig.AddVLine(1000.0, "goal: p99 <= 1 ms");
  try {
    fig.Save(path);
  } catch (const std::exception& e) {
    throw InputError(path + ": cannot write the figure (" + e.what() + ")");
  }
}

}  // namespace

void WriteAggregatorReport(const AggregatorBenchOptions& o, const Machine& m, const std::vector<LatencyRun>& latency,
                           const std::vector<FanInRun>& fanin, const std::string& micro, const std::string& micro_command) {
  namespace fs = std::filesystem;
  const fs::path dir(o.out_dir);
  const std::string md_path = (dir / "aggregator.md").string(), svg_path = (dir / "aggregator-latency.svg").string();
  std::ostringstream md;
  md << "# Aggregator bench (`ruffini bench-aggregator`)\n\n"
     << "Written by `" << o.command << "` (docs/bench/README.md says how to rerun it). Numbers are from one run on "
     << "the machine below; nothing here is a test (speed goals never are).\n\n";
  md << "## Machine\n\n"
     << "| | |\n| --- | --- |\n"
     << "| cores (`nproc`) | " << m.nproc << " |\n"
     << "| CPU | " << (m.cpu_model.empty() ? "unknown" : m.cpu_model) << " |\n"
     << "| load average (1, 5, 15 min) before | " << m.load_before << " |\n"
     << "| load average (1, 5, 15 min) after | " << m.load_after << " |\n\n"
     << "The machine is shared: the load average counts other people's builds and tests as well as this bench. "
     << "Every process below (sim, decoders, aggregator, this bench) shares the same " << m.nproc << " cores.\n\n";

  // --- Latency.
  md << "## Frame-to-stop latency (real processes)\n\n"
     << "`ruffini-sim --scenario` (1 kHz), one `ruffini-decoder` per patch (defaults: paper-float, 10 ms "
     << "heartbeats; `--silence-ms 100`, its interrogator watchdog widened for a loaded machine) and "
     << "`ruffini-aggregator` (the scene's own deadlines: 30 ms patch silence, 50 ms joint-state age) run as "
     << "processes on 127.0.0.1 with port 0 and ports files. This bench is the controller: a WatchSafety "
     << "subscriber on its own channel and thread, joint states at 100 Hz, and after each STOP a ResetStop naming "
     << "the current epoch every 50 ms until accepted (refused while the press is held or the patch not healthy "
     << "long enough). The scenario (generated into the work folder) presses 2.5 N (threshold 1.5 N) on one patch "
     << "after another every " << Fixed(o.touch_period_s, 1) << " s (ramp 0.1 s, hold 0.3 s, release 0.1 s), "
     << "so each press gives one STOP. Latency = arrival of the STOP at the subscriber (`system_clock`, Unix ns, "
     << "taken when `Read` returns) - the cause's `t_ns` (the sim's scheduled send time of the frame that latched "
     << "the STOP, docs/sim.md). Split at the STOP's `changed_t_ns` (the aggregator's clock when it latched). One "
     << "host, one clock. The window opens at the first CLEAR and lasts " << Fixed(o.seconds, 0) << " s.\n\n"
     << "The 4-patch run is `" << Shown(o.cobot_scene) << "`; larger runs use a generated scene: the same robot "
     << "(srs7), the same patch spec and model, N patches in rings around the forearm and upper arm (several yaws "
     << "per ring), the cobot scene's safety and twin sections.\n\n";
  md << "| patches | STOPs | p50 (us) | p90 (us) | p99 (us) | max (us) | mean (us) | goal p50 <= 200 us | goal p99 <= 1 ms |\n"
     << "| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n";
  for (const auto& r : latency) {
    const auto& q = r.latency;
    const bool have = q.count > 0;
    md << "| " << r.patches << " | " << q.count << " | " << Us(q.p50_us) << " | " << Us(q.p90_us) << " | "
       << Us(q.p99_us) << " | " << Us(q.max_us) << " | " << Us(q.mean_us) << " | " << Against(q.p50_us, 200.0, have)
       << " | " << Against(q.p99_us, 1000.0, have) << " |\n";
  }
  md << "\nWith fewer than 100 STOPs, p99 is the largest or second largest sample: read it as \"the worst of the "
     << "run\".\n\nWhere the time goes (same STOPs):\n\n"
     << "| patches | cause `t_ns` -> latched (`changed_t_ns`): p50 / p99 / max (us) | latched -> arrival at the subscriber: p50 / p99 / max (us) |\n"
     << "| --- | --- | --- |\n";
  for (const auto& r : latency) {
    md << "| " << r.patches << " | " << Us(r.to_latch.p50_us) << " / " << Us(r.to_latch.p99_us) << " / "
       << Us(r.to_latch.max_us) << " | " << Us(r.latch_to_arrival.p50_us) << " / " << Us(r.latch_to_arrival.p99_us)
       << " / " << Us(r.latch_to_arrival.max_us) << " |\n";
  }
  md << "\nThe first column is the sim's write, loopback TCP, the decoder (ingest, decode, its publisher), gRPC "
     << "and the aggregator's event queue up to the latch; the second is the aggregator's publication (one write "
     << "in flight per subscriber), gRPC and the subscriber's read.\n\n";
  md << "Run details:\n\n"
     << "| patches | scene | window (s) | start -> first CLEAR (s) | hard presses scheduled in the window (approx.) | STOPs | entries into FAULT (cause) | resets accepted / refused | CPU aggregator / sim / decoders summed (% of one core) |\n"
     << "| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n";
  for (const auto& r : latency) {
    std::string causes;
    for (const auto& [k, n] : r.fault_causes) causes += (causes.empty() ? "" : ", ") + k + " " + std::to_string(n);
    md << "| " << r.patches << " | `" << Shown(r.scene) << "` | " << Fixed(r.window_s, 1) << " | " << Fixed(r.setup_s, 1)
       << " | " << r.presses_in_window << " | " << r.stops << " | " << r.faults << (causes.empty() ? "" : " (" + causes + ")")
       << " | " << r.resets_accepted << " / " << r.resets_refused << " | " << Fixed(r.aggregator_cpu_pct, 1) << " / "
       << Fixed(r.sim_cpu_pct, 1) << " / " << Fixed(r.decoders_cpu_pct, 1) << " |\n";
  }
  md << "\n![latency CDF](aggregator-latency.svg)\n\n";

  // --- Fan-in.
  md << "## Fan-in capacity (synthetic decoders)\n\n"
     << "`ruffini-aggregator` on a generated N-patch scene (as above; its deadlines: 30 ms patch silence). N "
     << "synthetic decoders run inside this bench process, each a gRPC Connect stream on its own channel (its "
     << "own TCP connection): a valid hello (spec fingerprint and model SHA-256 read with the aggregator's own "
     << "`SetupFromScene`), then from one pacing thread on absolute 1 ms deadlines a located contact of 0.5 N "
     << "(below the 1.5 N threshold) per patch per tick and a healthy heartbeat every 10 ms, seq + 1 each "
     << "(callback API, one write in flight per stream, at most 64 queued). Joint states at 100 Hz and one "
     << "WatchSafety subscriber as above. After every hello is accepted and a reset clears the start-up FAULT, "
     << "a 0.3 s settle, then a " << Fixed(o.fanin_seconds, 0) << " s window.\n\n"
     << "A **miss** is any of: a FAULT or STOP at the subscriber; a gap between consecutive SafetyState messages at "
     << "the subscriber above 30 ms (heartbeats are every 10 ms); the aggregator's "
     << "`ruffini_aggregator_patch_messages_total` (read from its metrics port at the window's end) behind the "
     << "messages sent by more than 30 ms of traffic (the aggregator copies that counter every 5 ms, so a few ms "
     << "of backlog are only that).\n\n"
     << "| N | contacts + heartbeats sent | messages/s | max SafetyState gap (ms) | backlog at the end (ms of traffic) | FAULT / STOP messages | sender overflows | pacer ticks late > 1 ms | aggregator CPU (% of one core) | bench process CPU (%) | result |\n"
     << "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n";
  int best = 0;
  bool clean_so_far = true;
  for (const auto& r : fanin) {
    if (!r.ran) {
      md << "| " << r.patches << " | - | - | - | - | - | - | - | - | - | setup failed: " << r.error << " |\n";
      clean_so_far = false;
      continue;
    }
    const double rate = static_cast<double>(r.contacts_sent + r.heartbeats_sent) / r.window_s;
    md << "| " << r.patches << " | " << r.contacts_sent << " + " << r.heartbeats_sent << " | " << Fixed(rate, 0)
       << " | " << Fixed(r.max_heartbeat_gap_ms, 1) << " | " << Fixed(r.backlog_ms, 1) << " | " << r.faults << " / "
       << r.stops << " | " << r.sender_overflows << " | " << r.pacer_late_ticks << " of " << r.ticks << " | "
       << Fixed(r.aggregator_cpu_pct, 1) << " | " << Fixed(r.bench_cpu_pct, 1) << " | "
       << (r.miss ? "**miss**: " + r.miss_reason : "no miss") << " |\n";
    if (!r.miss && clean_so_far) best = r.patches;
    if (r.miss) clean_so_far = false;
  }
  md << "\nLargest N without a miss (every smaller N clean too): **" << best << "**; goal >= 64: " << Met(best >= 64)
     << ".\n\n"
     << "Honest caveat: the synthetic senders (N gRPC streams, the pacing thread, gRPC's own threads) run in this "
     << "bench process on the same cores as the aggregator; its CPU column is what they cost. Real decoders cost "
     << "more each (bench-service: about 10 % of a core per decoder at 1 kHz) and would sit on other machines or "
     << "cores. A sender overflow or a late pacer tick is the sender's lag, not the aggregator's, but it shows up "
     << "as fewer messages sent in the window (the messages/s column: N x 1100 when the senders keep up).\n\n";

  // --- Micro.
  md << "## FK and fusion cost per update (Google Benchmark)\n\n";
  if (micro.empty()) {
    md << "Not run: `aggregate_bench` was not found next to `ruffini` (build it: `cmake --build build/release "
       << "--target aggregate_bench`; the bench runs it when it is there).\n\n";
  } else {
    md << "`" << micro_command << "` (tests/bench/aggregate_bench.cpp): `robot::ForwardKinematics` on srs7, "
       << "`fusion::Fuser::Update` for 1 contact, 2 (a seam: forearm_a and forearm_b of the cobot scene, one "
       << "press) and 8 (8 patches on the forearm and upper arm), and `aggregate::Core::OnPatchMessage` for one "
       << "contact message (0.5 N, located; placement with the joint state interpolated from 1 s of 100 Hz "
       << "history, FK and the policy):\n\n```\n"
       << micro << "```\n\n";
  }

  std::error_code ec;
  fs::create_directories(dir, ec);
  {
    std::ofstream out(md_path, std::ios::trunc);
    out << md.str();
    out.flush();
    if (!out) throw InputError(md_path + ": cannot write the report");
  }
  WriteCdf(latency, svg_path);
}

}  // namespace ruffini::harness
