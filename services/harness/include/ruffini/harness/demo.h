#pragma once
// `ruffini demo`: the whole system as separate processes on loopback (port 0): ruffini-sim playing a scripted
// scenario on the cobot scene, one ruffini-decoder per patch, ruffini-aggregator, ruffini-controller (joint
// states at 1 kHz, halts on STOP); the demo itself watches the safety and contact streams, drives the events
// the scenario cannot (a decoder killed and restarted, joint states stopping, the operator's resets), checks
// each scripted event's safety response, and writes a report (Markdown + SVG). docs/demo.md has the timeline.
#include <functional>
#include <string>

namespace ruffini::harness {

struct DemoOptions {
  std::string scene_path;      // the cobot scene
  std::string scenario_path;   // the touches (the sim's clock)
  std::string out_dir = "demo-report";
  std::string bin_dir;         // where ruffini-sim, -decoder, -aggregator, -controller are
  double rate_hz = 1000.0;      // the interrogator's (the sim's) frame rate
  // The controller's joint states. 250 Hz (4 ms: a KUKA RSI cycle; the soak's default too): the scene's 50 ms
  // joint-state deadline is 12 periods (at least 5 are required). At 1 kHz the controller alone took 3.4 to
  // 4.4 s of CPU in the demo's first 14 s, a quarter to a third of a core (docs/demo.md, "Load").
  double joint_rate_hz = 250.0;
  // Mutual TLS (docs/security.md): every process gets --tls-dir DIR, the demo itself is the operator
  // (DIR/operator.crt). Empty: every process runs --insecure on loopback.
  std::string tls_dir;
};

struct DemoResult {
  int events = 0;
  int passed = 0;
  std::string report_path;
};

// Runs the demo; `log` gets the live timeline. Throws InputError on bad input (a missing executable, a scene
// without a robot or safety section); a failed expectation is counted, not thrown.
DemoResult RunDemo(const DemoOptions& options, const std::function<void(const std::string&)>& log);

}  // namespace ruffini::harness
