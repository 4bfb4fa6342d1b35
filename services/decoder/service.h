#pragma once
// ruffini-decoder: one fibre, one service. Three threads and two lock-free rings (DESIGN.md, "Threads and
// time"):
//
//   ingest (Boost.Asio): TCP to the interrogator's peak stream, reconnect with backoff, the Hyperion codec
//     (parse, pick the patch's channel) -> ring A (frames and connection events; 8192 slots)
//   decode (real time): ring A -> link::Monitor (decode::Pipeline, health, faults, heartbeats) -> ring B
//     (messages; 2048 slots). Never waits on either side; allocates nothing per frame.
//   publish (gRPC): ring B -> ruffini.v1.PatchMessage -> Aggregator.Connect, reconnect with backoff.
//
// When ring A is full the ingest thread drops the frame and counts it (the decode thread then reports an
// overload fault). When ring B is full, heartbeats and mid-contact frames are dropped and counted (the next
// heartbeat carries fresh health anyway), while onsets, releases and faults wait in a bounded overflow on
// the decode thread and go first once there is room. A message made before the current aggregator stream
// began is never sent on it (no stale contacts after a reconnect), and none that waited past the freshness
// budget in the decoder's own rings is either (docs/safety-channel.md). Every message carries the safety
// layer: this process's run id, its steady-clock send time, the aggregator run it is addressed to (from
// HelloAccepted; the publisher sends nothing but the hello before that) and a CRC.
#include <cstdint>
#include <memory>
#include <string>

#include "ruffini/link/monitor.h"
#include "ruffini/service/common.h"

namespace ruffini::decoder {

struct ServiceConfig {
  std::string scene_path;
  std::string patch;                 // the scene's patch name ("" : the only one)
  service::HostPort interrogator;    // the peak-stream port
  int channel = 0;                   // 1..16 as the instrument's panel counts; 0: the patch's place in the scene
  service::HostPort aggregator;
  service::HostPort metrics;         // port 0: pick a free one
  std::string model_path;            // "": the scene's `model:` for the patch
  std::string decoder = "paper-float";
  double rate_hz = 1000.0;           // the interrogator's frame rate
  double heartbeat_ms = 10.0;
  double silence_ms = 0.0;           // 0: 3 frame periods
  int reject_fault_frames = 0;       // 0: 20 ms of frames (at least 3)
  bool allow_missing = true;         // a dark grating (15 peaks) is a missing peak, not a rejected frame
  // The safety layer's freshness budget (docs/safety-channel.md): a frame or message that waited longer than
  // this in the decoder's own queues is dropped and reported (an overload fault for ring A, a `late` fault
  // for ring B), never sent as if current.
  double freshness_budget_ms = 20.0;
  // The aggregator link: exactly one of tls_dir (mutual TLS with DIR/ca.crt, DIR/decoder-PATCH.crt and .key,
  // docs/security.md) and insecure (plaintext).
  std::string tls_dir;
  bool insecure = false;
  // Re-tare (docs/safety.md "Re-tare"): a touch explaining the shifts with at least this force refuses it.
  // 0: half the smallest threshold of the patch's region (the scene's safety section), 0.75 N without one.
  double retare_force_n = 0.0;
  // The baseline's staleness limit, s (0: the default, 300 s). Tests only: a short one makes a stale
  // baseline in seconds. The hello's decoder configuration carries it.
  double max_frozen_s = 0.0;
  // The rest file (review 10, finding 1; decode::BaselineConfig::rest_nm): "" none. While the patch is
  // healthy, tracking and out of contact, its baseline is written here every few seconds (a new file
  // replaces the old one whole). A decoder that starts with one refuses a start-up capture that is not that
  // rest (a press held through a restart) and stays capturing, unhealthy, until it is. Keep it where a
  // restart finds it (a pod's emptyDir, docs/deploy.md); delete it only when the cover has really changed.
  std::string rest_file;
};

class DecoderService {
 public:
  // Loads and checks everything (scene, patch, model against the patch, decoder choice, addresses) and binds
  // the metrics port. Throws InputError with a message naming what is wrong.
  explicit DecoderService(ServiceConfig config);
  ~DecoderService();
  DecoderService(const DecoderService&) = delete;
  DecoderService& operator=(const DecoderService&) = delete;

  void Start();
  // Sends the shutting_down fault, closes both links and joins the threads (a few hundred ms at most).
  void Stop();

  [[nodiscard]] std::uint16_t metrics_port() const noexcept;
  // One line: patch, model, decoder choice, rate, addresses.
  [[nodiscard]] std::string Describe() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ruffini::decoder
