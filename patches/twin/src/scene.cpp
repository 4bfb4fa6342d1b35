#include "ruffini/twin/scene.h"

#include <algorithm>
#include "ruffini/twin/twin.h"
#include "ruffini/twin/viscoelastic.h"

#include "ruffini/error.h"
#include "ruffini/patch/spec_loader.h"
#include "ruffini/scene_file.h"
#include "ruffini/yaml_reader.h"

namespace ruffini::twin {
namespace {

constexpr double kBig = 1e9;
constexpr long kGratingMax = static_cast<long>(patch::kGratings);

TwinEffects ReadEffects(YamlReader& e) {
  TwinEffects out;
  if (auto n = e.MapOr("noise")) {
    out.noise = NoiseEffect{n->NumberOr("sigma_pm", NoiseEffect{}.sigma_pm, 0.0, 10.0)};
    n->Finish();
  }
  if (auto g = e.MapOr("gain_spread")) {
    out.gain_spread = GainSpreadEffect{g->NumberOr("sigma", GainSpreadEffect{}.sigma, 0.0, 0.5)};
    g->Finish();
  }
  if (e.Has("irregular_gratings")) {
    IrregularEffect ir;
    for (YamlReader& g : e.Sequence("irregular_gratings")) {
      IrregularGrating ig;
      ig.grating = static_cast<int>(g.Integer("grating", 1, kGratingMax));
      for (YamlReader& l : g.Sequence("lobes")) {
        Lobe lobe;
        lobe.along_mm = l.Number("along_mm", -40.0, 40.0);
        lobe.across_mm = l.Number("across_mm", -40.0, 40.0);
        lobe.gain = l.Number("gain", 0.0, 5.0);
        l.Finish();
        ig.lobes.push_back(lobe);
      }
      if (ig.lobes.empty()) g.Fail("lobes", "must list at least one lobe");
      g.Finish();
      ir.gratings.push_back(ig);
    }
    out.irregular = ir;
  }
  if (auto s = e.MapOr("stiffening")) {
    out.stiffening = StiffeningEffect{};
    s->Finish();
  }
  if (auto t = e.MapOr("temperature")) {
    TemperatureEffect te;
    te.offset_c = t->NumberOr("offset_c", te.offset_c, -100.0, 100.0);
    te.amplitude_c = t->NumberOr("amplitude_c", te.amplitude_c, 0.0, 100.0);
    te.period_s = t->NumberOr("period_s", te.period_s, 1e-3, kBig);
    te.ramp_c_per_s = t->NumberOr("ramp_c_per_s", te.ramp_c_per_s, -10.0, 10.0);
    te.coefficient_pm_per_c = t->NumberOr("coefficient_pm_per_c", te.coefficient_pm_per_c, 0.0, 100.0);
    te.spread = t->NumberOr("spread", te.spread, 0.0, 0.5);
    te.strain_pm_per_c = t->NumberOr("strain_pm_per_c", te.strain_pm_per_c, 0.0, 1000.0);
    if (auto g = t->MapOr("gradient")) {
      te.gradient_along_c = g->NumberOr("along_c", 0.0, -100.0, 100.0);
      te.gradient_around_c = g->NumberOr("around_c", 0.0, -100.0, 100.0);
      te.gradient_around_r_deg = g->NumberOr("around_r_deg", 0.0, -360.0, 360.0);
      te.gradient_tau_s = g->NumberOr("tau_s", 0.0, 0.0, kBig);
      g->Finish();
    }
    if (auto tri = t->MapOr("triangle")) {
      te.triangle_rate_c_per_h = tri->Number("rate_c_per_h", -1000.0, 1000.0);
      te.triangle_period_s = tri->NumberOr("period_s", te.triangle_period_s, 1.0, kBig);
      tri->Finish();
    }
    if (t->Has("knots")) {
      for (YamlReader& k : t->Sequence("knots")) {
        TemperatureKnot knot;
        knot.t_s = k.Number("t_s", -kBig, kBig);
        knot.c = k.Number("c", -100.0, 100.0);
        if (!te.knots.empty() && !(knot.t_s > te.knots.back().t_s)) {
          k.Fail("t_s", "must be later than the knot before it (t_s " + FormatNumber(te.knots.back().t_s) +
                            "); a step is two knots a short time apart");
        }
        k.Finish();
        te.knots.push_back(knot);
      }
      if (te.knots.empty()) t->Fail("knots", "must list at least one knot ({t_s, c}) or be left out");
    }
    t->Finish();
    out.temperature = te;
  }
  if (auto v = e.MapOr("viscoelastic")) {
    ViscoelasticEffect ve;
    if (v->Has("terms")) {
      ve.terms.clear();
      for (YamlReader& k : v->Sequence("terms")) {
        PronyTerm term;
        term.g = k.Number("g", 0.0, 1.0);
        term.tau_s = k.Number("tau_s", 1e-3, 1e5);
        k.Finish();
        ve.terms.push_back(term);
      }
      if (ve.terms.empty() || ve.terms.size() > ViscoelasticFilter::kMaxTerms) {
        v->Fail("terms", "must list 1 to " + std::to_string(ViscoelasticFilter::kMaxTerms) + " Prony terms ({g, tau_s})");
      }
      if (ve.total_creep() > 1.0) {
        v->Fail("terms", "must add up to a creep of at most 1 (the sum of g is " + FormatNumber(ve.total_creep()) + ")");
      }
    }
    v->Finish();
    out.viscoelastic = ve;
  }
  if (e.Has("faults")) {
    for (YamlReader& f : e.Sequence("faults")) {
      FaultEffect fe;
      fe.grating = static_cast<int>(f.Integer("grating", 1, kGratingMax));
      fe.kind = f.Choice("kind", {"dead", "dimmed"}) == "dead" ? FaultEffect::Kind::kDead : FaultEffect::Kind::kDimmed;
      fe.dropout = f.NumberOr("dropout", fe.kind == FaultEffect::Kind::kDimmed ? 0.2 : 0.0, 0.0, 1.0);
      fe.noise_factor = f.NumberOr("noise_factor", fe.kind == FaultEffect::Kind::kDimmed ? 4.0 : 1.0, 1.0, 100.0);
      f.Finish();
      out.faults.push_back(fe);
    }
  }
  if (auto h = e.MapOr("hard_press")) {
    out.hard_press.microbend_compression =
        h->NumberOr("microbend_compression", out.hard_press.microbend_compression, 0.31, 0.98);
    out.hard_press.pinch_margin_mm = h->NumberOr("pinch_margin_mm", out.hard_press.pinch_margin_mm, 0.0, 10.0);
    h->Finish();
    out.hard_press_named = true;
  }
  if (auto ed = e.MapOr("edges")) {
    EdgeEffect ee;
    const char* names[4] = {"y_min", "y_max", "r_min", "r_max"};
    for (int i = 0; i < 4; ++i) {
      if (!ed->Has(names[i])) continue;
      const std::string k = ed->Choice(names[i], {"continued", "free", "bonded"});
      ee.kind[static_cast<std::size_t>(i)] = k == "continued" ? EdgeEffect::Kind::kContinued
                                             : k == "free"    ? EdgeEffect::Kind::kFree
                                                              : EdgeEffect::Kind::kBonded;
    }
    ee.free_image_gain = ed->NumberOr("free_image_gain", ee.free_image_gain, 0.0, 1.0);
    ee.bonded_image_gain = ed->NumberOr("bonded_image_gain", ee.bonded_image_gain, -1.0, 0.0);
    ee.zone_mm = ed->NumberOr("zone_mm", ee.zone_mm, 1.0, 40.0);
    ed->Finish();
    out.edges = ee;
  }
  if (auto s = e.MapOr("skin_sample")) {
    SkinSampleEffect ss;
    ss.seed = static_cast<std::uint64_t>(s->IntegerOr("seed", static_cast<long>(ss.seed), 0, 1L << 40));
    ss.position_mm = s->NumberOr("position_mm", ss.position_mm, 0.0, 10.0);
    ss.thickness_sigma = s->NumberOr("thickness_sigma", ss.thickness_sigma, 0.0, 0.2);
    ss.wavelength_nm = s->NumberOr("wavelength_nm", ss.wavelength_nm, 0.0, 0.05);
    s->Finish();
    out.skin_sample = ss;
  }
  e.Finish();
  return out;
}

}  // namespace

const ScenePatch& Scene::Patch(const std::string& patch_name) const {
  if (patch_name.empty()) {
    if (patches.size() == 1) return patches[0];
    throw InputError(source + ": the scene has " + std::to_string(patches.size()) +
                     " patches; name one with --patch");
  }
  for (const auto& p : patches) {
    if (p.name == patch_name) return p;
  }
  throw InputError(source + ": no patch named '" + patch_name + "' in the scene");
}

Scene LoadScene(const std::string& path) {
  // The root reader checks the file's shape and the patches' paths; the twin reads the specs and its own
  // section, and builds nothing for the robot or safety sections (their parts read them).
  SceneFile file = LoadSceneFile(path);
  Scene s;
  s.source = path;
  s.name = file.name;
  for (const SceneFilePatch& p : file.patches) {
    s.patches.push_back(ScenePatch{.name = p.name,
                                   .spec_path = p.spec_path,
                                   .spec = patch::LoadPatchSpec(p.spec_path),
                                   .model_path = p.model_path,
                                   .cast_seed = std::nullopt});
  }
  if (auto& t = file.twin) {
    if (auto pr = t->MapOr("probe")) {
      s.probe.shape = pr->Choice("shape", {"sphere", "point"}) == "sphere" ? Probe::Shape::kSphere : Probe::Shape::kPoint;
      s.probe.radius_mm = pr->Number("radius_mm", 0.01, kMaxProbeRadiusMm);
      pr->Finish();
    }
    if (auto lc = t->MapOr("load_cell")) {
      s.load_cell.noise_n = lc->NumberOr("noise_n", s.load_cell.noise_n, 0.0, 10.0);
      s.load_cell.resolution_n = lc->NumberOr("resolution_n", s.load_cell.resolution_n, 0.0, 1.0);
      lc->Finish();
    }
    if (auto e = t->MapOr("effects")) s.effects = ReadEffects(*e);
    if (t->Has("casts")) {
      // casts: [{patch: forearm_b, skin_sample: 3}, ...]: each patch its own cast of the design.
      for (YamlReader& c : t->Sequence("casts")) {
        const std::string name = c.String("patch");
        auto it = std::find_if(s.patches.begin(), s.patches.end(), [&](const ScenePatch& p) { return p.name == name; });
        if (it == s.patches.end()) c.Fail("patch", "is not a patch of this scene");
        if (it->cast_seed) c.Fail("patch", "has a cast already");
        it->cast_seed = static_cast<std::uint64_t>(c.Integer("skin_sample", 0, 1L << 40));
        c.Finish();
      }
    }
    t->Finish();
  }
  return s;
}

TwinEffects Scene::EffectsOf(std::size_t patch) const {
  TwinEffects e = effects;
  if (patch < patches.size() && patches[patch].cast_seed) {
    if (!e.skin_sample) e.skin_sample = SkinSampleEffect{};
    e.skin_sample->seed = *patches[patch].cast_seed;
  }
  return e;
}

void OverrideSkinSample(Scene& scene, std::uint64_t seed) {
  if (!scene.effects.skin_sample) scene.effects.skin_sample = SkinSampleEffect{};
  scene.effects.skin_sample->seed = seed;
}

}  // namespace ruffini::twin
