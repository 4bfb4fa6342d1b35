#pragma once
// Shared test fixtures: the default scene and twins built once per test process.
#include "ruffini/patch/spec_loader.h"
#include "ruffini/twin/scene.h"
#include "ruffini/twin/twin.h"

namespace ruffini::twin::fixtures {

inline const Scene& DefaultScene() {
  static const Scene scene = LoadScene(RUFFINI_SOURCE_DIR "/config/scenes/forearm.yaml");
  return scene;
}

inline const patch::PatchSpec& Spec() { return DefaultScene().Patch().spec; }

// No effects at all: nominal layer, unit gains, one lobe per grating, no noise.
inline const SkinTwin& PlainTwin() {
  static const SkinTwin twin(Spec(), TwinEffects{}, {5.5});
  return twin;
}

// The default scene's twin (every effect the scene names).
inline const SkinTwin& DefaultTwin() {
  static const SkinTwin twin(Spec(), DefaultScene().effects, {DefaultScene().probe.radius_mm});
  return twin;
}

}  // namespace ruffini::twin::fixtures
