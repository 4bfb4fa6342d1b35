#pragma once
// A scripted scenario for the live twin: presses on the scene's patches, each a force profile that ramps up
// linearly, holds and releases linearly.
//
//   loop: true              # optional (default true): the script restarts after duration_s
//   duration_s: 4           # optional: the script's length (default: the end of its last press)
//   seed: 1                 # optional: interrogator noise seed
//   presses:
//     - {t_s: 0.5, patch: forearm, y_mm: 10, r_deg: 0, force_n: 1.5, ramp_s: 0.2, hold_s: 0.5, release_s: 0.2}
//   offsets:                # optional: a grating's peak stepped by pm from t_s on (grating 1..16)
//     - {t_s: 3, patch: forearm, grating: 16, pm: -0.8}
//
// One probe, any point of the limb: (y_mm, r_deg) are coordinates on the named patch's cylinder and may lie
// outside it (across a seam, on bare limb). In a scene with a robot (mounts), the probe loads every patch on
// the same link whose cover lies under its footprint, sharing the force by contact mechanics (ProbeLoads).
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "ruffini/robot/scene.h"
#include "ruffini/sim/source.h"
#include "ruffini/twin/scene.h"
#include "ruffini/twin/twin.h"
#include "ruffini/twin/viscoelastic.h"

namespace ruffini::sim {

// One patch's share of a probe: where it acts on that patch (clamped into the patch: the share acts at the
// cover's edge nearest the probe) and the fraction of the probe's force it carries.
struct PatchLoad {
  std::size_t patch = 0;
  double y_mm = 0.0, r_deg = 0.0;
  double share = 1.0;
};

struct Press {
  double t_s = 0.0;          // start of the ramp
  std::size_t patch = 0;     // index into the scene's patches
  double y_mm = 0.0, r_deg = 0.0;
  double force_n = 0.0;      // held force
  double ramp_s = 0.0, hold_s = 0.0, release_s = 0.0;
  [[nodiscard]] double end_s() const noexcept { return t_s + ramp_s + hold_s + release_s; }
  // Applied force at time t (0 outside the press).
  [[nodiscard]] double ForceAt(double t) const noexcept;
};

// A step on one grating's peak from t_s on (pm, added after the interrogator's noise): a grating that stays
// off after a release, as a baseline that kept part of a press sees it (docs/safety.md "Re-tare").
struct Offset {
  double t_s = 0.0;
  std::size_t patch = 0;   // index into the scene's patches
  std::size_t grating = 0; // 0-based (the file says 1..16, as the instrument's panel counts)
  double pm = 0.0;
};

struct Scenario {
  std::string source;
  bool loop = true;
  double duration_s = 0.0;
  std::uint64_t seed = 1;
  std::vector<Press> presses;
  std::vector<Offset> offsets;
};

// Where one probe at (y_mm, r_deg) on patch `patch`'s cylinder presses the scene's patches. The contact law's
// footprint (radius a, from the held force on a continuous cover) is a Hertz pressure p0 sqrt(1 - r^2/a^2);
// its line load across a straight cover edge is parabolic, so the part of it at signed distance > -e of the
// edge (e > 0: the centre on the cover) carries f(e/a) = 1/2 + 3/4 (s - s^3/3), s = clamp(e/a, -1, 1).
// Each patch's fraction is f over its Y and its arc edges (a product, for a corner); the fractions are
// normalised over the patches the footprint touches (bare limb lies a cover's thickness lower and takes
// nothing before the probe bottoms out). Without mounts (robot == nullptr) only the named patch, unclipped.
// Patches on other links than the named patch's, or on another cylinder (radii differ by > 1 mm), are not
// touched.
struct MountedScene {
  robot::RobotScene robot;
};
std::vector<PatchLoad> ProbeLoads(const twin::Scene& scene, const MountedScene* mounts, std::size_t patch, double y_mm,
                                  double r_deg, double contact_radius_mm);

// The twin effects of patch `patch`: the scene's with the patch's own cast (Scene::EffectsOf), and every edge another patch's cover continues beyond (a
// seam, found through the mounts) made `continued` when the scene names `edges`.
twin::TwinEffects EffectsFor(const twin::Scene& scene, const MountedScene* mounts, std::size_t patch);

// What a sensitivity map measured on patch `patch` of this scene is valid for (SensitivityMap.measured_on): the
// spec (name and fingerprint), the cast (the fabrication seed of EffectsFor's effects) and its four edges as
// EffectsFor makes them (free, bonded, continued at a seam; "not modelled" without the scene's `edges`). Two
// patches with the same text respond alike, so one map serves both (the cobot scene's two upper-arm patches).
std::string MeasuredOn(const twin::Scene& scene, const MountedScene* mounts, std::size_t patch);
// Every parameter of the twin a map was measured with besides those (review 12, finding 1: the noise, the cast's
// fabrication parameters, irregular gratings, stiffening, temperature, creep, faults, the edges' gains, the
// probe): the scene file's `twin.effects` and `twin.probe` as YAML (re-emitted: comments and spacing do not
// count, the order of keys does). Empty without a twin section. A map records a digest of it.
std::string TwinParameters(const twin::Scene& scene);

// The scene's mounts, when it has a robot section (nullptr otherwise).
std::unique_ptr<MountedScene> LoadMounts(const twin::Scene& scene);

// Loads and validates against the scene (patch names). Throws InputError with file:line:col and the key.
Scenario LoadScenario(const std::string& path, const twin::Scene& scene);

// The live twin under a scenario: one SkinTwin and one InterrogatorSim per patch (patch i on channel i).
// Sample k is at t = k / rate_hz (modulo duration_s when looping). Sample() must be called with rising k.
// With the scene's viscoelastic effect, each patch has one probe: the latest press that has started on it
// drives a ViscoelasticSites (creep while held, fading residuals after release and at earlier sites); other
// presses overlapping it on the same patch are ignored. Without it, overlapping presses superpose.
class ScriptedSource final : public FrameSource {
 public:
  // Throws InputError for more than 16 patches or a probe the twin cannot model.
  ScriptedSource(const twin::Scene& scene, Scenario scenario, double rate_hz);
  ~ScriptedSource() override;
  [[nodiscard]] const Scenario& scenario() const noexcept { return scenario_; }
  [[nodiscard]] const twin::SkinTwin& twin(std::size_t patch) const { return *twins_.at(patch); }
  // The patches press i loads (ProbeLoads; the shares sum to 1, or none on bare limb).
  [[nodiscard]] const std::vector<PatchLoad>& loads(std::size_t press) const { return loads_.at(press); }
  [[nodiscard]] std::size_t channels() const noexcept override { return twins_.size(); }
  void Sample(std::uint64_t sample, std::span<Wavelengths> out) override;

 private:
  Scenario scenario_;
  twin::Probe probe_;
  double rate_hz_;
  std::vector<std::unique_ptr<twin::SkinTwin>> twins_;
  std::vector<std::unique_ptr<twin::InterrogatorSim>> sims_;
  // A viscoelastic scene: one creep filter per press and patch it loads, so presses at once on one patch each
  // creep, and each leaves its own residual where it was.
  struct PressFilter {
    std::size_t press = 0, patch = 0;
    patch::SurfacePoint at;
    double share = 0.0;
    twin::ViscoelasticFilter filter;
  };
  std::vector<PressFilter> filters_;
  std::vector<twin::Contact> contacts_;
  std::unique_ptr<MountedScene> mounts_;
  std::vector<std::vector<PatchLoad>> loads_;     // per press
};

}  // namespace ruffini::sim
