// One-off (stop 31, not built by the project): the maps measured at stop 31 recorded measured_on without the
// twin parameters' digest (added after review 12). Re-label them in the new format, after checking each map's old
// record, decoder digest and source. Built once as a temporary executable linked to ruffini::aggregator_server,
// ruffini::sim and ruffini::decode, run from the repository root (config/models/README.md).
#include <cstdio>
#include <string>
#include "ruffini/decode/model_io.h"
#include "ruffini/sim/scenario.h"
#include "ruffini/twin/scene.h"
#include "scene_setup.h"
using namespace ruffini;
int main() {
  struct Item { const char* scene; const char* patch; const char* model; };
  const Item items[] = {
      {"config/scenes/cobot.yaml", "upper_arm_a", "config/models/forearm.rmodel"},
      {"config/scenes/cobot.yaml", "forearm_a", "config/models/cobot-forearm_a.rmodel"},
      {"config/scenes/cobot.yaml", "forearm_b", "config/models/cobot-forearm_b.rmodel"},
      {"config/scenes/cobot-field.yaml", "forearm_a", "config/models/cobot-field-forearm_a.rmodel"},
      {"config/scenes/cobot-field.yaml", "forearm_b", "config/models/cobot-field-forearm_b.rmodel"},
      {"config/scenes/cobot-field.yaml", "upper_arm_a", "config/models/cobot-field-upper_arm_a.rmodel"},
      {"config/scenes/cobot-field.yaml", "upper_arm_b", "config/models/cobot-field-upper_arm_b.rmodel"},
  };
  int bad = 0;
  for (const Item& it : items) {
    v1::DecoderModel m = decode::LoadModel(it.model);
    const twin::Scene scene = twin::LoadScene(it.scene);
    const auto mounts = sim::LoadMounts(scene);
    std::size_t idx = scene.patches.size();
    for (std::size_t i = 0; i < scene.patches.size(); ++i) if (scene.patches[i].name == it.patch) idx = i;
    const std::string old = sim::MeasuredOn(scene, mounts.get(), idx);
    const std::string digest = aggregator::DecoderSha256(m);
    const std::string src = std::string("scene ") + it.scene + ", patch " + it.patch + " ";
    for (auto& map : *m.mutable_sensitivity()) {
      const bool ok = map.measured_on() == old && map.model_sha256() == digest && map.source().find(src) != std::string::npos;
      std::printf("%s %s: old record %s, decoder %s, source %s -> %s\n", it.model, it.patch,
                  map.measured_on() == old ? "matches" : "DIFFERS", map.model_sha256() == digest ? "matches" : "DIFFERS",
                  map.source().find(src) != std::string::npos ? "names it" : "DIFFERS", ok ? "relabelled" : "LEFT");
      if (!ok) { ++bad; continue; }
      aggregator::BindMap(map, it.scene, it.patch, m);
    }
    decode::SaveModel(it.model, m);
  }
  return bad == 0 ? 0 : 1;
}
