// Prints what the shipped decoder reports for hard presses over a patch (docs/twin.md, "Hard presses"):
// for each force, the share of grid points (every 10 mm along Y and around the arc, plus 2 mm from each
// edge) where the aggregator's existing rule would stop (a contact above the threshold, an over-range
// contact, or a fault), through the twin, the Hyperion codec, link::Monitor and the decode pipeline.
//
//   build/release/bin/hard_press_grid [scene] [patch index] [threshold N] [forces N ...]
//   (defaults: config/scenes/cobot.yaml, patch 0, 1.5 N, 20 50 200)
#include <cstdio>
#include <cstdlib>
#include <numbers>
#include <string>
#include <vector>

#include "hard_press.h"

int main(int argc, char** argv) {
  using namespace ruffini;
  const std::string scene_path = argc > 1 ? argv[1] : RUFFINI_SOURCE_DIR "/config/scenes/cobot.yaml";
  const std::size_t patch = argc > 2 ? std::strtoul(argv[2], nullptr, 10) : 0;
  const double threshold = argc > 3 ? std::strtod(argv[3], nullptr) : 1.5;
  std::vector<double> forces;
  for (int i = 4; i < argc; ++i) forces.push_back(std::strtod(argv[i], nullptr));
  if (forces.empty()) forces = {20.0, 50.0, 200.0};
  const twin::Scene scene = twin::LoadScene(scene_path);
  const auto& sp = scene.patches.at(patch);
  const v1::DecoderModel model = decode::LoadModel(sp.model_path);
  testing::HardPressRig rig(scene, patch, model);
  const patch::Region ext = sp.spec.Extent();
  const double mm_per_deg = sp.spec.surface_radius_mm * std::numbers::pi / 180.0;
  const double length = ext.y_max_mm - ext.y_min_mm, arc = (ext.r_max_deg - ext.r_min_deg) * mm_per_deg;
  const std::vector<double> ys = testing::GridMm(length), arcs = testing::GridMm(arc);
  std::printf("scene %s, patch %s, threshold %.2f N, %zu x %zu points (Y every 10 mm, arc every 10 mm, +2 mm from each edge)\n",
              scene_path.c_str(), sp.name.c_str(), threshold, ys.size(), arcs.size());
  std::printf("%8s %8s %10s %10s %8s %8s %12s\n", "force_N", "points", "stop_all", "by_force", "over_rng", "fault",
              "edge_stop");
  for (double f : forces) {
    int n = 0, stop = 0, by_force = 0, over = 0, fault = 0, edge = 0, edge_stop = 0;
    for (double y : ys) {
      for (double a : arcs) {
        const testing::ProbeAt p{ext.y_min_mm + y, ext.r_min_deg + a / mm_per_deg, f};
        const testing::PressOutcome o = rig.Press(std::span<const testing::ProbeAt>(&p, 1), threshold);
        ++n;
        stop += o.stops();
        by_force += o.stop_force;
        over += o.over_range;
        fault += o.fault;
        const bool at_edge = y < 3 || y > length - 3 || a < 3 || a > arc - 3;
        edge += at_edge;
        edge_stop += at_edge && o.stops();
        if (!o.stops() && std::getenv("HARD_PRESS_VERBOSE")) {
          std::printf("  no stop at Y %.1f R %.1f: max force %.2f N\n", p.y_mm, p.r_deg, o.max_force_n);
        }
      }
    }
    std::printf("%8.1f %8d %9.1f%% %9.1f%% %7.1f%% %7.1f%% %5d/%-5d\n", f, n, 100.0 * stop / n, 100.0 * by_force / n,
                100.0 * over / n, 100.0 * fault / n, edge_stop, edge);
  }
  return 0;
}
