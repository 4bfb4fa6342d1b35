#include "scene_setup.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <sstream>

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/io/zero_copy_stream_impl_lite.h>

#include "ruffini/decode/model_io.h"
#include "ruffini/error.h"
#include "ruffini/robot/scene.h"
#include "ruffini/safety/scene.h"
#include "ruffini/scene_file.h"
#include "ruffini/service/common.h"
#include "ruffini/sim/scenario.h"
#include "ruffini/twin/scene.h"

namespace ruffini::aggregator {

std::uint64_t DrawRunId() {
  // std::random_device is the OS's entropy source on Linux (getrandom); two draws make 64 bits.
  std::random_device rd;
  std::uint64_t id = 0;
  while (id == 0) id = (static_cast<std::uint64_t>(rd()) << 32) ^ static_cast<std::uint64_t>(rd());
  return id;
}

namespace {

std::string Num(double v) {
  if (std::isinf(v)) return "inf";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f", v);
  return buf;
}

}  // namespace

std::vector<fusion::FusionConfig::SeamBand> SeamsOf(const aggregate::Setup& setup) {
  std::vector<robot::MountedSurface> surfaces;
  for (const auto& p : setup.patches) {
    if (!p.mount) return {};  // every patch of a scene with a robot has a mount (SetupFromScene)
    surfaces.push_back({*p.mount, p.extent_y_mm, p.extent_r_deg});
  }
  // A side's band comes from its model's map at its region's threshold (the smallest level at or above it).
  auto band = [&](std::size_t i, robot::PatchEdge edge) {
    float threshold = 0;
    for (const auto& r : setup.safety.regions) {
      if (r.name == setup.safety.patches[i].region) threshold = r.threshold_n;
    }
    const v1::SensitivityMap* map = nullptr;
    for (const auto& m : setup.patches[i].sensitivity) {
      if (m.level_n() >= threshold && (map == nullptr || m.level_n() < map->level_n())) map = &m;
    }
    if (map == nullptr) return 0.0;
    const robot::MountedSurface& s = surfaces[i];
    return decode::EdgeReachMm(*map, [&](double y, double r) { return robot::DistanceToEdgeMm(s, edge, {y, r}); });
  };
  std::vector<fusion::FusionConfig::SeamBand> out;
  for (const robot::Seam& seam : robot::FindSeams(surfaces)) {
    out.push_back({seam, band(seam.a, seam.edge_a), band(seam.b, seam.edge_b)});
  }
  return out;
}

aggregate::Setup SetupFromScene(const std::string& scene_path) {
  const SceneFile file = LoadSceneFile(scene_path);
  if (!file.safety) {
    throw InputError(scene_path + ": the scene has no `safety:` section (body regions and their thresholds); "
                     "the aggregator cannot judge contacts without it");
  }
  aggregate::Setup setup;
  setup.safety = safety::ConfigFromScene(file);
  const twin::Scene scene = twin::LoadScene(scene_path);
  std::optional<robot::RobotScene> robot;
  if (file.robot) {
    robot = robot::LoadRobotScene(file);
    setup.robot = robot->model;
  }
  for (const auto& p : scene.patches) {
    aggregate::PatchExpectation e;
    e.id = p.name;
    e.spec_name = p.spec.name;
    e.spec_fingerprint = p.spec.Fingerprint();
    e.extent_y_mm = p.spec.extent_y_mm;
    e.extent_r_deg = p.spec.extent_r_deg;
    if (!p.model_path.empty()) e.model_sha256 = service::Sha256OfFile(p.model_path);
    if (robot) {
      const robot::MountedPatch* m = robot->FindPatch(p.name);
      if (m == nullptr) throw InputError(scene_path + ": patch '" + p.name + "' has no mount");
      e.mount = m->mount;
    }
    setup.patches.push_back(std::move(e));
  }
  SceneCoverage coverage = CoverageOfScene(scene_path);
  if (!coverage.refusal.empty()) throw InputError(scene_path + ": " + coverage.refusal);
  setup.coverage = std::move(coverage.regions);
  for (std::size_t i = 0; i < setup.patches.size(); ++i) setup.patches[i].sensitivity = std::move(coverage.maps[i]);
  if (robot) setup.seams = SeamsOf(setup);
  setup.instance = service::InstanceName();
  setup.robot_name = file.name;
  setup.run_id = DrawRunId();
  return setup;
}

std::string Describe(const aggregate::Setup& setup) {
  std::ostringstream out;
  out << setup.patches.size() << " patches (";
  for (std::size_t i = 0; i < setup.safety.patches.size(); ++i) {
    const auto& p = setup.safety.patches[i];
    out << (i ? ", " : "") << p.id << " in " << p.region;
    if (setup.patches[i].mount) out << " on " << setup.patches[i].mount->link;
  }
  out << "); regions:";
  for (const auto& r : setup.safety.regions) {
    out << " " << r.name << " > " << r.threshold_n << " N stops";
    for (const v1::RegionCoverage& c : setup.coverage) {
      if (c.region() != r.name) continue;
      out << " (guaranteed from " << c.guaranteed_threshold_n() << " N: a press of " << c.stop_force_n()
          << " N stops on its covered surface, " << c.covered_points() << " of " << c.points() << " map points";
      if (c.accepted_bands_size() == 0) out << ", no band accepted as uncovered)";
      else {
        out << "; accepted uncovered:";
        for (int k = 0; k < c.accepted_bands_size(); ++k) {
          const auto& b = c.accepted_bands(k);
          out << (k ? ", " : " ") << b.name() << " on " << (b.patch_id().empty() ? "every patch" : b.patch_id());
        }
        out << ")";
      }
    }
    out << ";";
  }
  for (const auto& sb : setup.seams) {
    out << " seam " << setup.patches[sb.seam.a].id << " " << robot::ToString(sb.seam.edge_a) << " | "
        << setup.patches[sb.seam.b].id << " " << robot::ToString(sb.seam.edge_b) << " (bands " << Num(sb.band_a_mm)
        << " / " << Num(sb.band_b_mm) << " mm" << (sb.band_a_mm > 0 && sb.band_b_mm > 0 ? "" : ": no seam rule, a side has no map") << ");";
  }
  const auto& rule = setup.safety.stop_rule;
  if (rule.sd_k == 0.0f) out << " stop rule: the force alone;";
  else out << " stop rule: force " << (rule.sd_k > 0 ? "+ " : "- ") << std::abs(rule.sd_k) << " x sd (max_sd_n " << rule.max_sd_n << " N);";
  out << " robot name '" << setup.robot_name << "', run id " << std::hex << setup.run_id << std::dec << ";";
  out << " robot: " << (setup.robot ? setup.robot->name() + " (" + std::to_string(setup.robot->num_dof()) + " joints)" : "none");
  return out.str();
}


std::string DecoderSha256(const v1::DecoderModel& model) {
  v1::DecoderModel decoder = model;
  decoder.clear_sensitivity();
  std::string bytes;
  google::protobuf::io::StringOutputStream raw(&bytes);
  {
    google::protobuf::io::CodedOutputStream coded(&raw);
    coded.SetSerializationDeterministic(true);  // the same model, the same bytes
    if (!decoder.SerializeToCodedStream(&coded)) throw InputError("model: cannot serialise for its digest");
  }
  return service::Sha256Hex(bytes);
}

namespace {

// SensitivityMap.measured_on: the patch as mounted (sim::MeasuredOn) and twin_digest, TwinDigest(scene).
std::string MeasuredOnText(const twin::Scene& scene, const sim::MountedScene* mounts, std::size_t patch,
                           const std::string& twin_digest) {
  return sim::MeasuredOn(scene, mounts, patch) + ", twin " + twin_digest;
}
// A digest of every twin parameter besides the patch's cast and edges (sim::TwinParameters; the scene file is read
// again, so once per scene).
std::string TwinDigest(const twin::Scene& scene) { return service::Sha256Hex(sim::TwinParameters(scene)).substr(0, 16); }

}  // namespace

void BindMap(v1::SensitivityMap& map, const std::string& scene_path, const std::string& patch,
             const v1::DecoderModel& model) {
  const twin::Scene scene = twin::LoadScene(scene_path);
  const auto mounts = sim::LoadMounts(scene);
  for (std::size_t i = 0; i < scene.patches.size(); ++i) {
    if (scene.patches[i].name != patch) continue;
    map.set_measured_on(MeasuredOnText(scene, mounts.get(), i, TwinDigest(scene)));
    map.set_model_sha256(DecoderSha256(model));
    return;
  }
  throw InputError(scene_path + ": no patch '" + patch + "'");
}

SceneCoverage CoverageOfScene(const std::string& scene_path) {
  const SceneFile file = LoadSceneFile(scene_path);
  const safety::Config config = safety::ConfigFromScene(file);
  const twin::Scene scene = twin::LoadScene(scene_path);
  const safety::CoverageConfig& cov = config.coverage;
  SceneCoverage out;
  std::vector<v1::DecoderModel> models(scene.patches.size());
  std::vector<bool> has_model(scene.patches.size(), false);
  for (std::size_t i = 0; i < scene.patches.size(); ++i) {
    const twin::ScenePatch& p = scene.patches[i];
    if (!p.model_path.empty()) {
      models[i] = decode::LoadModel(p.model_path);
      has_model[i] = true;
    }
  }
  // The maps that fit each patch: measured on the patch as this scene mounts it, with this model's decoder.
  const auto mounts = sim::LoadMounts(scene);
  std::vector<google::protobuf::RepeatedPtrField<v1::SensitivityMap>> fitting(scene.patches.size());
  out.map_problems.assign(scene.patches.size(), "");
  const std::string twin_digest = TwinDigest(scene);
  for (std::size_t i = 0; i < scene.patches.size(); ++i) {
    if (!has_model[i] || models[i].sensitivity_size() == 0) continue;
    const std::string here = MeasuredOnText(scene, mounts.get(), i, twin_digest);
    const std::string digest = DecoderSha256(models[i]);
    std::string& problem = out.map_problems[i];
    for (const v1::SensitivityMap& m : models[i].sensitivity()) {
      if (m.measured_on() == here && m.model_sha256() == digest) {
        *fitting[i].Add() = m;
        continue;
      }
      problem += std::string(problem.empty() ? "patch " + scene.patches[i].name + ": " : "; ") + "the map of level " + Num(m.level_n()) + " N in " +
                 scene.patches[i].model_path + " is not used: ";
      if (m.measured_on().empty() && m.model_sha256().empty()) {
        problem += "it records neither the patch nor the decoder it was measured with (a map from before stop 31)";
      } else {
        if (m.measured_on() != here) {
          problem += "it was measured on " + m.measured_on() + ", but here the patch is " + here;
        }
        if (m.model_sha256() != digest) {
          problem += std::string(m.measured_on() != here ? "; and " : "") + "it was measured with decoder " +
                     m.model_sha256().substr(0, 12) + ", but the model's decoder is " + digest.substr(0, 12) +
                     " (changed since: a recalibration, an uncertainty refit or a response map)";
        }
      }
      problem += "; measure it here (`ruffini sensitivity --scene " + scene_path + " --patch " + scene.patches[i].name + "`)";
    }
  }
  // What the aggregator keeps of each patch's maps (GetStatus, the seams' bands: SeamsOf) is what fits it.
  for (std::size_t i = 0; i < scene.patches.size(); ++i) out.maps.emplace_back(fitting[i].begin(), fitting[i].end());
  std::vector<decode::UncoveredBand> bands;
  for (const auto& b : cov.accepted_uncovered) {
    for (const twin::ScenePatch& p : scene.patches) {
      if (!b.patch.empty() && p.name != b.patch) continue;
      if (b.y_max_mm > p.spec.extent_y_mm || b.r_max_deg > p.spec.extent_r_deg) {
        throw InputError(scene_path + ": safety.coverage.accepted_uncovered '" + b.name + "' reaches beyond patch " +
                         p.name + "'s surface (Y 0.." + Num(p.spec.extent_y_mm) + " mm, R 0.." +
                         Num(p.spec.extent_r_deg) + " deg)");
      }
    }
    bands.push_back({b.name, b.patch, b.y_min_mm, b.y_max_mm, b.r_min_deg, b.r_max_deg, b.source});
  }
  std::string refusal;
  // Patches on a seam: a seam contact is judged on the sum of both sides' forces (the fuser adds them), so a
  // side that refuses faint contacts could drop part of a stop whatever its refusal force.
  std::vector<bool> on_seam(scene.patches.size(), false);
  if (file.robot) {
    const robot::RobotScene rs = robot::LoadRobotScene(file);
    std::vector<robot::MountedSurface> surfaces;
    for (const twin::ScenePatch& p : scene.patches) {
      const robot::MountedPatch* m = rs.FindPatch(p.name);
      if (m == nullptr) throw InputError(scene_path + ": patch '" + p.name + "' has no mount");
      surfaces.push_back({m->mount, p.spec.extent_y_mm, p.spec.extent_r_deg});
    }
    for (const robot::Seam& seam : robot::FindSeams(surfaces)) on_seam[seam.a] = on_seam[seam.b] = true;
  }
  for (std::size_t i = 0; i < scene.patches.size(); ++i) {
    if (!has_model[i] || !on_seam[i] || !(models[i].preprocessing().faint_refuse_below_n() > 0.0f)) continue;
    refusal += std::string(refusal.empty() ? "" : "; ") + "patch " + scene.patches[i].name + "'s model " +
               scene.patches[i].model_path + " refuses faint contacts below " +
               Num(models[i].preprocessing().faint_refuse_below_n()) +
               " N, but the patch shares a seam: a seam contact is judged on the sum of both sides, so a refused side "
               "could be part of a stop (run a model that does not refuse on a seamed patch)";
  }
  for (const safety::RegionConfig& r : config.regions) {
    std::vector<decode::CoveragePatch> patches;
    for (std::size_t i = 0; i < scene.patches.size(); ++i) {
      if (config.patches[i].region != r.name) continue;
      decode::CoveragePatch cp;
      cp.id = scene.patches[i].name;
      cp.maps = has_model[i] ? &fitting[i] : nullptr;
      cp.extent_y_mm = scene.patches[i].spec.extent_y_mm;
      cp.extent_r_deg = scene.patches[i].spec.extent_r_deg;
      cp.mm_per_deg = scene.patches[i].spec.surface_radius_mm * std::numbers::pi / 180.0;
      patches.push_back(cp);
    }
    // A stop rule that lowers a force (sd_k < 0) needs maps at the threshold plus the largest lowering.
    const double margin = std::max(0.0f, -config.stop_rule.sd_k) * config.stop_rule.max_sd_n;
    // A decoder that refuses faint contacts below some force (Preprocessing.faint_refuse_below_n) must never
    // refuse a frame the stop rule would stop on. The force alone (sd_k <= 0) stops above the threshold; a
    // raising rule (sd_k > 0) stops down to the threshold less sd_k x the largest sd the model reports (its
    // Uncertainty; without one every reading is a doubt and any force could stop).
    for (std::size_t i = 0; i < scene.patches.size(); ++i) {
      if (config.patches[i].region != r.name || !has_model[i]) continue;
      const double below = models[i].preprocessing().faint_refuse_below_n();
      if (!(below > 0.0)) continue;
      double lowest_stop_n = r.threshold_n;
      if (config.stop_rule.sd_k > 0.0f) {
        const auto& sd = models[i].uncertainty().force_sd_n();
        lowest_stop_n = sd.empty() ? 0.0
                                   : r.threshold_n - config.stop_rule.sd_k * *std::max_element(sd.begin(), sd.end());
      }
      if (below > lowest_stop_n) {
        refusal += std::string(refusal.empty() ? "" : "; ") + "patch " + scene.patches[i].name + "'s model " +
                   scene.patches[i].model_path + " refuses faint contacts below " + Num(below) + " N, but region '" +
                   r.name + "' (threshold " + Num(r.threshold_n) + " N, stop rule sd_k " + Num(config.stop_rule.sd_k) +
                   ") may stop on a force of " + Num(std::max(0.0, lowest_stop_n)) +
                   " N: a refused frame could be a stop (raise the threshold, or calibrate the model with a lower "
                   "--faint-refuse-below-n)";
      }
    }
    decode::RegionGuarantee g = decode::GuaranteeRegion(patches, bands, r.threshold_n, cov.press_factor, margin);
    v1::RegionCoverage rc;
    rc.set_region(r.name);
    rc.set_threshold_n(r.threshold_n);
    rc.set_press_factor(static_cast<float>(cov.press_factor));
    rc.set_map_level_n(static_cast<float>(g.map_level_n));
    rc.set_stop_force_n(static_cast<float>(g.stop_force_n));
    rc.set_guaranteed_threshold_n(static_cast<float>(g.guaranteed_threshold_n));
    rc.set_points(g.points);
    rc.set_covered_points(g.covered_points);
    std::size_t k = 0;  // g.bands: the bands on this region's patches, in the scene's order
    for (const decode::UncoveredBand& b : bands) {
      bool mine = false;
      for (const auto& p : patches) mine = mine || b.On(p.id);
      if (!mine) continue;
      v1::AcceptedBand* ab = rc.add_accepted_bands();
      ab->set_name(b.name);
      ab->set_patch_id(b.patch);
      ab->set_y_min_mm(b.y_min_mm);
      ab->set_y_max_mm(b.y_max_mm);
      ab->set_r_min_deg(b.r_min_deg);
      ab->set_r_max_deg(b.r_max_deg);
      ab->set_source(b.source);
      ab->set_points(g.bands[k].points);
      ab->set_uncovered_points(g.bands[k].uncovered_points);
      ++k;
    }
    if (!g.ok()) {
      std::string why = "region '" + r.name + "' threshold " + Num(r.threshold_n) + " N is ";
      if (!g.unmapped.empty()) {
        why += "not guaranteed: the model of patch";
        for (const auto& id : g.unmapped) why += " " + id;
        why += " has no sensitivity map at or above " + Num(r.threshold_n + margin) + " N";
        if (margin > 0) {
          why += " (the threshold plus the stop rule's largest lowering, |sd_k| x max_sd_n = " + Num(margin) + " N)";
        }
        why += " (measure one with `ruffini sensitivity`, or accept the whole patch as uncovered)";
        for (std::size_t i = 0; i < scene.patches.size(); ++i) {
          const bool unmapped = std::find(g.unmapped.begin(), g.unmapped.end(), scene.patches[i].name) != g.unmapped.end();
          if (unmapped && !out.map_problems[i].empty()) why += "; " + out.map_problems[i];
        }
      } else if (!g.unmeasured.empty()) {
        why += "not guaranteed:";
        for (const auto& u : g.unmeasured) why += " " + u + ";";
        why += " measure the map to the edges (`ruffini sensitivity`) or accept the strips as uncovered bands";
      } else {
        why += "below what its patches guarantee, " + Num(g.guaranteed_threshold_n) + " N (" +
               std::to_string(g.uncovered.size()) + " of " + std::to_string(g.covered_points) +
               " covered map points need more than " + Num(cov.press_factor) + " x " + Num(r.threshold_n) +
               " N to be reported above " + Num(g.map_level_n) + " N; the worst needs " + Num(g.stop_force_n) +
               " N); raise the threshold or name the uncovered bands in safety.coverage.accepted_uncovered "
               "(`ruffini check-scene --points` lists them)";
      }
      refusal += (refusal.empty() ? "" : "; ") + why;
    }
    out.regions.push_back(std::move(rc));
    out.guarantees.push_back(std::move(g));
  }
  out.refusal = refusal;
  return out;
}

std::string DescribeCoverage(const SceneCoverage& c, bool points) {
  std::ostringstream out;
  for (std::size_t i = 0; i < c.regions.size(); ++i) {
    const v1::RegionCoverage& r = c.regions[i];
    const decode::RegionGuarantee& g = c.guarantees[i];
    if (g.patches == 0) {
      // Nothing to guarantee: a scene may name a region none of its patches is in (a soak's --patches subset).
      out << "region " << r.region() << ": threshold " << Num(r.threshold_n()) << " N; no patch of the scene is in "
          << "this region: nothing is covered, nothing to guarantee\n";
      continue;
    }
    out << "region " << r.region() << ": threshold " << Num(r.threshold_n()) << " N, press factor "
        << Num(r.press_factor()) << "; ";
    if (r.points() == 0) {
      // No map this region's patches can use (review 14: this line once read "maps of level nan N; guaranteed
      // threshold inf N ... 0 of 0 map points").
      out << "no usable sensitivity map, so no threshold can be guaranteed: ";
    } else {
      out << "maps of level " << Num(r.map_level_n()) << " N; guaranteed threshold " << Num(r.guaranteed_threshold_n())
          << " N (every press of " << Num(r.stop_force_n()) << " N or more is reported above the level on the "
          << "covered surface: " << r.covered_points() << " of " << r.points() << " map points): ";
    }
    out
        << (!g.ok() ? "NOT GUARANTEED"
                    : g.covered_points == 0 ? "NOTHING COVERED (every patch accepted as uncovered: nothing is promised)"
                                            : "GUARANTEED")
        << "\n";
    for (const auto& id : g.unmapped) out << "  patch " << id << ": no sensitivity map at or above the threshold\n";
    for (const auto& u : g.unmeasured) out << "  " << u << "\n";
    for (const v1::AcceptedBand& b : r.accepted_bands()) {
      out << "  accepted uncovered band " << b.name() << " on " << (b.patch_id().empty() ? "every patch" : b.patch_id()) << ": Y " << Num(b.y_min_mm()) << ".."
          << Num(b.y_max_mm()) << " mm, R " << Num(b.r_min_deg()) << ".." << Num(b.r_max_deg()) << " deg, "
          << b.points() << " map points, " << b.uncovered_points() << " of them weak (" << b.source() << ")\n";
    }
    if (!g.uncovered.empty()) {
      out << "  " << g.uncovered.size() << " covered map points need more than " << Num(r.press_factor()) << " x "
          << Num(r.threshold_n()) << " N" << (points ? ":" : " (--points lists them)") << "\n";
      if (points) {
        for (const auto& p : g.uncovered) {
          out << "    " << p.patch << " Y " << Num(p.y_mm) << " mm R " << Num(p.r_deg) << " deg: " << Num(p.min_force_n)
              << " N\n";
        }
      }
    }
  }
  for (const std::string& p : c.map_problems) {
    if (!p.empty()) out << "  maps not used: " << p << "\n";
  }
  if (!c.refusal.empty()) out << "refused: " << c.refusal << "\n";
  return out.str();
}

}  // namespace ruffini::aggregator
