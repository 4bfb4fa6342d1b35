#pragma once
// The twin's view of a scene: the patches (their specs) and the effects the twin must model. The file's shape
// is the root reader's (ruffini/scene_file.h); a scene's `robot`, `mount`, `region` and `safety` keys are
// read by ruffini::robot (robot/scene.h) and ruffini::safety (safety/scene.h): the twin builds nothing from
// them. Only what a scene names is built.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "ruffini/patch/spec.h"
#include "ruffini/twin/contact.h"
#include "ruffini/twin/effects.h"

namespace ruffini::twin {

struct ScenePatch {
  std::string name;
  std::string spec_path;
  patch::PatchSpec spec;
  // The decoder model the patch's decoder service runs (`model:`, relative to the scene file; optional:
  // empty when the scene names none). The twin never reads it.
  std::string model_path;
  // This patch's own cast (skin sample), from the twin section's `casts:`; nullopt: the scene's
  // effects.skin_sample (every patch the same cast).
  std::optional<std::uint64_t> cast_seed;
};

// The indentation rig's force sensor (the paper's ATI Nano-43: 1/256 N resolution).
struct LoadCell {
  double noise_n = 0.02;
  double resolution_n = 1.0 / 256.0;
};

struct Scene {
  std::string name;
  std::string source;  // file it came from
  std::vector<ScenePatch> patches;
  Probe probe;         // the indentation probe
  LoadCell load_cell;
  TwinEffects effects;

  // The one patch a single-patch command works on: the named one, or the only one. Throws InputError.
  [[nodiscard]] const ScenePatch& Patch(const std::string& patch_name = "") const;
  // The twin effects of patch i: the scene's, with the patch's own cast (cast_seed) as its skin sample (the
  // scene's skin_sample parameters, or the defaults when the scene names none).
  [[nodiscard]] TwinEffects EffectsOf(std::size_t patch) const;
};

// Loads and validates; patch spec paths are relative to the scene file. Throws InputError with
// file:line:col, the key and what was expected.
Scene LoadScene(const std::string& path);

// Applies a --skin-sample override: sets the skin sample seed, turning the effect on if the scene had it off.
void OverrideSkinSample(Scene& scene, std::uint64_t seed);

}  // namespace ruffini::twin
