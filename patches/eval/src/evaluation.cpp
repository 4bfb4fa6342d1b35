#include "ruffini/eval/evaluation.h"

#include "ruffini/paper.h"

#include <hdf5.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>

#include "ruffini/error.h"
#include "ruffini/patch/geometry.h"
#include "ruffini/plot/svg.h"

namespace ruffini::eval {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::string F(const char* fmt, double v) {
  char b[64];
  std::snprintf(b, sizeof b, fmt, v);
  return b;
}

std::vector<BinStats> Bin(const std::vector<double>& x, const std::vector<double>& err, const std::vector<double>& edges) {
  std::vector<BinStats> out;
  for (std::size_t b = 0; b + 1 < edges.size(); ++b) {
    std::vector<double> e;
    for (std::size_t k = 0; k < x.size(); ++k) {
      if (x[k] >= edges[b] && x[k] < edges[b + 1]) e.push_back(err[k]);
    }
    out.push_back({edges[b], edges[b + 1], stats::Summarize(e), e.size()});
  }
  return out;
}

std::vector<double> Edges(double lo, double hi, int n) {
  std::vector<double> e;
  for (int k = 0; k <= n; ++k) e.push_back(lo + (hi - lo) * k / n);
  return e;
}

}  // namespace

decode::ResponseModel FitResponse(const Prepared& p, const patch::PatchSpec& spec, const std::vector<std::int32_t>& test_ids,
                                  const patch::Region* area) {
  const std::set<std::int32_t> test(test_ids.begin(), test_ids.end());
  std::vector<decode::ShiftsPm> s;
  std::vector<float> f, y, r;
  for (std::size_t k = 0; k < p.size(); ++k) {
    if (p.indentation[k] < 0 || test.count(p.indentation[k])) continue;
    s.push_back(p.shift_pm[k]);
    f.push_back(p.force_n[k]);
    y.push_back(p.y_mm[k]);
    r.push_back(p.r_deg[k]);
  }
  const patch::Region patch_extent = spec.Extent();
  return decode::ResponseModel::Fit(s, f, y, r, area != nullptr ? *area : spec.indented_area, spec.surface_radius_mm, 0.1,
                                    &patch_extent);
}

Predictions RunDecoder(FrameDecoder& dec, const Prepared& p, const std::vector<std::int32_t>& test_ids,
                       const std::function<void(std::uint64_t, std::uint64_t)>& progress, bool test_only) {
  Predictions out;
  const std::size_t n = p.size();
  out.force_n.assign(n, static_cast<float>(kNaN));
  out.y_mm.assign(n, static_cast<float>(kNaN));
  out.r_deg.assign(n, static_cast<float>(kNaN));
  out.valid.assign(n, 0);
  out.located.assign(n, 0);
  out.test.assign(n, 0);
  const std::set<std::int32_t> test(test_ids.begin(), test_ids.end());
  std::int32_t current = -2;
  bool in_test = false;
  for (std::size_t k = 0; k < n; ++k) {
    if (p.indentation[k] != current) {
      current = p.indentation[k];
      in_test = current >= 0 && test.count(current);
      if (!test_only || in_test) dec.Reset(&p.shift_pm[k]);
    }
    out.test[k] = in_test ? 1 : 0;
    if (test_only && !in_test) continue;
    const decode::DecodeOutput o = dec.Decode(p.shift_pm[k]);
    out.valid[k] = o.valid ? 1 : 0;
    out.located[k] = o.located ? 1 : 0;
    if (o.valid) out.force_n[k] = o.force_n;
    if (o.located) {
      out.y_mm[k] = o.y_mm;
      out.r_deg[k] = o.r_deg;
    }
    if (progress && (k % 65536 == 0 || k + 1 == n)) progress(k + 1, n);
  }
  return out;
}

Evaluation Evaluate(const Prepared& p, const Predictions& pred, const patch::PatchSpec& spec, double gate_n) {
  Evaluation ev;
  const patch::Geometry geo(spec.surface_radius_mm);
  // Random guess from the training part (every indentation frame not in the test set).
  std::vector<double> train_force, train_y, train_r;
  for (std::size_t k = 0; k < p.size(); ++k) {
    if (p.indentation[k] < 0 || pred.test[k]) continue;
    train_force.push_back(p.force_n[k]);
    train_y.push_back(p.y_mm[k]);
    train_r.push_back(p.r_deg[k]);
  }
  if (train_force.empty()) {  // unseen data, every indentation scored: the guess is the data's own medians
    for (std::size_t k = 0; k < p.size(); ++k) {
      if (p.indentation[k] < 0) continue;
      train_force.push_back(p.force_n[k]);
      train_y.push_back(p.y_mm[k]);
      train_r.push_back(p.r_deg[k]);
    }
  }
  ev.rg_force_guess_n = stats::Median(train_force);
  ev.rg_location_guess = {stats::Median(train_y), stats::Median(train_r)};

  std::vector<double> f_err, f_rg, f_label, l_err, l_rg, l_label;
  std::vector<double> map_f_y, map_f_r, map_l_y, map_l_r;
  for (std::size_t k = 0; k < p.size(); ++k) {
    if (!pred.test[k] || !std::isfinite(p.force_n[k])) continue;
    // An invalid frame is scored as a force of 0 (what a consumer of the flag would assume): never dropped.
    const double fp = pred.valid[k] ? pred.force_n[k] : 0.0;
    f_err.push_back(std::abs(fp - p.force_n[k]) * 1e3);
    f_rg.push_back(std::abs(ev.rg_force_guess_n - p.force_n[k]) * 1e3);
    f_label.push_back(p.force_n[k]);
    map_f_y.push_back(p.y_mm[k]);
    map_f_r.push_back(p.r_deg[k]);
    if (p.force_n[k] > gate_n && std::isfinite(p.y_mm[k])) {
      if (!pred.located[k]) {
        ++ev.location_missed;
        continue;
      }
      l_err.push_back(geo.SurfaceDistanceMm({pred.y_mm[k], pred.r_deg[k]}, {p.y_mm[k], p.r_deg[k]}));
      l_rg.push_back(geo.SurfaceDistanceMm(ev.rg_location_guess, {p.y_mm[k], p.r_deg[k]}));
      l_label.push_back(p.force_n[k]);
      map_l_y.push_back(p.y_mm[k]);
      map_l_r.push_back(p.r_deg[k]);
    }
  }
  ev.force_frames = f_err.size();
  ev.location_frames = l_err.size();
  ev.force_error_mn = stats::Summarize(f_err);
  ev.rg_force_error_mn = stats::Summarize(f_rg);
  ev.location_error_mm = stats::Summarize(l_err);
  ev.rg_location_error_mm = stats::Summarize(l_rg);
  ev.force_wilcoxon = stats::WilcoxonSignedRank(f_err, f_rg);
  ev.location_wilcoxon = stats::WilcoxonSignedRank(l_err, l_rg);
  ev.force_cohens_d = std::abs(stats::CohensDPaired(f_err, f_rg));
  ev.location_cohens_d = std::abs(stats::CohensDPaired(l_err, l_rg));

  std::vector<double> over;  // force error restricted to frames above the gate, binned by force
  std::vector<double> over_label;
  for (std::size_t k = 0; k < f_err.size(); ++k) {
    if (f_label[k] >= gate_n) {
      over.push_back(f_err[k]);
      over_label.push_back(f_label[k]);
    }
  }
  ev.force_vs_force = Bin(over_label, over, Edges(0.05, 2.5, 10));
  ev.force_vs_force_low = Bin(over_label, over, Edges(0.05, 0.5, 9));
  ev.location_vs_force = Bin(l_label, l_err, Edges(0.05, 2.5, 10));
  ev.location_vs_force_low = Bin(l_label, l_err, Edges(0.05, 0.5, 9));
  {  // R^2 of a straight line through the binned medians
    std::vector<double> x, y;
    for (const auto& b : ev.force_vs_force) {
      if (b.n > 0) {
        x.push_back(0.5 * (b.lo + b.hi));
        y.push_back(b.error.median);
      }
    }
    const double n = static_cast<double>(x.size());
    double mx = 0, my = 0;
    for (std::size_t k = 0; k < x.size(); ++k) {
      mx += x[k] / n;
      my += y[k] / n;
    }
    double sxy = 0, sxx = 0, syy = 0;
    for (std::size_t k = 0; k < x.size(); ++k) {
      sxy += (x[k] - mx) * (y[k] - my);
      sxx += (x[k] - mx) * (x[k] - mx);
      syy += (y[k] - my) * (y[k] - my);
    }
    ev.force_error_r2 = (sxx > 0 && syy > 0) ? sxy * sxy / (sxx * syy) : kNaN;
  }
  // Error maps: the indented area in 12 x 10 cells (10 mm x 9 deg for the paper's area).
  const auto& a = spec.indented_area;
  ev.map_ny = 12;
  ev.map_nr = 10;
  auto map = [&](const std::vector<double>& ys, const std::vector<double>& rs, const std::vector<double>& err,
                 double& edge, double& interior) {
    std::vector<std::vector<double>> cells(static_cast<std::size_t>(ev.map_ny * ev.map_nr));
    std::vector<double> e_edge, e_in;
    for (std::size_t k = 0; k < err.size(); ++k) {
      const int iy = std::clamp(static_cast<int>((ys[k] - a.y_min_mm) / (a.y_max_mm - a.y_min_mm) * ev.map_ny), 0, ev.map_ny - 1);
      const int ir = std::clamp(static_cast<int>((rs[k] - a.r_min_deg) / (a.r_max_deg - a.r_min_deg) * ev.map_nr), 0, ev.map_nr - 1);
      cells[static_cast<std::size_t>(iy * ev.map_nr + ir)].push_back(err[k]);
      const bool at_edge = iy == 0 || ir == 0 || iy == ev.map_ny - 1 || ir == ev.map_nr - 1;
      (at_edge ? e_edge : e_in).push_back(err[k]);
    }
    edge = stats::Median(e_edge);
    interior = stats::Median(e_in);
    std::vector<double> m;
    for (auto& c : cells) m.push_back(stats::Median(c));
    return m;
  };
  ev.force_map_mn = map(map_f_y, map_f_r, f_err, ev.edge_force_mn, ev.interior_force_mn);
  ev.location_map_mm = map(map_l_y, map_l_r, l_err, ev.edge_location_mm, ev.interior_location_mm);
  return ev;
}

void WritePredictions(const std::string& path, const Predictions& pred) {
  using dataset::Column;
  const std::size_t n = pred.force_n.size();
  const Column cols[] = {
      {"force_n", Column::Type::kF32, n, 1, pred.force_n.data()}, {"y_mm", Column::Type::kF32, n, 1, pred.y_mm.data()},
      {"r_deg", Column::Type::kF32, n, 1, pred.r_deg.data()},     {"valid", Column::Type::kU8, n, 1, pred.valid.data()},
      {"located", Column::Type::kU8, n, 1, pred.located.data()},  {"test", Column::Type::kU8, n, 1, pred.test.data()},
  };
  dataset::WriteColumns(path, "pred", cols);
}

namespace {

void BinFigure(const std::string& path, const std::string& title, const std::string& ylabel,
               const std::vector<BinStats>& bins) {
  plot::Figure fig(title, "force label (N)", ylabel, 640, 400);
  plot::Series med{"median", {}, {}, "#1f77b4", plot::Series::Style::kLinePoints};
  plot::Series q1{"quartiles", {}, {}, "#9ecae1", plot::Series::Style::kLine};
  plot::Series q3{"", {}, {}, "#9ecae1", plot::Series::Style::kLine};
  for (const auto& b : bins) {
    const double x = 0.5 * (b.lo + b.hi);
    med.x.push_back(x);
    med.y.push_back(b.error.median);
    q1.x.push_back(x);
    q1.y.push_back(b.error.q1);
    q3.x.push_back(x);
    q3.y.push_back(b.error.q3);
  }
  fig.Add(q1).Add(q3).Add(med);
  fig.Save(path);
}

void MapFigure(const std::string& path, const std::string& title, const std::string& unit, const Evaluation& ev,
               const std::vector<double>& values, const patch::PatchSpec& spec) {
  plot::Figure fig(title, "R (deg)", "Y (mm)", 520, 560);
  plot::HeatLayer h;
  h.cols = ev.map_nr;
  h.rows = ev.map_ny;
  h.values = values;
  h.x_min = spec.indented_area.r_min_deg;
  h.x_max = spec.indented_area.r_max_deg;
  h.y_min = spec.indented_area.y_min_mm;
  h.y_max = spec.indented_area.y_max_mm;
  h.colourbar_label = "median error (" + unit + ")";
  fig.SetHeat(h);
  for (std::size_t i = 0; i < spec.gratings.size(); ++i) {
    fig.AddMarker({spec.gratings[i].centre.r_deg, spec.gratings[i].centre.y_mm, std::to_string(i + 1)});
  }
  fig.Save(path);
}

std::string Row(const std::string& what, const std::string& paper, const std::string& ours) {
  return "| " + what + " | " + paper + " | " + ours + " |\n";
}

}  // namespace

void WriteReport(const std::string& dir, const v1::DecoderModel& m, const std::string& data_path, const Prepared& p,
                 const Predictions& pred, const Evaluation& ev, const patch::PatchSpec& spec,
                 const std::string& command, const std::string& extra, const std::string& front) {
  std::filesystem::create_directories(dir);
  const std::filesystem::path d(dir);
  WritePredictions((d / "predictions.h5").string(), pred);
  BinFigure((d / "force_error_vs_force.svg").string(), "Force error vs force (test set, 0.05-2.5 N)", "abs error (mN)", ev.force_vs_force);
  BinFigure((d / "force_error_vs_force_low.svg").string(), "Force error vs force (0.05-0.5 N)", "abs error (mN)", ev.force_vs_force_low);
  BinFigure((d / "location_error_vs_force.svg").string(), "Location error vs force (test set, 0.05-2.5 N)", "error (mm)", ev.location_vs_force);
  BinFigure((d / "location_error_vs_force_low.svg").string(), "Location error vs force (0.05-0.5 N)", "error (mm)", ev.location_vs_force_low);
  MapFigure((d / "force_error_map.svg").string(), "Median force error over the patch", "mN", ev, ev.force_map_mn, spec);
  MapFigure((d / "location_error_map.svg").string(), "Median location error over the patch", "mm", ev, ev.location_map_mm, spec);

  std::ostringstream o;
  const auto& t = m.training();
  o << "# Decoder evaluation\n\n";
  o << "Reproduce: `" << command << "`\n\n";
  o << "- Model: patch `" << m.patch_name() << "` (fingerprint " << m.patch_fingerprint() << "), force window W = "
    << m.force().window() << ", location MLP widths";
  for (auto w : t.mlp_widths()) o << " " << w;
  const bool unit = !m.location().empty() && m.location(0).input_kind() == v1::LocationNet::UNIT;
  o << ", dropout " << t.dropout() << ", location input " << (unit ? "unit pattern (shifts / norm)" : "raw shifts")
    << (t.location_label_sigma_mm() > 0 ? ", soft location labels (sigma " + F("%.1f", t.location_label_sigma_mm()) + " mm)" : std::string())
    << ", force loss " << (t.force_loss().empty() ? std::string("mse") : t.force_loss()) << ", optimiser "
    << t.optimizer() << (t.lr_schedule() == "cosine" ? " (cosine learning-rate decay)" : "") << ", " << t.epochs() << " epochs (location nets "
    << (t.epochs_location() ? t.epochs_location() : t.epochs()) << ") of "
    << t.frames_per_epoch() << " samples, batch " << t.batch() << ", seed " << t.seed() << ", trained in "
    << F("%.0f", t.seconds()) << " s on `" << t.dataset() << "`.\n";
  o << "- Data: `" << data_path << "` (" << p.source << "), " << p.ids.size() << " indentations, " << p.size()
    << " frames; test set: " << m.test_indentations_size() << " held-out indentations (" << ev.force_frames
    << " frames, " << ev.location_frames << " above the 50 mN gate).\n\n";
  o << front;
  o << "## Test set, side by side with the paper\n\n| measure | paper | ours |\n|---|---|---|\n";
  o << Row("force error, median (IQR)", F("%.0f mN", paper::kForceErrorMn) + " (" + F("%.0f", paper::kForceIqrMn) + ")", F("%.1f mN", ev.force_error_mn.median) + " (" + F("%.1f", ev.force_error_mn.iqr()) + ")");
  o << Row("location error, median (IQR)", F("%.1f mm", paper::kLocationErrorMm) + " (" + F("%.1f", paper::kLocationIqrMm) + ")", F("%.2f mm", ev.location_error_mm.median) + " (" + F("%.2f", ev.location_error_mm.iqr()) + ")");
  o << Row("random-guess force error (guess)", F("%.0f mN", paper::kRgForceErrorN * 1e3) + " (IQR " + F("%.0f", paper::kRgForceIqrN * 1e3) + "), guess " + F("%.0f mN", paper::kMedianForceN * 1e3),
           F("%.0f mN", ev.rg_force_error_mn.median) + " (IQR " + F("%.0f", ev.rg_force_error_mn.iqr()) + "), guess " + F("%.0f mN", ev.rg_force_guess_n * 1e3));
  o << Row("random-guess location error", F("%.2f mm", paper::kRgLocationMm) + " (IQR " + F("%.2f", paper::kRgLocationIqrMm) + ")",
           F("%.2f mm", ev.rg_location_error_mm.median) + " (IQR " + F("%.2f", ev.rg_location_error_mm.iqr()) + ")");
  auto pv = [](double pval) { return pval > 0 ? "p = " + F("%.3g", pval) : std::string("p < 1e-300"); };
  o << Row("Wilcoxon vs random guess, force", "p < 0.001", pv(ev.force_wilcoxon.p_two_sided) + " (n = " + std::to_string(ev.force_wilcoxon.n) + ")");
  o << Row("Wilcoxon vs random guess, location", "p < 0.001", pv(ev.location_wilcoxon.p_two_sided) + " (n = " + std::to_string(ev.location_wilcoxon.n) + ")");
  o << Row("Cohen's d (paired) force / location", F("%.2f", paper::kCohensDForce) + " / " + F("%.2f", paper::kCohensDLocation), F("%.2f", ev.force_cohens_d) + " / " + F("%.2f", ev.location_cohens_d));
  o << Row("frames above the gate not located", "-", std::to_string(ev.location_missed) + " of " + std::to_string(ev.location_frames + ev.location_missed));
  o << Row("force error vs force: R2 of a line (binned medians)", F("%.2f", paper::kForceErrorVsForceR2), F("%.2f", ev.force_error_r2));
  o << Row("edges vs interior, force (mN)", "worse at the edges", F("%.1f", ev.edge_force_mn) + " vs " + F("%.1f", ev.interior_force_mn));
  o << Row("edges vs interior, location (mm)", "worse at the edges", F("%.2f", ev.edge_location_mm) + " vs " + F("%.2f", ev.interior_location_mm));
  o << "\nForce error is over every test frame (invalid frames count as 0 N). Location error is over test frames with a force label above 50 mN that the gate let through; frames the gate kept closed are counted above and left out. Random guesses use the medians of the training part, as the paper did. Cohen's d is paired: the mean difference of the absolute errors over their standard deviation.\n\n";

  o << "## 5-fold cross-validation inside the training part\n\n";
  const char* nets[6] = {"force", "SG", "VSG", "HSG", "DSG", "union"};
  const char* paper_val[6] = {"35 (56)", "12.5 (8.4)", "8.6 (4.9)", "11.0 (9.3)", "6.5 (4.8)", "3.6 (2.7)"};
  o << "| net | unit | paper validation median (IQR) | fold | train median (IQR) | validation median (IQR) |\n|---|---|---|---|---|---|\n";
  for (int k = 0; k < 6; ++k) {
    std::vector<double> vm, vi;
    for (const auto& r : t.folds()) {
      if (r.net() != nets[k]) continue;
      o << "| " << nets[k] << " | " << (k == 0 ? "mN" : "mm") << " | " << paper_val[k] << " | " << r.fold() << " | "
        << F("%.1f", r.train_median()) << " (" << F("%.1f", r.train_iqr()) << ") | " << F("%.1f", r.validation_median()) << " ("
        << F("%.1f", r.validation_iqr()) << ") |\n";
      vm.push_back(r.validation_median());
      vi.push_back(r.validation_iqr());
    }
    if (!vm.empty()) {
      const auto s = stats::Summarize(vm);
      o << "| **" << nets[k] << "** | | | median over folds | | **" << F("%.1f", s.median) << "** (IQR over folds " << F("%.1f", s.iqr())
        << "; median IQR " << F("%.1f", stats::Median(vi)) << ") |\n";
    }
  }
  if (t.folds().empty()) o << "(trained without cross-validation: `--folds 0`)\n";
  o << "\n## Error against force\n\n";
  o << "| force bin (N) | frames | force error median (mN) | location error median (mm) |\n|---|---|---|---|\n";
  for (std::size_t b = 0; b < ev.force_vs_force.size(); ++b) {
    o << "| " << F("%.2f", ev.force_vs_force[b].lo) << "-" << F("%.2f", ev.force_vs_force[b].hi) << " | " << ev.force_vs_force[b].n
      << " | " << F("%.1f", ev.force_vs_force[b].error.median) << " | " << F("%.2f", ev.location_vs_force[b].error.median) << " |\n";
  }
  o << "\n![force error vs force](force_error_vs_force.svg) ![0.05-0.5 N](force_error_vs_force_low.svg)\n\n";
  o << "![location error vs force](location_error_vs_force.svg) ![0.05-0.5 N](location_error_vs_force_low.svg)\n\n";
  o << "## Error maps\n\n![force error map](force_error_map.svg) ![location error map](location_error_map.svg)\n\n";
  o << extra;
  o << "\nPer-frame predictions: `predictions.h5` (`/pred/force_n`, `/pred/y_mm`, `/pred/r_deg`, `/pred/valid`, `/pred/located`, `/pred/test`), aligned with the dataset's frames.\n";
  std::ofstream out((d / "report.md").string());
  out << o.str();
  if (!out) throw InputError((d / "report.md").string() + ": cannot write the report");
}

}  // namespace ruffini::eval
