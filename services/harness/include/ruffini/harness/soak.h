#pragma once
// `ruffini soak`: the whole system under load and injected faults for a given time, every safety promise
// checked (issue 15, section 5; docs/soak.md). Processes on loopback, as in the demo: ruffini-sim playing a
// generated scenario of presses above and below the threshold, one ruffini-decoder per patch (a few of them
// behind a TCP proxy), ruffini-aggregator, and two ruffini-controllers (one publishes the joint states, the other
// only obeys, behind a proxy). Meanwhile the soak kills and restarts decoders at random, restarts the aggregator
// once (on the same port), freezes and throttles proxied links, churns watch subscribers, and acts as the
// operator (a reset once a stop's cause has gone). It writes a report:
//   - presses above the threshold after which some controller was not halted within the bound (must be 0);
//   - CLEARs (at the aggregator or a controller) of an epoch no accepted reset cleared (0);
//   - FAULT epochs not explained by an injected fault (0);
//   - RSS and open fds per process over time (flat), crashes (0).
#include <cstdint>
#include <functional>
#include <string>

namespace ruffini::harness {

struct SoakOptions {
  std::string scene_path;           // a scene with a robot, a safety section and 1..16 patches
  int patches = 0;                  // 1..16: only the scene's first N patches (a derived scene in OUT); 0: all
  std::string out_dir = "soak-report";
  std::string bin_dir;              // where ruffini-sim, -decoder, -aggregator, -controller are
  double duration_s = 60.0;         // the soak proper (presses and faults), after start-up
  double rate_hz = 500.0;           // interrogator rate
  double joint_rate_hz = 250.0;     // joint states from the first controller
  std::uint64_t seed = 1;
  double press_every_s = 3.0;       // one press at a time, one every this long on average
  double above_share = 0.6;         // share of presses above the threshold (the others at most half of it)
  double kill_every_s = 40.0;       // a decoder killed (SIGKILL or SIGTERM) on average this often; 0: never
  double link_fault_every_s = 45.0; // a proxied link frozen or throttled on average this often; 0: never
  bool restart_aggregator = true;   // once, at half time
  int proxied_decoders = 2;         // decoders behind a TCP proxy (the freeze and throttle targets)
  int churn_threads = 2;            // threads opening and abandoning watch streams
  double stop_bound_ms = 100.0;     // true crossing of the threshold to a halt at every controller
  double sample_every_s = 5.0;      // RSS and fd samples
  // Budgets the decoders and the aggregator get (--freshness-budget-ms, --patch-freshness-ms); 0: theirs.
  // An unexplained FAULT fails the run (the default). ctest's 40-second run counts and reports them but passes:
  // on a shared 2-core CI machine a process starved for 30 ms faults safely, and that says nothing about the
  // channel; lost stops, false clears and crashes always fail.
  bool unexplained_faults_fail = true;
  int freshness_budget_ms = 0;  // also the controllers' (ruffini-controller --freshness-budget-ms)
  // > 0: real-time scheduling (SCHED_FIFO, through chrt; needs CAP_SYS_NICE), as a robot cell runs its safety
  // chain: the decoders, the aggregator and the controllers at this priority; the sim (the interrogator's
  // stand-in, hardware that never waits for a core) and the TCP proxies (the network's) 10 above. The soak's
  // own judge, operator and watch churn stay at normal priority. 0: everything at normal priority.
  int realtime_priority = 0;
  // > 0: SCHED_FIFO at this priority for the stand-ins only (the sim, the interrogator's; the proxies, the
  // network's), whatever realtime_priority says; 0: realtime_priority + 10 when that is set, else normal.
  int stand_in_priority = 0;
};

struct SoakResult {
  int presses_above = 0, presses_below = 0;
  int lost_stops = 0;        // presses above the threshold with a controller not halted within the bound
  int false_clears = 0;      // CLEARs of an epoch no accepted reset cleared
  int unexplained_faults = 0;
  int crashes = 0;           // a process that exited without being told to, or did not exit cleanly
  int stops_without_press = 0;  // STOP epochs with no press above the threshold under way (reported)
  bool pass = false;         // lost_stops, false_clears and crashes 0, and unexplained_faults 0 unless tolerated
  std::string report_path;
};

// Runs the soak; `log` gets progress lines. Throws InputError on bad input (a missing executable, a scene without
// a robot or safety section, more than 16 patches).
SoakResult RunSoak(const SoakOptions& options, const std::function<void(const std::string&)>& log);

}  // namespace ruffini::harness
