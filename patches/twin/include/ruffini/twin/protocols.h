#pragma once
// Indentation protocols: reproducible functions of (scene, seed) that drive the twin and stream frames.
//
// paper: 2700 force-controlled indentations at uniform random positions over the indented area, the 11 mm
//   probe moving at constant speed (0.28 mm/s) from about 1.04 mm above the surface until the force reaches
//   2.5 N (only the increasing-load phase is kept), 100 Hz, force following the sphere-on-bonded-layer law;
//   the force label is the load cell's reading (noise, 1/256 N steps). About 1000 frames an indentation,
//   37 % of them before contact. A rest period first gives decoders an untouched baseline.
// vonfrey: the paper's sensitivity test: 8 filaments (0.4 g to 60 g) x subjects x sites at random positions,
//   each a short ramp, a hold at the filament's buckling force and a release.
// receptive-field: a grid scan with the probe, each site ramped to 2.5 N, for hot-spot maps.
// coverage: the paper protocol over the WHOLE patch (issue 16): the same force-controlled ramps (probe speed,
//   approach, rest first, labels, only the increasing-load phase), at uniform random positions over the
//   patch's extent, edge to edge (Y 0..extent, R 0..extent), a fixed fraction of them (edge_fraction) drawn
//   uniformly within edge_band_mm of an edge (distance on the surface, R as arc length) since that is where
//   the paper-trained nets have seen nothing. Each ramp stops at a peak force drawn log-uniformly in
//   force_min_n..force_max_n; force_max_n = 0 means the contact law's linear limit (4.2 N for the paper's
//   11 mm sphere on 8 mm of cover), the force beyond which the twin flags every frame saturated, which the
//   decode pipeline reports as over range and never feeds to the nets. A ramp also stops after the first frame
//   the twin flags saturated (a peak out of its band), which is kept.
// field: what a skin meets in use rather than in the lab: press-hold-release cycles of the scene's probe at
//   uniform random positions over the indented area, each after a rest of U(1, 30) s untouched: a
//   force-controlled ramp up over U(0.5, 3) s to a force drawn log-uniformly in 0.1-2.5 N, a hold of
//   U(0, 120) s and a ramp down over U(0.3, 2) s; a long rest first (a decoder's baseline); duration_s in all.
//   Labels as the paper protocol writes them: force_n the load cell, true_force_n the applied force, y/r and
//   indentation = the cycle's index over its ramp up, hold and ramp down (contiguous), -1 and NaN in rests.
//   Meant for scenes with field effects (viscoelastic silicone, temperature histories): see forearm-field.yaml.
// When the scene names the viscoelastic effect, every protocol drives the twin with the filtered force of
// each site it pressed (viscoelastic.h); labels stay the applied force. Without it, frames are as before.
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "ruffini/dataset/dataset.h"
#include "ruffini/twin/scene.h"
#include "ruffini/twin/twin.h"

namespace ruffini::twin {

struct PaperProtocol {
  int indentations = 2700;
  double rate_hz = 100.0;
  double max_force_n = 2.5;
  double speed_mm_s = 0.28;
  double approach_mm = 1.04;      // mean gap between probe and skin when a recording starts
  double approach_jitter = 0.15;  // relative, uniform
  int rest_frames = 200;
};

struct CoverageProtocol {
  int indentations = 2700;
  double rate_hz = 100.0;
  double force_min_n = 0.05;      // peak forces: log-uniform in force_min_n..force_max_n
  double force_max_n = 0.0;       // 0: the contact law's linear limit
  double edge_fraction = 0.3;     // share of presses drawn within edge_band_mm of an edge
  double edge_band_mm = 12.0;
  double speed_mm_s = 0.28;
  double approach_mm = 1.04;
  double approach_jitter = 0.15;
  int rest_frames = 200;

  // Throws InputError naming the first field out of range.
  void Validate() const;
};

struct VonFreyProtocol {
  std::vector<double> filaments_g = {0.4, 0.6, 1.0, 2.0, 4.0, 10.0, 26.0, 60.0};
  int subjects = 12;
  int sites = 20;                 // per subject and filament
  double tip_radius_mm = 0.25;    // point-like load
  double rate_hz = 100.0;
  int rest_frames = 30, ramp_frames = 10, hold_frames = 50, release_frames = 10;
  // Sites: uniform over the indented area, or (if > 0) within this distance of a random grating centre.
  double near_grating_mm = 0.0;
};

struct ReceptiveFieldProtocol {
  double step_mm = 2.0;           // grid step in Y and in arc length
  double max_force_n = 2.5;
  int ramp_frames = 50;
  double rate_hz = 100.0;
};

struct FieldProtocol {
  double duration_s = 3600.0;
  double rate_hz = 100.0;
  double first_rest_s = 10.0;     // untouched baseline before the first press
  double rest_min_s = 1.0, rest_max_s = 30.0;
  double ramp_up_min_s = 0.5, ramp_up_max_s = 3.0;
  double force_min_n = 0.1, force_max_n = 2.5;  // log-uniform
  double hold_min_s = 0.0, hold_max_s = 120.0;
  double ramp_down_min_s = 0.3, ramp_down_max_s = 2.0;

  // Throws InputError naming the first field out of range (e.g. "field protocol: rest_min_s (5) must not
  // exceed rest_max_s (1)").
  void Validate() const;
};

// Receives frames in blocks; must copy what it keeps.
using FrameSink = std::function<void(std::span<const dataset::Frame>)>;
// Called now and then with (done, total) units of work (indentations, stimulations, sites).
using ProgressFn = std::function<void(std::uint64_t, std::uint64_t)>;

struct ProtocolRun {
  std::uint64_t frames = 0;
  int indentations = 0;
};

ProtocolRun RunPaper(const SkinTwin& twin, const Scene& scene, const PaperProtocol& p, std::uint64_t seed,
                     const FrameSink& sink, const ProgressFn& progress = {});
ProtocolRun RunCoverage(const SkinTwin& twin, const Scene& scene, const CoverageProtocol& p, std::uint64_t seed,
                        const FrameSink& sink, const ProgressFn& progress = {});
ProtocolRun RunVonFrey(const SkinTwin& twin, const VonFreyProtocol& p, std::uint64_t seed, const FrameSink& sink,
                       const ProgressFn& progress = {});
ProtocolRun RunReceptiveField(const SkinTwin& twin, const Scene& scene, const ReceptiveFieldProtocol& p,
                              std::uint64_t seed, const FrameSink& sink, const ProgressFn& progress = {});

// Progress counts seconds of recording done / total.
ProtocolRun RunField(const SkinTwin& twin, const Scene& scene, const FieldProtocol& p, std::uint64_t seed,
                     const FrameSink& sink, const ProgressFn& progress = {});

// Newtons for a von Frey filament's nominal grams.
inline double GramsToNewtons(double g) { return g * 9.80665e-3; }

// Dataset header for a twin run: sample rate, provenance and the cast's reference wavelengths.
dataset::DatasetInfo TwinDatasetInfo(const SkinTwin& twin, const Scene& scene, const std::string& protocol,
                                     std::uint64_t seed, double rate_hz);

}  // namespace ruffini::twin
