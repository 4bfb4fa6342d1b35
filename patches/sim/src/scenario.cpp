#include "ruffini/sim/scenario.h"

#include <yaml-cpp/yaml.h>

#include "ruffini/robot/mount.h"
#include "ruffini/robot/scene.h"
#include "ruffini/scene_file.h"

#include <algorithm>
#include <array>
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
  if (root.Has("offsets")) {
    for (YamlReader& o : root.Sequence("offsets")) {
      Offset off;
      off.t_s = o.Number("t_s", 0.0, 1e6);
      const std::string name = o.String("patch");
      const auto it = std::find_if(scene.patches.begin(), scene.patches.end(),
                                   [&](const twin::ScenePatch& sp) { return sp.name == name; });
      if (it == scene.patches.end()) o.Fail("patch", "is not a patch of scene " + scene.source);
      off.patch = static_cast<std::size_t>(it - scene.patches.begin());
      off.grating = static_cast<std::size_t>(o.Integer("grating", 1, static_cast<long>(kGratings)) - 1);
      off.pm = o.Number("pm", -1e4, 1e4);
      o.Finish();
      s.offsets.push_back(off);
    }
  }
  double end = 0.0;
  for (const auto& p : s.presses) end = std::max(end, p.end_s());
  s.duration_s = root.NumberOr("duration_s", end, 0.0, 1e6);
  if (s.loop && !(s.duration_s > 0.0)) root.Fail("duration_s", "must be above 0 for a looping scenario");
  root.Finish();
  return s;
}

std::unique_ptr<MountedScene> LoadMounts(const twin::Scene& scene) {
  if (scene.source.empty()) return nullptr;
  SceneFile file = LoadSceneFile(scene.source);
  if (!file.robot) return nullptr;
  auto m = std::make_unique<MountedScene>();
  m->robot = robot::LoadRobotScene(file);
  return m;
}

namespace {
double EdgeFraction(double e_mm, double a_mm) {
  const double s = std::clamp(a_mm > 0 ? e_mm / a_mm : (e_mm >= 0 ? 1.0 : -1.0), -1.0, 1.0);
  return 0.5 + 0.75 * (s - s * s * s / 3.0);
}
}  // namespace

std::vector<PatchLoad> ProbeLoads(const twin::Scene& scene, const MountedScene* mounts, std::size_t patch, double y_mm,
                                  double r_deg, double contact_radius_mm) {
  if (mounts == nullptr || patch >= mounts->robot.patches.size()) return {PatchLoad{patch, y_mm, r_deg, 1.0}};
  const robot::MountedPatch& home = mounts->robot.patches[patch];
  const Eigen::Vector3d p_L = robot::PatchToLink(home.mount, {y_mm, r_deg}).p_LS_m;
  std::vector<PatchLoad> loads;
  double total = 0.0;
  for (std::size_t i = 0; i < mounts->robot.patches.size() && i < scene.patches.size(); ++i) {
    const robot::MountedPatch& mp = mounts->robot.patches[i];
    if (mp.link_index != home.link_index) continue;
    const auto proj = robot::LinkToPatch(mp.mount, p_L);
    if (!proj || std::abs(proj->height_mm) > 1.0) continue;
    const patch::PatchSpec& spec = scene.patches[i].spec;
    const patch::Geometry g(spec);
    double r = proj->point.r_deg;
    // R on the patch's side of the cut (LinkToPatch gives (-90, 270]): pick the value nearest the span.
    if (r > spec.extent_r_deg + 180.0) r -= 360.0;
    const double y = proj->point.y_mm;
    const double e_y = std::min(y, spec.extent_y_mm - y);
    const double e_r = std::min(g.ArcMm(r), g.ArcMm(spec.extent_r_deg - r));
    const double f = EdgeFraction(e_y, contact_radius_mm) * EdgeFraction(e_r, contact_radius_mm);
    if (!(f > 1e-9)) continue;
    loads.push_back(PatchLoad{i, std::clamp(y, 0.0, spec.extent_y_mm), std::clamp(r, 0.0, spec.extent_r_deg), f});
    total += f;
  }
  for (auto& l : loads) l.share /= total;
  return loads;
}

twin::TwinEffects EffectsFor(const twin::Scene& scene, const MountedScene* mounts, std::size_t patch) {
  twin::TwinEffects e = scene.EffectsOf(patch);  // the patch's own cast, if it names one
  if (!e.edges || mounts == nullptr || patch >= mounts->robot.patches.size()) return e;
  // An edge another patch's cover continues beyond (a seam: robot::FindSeams) is `continued`.
  std::vector<robot::MountedSurface> surfaces;
  for (std::size_t i = 0; i < mounts->robot.patches.size() && i < scene.patches.size(); ++i) {
    const patch::PatchSpec& spec = scene.patches[i].spec;
    surfaces.push_back({mounts->robot.patches[i].mount, spec.extent_y_mm, spec.extent_r_deg});
  }
  for (const robot::Seam& s : robot::FindSeams(surfaces)) {
    if (s.a == patch) e.edges->kind[static_cast<std::size_t>(s.edge_a)] = twin::EdgeEffect::Kind::kContinued;
    if (s.b == patch) e.edges->kind[static_cast<std::size_t>(s.edge_b)] = twin::EdgeEffect::Kind::kContinued;
  }
  return e;
}

std::string MeasuredOn(const twin::Scene& scene, const MountedScene* mounts, std::size_t patch) {
  const patch::PatchSpec& spec = scene.patches.at(patch).spec;
  const twin::TwinEffects e = EffectsFor(scene, mounts, patch);
  std::string out = "spec " + spec.name + " (" + spec.Fingerprint() + "), cast " + std::to_string(e.fabrication_seed());
  if (!e.edges) return out + ", edges not modelled";
  static constexpr std::array<const char*, 4> kEdge = {"Y 0", "Y end", "R 0", "R end"};
  for (std::size_t k = 0; k < kEdge.size(); ++k) {
    const twin::EdgeEffect::Kind kind = e.edges->kind[k];
    out += std::string(k == 0 ? ", edges " : ", ") + kEdge[k] + " " +
           (kind == twin::EdgeEffect::Kind::kFree ? "free" : kind == twin::EdgeEffect::Kind::kBonded ? "bonded" : "continued");
  }
  return out;
}

std::string TwinParameters(const twin::Scene& scene) {
  const YAML::Node file = YAML::LoadFile(scene.source);
  const YAML::Node twin = file["twin"];
  if (!twin) return "";
  return "effects:\n" + YAML::Dump(twin["effects"]) + "\nprobe:\n" + YAML::Dump(twin["probe"]) + "\n";
}

ScriptedSource::ScriptedSource(const twin::Scene& scene, Scenario scenario, double rate_hz)
    : scenario_(std::move(scenario)), probe_(scene.probe), rate_hz_(rate_hz) {
  if (scene.patches.empty() || scene.patches.size() > ingest::kChannels) {
    throw InputError(scene.source + ": " + std::to_string(scene.patches.size()) +
                     " patches; a Hyperion frame carries 1..16 channels");
  }
  if (!(rate_hz_ > 0.0)) throw InputError("scripted source: the rate must be above 0");
  mounts_ = LoadMounts(scene);
  for (std::size_t i = 0; i < scene.patches.size(); ++i) {
    twins_.push_back(std::make_unique<twin::SkinTwin>(scene.patches[i].spec, EffectsFor(scene, mounts_.get(), i),
                                                      std::vector<double>{scene.probe.radius_mm}));
    sims_.push_back(std::make_unique<twin::InterrogatorSim>(*twins_.back(), twin::DeriveSeed(scenario_.seed, i)));
  }
  contacts_.reserve(scenario_.presses.size() * scene.patches.size());
  for (const auto& p : scenario_.presses) {
    const twin::ContactLaw* law = twins_[p.patch]->contact_law(probe_);
    const double a = law != nullptr ? law->ContactRadiusMm(std::min(p.force_n, law->linear_limit_force_n()))
                                    : probe_.radius_mm;
    loads_.push_back(ProbeLoads(scene, mounts_.get(), p.patch, p.y_mm, p.r_deg, a));
  }
  if (scene.effects.viscoelastic) {
    for (std::size_t i = 0; i < scenario_.presses.size(); ++i) {
      for (const PatchLoad& l : loads_[i]) {
        filters_.push_back({i, l.patch, {l.y_mm, l.r_deg}, l.share, twin::ViscoelasticFilter(*scene.effects.viscoelastic, 1.0 / rate_hz_)});
      }
    }
  }
}

ScriptedSource::~ScriptedSource() = default;

void ScriptedSource::Sample(std::uint64_t sample, std::span<Wavelengths> out) {
  const double t_abs = static_cast<double>(sample) / rate_hz_;
  const double t = scenario_.loop ? std::fmod(t_abs, scenario_.duration_s) : t_abs;
  for (std::size_t c = 0; c < twins_.size() && c < out.size(); ++c) {
    twin::Shifts s{};
    std::uint32_t flags = 0;
    contacts_.clear();
    if (!filters_.empty()) {
      // Each press's filter steps once per sample, loaded or not (its residual fades where it pressed).
      for (PressFilter& f : filters_) {
        if (f.patch != c) continue;
        const double eff = f.filter.Step(f.share * scenario_.presses[f.press].ForceAt(t));
        if (eff > 0.0) contacts_.push_back(twin::Contact{f.at, eff, probe_});
      }
    } else {
      for (std::size_t i = 0; i < scenario_.presses.size(); ++i) {
        const auto& p = scenario_.presses[i];
        for (const auto& l : loads_[i]) {
          if (l.patch != c) continue;
          const double f = l.share * p.ForceAt(t);
          if (f > 0.0) contacts_.push_back(twin::Contact{{l.y_mm, l.r_deg}, f, probe_});
        }
      }
    }
    twins_[c]->StrainShiftsPm(contacts_, s, flags);
    sims_[c]->Read(t_abs, s, out[c], flags);
    for (const Offset& o : scenario_.offsets) {
      if (o.patch == c && t >= o.t_s && std::isfinite(out[c][o.grating])) out[c][o.grating] += o.pm * 1e-3;
    }
  }
}

}  // namespace ruffini::sim
