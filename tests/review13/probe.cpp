// Review 13: presses through the same path as tests/decode/hard_press.h (twin -> Hyperion bytes -> ingest ->
// link::Monitor -> the scene's model), reading cases from stdin, one per line:
//   PATCH SEED Y R F [Y R F ...]     (all probes ramp, hold and release together, as the unit tests' rig)
// prints: stops yes/NO, largest force, fault, over range.  Usage: probe SCENE < cases
#include <cstdio>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>
#include "hard_press.h"
#include "ruffini/twin/scene.h"
int main(int argc, char** argv) {
  using namespace ruffini;
  const twin::Scene scene = twin::LoadScene(argv[1]);
  std::string line;
  while (std::getline(std::cin, line)) {
    std::istringstream in(line);
    std::string name; std::uint64_t seed = 1;
    if (!(in >> name >> seed)) continue;
    std::size_t p = 0;
    while (p < scene.patches.size() && scene.patches[p].name != name) ++p;
    if (p == scene.patches.size()) { std::printf("no patch %s\n", name.c_str()); continue; }
    static std::vector<std::pair<std::size_t, v1::DecoderModel>> models;
    const v1::DecoderModel* m = nullptr;
    for (auto& [i, mm] : models) if (i == p) m = &mm;
    if (!m) { models.emplace_back(p, decode::LoadModel(scene.patches[p].model_path)); m = &models.back().second; }
    testing::HardPressRig rig(scene, p, *m);
    std::vector<testing::ProbeAt> probes; double y, r, f;
    while (in >> y >> r >> f) probes.push_back({y, r, f});
    const auto o = rig.Press(probes, 1.5, seed);
    std::printf("%s : stops %s, largest %.2f N%s%s\n", line.c_str(), o.stops() ? "yes" : "NO", o.max_force_n,
                o.fault ? ", fault" : "", o.over_range ? ", over range" : "");
    std::fflush(stdout);
  }
}
