#pragma once
// `ruffini bench-service`: what the decoder service costs, measured three ways (docs/bench/service.md).
//
// 1. Throughput, one thread, "parse to message": Hyperion frames from the live twin pre-encoded into one byte
//    buffer, then ingest::StreamDecoder::Feed -> link::Monitor::OnFrame (+ Tick) -> a sink that turns each
//    message into ruffini.v1.PatchMessage (link::ToProto) and serializes it. No sockets, no threads: the
//    decode thread's work plus the publisher's conversion, back to back.
// 2. End to end: the real ruffini-sim and ruffini-decoder processes on 127.0.0.1 (port 0, ports files), the
//    decoder publishing to a recording Aggregator in this process; latency = arrival (system_clock) - t_ns.
// 3. CPU: utime + stime of both processes from /proc/<pid>/stat over the measured window.
//
// Not real-time code: this is a measuring harness; it allocates freely outside the timed loops (the timed
// loops allocate only inside protobuf serialization, as the publisher does).
#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

namespace ruffini::harness {

struct ServiceBenchOptions {
  std::string scene_path;     // the scene; its patch `patch` names the model
  std::string patch = "forearm";
  std::string scenario_path;  // presses (both the pre-encoded frames and the sim's stream)
  std::string out_dir;
  std::string command;        // the command line, written into the report
  // Throughput.
  std::size_t frames = 200000;
  double stream_rate_hz = 1000.0;  // the pre-encoded stream's rate (sets the baseline and heartbeats)
  int repeats = 3;                 // timed passes per configuration (the report gives the median and best)
  // End to end.
  std::vector<double> rates_hz = {1000.0, 5000.0};
  double seconds = 20.0;        // measured window per rate, after the baseline capture and warm-up
  double warmup_s = 1.0;        // after the first healthy heartbeat, before the window opens
  std::string bin_dir;          // where ruffini-sim and ruffini-decoder are
  std::string work_dir;         // logs and ports files of the processes
};

// --- 1. Throughput -----------------------------------------------------------------------------------------
struct ThroughputRow {
  std::string config;      // decoder choice (paper-float, ...) or a stage ("codec only", ...)
  std::string stage;       // what the timed loop does
  std::vector<double> frames_per_s;      // one per repeat, wall time
  std::vector<double> frames_per_cpu_s;  // one per repeat, the thread's CPU time
  double median_fps = 0.0, best_fps = 0.0, median_cpu_fps = 0.0;
  std::uint64_t messages = 0, contact_messages = 0, heartbeats = 0, faults = 0, bytes_serialized = 0;
};
struct ThroughputResult {
  std::size_t frames = 0;
  std::size_t buffer_bytes = 0;
  double encode_s = 0.0;          // twin + encoder, untimed preparation
  std::uint64_t frames_in_contact = 0;  // Monitor's health().in_contact after the frame (paper-float)
  std::uint64_t capturing_frames = 0;   // frames before the baseline was captured (paper-float)
  std::vector<ThroughputRow> rows;
};
ThroughputResult RunThroughput(const ServiceBenchOptions& o, const std::function<void(const std::string&)>& log);

// --- 2 and 3. End to end -----------------------------------------------------------------------------------
struct Quantiles {
  std::size_t count = 0;
  double p50_us = 0.0, p90_us = 0.0, p99_us = 0.0, p999_us = 0.0, max_us = 0.0, mean_us = 0.0, min_us = 0.0;
};
Quantiles QuantilesOf(std::vector<double> us);

struct EndToEndRun {
  double rate_hz = 0.0;
  double window_s = 0.0;             // wall time of the measured window (steady clock)
  Quantiles latency;                 // arrival - t_ns, contact messages arriving in the window
  Quantiles to_decoder;              // decoder_t_ns - t_ns (sim write lag, TCP, ingest, decode)
  Quantiles to_aggregator;           // arrival - decoder_t_ns (ring B, publisher, gRPC)
  std::vector<double> latency_us;    // every sample of `latency` (for the histogram)
  std::uint64_t messages = 0, heartbeats = 0, faults = 0;
  std::map<std::string, std::uint64_t> fault_counts;  // by fault name (snake_case), in the window
  std::uint64_t serial_span = 0;     // last - first interrogator serial of the window's contact messages
  std::uint64_t messages_dropped = 0, serial_gaps = 0;  // the last heartbeat's counters (cumulative)
  double decoder_cpu_pct = 0.0, sim_cpu_pct = 0.0;      // % of one core over the window
  // The decoder's CPU by thread name (its own threads keep the process name; gRPC names its threads).
  std::map<std::string, double> decoder_threads_cpu_pct;
  double capture_wait_s = 0.0;       // decoder start -> first healthy heartbeat
  std::string sim_write_lag;         // the sim's own log line at shutdown (the whole run)
  int sim_exit = -1, decoder_exit = -1;
  bool sim_killed = false, decoder_killed = false;
};
// Throws InputError naming the path when ruffini-sim or ruffini-decoder is not an executable in bin_dir.
void CheckServiceExecutables(const std::string& bin_dir);
EndToEndRun RunEndToEnd(const ServiceBenchOptions& o, double rate_hz, const std::function<void(const std::string&)>& log);

// --- 4. Report ---------------------------------------------------------------------------------------------
struct Machine {
  int nproc = 0;
  std::string cpu_model;
  std::string load_before, load_after;  // /proc/loadavg's first three fields
};
Machine MachineNow();
std::string LoadAverage();

// Writes out_dir/service.md and out_dir/service-latency.svg. Throws InputError naming the path.
void WriteServiceReport(const ServiceBenchOptions& o, const Machine& m, const ThroughputResult& t,
                        const std::vector<EndToEndRun>& runs);

}  // namespace ruffini::harness
