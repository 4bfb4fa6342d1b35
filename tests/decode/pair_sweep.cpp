// A hard press at one place with a light touch swept over the patch (review 10 finding 2; docs/experiments/pair.md):
// the worst placements of the second touch, which `ruffini coverage-targets --target pair` samples at random. Each
// press goes through the twin, the Hyperion bytes, the ingest codec, link::Monitor and the scene's model
// (tests/decode/hard_press.h): first the hard press alone, then with the light touch held at every node of a
// 20 mm x 20 deg grid (Y 10-130 mm, R 10-130 deg) at least 30 mm away. Prints one line per placement (the
// largest force reported, whether it stops at the threshold, the frames of the hold flagged `multiple`) and the
// count of placements without a stop.
//
//   pair_sweep SCENE PATCH Y_MM R_DEG FORCE_N LIGHT_N [THRESHOLD_N=1.5] [SEED=1] [confirm]
// (confirm: PipelineConfig::multi_confirm_anywhere on, a flag only when no single touch anywhere explains the frame;
// the environment's PAIR_SWEEP_WINDOW=N sets PipelineConfig::multi_window_nodes, the single check's window)
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <numbers>
#include <span>
#include <stdexcept>
#include <string>

#include "hard_press.h"
#include "ruffini/twin/scene.h"

int main(int argc, char** argv) try {
  using namespace ruffini;
  if (argc < 7) {
    std::fprintf(stderr, "usage: pair_sweep SCENE PATCH Y_MM R_DEG FORCE_N LIGHT_N [THRESHOLD_N] [SEED] [confirm]\n");
    return 2;
  }
  const twin::Scene scene = twin::LoadScene(argv[1]);
  std::size_t p = scene.patches.size();
  for (std::size_t i = 0; i < scene.patches.size(); ++i) {
    if (scene.patches[i].name == argv[2]) p = i;
  }
  if (p == scene.patches.size()) {
    std::fprintf(stderr, "%s: no patch '%s'\n", argv[1], argv[2]);
    return 2;
  }
  const v1::DecoderModel model = decode::LoadModel(scene.patches[p].model_path);
  testing::HardPressRig rig(scene, p, model);
  if (argc > 9 && std::string(argv[9]) == "confirm") rig.pipeline_config().multi_confirm_anywhere = true;
  // PipelineConfig::multi_window_nodes, for measuring (docs/experiments/pair.md section 4); the pipeline refuses
  // values outside 0..20 (+-20 nodes costs about 50 us per in-contact frame: review 15).
  if (const char* w = std::getenv("PAIR_SWEEP_WINDOW")) {
    char* end = nullptr;
    const long v = std::strtol(w, &end, 10);
    if (end == w || *end != '\0') throw std::runtime_error(std::string("PAIR_SWEEP_WINDOW: not a whole number: '") + w + "'");
    rig.pipeline_config().multi_window_nodes = static_cast<int>(std::clamp(v, -1L, 1000L));
  }
  const double y = std::atof(argv[3]), r = std::atof(argv[4]), f = std::atof(argv[5]), fl = std::atof(argv[6]);
  const double threshold = argc > 7 ? std::atof(argv[7]) : 1.5;
  const std::uint64_t seed = argc > 8 ? std::strtoull(argv[8], nullptr, 10) : 1;
  const double mm_per_deg = scene.patches[p].spec.surface_radius_mm * std::numbers::pi / 180.0;
  const testing::ProbeAt one{y, r, f};
  const auto alone = rig.Press(std::span<const testing::ProbeAt>(&one, 1), threshold, seed);
  std::printf("%g N at Y %g R %g alone: largest %.2f N, stops %s%s\n", f, y, r, alone.max_force_n,
              alone.stops() ? "yes" : "NO", alone.over_range ? " (over range)" : "");
  int missed = 0, total = 0;
  for (double ly = 10; ly <= 130; ly += 20) {
    for (double lr = 10; lr <= 130; lr += 20) {
      if (std::hypot(ly - y, (lr - r) * mm_per_deg) < 30) continue;
      const testing::ProbeAt two[2] = {{y, r, f}, {ly, lr, fl}};
      const auto o = rig.Press(two, threshold, seed);
      int flagged = 0;
      for (const auto& c : o.hold) flagged += c.multiple ? 1 : 0;
      ++total;
      missed += o.stops() ? 0 : 1;
      std::printf("  %g N at Y %5.1f R %5.1f: largest %.2f N, stops %s, flagged %d of %zu hold frames\n", fl, ly, lr,
                  o.max_force_n, o.stops() ? "yes" : "NO", flagged, o.hold.size());
    }
  }
  std::printf("placements without a stop: %d of %d\n", missed, total);
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "pair_sweep: %s\n", e.what());
  return 1;
}
