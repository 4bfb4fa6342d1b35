#include "figures.h"

#include <cmath>
#include <cstdio>
#include <filesystem>

#include "ruffini/plot/svg.h"

namespace ruffini::cli {

std::vector<std::string> WriteHotSpotFigures(const twin::SkinTwin& twin, const twin::HotSpotMaps& maps,
                                             const twin::TwinReport& report, double hot_spot_force_n,
                                             const std::string& dir) {
  std::vector<std::string> paths;
  const auto& spec = twin.spec();
  for (std::size_t i = 0; i < patch::kGratings; ++i) {
    char title[160];
    std::snprintf(title, sizeof title, "FBG %zu: force for a 20 pm shift (hot spot %.1f mm2, %d area%s)", i + 1,
                  report.hot_spots[i].area_mm2, report.hot_spots[i].areas, report.hot_spots[i].areas == 1 ? "" : "s");
    plot::Figure fig(title, "R (deg)", "Y (mm)", 560, 560);
    plot::HeatLayer h;
    h.cols = maps.na;
    h.rows = maps.ny;
    h.values = maps.force_n[i];
    h.x_min = 0.0;
    h.x_max = twin.geometry().RDeg(maps.step_mm * (maps.na - 1));
    h.y_min = 0.0;
    h.y_max = maps.step_mm * (maps.ny - 1);
    h.v_min = 0.0;
    h.v_max = 2.5;
    h.colourbar_label = "force (N); black: hot spot <= 2.5/6 N; grey: > 2.5 N";
    h.black_at_or_below = hot_spot_force_n;
    fig.SetHeat(h);
    plot::Series path{"fibre", {}, {}, "#ffffff", plot::Series::Style::kLine};
    for (const auto& p : spec.fibre.path) {
      path.x.push_back(p.r_deg);
      path.y.push_back(p.y_mm);
    }
    fig.Add(path);
    const auto& c = twin.grating_centres()[i];
    fig.AddMarker({c.r_deg, c.y_mm, "FBG " + std::to_string(i + 1)});
    char name[64];
    std::snprintf(name, sizeof name, "hotspot_fbg%02zu.svg", i + 1);
    const std::string p = (std::filesystem::path(dir) / name).string();
    fig.Save(p);
    paths.push_back(p);
  }
  // All gratings in one picture: for each cell the smallest force over gratings.
  plot::Figure all("All gratings: smallest force for a 20 pm shift on any grating", "R (deg)", "Y (mm)", 560, 560);
  plot::HeatLayer h;
  h.cols = maps.na;
  h.rows = maps.ny;
  h.values.assign(static_cast<std::size_t>(maps.na * maps.ny), std::nan(""));
  for (std::size_t k = 0; k < h.values.size(); ++k) {
    for (std::size_t i = 0; i < patch::kGratings; ++i) {
      const double v = maps.force_n[i][k];
      if (!std::isnan(v) && (std::isnan(h.values[k]) || v < h.values[k])) h.values[k] = v;
    }
  }
  h.x_max = twin.geometry().RDeg(maps.step_mm * (maps.na - 1));
  h.y_max = maps.step_mm * (maps.ny - 1);
  h.v_min = 0.0;
  h.v_max = 2.5;
  h.colourbar_label = "force (N); black: hot spots";
  h.black_at_or_below = hot_spot_force_n;
  all.SetHeat(h);
  for (std::size_t i = 0; i < patch::kGratings; ++i) {
    const auto& c = twin.grating_centres()[i];
    all.AddMarker({c.r_deg, c.y_mm, std::to_string(i + 1)});
  }
  const std::string p = (std::filesystem::path(dir) / "hotspots_all.svg").string();
  all.Save(p);
  paths.push_back(p);
  return paths;
}

std::string WriteDetectionFigure(const twin::TwinReport& report, const std::string& dir) {
  plot::Figure fig("Touch detection (any grating > 2 pm) vs von Frey force", "force (N)", "detection rate", 640, 420);
  fig.SetLogX(true);
  fig.SetYRange(0.0, 1.05);
  auto add = [&](const twin::DetectionFit& f, const std::string& label, const std::string& colour) {
    plot::Series pts{label + " (measured)", {}, {}, colour, plot::Series::Style::kPoints};
    for (const auto& p : f.points) {
      pts.x.push_back(p.force_n);
      pts.y.push_back(p.rate());
    }
    fig.Add(pts);
    char buf[128];
    std::snprintf(buf, sizeof buf, "%s fit, 75 %% at %.0f mN", label.c_str(), f.threshold75_n * 1e3);
    plot::Series curve{buf, {}, {}, colour, plot::Series::Style::kLine};
    for (int k = 0; k <= 200; ++k) {
      const double x = std::pow(10.0, -2.6 + 2.5 * k / 200.0);
      curve.x.push_back(x);
      curve.y.push_back(1.0 / (1.0 + std::exp(-f.a_per_n * (x - f.b_n))));
    }
    fig.Add(curve);
  };
  add(report.detection_uniform, "uniform sites", "#1f77b4");
  add(report.detection_near_grating, "sites <= 3 mm from a FBG", "#d62728");
  fig.AddVLine(twin::Targets::kDetection75N, "paper: 75 % at 50.6 mN");
  fig.AddHLine(0.75, "75 %");
  const std::string p = (std::filesystem::path(dir) / "detection_curve.svg").string();
  fig.Save(p);
  return p;
}

}  // namespace ruffini::cli
