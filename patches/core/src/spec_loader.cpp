#include "ruffini/patch/spec_loader.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <fstream>
#include <sstream>

#include "ruffini/error.h"
#include "ruffini/patch/geometry.h"
#include "ruffini/yaml_reader.h"

namespace ruffini::patch {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

SurfacePoint ReadPoint(YamlReader& r, double y_max, double r_max) {
  SurfacePoint p;
  p.y_mm = r.Number("y_mm", 0.0, y_max);
  p.r_deg = r.Number("r_deg", 0.0, r_max);
  r.Finish();
  return p;
}

// Distance from p to the polyline, in the unrolled surface (mm).
double DistanceToPath(const Geometry& g, const std::vector<SurfacePoint>& path, const SurfacePoint& p) {
  double best = kInf;
  const UnrolledPoint q = g.Unroll(p);
  for (std::size_t i = 0; i + 1 < path.size(); ++i) {
    const UnrolledPoint a = g.Unroll(path[i]), b = g.Unroll(path[i + 1]);
    const double dx = b.y_mm - a.y_mm, dy = b.arc_mm - a.arc_mm;
    const double len2 = dx * dx + dy * dy;
    double t = len2 > 0 ? ((q.y_mm - a.y_mm) * dx + (q.arc_mm - a.arc_mm) * dy) / len2 : 0.0;
    t = std::clamp(t, 0.0, 1.0);
    best = std::min(best, std::hypot(a.y_mm + t * dx - q.y_mm, a.arc_mm + t * dy - q.arc_mm));
  }
  return best;
}

}  // namespace

PatchSpec ParsePatchSpec(const std::string& yaml_text, const std::string& source_name) {
  YamlReader root = YamlReader::Parse(yaml_text, source_name);
  PatchSpec s;
  s.source = source_name;
  s.name = root.String("name");
  s.surface_radius_mm = root.Number("surface_radius_mm", 5.0, 500.0);
  {
    YamlReader e = root.Map("extent");
    s.extent_y_mm = e.Number("y_mm", 10.0, 2000.0);
    s.extent_r_deg = e.Number("r_deg", 5.0, 360.0);
    e.Finish();
  }
  {
    YamlReader a = root.Map("indented_area");
    s.indented_area.y_min_mm = a.Number("y_min_mm", 0.0, s.extent_y_mm);
    s.indented_area.y_max_mm = a.Number("y_max_mm", s.indented_area.y_min_mm, s.extent_y_mm);
    s.indented_area.r_min_deg = a.Number("r_min_deg", 0.0, s.extent_r_deg);
    s.indented_area.r_max_deg = a.Number("r_max_deg", s.indented_area.r_min_deg, s.extent_r_deg);
    a.Finish();
  }
  {
    YamlReader l = root.Map("layer");
    s.layer.thickness_mm = l.Number("thickness_mm", 1.0, 50.0);
    s.layer.fibre_depth_mm = l.Number("fibre_depth_mm", 0.1, s.layer.thickness_mm - 0.1);
    YamlReader m = l.Map("material");
    s.layer.material.youngs_modulus_kpa = m.Number("youngs_modulus_kpa", 1.0, 1e5);
    s.layer.material.poisson_ratio = m.Number("poisson_ratio", 0.0, 0.499);
    s.layer.material.density_kg_m3 = m.Number("density_kg_m3", 100.0, 5000.0);
    s.layer.material.yeoh_c1_kpa = m.Number("yeoh_c1_kpa", 0.1, 1e5);
    s.layer.material.yeoh_c2_pa = m.Number("yeoh_c2_pa", -1e6, 1e6);
    s.layer.material.yeoh_c3_pa = m.Number("yeoh_c3_pa", -1e6, 1e6);
    m.Finish();
    l.Finish();
  }
  {
    YamlReader f = root.Map("fibre");
    s.fibre.strain_optic_pm_per_microstrain = f.Number("strain_optic_pm_per_microstrain", 0.1, 10.0);
    s.fibre.strain_transfer = f.Number("strain_transfer", 1e-7, 1.0);
    s.fibre.band_half_width_nm = f.Number("band_half_width_nm", 0.05, 20.0);
    for (YamlReader& p : f.Sequence("path")) s.fibre.path.push_back(ReadPoint(p, s.extent_y_mm, s.extent_r_deg));
    if (s.fibre.path.size() < 2) f.Fail("path", "must have at least 2 points");
    f.Finish();
  }
  {
    YamlReader i = root.Map("interrogator");
    s.interrogator.window_min_nm = i.Number("window_min_nm", 1000.0, 2000.0);
    s.interrogator.window_max_nm = i.Number("window_max_nm", s.interrogator.window_min_nm, 2000.0);
    s.interrogator.noise_pm = i.Number("noise_pm", 0.0, 100.0);
    i.Finish();
  }
  std::vector<YamlReader> gs = root.Sequence("gratings");
  if (gs.size() != kGratings) {
    root.Fail("gratings", "has " + std::to_string(gs.size()) + " entries; a patch carries exactly " +
                              std::to_string(kGratings) + " gratings");
  }
  const Geometry geo(s.surface_radius_mm);
  const double lo = s.interrogator.window_min_nm, hi = s.interrogator.window_max_nm;
  const double hw = s.fibre.band_half_width_nm;
  for (std::size_t k = 0; k < kGratings; ++k) {
    YamlReader& g = gs[k];
    Grating& out = s.gratings[k];
    out.centre.y_mm = g.Number("y_mm", -kInf, kInf);
    out.centre.r_deg = g.Number("r_deg", -kInf, kInf);
    if (!s.Extent().Contains(out.centre)) {
      g.Fail("y_mm", "with r_deg " + FormatNumber(out.centre.r_deg) + " puts the grating outside the patch (Y 0.." +
                         FormatNumber(s.extent_y_mm) + " mm, R 0.." + FormatNumber(s.extent_r_deg) + " deg)");
    }
    out.direction_deg = g.Number("direction_deg", -360.0, 360.0);
    out.length_mm = g.Number("length_mm", 1.0, 30.0);
    if (k > 0 && out.length_mm != s.gratings[0].length_mm) {
      g.Fail("length_mm", "must equal gratings[0].length_mm (" + FormatNumber(s.gratings[0].length_mm) +
                              " mm): the twin shares one response table between gratings");
    }
    out.wavelength_nm = g.Number("wavelength_nm", -kInf, kInf);
    if (out.wavelength_nm - hw < lo || out.wavelength_nm + hw > hi) {
      g.Fail("wavelength_nm", "with its band of +-" + FormatNumber(hw) + " nm must lie inside the interrogator window " +
                                  FormatNumber(lo) + ".." + FormatNumber(hi) + " nm");
    }
    if (k > 0) {
      const double prev = s.gratings[k - 1].wavelength_nm;
      if (out.wavelength_nm - prev < 2.0 * hw) {
        g.Fail("wavelength_nm", "must be at least " + FormatNumber(2.0 * hw) + " nm above gratings[" +
                                    std::to_string(k - 1) + "] (" + FormatNumber(prev) +
                                    " nm) so their bands (+-band_half_width_nm, the largest shift the twin "
                                    "produces) cannot overlap");
      }
    }
    const double d = DistanceToPath(geo, s.fibre.path, out.centre);
    if (d > 1.0) {
      g.Fail("y_mm", "with r_deg " + FormatNumber(out.centre.r_deg) + " lies " + FormatNumber(std::round(d * 10) / 10) +
                         " mm from the fibre path; a grating must sit on it (within 1 mm)");
    }
    g.Finish();
  }
  root.Finish();
  return s;
}

PatchSpec LoadPatchSpec(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InputError(path + ": cannot open patch spec");
  std::stringstream ss;
  ss << in.rdbuf();
  return ParsePatchSpec(ss.str(), path);
}

void ValidatePatchSpec(const PatchSpec& spec) {
  // Round trip through the loader: one set of rules for files and in-memory specs.
  (void)ParsePatchSpec(DumpPatchSpec(spec), spec.source.empty() ? "<spec " + spec.name + ">" : spec.source);
}

std::string DumpPatchSpec(const PatchSpec& s) {
  std::ostringstream o;
  auto n = [](double v) { return FormatNumber(v); };
  o << "name: " << s.name << "\n";
  o << "surface_radius_mm: " << n(s.surface_radius_mm) << "\n";
  o << "extent: {y_mm: " << n(s.extent_y_mm) << ", r_deg: " << n(s.extent_r_deg) << "}\n";
  o << "indented_area: {y_min_mm: " << n(s.indented_area.y_min_mm) << ", y_max_mm: " << n(s.indented_area.y_max_mm)
    << ", r_min_deg: " << n(s.indented_area.r_min_deg) << ", r_max_deg: " << n(s.indented_area.r_max_deg) << "}\n";
  const Material& m = s.layer.material;
  o << "layer:\n  thickness_mm: " << n(s.layer.thickness_mm) << "\n  fibre_depth_mm: " << n(s.layer.fibre_depth_mm)
    << "\n  material: {youngs_modulus_kpa: " << n(m.youngs_modulus_kpa) << ", poisson_ratio: " << n(m.poisson_ratio)
    << ", density_kg_m3: " << n(m.density_kg_m3) << ", yeoh_c1_kpa: " << n(m.yeoh_c1_kpa)
    << ", yeoh_c2_pa: " << n(m.yeoh_c2_pa) << ", yeoh_c3_pa: " << n(m.yeoh_c3_pa) << "}\n";
  o << "fibre:\n  strain_optic_pm_per_microstrain: " << n(s.fibre.strain_optic_pm_per_microstrain)
    << "\n  strain_transfer: " << n(s.fibre.strain_transfer) << "\n  band_half_width_nm: " << n(s.fibre.band_half_width_nm)
    << "\n  path:\n";
  for (const auto& p : s.fibre.path) o << "    - {y_mm: " << n(p.y_mm) << ", r_deg: " << n(p.r_deg) << "}\n";
  o << "interrogator: {window_min_nm: " << n(s.interrogator.window_min_nm) << ", window_max_nm: "
    << n(s.interrogator.window_max_nm) << ", noise_pm: " << n(s.interrogator.noise_pm) << "}\n";
  o << "gratings:\n";
  for (const auto& g : s.gratings) {
    o << "  - {y_mm: " << n(g.centre.y_mm) << ", r_deg: " << n(g.centre.r_deg) << ", direction_deg: " << n(g.direction_deg)
      << ", length_mm: " << n(g.length_mm) << ", wavelength_nm: " << n(g.wavelength_nm) << "}\n";
  }
  return o.str();
}

}  // namespace ruffini::patch
