#include "ruffini/safety/scene.h"

#include <cmath>
#include <limits>

#include "ruffini/error.h"

namespace ruffini::safety {
namespace {

constexpr double kNsPerMs = 1e6;
constexpr double kMaxDeadlineMs = 60'000.0;
constexpr double kMaxHealthyMs = 600'000.0;

std::int64_t ToNs(double ms) { return static_cast<std::int64_t>(std::llround(ms * kNsPerMs)); }
double ToMs(std::int64_t ns) { return static_cast<double>(ns) / kNsPerMs; }

}  // namespace

Config ConfigFromScene(const SceneFile& scene) {
  if (!scene.safety) {
    throw InputError(scene.source + ": 'safety' is missing (a mapping with regions and deadlines expected)");
  }
  YamlReader s = *scene.safety;
  Config c;
  for (YamlReader& reg : s.Sequence("regions")) {
    RegionConfig rc;
    rc.name = reg.String("name");
    for (const RegionConfig& other : c.regions) {
      if (other.name == rc.name) reg.Fail("name", "is used by two regions; region names must be unique");
    }
    const double threshold_n =
        reg.Number("threshold_n", std::numeric_limits<double>::lowest(), std::numeric_limits<double>::max());
    if (!(threshold_n > 0.0 && threshold_n <= kMaxThresholdN)) {
      reg.Fail("threshold_n", "must be a force above 0 N and at most 1000 N (a contact above it stops the robot)");
    }
    rc.threshold_n = static_cast<float>(threshold_n);
    if (!reg.Has("source")) {
      reg.Fail("source", "is missing: say where the threshold comes from (ISO/TS 15066 values vary between "
                         "sources, FACTS.md), or why it was chosen");
    }
    rc.source = reg.String("source");
    reg.Finish();
    c.regions.push_back(std::move(rc));
  }
  if (c.regions.empty()) s.Fail("regions", "must list at least one body region ({name, threshold_n, source})");

  const double deadline_ms =
      s.NumberOr("silence_deadline_ms", ToMs(PatchConfig{}.silence_deadline_ns), 0.001, kMaxDeadlineMs);
  if (scene.robot) {
    c.joint_state_max_age_ns =
        ToNs(s.NumberOr("joint_state_max_age_ms", ToMs(c.joint_state_max_age_ns), 0.001, kMaxDeadlineMs));
  } else {
    c.joint_states_required = false;
    if (s.Has("joint_state_max_age_ms")) {
      s.Fail("joint_state_max_age_ms", "needs a robot: the scene has no 'robot' section, so no joint states");
    }
  }
  c.healthy_before_reset_ns =
      ToNs(s.NumberOr("healthy_before_reset_ms", ToMs(c.healthy_before_reset_ns), 0.0, kMaxHealthyMs));
  c.new_epoch_per_cause = s.BoolOr("new_epoch_per_cause", c.new_epoch_per_cause);
  s.Finish();

  for (const SceneFilePatch& p : scene.patches) {
    YamlReader entry = p.entry;
    PatchConfig pc;
    pc.id = p.name;
    pc.region = entry.String("region");
    bool known = false;
    std::string names;
    for (const RegionConfig& r : c.regions) {
      known = known || r.name == pc.region;
      names += (names.empty() ? "" : ", ") + r.name;
    }
    if (!known) entry.Fail("region", "names no region in safety.regions (regions: " + names + ")");
    pc.silence_deadline_ns = ToNs(entry.NumberOr("silence_deadline_ms", deadline_ms, 0.001, kMaxDeadlineMs));
    c.patches.push_back(std::move(pc));
  }
  try {
    Validate(c);
  } catch (const InputError& e) {
    throw InputError(scene.source + ": " + e.what());
  }
  return c;
}

Config ConfigFromScene(const std::string& scene_path) { return ConfigFromScene(LoadSceneFile(scene_path)); }

}  // namespace ruffini::safety
