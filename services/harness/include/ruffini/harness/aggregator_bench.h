#pragma once
// `ruffini bench-aggregator`: what the aggregator costs, measured two ways (docs/bench/aggregator.md).
//
// 1. Frame-to-stop latency: the real ruffini-sim, one ruffini-decoder per patch and ruffini-aggregator on
//    127.0.0.1 (port 0, ports files); this process is the controller (a WatchSafety subscriber, joint states at
//    100 Hz, ResetStop after each STOP once the patch is released and healthy). A generated scenario presses
//    hard (above the 1.5 N threshold) on one patch after another; each press gives one STOP. Latency = arrival
//    of the STOP at the subscriber (system_clock, Unix ns) - the cause's t_ns (the sim's scheduled send time of
//    the frame that latched it). The 4-patch run is config/scenes/cobot.yaml; larger ones are generated.
// 2. Fan-in capacity: N synthetic decoders in this process (one gRPC channel each, a valid hello read with
//    the aggregator's own SetupFromScene, then a contact below the threshold every 1 ms and a healthy
//    heartbeat every 10 ms) against ruffini-aggregator on a generated N-patch scene. A miss: any FAULT at the
//    subscriber, a WatchSafety heartbeat gap > 30 ms, or the aggregator's message count lagging what was sent
//    by more than 30 ms of traffic.
//
// Not real-time code: a measuring harness; it allocates freely.
#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "ruffini/harness/service_bench.h"  // Quantiles, Machine

namespace ruffini::harness {

struct AggregatorBenchOptions {
  std::string out_dir;
  std::string command;             // the command line, written into the report
  std::string cobot_scene;         // the 4-patch scene (config/scenes/cobot.yaml); generated scenes copy its robot,
                                   // patch spec, model, safety and twin sections
  std::vector<int> latency_patches = {4, 16};  // 4: the cobot scene itself; others generated (at most 16: the sim)
  double seconds = 75.0;           // latency window per configuration, after the first CLEAR
  double touch_period_s = 1.5;     // one hard press every this many seconds, patch after patch
  std::vector<int> fanin_patches = {4, 8, 16, 32, 48, 64};
  double fanin_seconds = 10.0;     // fan-in window per N
  std::string bin_dir;             // ruffini-sim, ruffini-decoder, ruffini-aggregator
  std::string work_dir;            // generated scenes, logs and ports files
};

struct LatencyRun {
  int patches = 0;
  std::string scene;               // the scene file used
  double window_s = 0.0;
  double setup_s = 0.0;            // processes started -> first CLEAR
  Quantiles latency;               // arrival - cause t_ns, per STOP
  Quantiles to_latch;              // changed_t_ns (the aggregator's latch) - cause t_ns
  Quantiles latch_to_arrival;      // arrival - changed_t_ns
  std::vector<double> latency_us;
  int presses_in_window = 0;       // hard presses the scenario schedules in the window (approximate: sim clock)
  int stops = 0, faults = 0, resets_accepted = 0, resets_refused = 0;
  std::map<std::string, int> fault_causes;  // cause kind -> entries into FAULT in the window
  double aggregator_cpu_pct = 0.0, sim_cpu_pct = 0.0, decoders_cpu_pct = 0.0;  // % of one core (decoders summed)
  int aggregator_exit = -1;
};

struct FanInRun {
  int patches = 0;
  bool ran = false;                // false: setup failed (see error)
  std::string error;
  double window_s = 0.0;
  std::uint64_t contacts_sent = 0, heartbeats_sent = 0;  // in the window
  std::uint64_t sender_overflows = 0;   // messages the synthetic senders could not queue (their own lag)
  std::uint64_t pacer_late_ticks = 0;   // 1 ms ticks the pacing thread started > 1 ms late
  std::uint64_t ticks = 0;
  double backlog_ms = 0.0;         // (sent - received by the aggregator) at the window's end, in ms of traffic
  double max_heartbeat_gap_ms = 0.0;
  std::uint64_t heartbeats_seen = 0;
  int faults = 0, stops = 0;
  std::string fault_cause;         // the first FAULT's cause in the window
  double aggregator_cpu_pct = 0.0, bench_cpu_pct = 0.0;
  bool miss = false;
  std::string miss_reason;
};

// Throws InputError naming the path when ruffini-sim, ruffini-decoder or ruffini-aggregator is missing.
void CheckAggregatorExecutables(const std::string& bin_dir);
// Writes an n-patch scene (srs7, the forearm spec and model, patches around the forearm and upper arm, the
// cobot scene's safety and twin sections) to `path`.
void WriteGeneratedScene(const std::string& cobot_scene, int n, const std::string& path);

LatencyRun RunLatency(const AggregatorBenchOptions& o, int patches, const std::function<void(const std::string&)>& log);
FanInRun RunFanIn(const AggregatorBenchOptions& o, int patches, const std::function<void(const std::string&)>& log);

// Writes out_dir/aggregator.md and out_dir/aggregator-latency.svg; `micro` is the Google Benchmark output
// (aggregate_bench's console table) when given. Throws InputError naming the path.
void WriteAggregatorReport(const AggregatorBenchOptions& o, const Machine& m, const std::vector<LatencyRun>& latency,
                           const std::vector<FanInRun>& fanin, const std::string& micro, const std::string& micro_command);

}  // namespace ruffini::harness
