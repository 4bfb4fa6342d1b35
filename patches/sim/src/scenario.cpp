#include "ruffini/sim/scenario.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "ruffini/error.h"
#include "ruffini/ingest/hyperion.h"
#include "ruffini/yaml_reader.h"

namespace ruffini::sim {

double Press::ForceAt(double t) const noexcept {
  const double u = t - t_s;
  if (u < 0.0) return 0.0;
  if (u < ramp_s) return force_n * u / ramp_s;
  if (u <= ramp_s + hold_s) return force_n;
  const double d = u - ramp_s - hold_s;
  if (d < release_s) return force_n * (1.0 - d / release_s);
  return 0.0;
}

Scenario LoadScenario(const std::string& path, const twin::Scene& scene) {
  YamlReader root = YamlReader::LoadFile(path);
  Scenario s;
  s.source = path;
  s.loop = root.BoolOr("loop", true);
  s.seed = static_cast<std::uint64_t>(root.IntegerOr("seed", 1, 0, std::numeric_limits<long>::max()));
  for (YamlReader& p : root.Sequence("presses")) {
    Press press;
    press.t_s = p.Number("t_s", 0.0, 1e6);
    const std::string name = p.String("patch");
    const auto it = std::find_if(scene.patches.begin(), scene.patches.end(),
                                 [&](const twin::ScenePatch& sp) { return sp.name == name; });
    if (it == scene.patches.end()) p.Fail("patch", "is not a patch of scene " + scene.source);
    press.patch = static_cast<std::size_t>(it - scene.patches.begin());
    press.y_mm = p.Number("y_mm", -1e4, 1e4);
    press.r_deg = p.Number("r_deg", -360.0, 360.0);
    press.force_n = p.Number("force_n", 0.0, 300.0);
    press.ramp_s = p.NumberOr("ramp_s", 0.0, 0.0, 1e4);
    press.hold_s = p.NumberOr("hold_s", 0.0, 0.0, 1e4);
    press.release_s = p.NumberOr("release_s", 0.0, 0.0, 1e4);
    p.Finish();
    s.presses.push_back(press);
  }
  double end = 0.0;
  for (const auto& p : s.presses) end = std::max(end, p.end_s());
  s.duration_s = root.NumberOr("duration_s", end, 0.0, 1e6);
  if (s.loop && !(s.duration_s > 0.0)) root.Fail("duration_s", "must be above 0 for a looping scenario");
  root.Finish();
  return s;
}

ScriptedSource::ScriptedSource(const twin::Scene& scene, Scenario scenario, double rate_hz)
    : scenario_(std::move(scenario)), probe_(scene.probe), rate_hz_(rate_hz) {
  if (scene.patches.empty() || scene.patches.size() > ingest::kChannels) {
    throw InputError(scene.source + ": " + std::to_string(scene.patches.size()) +
                     " patches; a Hyperion frame carries 1..16 channels");
  }
  if (!(rate_hz_ > 0.0)) throw InputError("scripted source: the rate must be above 0");
  for (std::size_t i = 0; i < scene.patches.size(); ++i) {
    twins_.push_back(std::make_unique<twin::SkinTwin>(scene.patches[i].spec, scene.effects,
                                                      std::vector<double>{scene.probe.radius_mm}));
    sims_.push_back(std::make_unique<twin::InterrogatorSim>(*twins_.back(), twin::DeriveSeed(scenario_.seed, i)));
  }
  contacts_.reserve(scenario_.presses.size());
  if (scene.effects.viscoelastic) {
    for (std::size_t i = 0; i < scene.patches.size(); ++i) {
      sites_.emplace_back(&*scene.effects.viscoelastic, 1.0 / rate_hz_, probe_);
    }
    current_press_.assign(scene.patches.size(), std::numeric_limits<std::size_t>::max());
  }
}

ScriptedSource::~ScriptedSource() = default;

void ScriptedSource::Sample(std::uint64_t sample, std::span<Wavelengths> out) {
  const double t_abs = static_cast<double>(sample) / rate_hz_;
  const double t = scenario_.loop ? std::fmod(t_abs, scenario_.duration_s) : t_abs;
  for (std::size_t c = 0; c < twins_.size() && c < out.size(); ++c) {
    twin::Shifts s{};
    std::uint32_t flags = 0;
    if (!sites_.empty()) {
      // One probe per patch: the latest press that has started drives the filter.
      std::size_t latest = std::numeric_limits<std::size_t>::max();
      for (std::size_t i = 0; i < scenario_.presses.size(); ++i) {
        const auto& p = scenario_.presses[i];
        if (p.patch == c && p.t_s <= t &&
            (latest == std::numeric_limits<std::size_t>::max() || p.t_s >= scenario_.presses[latest].t_s)) {
          latest = i;
        }
      }
      double f = 0.0;
      if (latest != std::numeric_limits<std::size_t>::max()) {
        const auto& p = scenario_.presses[latest];
        if (latest != current_press_[c]) sites_[c].MoveTo({p.y_mm, p.r_deg});
        f = p.ForceAt(t);
      }
      current_press_[c] = latest;
      twins_[c]->StrainShiftsPm(sites_[c].Step(f), s, flags);
    } else {
      contacts_.clear();
      for (const auto& p : scenario_.presses) {
        if (p.patch != c) continue;
        const double f = p.ForceAt(t);
        if (f > 0.0) contacts_.push_back(twin::Contact{{p.y_mm, p.r_deg}, f, probe_});
      }
      twins_[c]->StrainShiftsPm(contacts_, s, flags);
    }
    sims_[c]->Read(t_abs, s, out[c], flags);
  }
}

}  // namespace ruffini::sim
