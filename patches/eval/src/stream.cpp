#include "ruffini/eval/stream.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <set>
#include <sstream>

#include "ruffini/error.h"
#include "ruffini/patch/edge_distance.h"
#include "ruffini/patch/geometry.h"

namespace ruffini::eval {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr double kGateN = 0.05;     // the paper's gate: location is scored above it
constexpr double kQuietN = 0.02;    // below this true force a reported contact is a false contact
// chi-square(2) quantiles of the 1-, 2- and 3-sigma probabilities (68.27 %, 95.45 %, 99.73 %): -2 ln(1 - p).
constexpr double kChi2Sigma1 = 2.2957, kChi2Sigma2 = 6.1801, kChi2Sigma3 = 11.8290;

std::string F(const char* fmt, double v) {
  char b[64];
  std::snprintf(b, sizeof b, fmt, v);
  return b;
}

}  // namespace

namespace {

StreamPredictions Decode(const decode::Pipeline<float>& pipeline, const dataset::Dataset& d, OperatorRetare* op,
                         const ProgressFn& progress) {
  StreamPredictions out;
  const std::size_t n = d.size();
  out.force_n.resize(n);
  out.force_sd_n.resize(n);
  out.y_mm.resize(n);
  out.r_deg.resize(n);
  out.confidence.resize(n);
  out.common_mode_pm.resize(n);
  out.pos_cov_mm2.resize(3 * n);
  out.valid.resize(n);
  out.located.resize(n);
  out.in_contact.resize(n);
  out.reason.resize(n);
  out.baseline_frozen.resize(n);
  out.over_range.resize(n);
  decode::Pipeline<float>::Data data(pipeline);
  std::unique_ptr<decode::Retare> retare;
  if (op != nullptr) retare = std::make_unique<decode::Retare>(op->map, pipeline.config().baseline, op->config);
  const double dt = d.info.sample_rate_hz > 0 ? 1.0 / d.info.sample_rate_hz : 0.0;
  double last_request_s = -1e300, window_max_true = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const decode::PipelineOutput o = pipeline.Process(d.wavelength_nm[k], d.flags[k], data);
    out.force_n[k] = o.force_n;
    out.force_sd_n[k] = o.force_sd_n;
    out.y_mm[k] = o.y_mm;
    out.r_deg[k] = o.r_deg;
    out.confidence[k] = o.confidence;
    out.common_mode_pm[k] = o.common_mode_pm;
    out.pos_cov_mm2[3 * k] = o.cov_yy_mm2;
    out.pos_cov_mm2[3 * k + 1] = o.cov_yr_mm2;
    out.pos_cov_mm2[3 * k + 2] = o.cov_rr_mm2;
    out.valid[k] = o.valid;
    out.located[k] = o.located;
    out.in_contact[k] = o.in_contact;
    out.reason[k] = static_cast<std::uint8_t>(o.reason);
    out.over_range[k] = o.over_range;
    out.baseline_frozen[k] = data.baseline().state() == decode::BaselineTracker::State::kFrozen;
    if (retare) {
      // As link::Monitor: the window takes this frame's output; an accepted baseline holds from the next frame.
      const float truth = k < d.true_force_n.size() ? d.true_force_n[k] : 0.0f;
      const double t = static_cast<double>(k) * dt;
      if (retare->active()) {
        if (std::isfinite(truth)) window_max_true = std::max(window_max_true, static_cast<double>(truth));
        if (const auto res = retare->Feed(d.wavelength_nm[k], o, data.baseline())) {
          if (res->outcome == decode::RetareOutcome::kAccepted) {
            pipeline.Retare(retare->baseline_nm(), data);
            ++op->accepted;
            if (window_max_true > 0.02) ++op->accepted_while_pressed;
            op->accepted_max_true_n = std::max(op->accepted_max_true_n, window_max_true);
          } else if (res->outcome == decode::RetareOutcome::kPressing) {
            ++op->refused_pressing;
            if (!(window_max_true > 0.02)) ++op->refused_pressing_nothing;
          } else {
            ++op->refused_other;
          }
        }
      } else if (o.reason == decode::Reason::kBaselineStale && t - last_request_s >= op->every_s) {
        last_request_s = t;
        ++op->requests;
        retare->Start();
        window_max_true = std::isfinite(truth) ? truth : 0.0;
      }
    }
    if (progress && (k % 65536 == 0 || k + 1 == n)) progress(k + 1, n);
  }
  out.counters = data.counters();
  return out;
}

}  // namespace

StreamPredictions DecodeStream(const decode::Pipeline<float>& pipeline, const dataset::Dataset& d,
                               const ProgressFn& progress) {
  return Decode(pipeline, d, nullptr, progress);
}

StreamPredictions DecodeStream(const decode::Pipeline<float>& pipeline, const dataset::Dataset& d, OperatorRetare& op,
                               const ProgressFn& progress) {
  return Decode(pipeline, d, &op, progress);
}

void WriteStreamPredictions(const std::string& path, const StreamPredictions& p, const std::string& model,
                            const std::string& data) {
  using dataset::Column;
  const std::size_t n = p.size();
  const Column cols[] = {
      {"force_n", Column::Type::kF32, n, 1, p.force_n.data()},
      {"force_sd_n", Column::Type::kF32, n, 1, p.force_sd_n.data()},
      {"y_mm", Column::Type::kF32, n, 1, p.y_mm.data()},
      {"r_deg", Column::Type::kF32, n, 1, p.r_deg.data()},
      {"pos_cov_mm2", Column::Type::kF32, n, 3, p.pos_cov_mm2.data()},
      {"confidence", Column::Type::kF32, n, 1, p.confidence.data()},
      {"common_mode_pm", Column::Type::kF32, n, 1, p.common_mode_pm.data()},
      {"located", Column::Type::kU8, n, 1, p.located.data()},
      {"valid", Column::Type::kU8, n, 1, p.valid.data()},
      {"in_contact", Column::Type::kU8, n, 1, p.in_contact.data()},
      {"reason", Column::Type::kU8, n, 1, p.reason.data()},
      {"baseline_frozen", Column::Type::kU8, n, 1, p.baseline_frozen.data()},
      {"over_range", Column::Type::kU8, n, 1, p.over_range.data()},
  };
  std::string reasons;
  for (std::size_t r = 0; r < decode::kReasonCount; ++r) {
    if (!reasons.empty()) reasons += ", ";
    reasons += std::to_string(r) + " = " + std::string(decode::ReasonName(static_cast<decode::Reason>(r)));
  }
  dataset::WriteColumns(path, "pred", cols,
                        {{"format", "ruffini.predictions"}, {"model", model}, {"data", data}, {"reasons", reasons},
                         {"pos_cov_mm2", "per frame yy, yr, rr in mm^2 on the surface (r as arc length)"}});
}

std::vector<std::uint8_t> MaskOfIndentations(const dataset::Dataset& d, const std::vector<std::int32_t>& ids) {
  const std::set<std::int32_t> s(ids.begin(), ids.end());
  std::vector<std::uint8_t> m(d.size(), 0);
  for (std::size_t k = 0; k < d.size(); ++k) m[k] = d.indentation[k] >= 0 && s.count(d.indentation[k]) ? 1 : 0;
  return m;
}

StreamMetrics ScoreStream(const dataset::Dataset& d, const StreamPredictions& p, const patch::PatchSpec& spec,
                          const std::vector<std::uint8_t>& mask, const patch::SurfacePoint& guess) {
  if (p.size() != d.size()) {
    throw InputError("predictions have " + std::to_string(p.size()) + " frames, the dataset " + std::to_string(d.size()));
  }
  StreamMetrics m;
  m.guess = guess;
  const patch::Geometry geo(spec.surface_radius_mm);
  const std::vector<double> edges = {0.0, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 1e9};
  std::vector<std::vector<double>> bin_f(edges.size() - 1), bin_l(edges.size() - 1);
  std::vector<std::size_t> bin_n(edges.size() - 1), bin_miss(edges.size() - 1), bin_contact(edges.size() - 1);
  std::vector<double> f_all, f_above, f_cell, l_above, l_located;
  std::size_t above100 = 0, missed100 = 0;
  std::size_t f1 = 0, f2 = 0, f3 = 0, p1 = 0, p2 = 0, p3 = 0;
  struct ZoneData {
    std::vector<double> force, location, located, ratio, location_1n;
  } zone_edge, zone_in;
  for (std::size_t k = 0; k < d.size(); ++k) {
    if (!mask.empty() && !mask[k]) continue;
    ++m.frames;
    const bool valid = p.valid[k] != 0;
    if (!valid) {
      ++m.invalid;
      ++m.reasons[std::min<std::size_t>(p.reason[k], decode::kReasonCount - 1)];
    }
    const bool has_true = std::isfinite(d.true_force_n[k]);
    m.has_true_force = m.has_true_force || has_true;
    const double ref = has_true ? d.true_force_n[k] : d.force_n[k];
    if (!std::isfinite(ref)) continue;
    // An invalid frame reports no force (0): scored as such.
    const double pred = valid ? p.force_n[k] : 0.0;
    const double fe = std::abs(pred - ref) * 1e3;
    f_all.push_back(fe);
    if (std::isfinite(d.force_n[k])) f_cell.push_back(std::abs(pred - d.force_n[k]) * 1e3);
    const bool located = valid && p.located[k];
    const auto bin = static_cast<std::size_t>(std::upper_bound(edges.begin(), edges.end(), ref) - edges.begin()) - 1;
    const std::size_t b = std::min(bin, edges.size() - 2);
    ++bin_n[b];
    bin_f[b].push_back(fe);
    if (valid && p.in_contact[k]) ++bin_contact[b];
    if (!located) ++bin_miss[b];
    if (ref < kQuietN) {
      ++m.quiet_frames;
      if (valid && p.in_contact[k]) ++m.false_contacts;
    }
    if (valid && p.in_contact[k] && std::isfinite(p.force_sd_n[k])) {
      ++m.force_cov_frames;
      const double z = std::abs(pred - ref) / p.force_sd_n[k];
      f1 += z <= 1.0;
      f2 += z <= 2.0;
      f3 += z <= 3.0;
    }
    if (ref > kGateN && std::isfinite(d.y_mm[k]) && std::isfinite(d.r_deg[k])) {
      f_above.push_back(fe);
      ++m.above_frames;
      const patch::SurfacePoint truth{d.y_mm[k], d.r_deg[k]};
      double le;
      if (located) {
        le = geo.SurfaceDistanceMm({p.y_mm[k], p.r_deg[k]}, truth);
        l_located.push_back(le);
        const double cyy = p.pos_cov_mm2[3 * k], cyr = p.pos_cov_mm2[3 * k + 1], crr = p.pos_cov_mm2[3 * k + 2];
        const double det = cyy * crr - cyr * cyr;
        if (std::isfinite(det) && det > 0 && cyy > 0) {
          const double dy = p.y_mm[k] - truth.y_mm, da = geo.ArcMm(p.r_deg[k] - truth.r_deg);
          const double d2 = (crr * dy * dy - 2 * cyr * dy * da + cyy * da * da) / det;
          ++m.position_cov_frames;
          p1 += d2 <= kChi2Sigma1;
          p2 += d2 <= kChi2Sigma2;
          p3 += d2 <= kChi2Sigma3;
        }
      } else {
        le = geo.SurfaceDistanceMm(guess, truth);
        ++m.above_missed;
      }
      l_above.push_back(le);
      bin_l[b].push_back(le);
      const bool near = patch::EdgeDistanceMm(spec, truth) <= StreamMetrics::kEdgeBandMm;
      EdgeZone& zone = near ? m.near_edge : m.interior;
      ZoneData& zd = near ? zone_edge : zone_in;
      ++zone.frames;
      zone.missed += located ? 0 : 1;
      zone.over_range += !valid && p.in_contact[k] ? 1 : 0;
      zd.force.push_back(fe);
      zd.location.push_back(le);
      if (located) zd.located.push_back(le);
      if (ref > 1.0) {
        zd.ratio.push_back(pred / ref);
        zd.location_1n.push_back(le);
      }
      if (ref > 0.1) {
        ++above100;
        missed100 += !located;
      }
    }
  }
  // Longest frozen stretch and longest press over the whole stream (the baseline is a property of the stream).
  {
    const double dt = d.size() > 1 ? (d.t_s.back() - d.t_s.front()) / static_cast<double>(d.size() - 1) : 0.0;
    std::size_t run_f = 0, best_f = 0, run_p = 0, best_p = 0;
    for (std::size_t k = 0; k < d.size(); ++k) {
      run_f = p.baseline_frozen[k] ? run_f + 1 : 0;
      best_f = std::max(best_f, run_f);
      const double ref = std::isfinite(d.true_force_n[k]) ? d.true_force_n[k] : d.force_n[k];
      run_p = std::isfinite(ref) && ref > kQuietN ? run_p + 1 : 0;
      best_p = std::max(best_p, run_p);
    }
    m.longest_frozen_s = static_cast<double>(best_f) * dt;
    m.longest_press_s = static_cast<double>(best_p) * dt;
  }
  for (auto [zone, zd] : {std::pair{&m.near_edge, &zone_edge}, std::pair{&m.interior, &zone_in}}) {
    zone->force_mn = stats::Summarize(zd->force);
    zone->location_mm = stats::Summarize(zd->location);
    zone->location_located_mm = stats::Summarize(zd->located);
    zone->frames_above_1n = zd->ratio.size();
    zone->location_above_1n_mm = stats::Summarize(zd->location_1n);
    zone->force_ratio_above_1n = zd->ratio.empty() ? kNaN : stats::Median(zd->ratio);
  }
  m.force_all_mn = stats::Summarize(f_all);
  m.force_above_mn = stats::Summarize(f_above);
  m.force_all_loadcell_mn = stats::Summarize(f_cell);
  m.location_above_mm = stats::Summarize(l_above);
  m.location_located_mm = stats::Summarize(l_located);
  m.miss_rate_above_100mn = above100 ? static_cast<double>(missed100) / static_cast<double>(above100) : kNaN;
  m.false_contact_rate = m.quiet_frames ? static_cast<double>(m.false_contacts) / static_cast<double>(m.quiet_frames) : kNaN;
  const auto share = [](std::size_t a, std::size_t b) { return b ? static_cast<double>(a) / static_cast<double>(b) : kNaN; };
  m.force_within_1sd = share(f1, m.force_cov_frames);
  m.force_within_2sd = share(f2, m.force_cov_frames);
  m.position_within_1sd = share(p1, m.position_cov_frames);
  m.position_within_2sd = share(p2, m.position_cov_frames);
  m.force_within_3sd = share(f3, m.force_cov_frames);
  m.position_within_3sd = share(p3, m.position_cov_frames);
  for (std::size_t b = 0; b + 1 < edges.size(); ++b) {
    ForceBinRow r;
    r.lo_n = edges[b];
    r.hi_n = edges[b + 1];
    r.frames = bin_n[b];
    r.missed = share(bin_miss[b], bin_n[b]);
    r.in_contact = share(bin_contact[b], bin_n[b]);
    r.force_error_mn = stats::Median(bin_f[b]);
    r.location_error_mm = stats::Median(bin_l[b]);
    m.bins.push_back(r);
  }
  return m;
}

std::string StreamMetricsHeader() {
  return "| data | frames | force, all frames: median (IQR) mN | same, against the load cell | force > 50 mN | location > 50 mN, misses as failures: "
         "median (IQR) mm | located only | missed > 50 mN | missed > 100 mN | false contacts (< 20 mN) | invalid |\n"
         "|---|---|---|---|---|---|---|---|---|---|---|\n";
}

std::string StreamMetricsRow(const std::string& name, const StreamMetrics& m) {
  std::ostringstream o;
  const auto s = [](const stats::Summary& v, const char* fmt) { return F(fmt, v.median) + " (" + F(fmt, v.iqr()) + ")"; };
  o << "| " << name << " | " << m.frames << " | " << s(m.force_all_mn, "%.1f") << " | " << s(m.force_all_loadcell_mn, "%.1f") << " | "
    << s(m.force_above_mn, "%.1f") << " | "
    << s(m.location_above_mm, "%.2f") << " | " << s(m.location_located_mm, "%.2f") << " | "
    << F("%.1f %%", 100.0 * static_cast<double>(m.above_missed) / std::max<double>(1.0, static_cast<double>(m.above_frames)))
    << " | " << F("%.2f %%", 100.0 * m.miss_rate_above_100mn) << " | "
    << F("%.3f %%", 100.0 * m.false_contact_rate) << " (" << m.false_contacts << " of " << m.quiet_frames << ") | "
    << m.invalid << " |\n";
  return o.str();
}

std::string EdgeZoneTable(const std::vector<std::pair<std::string, const StreamMetrics*>>& rows) {
  std::ostringstream o;
  const auto s = [](const stats::Summary& v, const char* fmt) { return F(fmt, v.median) + " (" + F(fmt, v.iqr()) + ")"; };
  o << "| data | zone | pressed frames (> 50 mN) | force error, median (IQR) mN | reported / true force above 1 N, median | "
       "location, misses as failures: median (IQR) mm | located only | above 1 N, misses as failures | not located | over range |\n"
       "|---|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& [name, m] : rows) {
    for (const auto& [zone_name, z] : {std::pair{F("within %.0f mm of an edge", StreamMetrics::kEdgeBandMm), &m->near_edge},
                                      std::pair{std::string("interior"), &m->interior}}) {
      o << "| " << name << " | " << zone_name << " | " << z->frames << " | " << s(z->force_mn, "%.1f") << " | "
        << (std::isfinite(z->force_ratio_above_1n) ? F("%.2f", z->force_ratio_above_1n) : std::string("-")) << " | "
        << s(z->location_mm, "%.2f") << " | " << s(z->location_located_mm, "%.2f") << " | "
        << (z->frames_above_1n ? s(z->location_above_1n_mm, "%.2f") : std::string("-")) << " | "
        << F("%.1f %%", 100.0 * static_cast<double>(z->missed) / std::max<double>(1.0, static_cast<double>(z->frames))) << " | "
        << F("%.1f %%", 100.0 * static_cast<double>(z->over_range) / std::max<double>(1.0, static_cast<double>(z->frames))) << " |\n";
    }
  }
  return o.str();
}

std::string ForceBinTable(const StreamMetrics& m) {
  std::ostringstream o;
  o << "| true force (N) | frames | reported in contact | not located | force error, median mN | location error (misses as failures), median mm |\n"
       "|---|---|---|---|---|---|\n";
  for (const auto& r : m.bins) {
    o << "| " << F("%.2f", r.lo_n) << " - " << (r.hi_n > 1e6 ? std::string("...") : F("%.2f", r.hi_n)) << " | " << r.frames << " | "
      << F("%.3f %%", 100 * r.in_contact) << " | " << F("%.2f %%", 100 * r.missed) << " | " << F("%.1f", r.force_error_mn) << " | "
      << (std::isfinite(r.location_error_mm) ? F("%.2f", r.location_error_mm) : std::string("-")) << " |\n";
  }
  return o.str();
}

std::string StreamReportSection(const std::vector<StreamReportRow>& rows, const StreamMetrics& whole, bool training_data,
                                const v1::Uncertainty* u) {
  if (rows.empty()) throw InputError("stream report: no data");
  const StreamMetrics& sm = rows.front().scored;
  const auto pct = [](double v) { return F("%.1f %%", 100.0 * v); };
  std::ostringstream h;
  h << "## Scored as a skeptical reviewer would\n\n"
    << "Every frame decoded in stream order through `decode::Pipeline` (the decoder service's code: baseline tracked "
       "throughout, no resets at indentation boundaries). Reference force: the applied force where the data has it (twin), "
       "else the load cell. Location above 50 mN counts every frame that was not located (gate closed or frame invalid) "
       "as a failure scored at the random guess's error (guess "
    << F("%.1f", sm.guess.y_mm) << " mm, " << F("%.1f", sm.guess.r_deg)
    << " deg). A false contact is a frame reported in contact whose true force is under 20 mN. Scored data: "
    << (training_data ? "the model's held-out test indentations of its training data (knobs were chosen on this data "
                        "in earlier sessions: read it as a validation figure)"
                      : "unseen data (another seed or cast): every indentation")
    << ".\n\n" << StreamMetricsHeader();
  for (const auto& r : rows) h << StreamMetricsRow(r.label, r.scored);
  std::string reasons;
  for (std::size_t r = 1; r < decode::kReasonCount; ++r) {
    if (whole.reasons[r] == 0) continue;
    reasons += std::string(reasons.empty() ? "" : ", ") + std::string(decode::ReasonName(static_cast<decode::Reason>(r))) + " " +
               std::to_string(whole.reasons[r]);
  }
  h << "\nAcross the whole stream (every frame, not only the scored ones):\n\n| data | false contacts (< 20 mN) | longest "
       "baseline freeze | longest press | invalid frames by reason |\n|---|---|---|---|---|\n"
    << "| " << rows.front().label << " | " << F("%.3f %%", 100.0 * whole.false_contact_rate) << " (" << whole.false_contacts
    << " of " << whole.quiet_frames << ") | " << F("%.1f s", whole.longest_frozen_s) << " | " << F("%.1f s", whole.longest_press_s)
    << " | " << (reasons.empty() ? std::string("none") : reasons) << " |\n";
  std::vector<std::pair<std::string, const StreamMetrics*>> zones;
  for (const auto& r : rows) zones.emplace_back(r.label, &r.scored);
  h << "\n### By distance from the patch's edge (pressed frames: reference force above 50 mN)\n\n" << EdgeZoneTable(zones);
  h << "\n### Per force bin (" << rows.front().label << ", scored frames)\n\n" << ForceBinTable(sm);
  h << "\n### Uncertainty\n\n";
  if (u != nullptr) {
    h << "Calibrated on `" << u->source() << "`. Share of in-contact frames whose force error is within 1 / 2 / 3 sd (target 68 +- 5 % / 95 +- 3 %; "
         "a normal error: 99.7 % within 3 sd): "
      << pct(sm.force_within_1sd) << " / " << pct(sm.force_within_2sd) << " / " << pct(sm.force_within_3sd) << " ("
      << sm.force_cov_frames
      << " frames); located frames above 50 mN whose position lies inside the 1 / 2 / 3 sigma ellipse (chi-square(2) 2.30 / 6.18 / "
         "11.83): "
      << pct(sm.position_within_1sd) << " / " << pct(sm.position_within_2sd) << " / " << pct(sm.position_within_3sd) << " ("
      << sm.position_cov_frames << " frames).\n";
  } else {
    h << "The model carries no calibrated uncertainty (run `ruffini calibrate` on validation data).\n";
  }
  h << "\n";
  return h.str();
}

std::vector<CoverageRow> CoverageBreakdown(const dataset::Dataset& d, const StreamPredictions& p, const patch::PatchSpec& spec) {
  struct Count {
    std::size_t fn = 0, pn = 0, y1 = 0, a1 = 0;
    std::array<std::size_t, 3> f{}, pc{};
  };
  const std::vector<std::string> names = {
      "all", "predicted force < 0.1 N", "predicted force 0.1-0.35 N", "predicted force 0.35-1 N", "predicted force 1-2.5 N",
      "predicted force >= 2.5 N", "onset (before 90 % of the peak)", "hold (>= 90 % of the peak)", "release (after it)",
      "outside indentations", "true position: indented area, >= 5 mm inside", "true position: indented area, < 5 mm from its border",
      "true position: outside the indented area", "reported position: indented area, >= 5 mm inside",
      "reported position: indented area, < 5 mm from its border", "reported position: outside the indented area", "reported covariance det^(1/4) < 1 mm", "reported covariance det^(1/4) 1-2 mm",
      "reported covariance det^(1/4) 2-4 mm", "reported covariance det^(1/4) >= 4 mm"};
  std::vector<Count> c(names.size());
  // Each indentation's first and last frame at >= 90 % of its peak reference force.
  std::vector<double> peak;
  std::vector<std::size_t> first, last;
  const auto ref_of = [&d](std::size_t k) { return std::isfinite(d.true_force_n[k]) ? d.true_force_n[k] : d.force_n[k]; };
  std::int32_t max_id = -1;
  for (std::size_t k = 0; k < d.size(); ++k) max_id = std::max(max_id, d.indentation[k]);
  peak.assign(static_cast<std::size_t>(max_id + 1), 0.0);
  first.assign(peak.size(), d.size());
  last.assign(peak.size(), 0);
  for (std::size_t k = 0; k < d.size(); ++k) {
    const double ref = ref_of(k);
    if (d.indentation[k] >= 0 && std::isfinite(ref)) peak[static_cast<std::size_t>(d.indentation[k])] = std::max(peak[static_cast<std::size_t>(d.indentation[k])], ref);
  }
  for (std::size_t k = 0; k < d.size(); ++k) {
    const double ref = ref_of(k);
    if (d.indentation[k] < 0 || !std::isfinite(ref)) continue;
    const auto i = static_cast<std::size_t>(d.indentation[k]);
    if (ref >= 0.9 * peak[i]) {
      first[i] = std::min(first[i], k);
      last[i] = std::max(last[i], k);
    }
  }
  const patch::Geometry geo(spec.surface_radius_mm);
  const patch::Region& area = spec.indented_area;
  const double mm_per_deg = geo.ArcMm(1.0);
  for (std::size_t k = 0; k < d.size(); ++k) {
    const double ref = ref_of(k);
    if (!std::isfinite(ref) || !p.valid[k]) continue;
    std::array<std::size_t, 6> groups{};
    std::size_t ng = 0;
    groups[ng++] = 0;
    const double pred = p.force_n[k];
    groups[ng++] = (pred < 0.1 ? 1 : pred < 0.35 ? 2 : pred < 1.0 ? 3 : pred < 2.5 ? 4 : 5);
    if (d.indentation[k] < 0) {
      groups[ng++] = 9;
    } else {
      const auto i = static_cast<std::size_t>(d.indentation[k]);
      groups[ng++] = k < first[i] ? 6 : k <= last[i] ? 7 : 8;
    }
    const bool has_pos = std::isfinite(d.y_mm[k]) && std::isfinite(d.r_deg[k]);
    if (has_pos) {
      const patch::SurfacePoint t{d.y_mm[k], d.r_deg[k]};
      const double inside = std::min({t.y_mm - area.y_min_mm, area.y_max_mm - t.y_mm, (t.r_deg - area.r_min_deg) * mm_per_deg,
                                      (area.r_max_deg - t.r_deg) * mm_per_deg});
      groups[ng++] = inside >= 5.0 ? 10 : inside >= 0.0 ? 11 : 12;
    }
    const double cyy = p.pos_cov_mm2[3 * k], cyr = p.pos_cov_mm2[3 * k + 1], crr = p.pos_cov_mm2[3 * k + 2];
    const double det = cyy * crr - cyr * cyr;
    const bool pos_ok = p.located[k] && ref > kGateN && has_pos && std::isfinite(det) && det > 0 && cyy > 0;
    if (pos_ok) {
      const double size = std::pow(det, 0.25);
      groups[ng++] = size < 1 ? 16 : size < 2 ? 17 : size < 4 ? 18 : 19;
      const double inside = std::min({p.y_mm[k] - area.y_min_mm, area.y_max_mm - p.y_mm[k], (p.r_deg[k] - area.r_min_deg) * mm_per_deg,
                                      (area.r_max_deg - p.r_deg[k]) * mm_per_deg});
      groups[ng++] = inside >= 5.0 ? 13 : inside >= 0.0 ? 14 : 15;
    }
    const bool force_ok = p.in_contact[k] && std::isfinite(p.force_sd_n[k]);
    const double z = std::abs(pred - ref) / p.force_sd_n[k];
    double d2 = 0, zy = 0, za = 0;
    if (pos_ok) {
      const double dy = p.y_mm[k] - d.y_mm[k], da = geo.ArcMm(p.r_deg[k] - d.r_deg[k]);
      d2 = (crr * dy * dy - 2 * cyr * dy * da + cyy * da * da) / det;
      zy = std::abs(dy) / std::sqrt(cyy);
      za = std::abs(da) / std::sqrt(crr);
    }
    for (std::size_t gi = 0; gi < ng; ++gi) {
      Count& n = c[groups[gi]];
      if (force_ok) {
        ++n.fn;
        for (std::size_t l = 0; l < 3; ++l) n.f[l] += z <= static_cast<double>(l + 1);
      }
      if (pos_ok) {
        ++n.pn;
        n.pc[0] += d2 <= kChi2Sigma1;
        n.pc[1] += d2 <= kChi2Sigma2;
        n.pc[2] += d2 <= kChi2Sigma3;
        n.y1 += zy <= 1.0;
        n.a1 += za <= 1.0;
      }
    }
  }
  std::vector<CoverageRow> out;
  const auto share = [](std::size_t a, std::size_t b) { return b ? static_cast<double>(a) / static_cast<double>(b) : kNaN; };
  for (std::size_t g = 0; g < names.size(); ++g) {
    CoverageRow r;
    r.group = names[g];
    r.force_frames = c[g].fn;
    r.position_frames = c[g].pn;
    for (std::size_t l = 0; l < 3; ++l) {
      r.force[l] = share(c[g].f[l], c[g].fn);
      r.position[l] = share(c[g].pc[l], c[g].pn);
    }
    r.y_within_1sd = share(c[g].y1, c[g].pn);
    r.arc_within_1sd = share(c[g].a1, c[g].pn);
    out.push_back(r);
  }
  return out;
}

std::string CoverageTable(const std::vector<CoverageRow>& rows) {
  std::ostringstream h;
  h << "| frames | force frames | force within 1 / 2 / 3 sd | located frames | position within 1 / 2 / 3 sigma | "
       "Y / arc alone within 1 sd |\n|---|---|---|---|---|---|\n";
  const auto pct = [](double v) { return std::isfinite(v) ? F("%.1f", 100.0 * v) : std::string("-"); };
  for (const auto& r : rows) {
    h << "| " << r.group << " | " << r.force_frames << " | " << pct(r.force[0]) << " / " << pct(r.force[1]) << " / " << pct(r.force[2])
      << " % | " << r.position_frames << " | " << pct(r.position[0]) << " / " << pct(r.position[1]) << " / " << pct(r.position[2])
      << " % | " << pct(r.y_within_1sd) << " / " << pct(r.arc_within_1sd) << " % |\n";
  }
  return h.str();
}

}  // namespace ruffini::eval
