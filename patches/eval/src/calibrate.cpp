#include "ruffini/eval/calibrate.h"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include "ruffini/decode/network_decoder.h"
#include "ruffini/decode/pipeline.h"
#include "ruffini/error.h"
#include "ruffini/eval/evaluation.h"
#include "ruffini/eval/prepared.h"
#include "ruffini/eval/stream.h"
#include "ruffini/patch/geometry.h"
#include "ruffini/stats.h"

namespace ruffini::eval {
namespace {

constexpr double kChi2Sigma1 = 2.2957, kChi2Sigma2 = 6.1801;
constexpr double kOneSigma = 0.682689, kTwoSigma = 0.954500;
constexpr double kMinFloorMm2 = 0.25;  // (0.5 mm)^2: a fine cell's centre is never exact

double Reference(const dataset::Dataset& d, std::size_t k) {
  return std::isfinite(d.true_force_n[k]) ? d.true_force_n[k] : d.force_n[k];
}

decode::PipelineConfig OpenConfig(const v1::DecoderModel& m, const dataset::Dataset& d) {
  decode::PipelineConfig c;
  c.baseline = decode::BaselineFor(m, d.info.sample_rate_hz);
  c.z_limit = std::numeric_limits<double>::infinity();  // fitting looks at every frame the nets can take
  return c;
}

}  // namespace

dataset::Dataset FirstIndentations(const dataset::Dataset& d, int indentations) {
  if (indentations <= 0) return d;
  std::size_t end = d.size();
  int seen = 0;
  std::int32_t current = -1;
  for (std::size_t k = 0; k < d.size(); ++k) {
    const std::int32_t id = d.indentation[k];
    if (id >= 0 && id != current) {
      if (seen == indentations) {
        end = k;
        break;
      }
      ++seen;
      current = id;
    }
  }
  if (seen < indentations) return d;
  dataset::Dataset out;
  out.info = d.info;
  const auto cut = [end](auto v) {
    v.resize(end);
    return v;
  };
  out.wavelength_nm = cut(d.wavelength_nm);
  out.t_s = cut(d.t_s);
  out.serial = cut(d.serial);
  out.flags = cut(d.flags);
  out.force_n = cut(d.force_n);
  out.true_force_n = cut(d.true_force_n);
  out.y_mm = cut(d.y_mm);
  out.r_deg = cut(d.r_deg);
  out.indentation = cut(d.indentation);
  return out;
}

v1::InputRange FitInputRange(const v1::DecoderModel& m, const patch::PatchSpec& spec, const dataset::Dataset& d,
                             double margin_fraction, double margin_pm) {
  (void)spec;
  const Prepared p = PrepareFrames(d, decode::BaselineFor(m, d.info.sample_rate_hz));
  std::array<float, kGratings> lo, hi;
  lo.fill(std::numeric_limits<float>::infinity());
  hi.fill(-std::numeric_limits<float>::infinity());
  for (const auto& s : p.shift_pm) {
    for (std::size_t i = 0; i < 16; ++i) {
      if (!std::isfinite(s[i])) continue;
      lo[i] = std::min(lo[i], s[i]);
      hi[i] = std::max(hi[i], s[i]);
    }
  }
  if (m.has_input_range()) {
    for (std::size_t i = 0; i < 16; ++i) {
      lo[i] = std::min(lo[i], m.input_range().min_shift_pm(static_cast<int>(i)));
      hi[i] = std::max(hi[i], m.input_range().max_shift_pm(static_cast<int>(i)));
    }
  }
  double span = 0;
  for (std::size_t i = 0; i < 16; ++i) {
    if (!std::isfinite(lo[i])) throw InputError("input range: grating " + std::to_string(i + 1) + " has no valid frame in the data");
    span = std::max(span, static_cast<double>(hi[i] - lo[i]));
  }
  v1::InputRange r;
  for (std::size_t i = 0; i < 16; ++i) {
    r.add_min_shift_pm(lo[i]);
    r.add_max_shift_pm(hi[i]);
  }
  r.set_margin_pm(static_cast<float>(margin_fraction * span + margin_pm));
  r.set_source(d.info.source);
  return r;
}

UncertaintyRows CollectUncertaintyRows(const v1::DecoderModel& model, const patch::PatchSpec& spec, const dataset::Dataset& d) {
  // Decode with unit scales so the pipeline hands out the NIP's raw covariance.
  v1::DecoderModel m = model;
  m.clear_input_range();
  auto* raw = m.mutable_uncertainty();
  raw->Clear();
  raw->add_force_knots_n(0.0f);
  raw->add_force_sd_n(1.0f);
  raw->add_position_scale(1.0f);
  const decode::Pipeline<float> pipe(m, spec, OpenConfig(m, d));
  const StreamPredictions p = DecodeStream(pipe, d);
  const patch::Geometry geo(spec.surface_radius_mm);
  UncertaintyRows rows;
  for (std::size_t k = 0; k < d.size(); ++k) {
    const double ref = Reference(d, k);
    if (!p.valid[k] || !p.in_contact[k] || !std::isfinite(ref)) continue;
    rows.force.push_back({p.force_n[k], std::abs(p.force_n[k] - ref)});
    if (p.located[k] && ref > 0.05 && std::isfinite(d.y_mm[k])) {
      rows.position.push_back({p.force_n[k], p.y_mm[k] - d.y_mm[k], geo.ArcMm(p.r_deg[k] - d.r_deg[k]), p.pos_cov_mm2[3 * k],
                               p.pos_cov_mm2[3 * k + 1], p.pos_cov_mm2[3 * k + 2]});
    }
  }
  return rows;
}

namespace {

// Both coverage levels are fitted, each against its band (issue 17: 68 +- 5 % within 1 sigma, 95 +- 3 % within
// 2): a scale s is scored by the larger of |coverage_1(s) - 68.27 %| / 5 % and |coverage_2(s) - 95.45 %| / 3 %.
// Both coverages grow with s, so between the scale that meets the 1-sigma level exactly and the one that meets
// the 2-sigma level exactly the two deviations have opposite signs, and the best scale is where the band-scaled
// deviations cancel: a bisection. With normal errors both scales coincide (the old 1-sigma fit); with heavy
// tails the fit widens until the 2-sigma share is as far inside its band as the 1-sigma share is inside its own,
// and, when the tails are too heavy for both bands, at least until the 2-sigma share reaches its band (92.45 %).
constexpr double kBand1 = 0.05, kBand2 = 0.03;

// Scale in [lo, hi] (log bisection) at which f(scale) crosses 0; f is non-decreasing.
template <typename F>
double Crossing(const F& f, double lo, double hi) {
  for (int it = 0; it < 50; ++it) {
    const double mid = std::sqrt(lo * hi);
    (f(mid) < 0 ? lo : hi) = mid;
  }
  return std::sqrt(lo * hi);
}

// cover(s, level) = share within level sigma at scale s (non-decreasing in s).
template <typename Cover>
double BalancedScale(const Cover& cover, double lo, double hi) {
  const double s1 = Crossing([&](double s) { return cover(s, 1) - kOneSigma; }, lo, hi);
  const double s2 = Crossing([&](double s) { return cover(s, 2) - kTwoSigma; }, lo, hi);
  if (!(std::abs(std::log(s1 / s2)) > 1e-9)) return s1;
  const double balanced = Crossing(
      [&](double s) { return (cover(s, 1) - kOneSigma) / kBand1 + (cover(s, 2) - kTwoSigma) / kBand2; }, std::min(s1, s2),
      std::max(s1, s2));
  // Never below the 2-sigma band: too narrow is the unsafe side (a confident wrong place), too wide only costs
  // 1-sigma share above its band.
  const double floor2 = Crossing([&](double s) { return cover(s, 2) - (kTwoSigma - kBand2); }, lo, hi);
  return std::max(balanced, floor2);
}

// How far the coverage lies outside the middle of the bands (1 = at a band's edge).
double BandCost(double c1, double c2) { return std::max(std::abs(c1 - kOneSigma) / kBand1, std::abs(c2 - kTwoSigma) / kBand2); }

double Mahalanobis2(const UncertaintyRows::Position& r, double k, double floor) {
  const double yy = k * r.cyy + floor, ya = k * r.cya, aa = k * r.caa + floor;
  const double det = yy * aa - ya * ya;
  return (aa * r.dy * r.dy - 2 * ya * r.dy * r.da + yy * r.da * r.da) / det;
}

}  // namespace

v1::Uncertainty FitUncertaintyRows(const UncertaintyRows& rows) {
  const auto& fr = rows.force;
  const auto& pr = rows.position;
  if (fr.size() < 200 || pr.size() < 200) {
    throw InputError("uncertainty: too few in-contact frames to fit (" + std::to_string(fr.size()) + " force, " +
                     std::to_string(pr.size()) + " located); calibrate on more indentations");
  }
  // Bins of predicted force with at least kMinRows frames each (force and position alike).
  const std::vector<double> edges = {0.0, 0.1, 0.2, 0.35, 0.5, 0.75, 1.0, 1.5, 2.0, 2.5, 1e9};
  constexpr std::size_t kMinRows = 100;
  // Position rows per bin: at most kMaxRows, an even stride through the bin (the floor search decodes nothing
  // but scores every bin once per floor and bisection step).
  constexpr std::size_t kMaxRows = 20000;
  struct Bin {
    double knot = 0, sd = 0;
    std::vector<const UncertaintyRows::Position*> rows;
    std::size_t all_rows = 0;
  };
  std::vector<Bin> bins;
  double lo = edges.front();
  for (std::size_t b = 1; b < edges.size(); ++b) {
    const double hi = edges[b];
    std::vector<double> errs, preds;
    std::vector<const UncertaintyRows::Position*> prow;
    for (const auto& r : fr) {
      if (r.pred >= lo && r.pred < hi) {
        errs.push_back(r.err);
        preds.push_back(r.pred);
      }
    }
    for (const auto& r : pr) {
      if (r.pred >= lo && r.pred < hi) prow.push_back(&r);
    }
    const bool last = b + 1 == edges.size();
    if ((errs.size() < kMinRows || prow.size() < kMinRows) && !last) continue;  // widen the bin
    if (errs.size() < kMinRows || prow.size() < kMinRows) {
      if (!bins.empty()) break;  // the tail is too thin: the last knot holds beyond it
      throw InputError("uncertainty: not enough frames per force bin");
    }
    Bin bin;
    bin.knot = stats::Median(preds);
    std::sort(errs.begin(), errs.end());
    const auto share_within = [&errs](double limit) {
      return static_cast<double>(std::upper_bound(errs.begin(), errs.end(), limit) - errs.begin()) / static_cast<double>(errs.size());
    };
    const double q1 = std::max(1e-4, stats::Quantile(errs, kOneSigma));
    bin.sd = std::max(1e-3, BalancedScale([&](double s, int level) { return share_within(level * s); }, q1 * 1e-3, q1 * 1e3));
    if (!bins.empty() && !(bin.knot > bins.back().knot)) continue;  // widen the bin
    bin.all_rows = prow.size();
    const std::size_t stride = (prow.size() + kMaxRows - 1) / kMaxRows;
    for (std::size_t i = 0; i < prow.size(); i += stride) bin.rows.push_back(prow[i]);
    bins.push_back(std::move(bin));
    lo = hi;
  }
  // Position: per bin a scale k of the NIP's covariance, and one floor on the diagonal for all bins. For each
  // floor (0.25 mm^2 - a fine cell's centre is never exact - up to 16 mm^2), each bin's k is the balanced scale;
  // the floor kept is the one whose bins end, on average over the frames, nearest the middle of both bands (a
  // floor widens most the frames whose NIP covariance is smallest: where the NIP is sure of itself but wrong).
  const auto fit_scales = [&bins](double floor, std::vector<double>& k) {
    double cost = 0, weight = 0;
    k.assign(bins.size(), 1.0);
    for (std::size_t b = 0; b < bins.size(); ++b) {
      const auto& bin_rows = bins[b].rows;
      const auto cover = [&](double s, int level) {
        const double limit = level == 1 ? kChi2Sigma1 : kChi2Sigma2;
        std::size_t inside = 0;
        for (const auto* r : bin_rows) inside += Mahalanobis2(*r, s, floor) <= limit;
        return static_cast<double>(inside) / static_cast<double>(bin_rows.size());
      };
      k[b] = BalancedScale(cover, 1e-4, 1e4);
      cost += BandCost(cover(k[b], 1), cover(k[b], 2)) * static_cast<double>(bins[b].all_rows);
      weight += static_cast<double>(bins[b].all_rows);
    }
    return cost / weight;
  };
  double best_floor = kMinFloorMm2, best_cost = std::numeric_limits<double>::infinity();
  std::vector<double> best_k, k;
  for (int i = 0; i <= 12; ++i) {
    const double floor = kMinFloorMm2 * std::pow(2.0, 0.5 * i);
    const double cost = fit_scales(floor, k);
    if (cost < best_cost - 0.02) {  // a larger floor only when it brings the bins 2 % of a band nearer
      best_cost = cost;
      best_floor = floor;
      best_k = k;
    }
  }
  v1::Uncertainty u;
  for (std::size_t b = 0; b < bins.size(); ++b) {
    u.add_force_knots_n(static_cast<float>(bins[b].knot));
    u.add_force_sd_n(static_cast<float>(bins[b].sd));
    u.add_position_scale(static_cast<float>(best_k[b]));
  }
  u.set_position_floor_mm2(static_cast<float>(best_floor));
  return u;
}

v1::Uncertainty FitUncertainty(const v1::DecoderModel& model, const patch::PatchSpec& spec, const dataset::Dataset& d) {
  v1::Uncertainty u = FitUncertaintyRows(CollectUncertaintyRows(model, spec, d));
  u.set_source(d.info.source);
  // Coverage on the fitting data with the fitted functions (piecewise linear between knots, as the runtime).
  v1::DecoderModel check = model;
  check.clear_input_range();
  *check.mutable_uncertainty() = u;
  const decode::Pipeline<float> pc(check, spec, OpenConfig(check, d));
  const StreamPredictions q = DecodeStream(pc, d);
  const StreamMetrics s = ScoreStream(d, q, spec, {}, {});
  u.set_force_within_1sd(static_cast<float>(s.force_within_1sd));
  u.set_force_within_2sd(static_cast<float>(s.force_within_2sd));
  u.set_force_within_3sd(static_cast<float>(s.force_within_3sd));
  u.set_position_within_1sd(static_cast<float>(s.position_within_1sd));
  u.set_position_within_2sd(static_cast<float>(s.position_within_2sd));
  u.set_position_within_3sd(static_cast<float>(s.position_within_3sd));
  return u;
}

std::vector<float> FitThermalRatio(const v1::DecoderModel& model, const patch::PatchSpec& spec, const dataset::Dataset& d) {
  (void)spec;
  if (!model.preprocessing().common_mode_removed()) throw InputError("thermal ratio: the model does not remove the common mode");
  // No decoder involved (it would need the ratios to decode well): each grating's peak against the first
  // second's mean, over the median grating's, once a second where the median has moved by 5 pm or more.
  // A touch moves a few gratings now and then; the median of the per-second ratios ignores it.
  if (d.size() < 2) throw InputError("thermal ratio: empty recording");
  const auto every = static_cast<std::size_t>(std::max(1.0, d.info.sample_rate_hz));
  decode::Wavelengths ref{};
  std::array<int, 16> n{};
  for (std::size_t k = 0; k < std::min(d.size(), every); ++k) {
    for (std::size_t i = 0; i < 16; ++i) {
      if (std::isfinite(d.wavelength_nm[k][i])) {
        ref[i] += d.wavelength_nm[k][i];
        ++n[i];
      }
    }
  }
  for (std::size_t i = 0; i < 16; ++i) ref[i] = n[i] ? ref[i] / n[i] : std::numeric_limits<double>::quiet_NaN();
  std::array<std::vector<double>, 16> ratios;
  for (std::size_t k = every; k < d.size(); k += every) {
    decode::ShiftsPm s;
    for (std::size_t i = 0; i < 16; ++i) s[i] = static_cast<float>((d.wavelength_nm[k][i] - ref[i]) * 1e3);
    const double med = decode::MedianOfPresent(s, 9);
    if (!(std::abs(med) >= 5.0)) continue;
    for (std::size_t i = 0; i < 16; ++i) {
      if (std::isfinite(s[i])) ratios[i].push_back(s[i] / med);
    }
  }
  if (ratios[0].size() < 60) {
    throw InputError("thermal ratio: the common drift moved 5 pm or more in only " + std::to_string(ratios[0].size()) +
                     " seconds of the data (need 60); record while the temperature moves by a degree or so");
  }
  decode::ShiftsPm r;
  for (std::size_t i = 0; i < 16; ++i) r[i] = ratios[i].empty() ? 1.0f : static_cast<float>(stats::Median(ratios[i]));
  const float med = decode::MedianOfPresent(r, 1);
  std::vector<float> out(16);
  for (std::size_t i = 0; i < 16; ++i) out[i] = std::clamp(r[i] / med, 0.6f, 1.6f);
  return out;
}

namespace {

// Non-negative least squares over 3 terms (normal equations): drop the most negative term until all are >= 0.
Eigen::Vector3d NonNegative3(const Eigen::Matrix3d& ata, const Eigen::Vector3d& atb) {
  std::array<bool, 3> active = {true, true, true};
  Eigen::Vector3d g = Eigen::Vector3d::Zero();
  for (int round = 0; round < 3; ++round) {
    Eigen::Matrix3d A = ata;
    Eigen::Vector3d b = atb;
    for (int j = 0; j < 3; ++j) {
      if (active[static_cast<std::size_t>(j)]) continue;
      A.row(j).setZero();
      A.col(j).setZero();
      A(j, j) = 1.0;
      b[j] = 0.0;
    }
    g = A.ldlt().solve(b);
    int worst = -1;
    for (int j = 0; j < 3; ++j) {
      if (active[static_cast<std::size_t>(j)] && g[j] < 0 && (worst < 0 || g[j] < g[worst])) worst = j;
    }
    if (worst < 0) break;
    active[static_cast<std::size_t>(worst)] = false;
  }
  for (int j = 0; j < 3; ++j) g[j] = active[static_cast<std::size_t>(j)] ? std::max(0.0, g[j]) : 0.0;
  return g;
}

}  // namespace

v1::CreepCompensation FitCreep(const v1::DecoderModel& model, const patch::PatchSpec& spec, const dataset::Dataset& d) {
  v1::DecoderModel m = model;
  m.clear_creep();
  m.clear_input_range();
  const decode::Pipeline<float> pipe(m, spec, OpenConfig(m, d));
  const StreamPredictions p = DecodeStream(pipe, d);
  const std::array<double, 3> tau = {1.0, 10.0, 100.0};
  const double dt = 1.0 / d.info.sample_rate_hz;
  std::array<double, 3> a{}, x{};
  for (std::size_t k = 0; k < 3; ++k) a[k] = 1.0 - std::exp(-dt / tau[k]);
  // The rows: each valid frame's decoded force, the applied force F and F low-passed with each tau (the
  // twin's discretisation), and the press it belongs to (a press and the rest after it, up to the next press;
  // the rest before the first press carries no creep and is left out).
  struct Row {
    double y, f;
    Eigen::Vector3d x;
    std::size_t press;
  };
  std::vector<Row> rows;
  rows.reserve(d.size());
  std::size_t presses = 0, pressed = 0;
  std::int32_t current = -1;
  for (std::size_t k = 0; k < d.size(); ++k) {
    const double ref = Reference(d, k);
    const double f = std::isfinite(ref) ? std::max(0.0, ref) : 0.0;
    for (std::size_t j = 0; j < 3; ++j) x[j] += a[j] * (f - x[j]);
    if (d.indentation[k] >= 0 && d.indentation[k] != current) {
      current = d.indentation[k];
      ++presses;
    }
    if (presses == 0 || !p.valid[k] || !std::isfinite(ref)) continue;
    rows.push_back({p.force_n[k], f, Eigen::Vector3d(x[0], x[1], x[2]), presses - 1});
    pressed += ref > 0.05;
  }
  if (pressed < 1000) throw InputError("creep fit: the data hold too few pressed frames (" + std::to_string(pressed) + "); use a field recording");
  // decoded = s_p (F + sum g x): the networks read the strain force, each press at its own static scale s_p
  // (another cast's gratings, gains fitted elsewhere, where on the patch it presses; not the creep's to
  // correct). A fit without s_p reads a decoder that is 10 % low as negative creep: the x terms follow F
  // within a press (x at tau 1 s correlates with F at 0.99), and the non-negative fit returns 0 (issue 17's
  // four field casts). The creep is what changes within a press at a fixed scale: the rise over a hold, the
  // residual after the release. Alternating least squares: the scales for the g, the g for the scales.
  std::vector<double> scale(presses, 1.0);
  Eigen::Vector3d g = Eigen::Vector3d::Zero();
  for (int it = 0; it < 100; ++it) {
    std::vector<double> num(presses, 0.0), den(presses, 0.0);
    for (const Row& r : rows) {
      const double fe = r.f + g.dot(r.x);
      num[r.press] += r.y * fe;
      den[r.press] += fe * fe;
    }
    // A press the decoder does not read (s <= 0) says nothing about the creep: left out.
    for (std::size_t q = 0; q < presses; ++q) scale[q] = den[q] > 0 ? std::max(0.0, num[q] / den[q]) : 0.0;
    Eigen::Matrix3d ata = Eigen::Matrix3d::Zero();
    Eigen::Vector3d atb = Eigen::Vector3d::Zero();
    for (const Row& r : rows) {
      const double s = scale[r.press];
      if (!(s > 0)) continue;
      const Eigen::Vector3d col = s * r.x;
      ata += col * col.transpose();
      atb += col * (r.y - s * r.f);
    }
    if (!(ata.trace() > 0)) throw InputError("creep fit: the decoder reads none of the presses");
    const Eigen::Vector3d next = NonNegative3(ata, atb);
    const double moved = (next - g).cwiseAbs().maxCoeff();
    g = next;
    if (moved < 1e-6) break;
  }
  v1::CreepCompensation c;
  for (std::size_t j = 0; j < 3; ++j) {
    c.add_g(static_cast<float>(g[static_cast<Eigen::Index>(j)]));
    c.add_tau_s(static_cast<float>(tau[j]));
  }
  c.set_source(d.info.source);
  return c;
}

void ApplyGains(v1::DecoderModel& m, const std::vector<float>& g) {
  if (g.size() != kGratings) throw InputError("gains: expected 16, got " + std::to_string(g.size()));
  auto fold = [&](v1::Normalization* n) {
    for (int i = 0; i < 16; ++i) {
      const float gi = g[static_cast<std::size_t>(i)];
      n->set_mean(i, n->mean(i) / gi);
      n->set_std(i, n->std(i) / gi);
    }
  };
  fold(m.mutable_force()->mutable_input());
  for (auto& l : *m.mutable_location()) {
    // UNIT nets see the pattern over its norm: a gain changes the pattern too, so it folds the same way
    // up to the norm's change, which the floor absorbs; RAW nets fold exactly.
    fold(l.mutable_input());
  }
}

std::vector<std::int32_t> IndentationsAfter(const dataset::Dataset& d, int indentations, std::size_t max_ids) {
  std::vector<std::int32_t> out;
  if (indentations <= 0) return out;  // calibrated on everything
  int seen = 0;
  std::int32_t current = -1;
  for (std::size_t k = 0; k < d.size() && out.size() < max_ids; ++k) {
    const std::int32_t id = d.indentation[k];
    if (id < 0 || id == current) continue;
    current = id;
    if (seen < indentations) {
      ++seen;
    } else if (std::find(out.begin(), out.end(), id) == out.end()) {
      out.push_back(id);
    }
  }
  return out;
}

v1::CastScore ScoreIndentations(const v1::DecoderModel& model, const patch::PatchSpec& spec, const dataset::Dataset& d,
                                const std::vector<std::int32_t>& ids) {
  if (ids.empty()) throw InputError("scoring a cast: no indentations to score");
  const Prepared p = PrepareFrames(d, decode::BaselineFor(model, d.info.sample_rate_hz));
  NetworkFrameDecoder<float> dec(model);
  const Predictions pred = RunDecoder(dec, p, ids, {}, /*test_only=*/true);
  const Evaluation ev = Evaluate(p, pred, spec);
  v1::CastScore s;
  s.set_indentations(static_cast<std::uint32_t>(ids.size()));
  s.set_force_error_mn(ev.force_error_mn.median);
  s.set_location_error_mm(ev.location_error_mm.median);
  return s;
}

GainFit FitGains(const v1::DecoderModel& model, const patch::PatchSpec& spec, const dataset::Dataset& d, int sweeps,
                 const GainProgress& progress) {
  const Prepared p = PrepareFrames(d, decode::BaselineFor(model, d.info.sample_rate_hz));
  const int w = static_cast<int>(model.force().window());
  // A subsample of indentation frames, each with its window (clamped at the indentation's first frame).
  std::vector<std::size_t> frames;
  for (std::size_t k = 0; k < p.size(); ++k) {
    if (p.indentation[k] >= 0 && std::isfinite(p.force_n[k])) frames.push_back(k);
  }
  if (frames.size() < 500) throw InputError("gain fit: too few indentation frames (" + std::to_string(frames.size()) + ")");
  std::mt19937_64 rng(7);
  std::shuffle(frames.begin(), frames.end(), rng);
  frames.resize(std::min<std::size_t>(frames.size(), 6000));
  std::vector<std::size_t> start(p.size(), 0);
  for (std::size_t r = 0; r < p.ranges.size(); ++r) {
    for (std::size_t k = p.ranges[r].first; k < p.ranges[r].second; ++k) start[k] = p.ranges[r].first;
  }
  // What the force net should read: the applied force, or with a creep compensation in the model the strain
  // force F + sum g x that the decoder's compensation turns back into F (the cover creeps under the cast's
  // presses too: fitted against F, the gains would take the creep's mean rise into the cast's scale).
  std::vector<float> target = p.force_n;
  if (model.has_creep() && model.creep().g_size() > 0) {
    const int terms = std::min(model.creep().g_size(), model.creep().tau_s_size());
    std::vector<double> x(static_cast<std::size_t>(terms), 0.0), a(x.size());
    for (int j = 0; j < terms; ++j) a[static_cast<std::size_t>(j)] = 1.0 - std::exp(-1.0 / (d.info.sample_rate_hz * model.creep().tau_s(j)));
    for (std::size_t k = 0; k < d.size(); ++k) {
      const double ref = Reference(d, k);
      const double f = std::isfinite(ref) ? std::max(0.0, ref) : 0.0;
      double strain = 0;
      for (std::size_t j = 0; j < x.size(); ++j) {
        x[j] += a[j] * (f - x[j]);  // the twin's discretisation, as FitCreep
        strain += model.creep().g(static_cast<int>(j)) * x[j];
      }
      target[k] = static_cast<float>(p.force_n[k] + strain);
    }
  }
  const patch::Geometry geo(spec.surface_radius_mm);
  GainFit fit;
  fit.gain.assign(16, 1.0f);
  std::vector<float> window(static_cast<std::size_t>(w) * 16);
  std::vector<float> probs;
  auto objective = [&](const std::vector<float>& g) {
    v1::DecoderModel m = model;
    ApplyGains(m, g);
    const decode::NetworkDecoder<float> dec(m);
    decode::NetworkDecoder<float>::Data data(dec);
    std::vector<double> fe, le;
    for (std::size_t k : frames) {
      for (int t = 0; t < w; ++t) {
        const std::size_t src = std::max<std::ptrdiff_t>(static_cast<std::ptrdiff_t>(start[k]), static_cast<std::ptrdiff_t>(k) - (w - 1 - t));
        for (std::size_t i = 0; i < 16; ++i) {
          const float v = p.shift_pm[src][i];
          window[static_cast<std::size_t>(t) * 16 + i] = std::isfinite(v) ? v : m.force().input().mean(static_cast<int>(i));
        }
      }
      const float f = dec.ForceOnWindow(window.data(), data);
      fe.push_back(std::abs(f - target[k]) * 1e3);
      if (p.force_n[k] > 0.05f) {
        dec.Probabilities(p.shift_pm[k], data, probs);
        const decode::Nip::Estimate e = dec.nip().Fuse(probs, spec.surface_radius_mm);
        if (e.ok) le.push_back(geo.SurfaceDistanceMm({e.y_mm, e.r_deg}, {p.y_mm[k], p.r_deg[k]}));
      }
    }
    ++fit.evaluations;
    return stats::Median(fe) + 10.0 * stats::Median(le);
  };
  double best = objective(fit.gain);
  fit.before = best;
  for (int s = 0; s < sweeps; ++s) {
    const float step0 = s == 0 ? 0.15f : 0.05f;
    for (std::size_t i = 0; i < 16; ++i) {
      for (float step = step0; step > 0.01f; step *= 0.5f) {
        bool moved = false;
        for (float dir : {1.0f, -1.0f}) {
          std::vector<float> g = fit.gain;
          g[i] = std::clamp(g[i] + dir * step, 0.6f, 1.6f);
          const double v = objective(g);
          if (v < best) {
            best = v;
            fit.gain = g;
            moved = true;
            break;
          }
        }
        if (moved) step *= 2.0f;  // try the same step again
      }
    }
    if (progress) progress(s + 1, sweeps, best);
  }
  fit.after = best;
  return fit;
}

}  // namespace ruffini::eval
