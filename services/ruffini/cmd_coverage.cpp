// Coverage subcommands (issue 16, docs/coverage.md):
//   sensitivity  measure a patch's sensitivity map on held-out twin presses and store it in a model file
//   check-scene  what each region's patches guarantee, and whether the scene's thresholds are met
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <mutex>
#include <numbers>
#include <random>
#include <sstream>
#include <thread>

#include "commands.h"
#include "progress.h"
#include "ruffini/decode/model_io.h"
#include "ruffini/decode/sensitivity.h"
#include "ruffini/error.h"
#include "ruffini/ingest/hyperion.h"
#include "ruffini/link/monitor.h"
#include "ruffini/plot/svg.h"
#include "ruffini/sim/scenario.h"
#include "ruffini/twin/scene.h"
#include "ruffini/twin/twin.h"
#include "scene_setup.h"

namespace ruffini::cli {
namespace {

struct SensitivityArgs {
  std::string scene, patch, model, out, report;
  double level_n = 1.5, reliability = 0.95, step_mm = 5.0, edge_mm = 2.0, jitter_mm = 1.0, rate_hz = 1000.0;
  unsigned presses = 20, threads = 1;
  std::uint64_t seed = 1000;
  std::vector<double> forces = {0.75, 1.0, 1.25, 1.5, 1.65, 1.8, 2.0, 2.25, 2.5, 3.0, 4.0, 5.0, 7.5, 10, 20, 50, 100, 200};
};

// The grid along one axis of `length` mm: `edge` from each end, and every multiple of `step` between them
// (kept at least 1 mm from the edge points).
std::vector<double> Axis(double length, double step, double edge) {
  std::vector<double> v{edge};
  for (double x = step; x < length - edge - 1.0 + 1e-9; x += step) {
    if (x > edge + 1.0 - 1e-9) v.push_back(x);
  }
  v.push_back(length - edge);
  return v;
}

// One grid point's presses: a stream of its own (baseline capture, then presses with rest between them), each
// press at the point jittered within +-jitter_mm in Y and arc.
class PointProbe {
 public:
  PointProbe(const twin::SkinTwin& tw, const v1::DecoderModel& model, const patch::PatchSpec& spec, const twin::Probe& probe,
             const SensitivityArgs& a, double y_mm, double r_deg, std::uint64_t seed)
      : twin_(tw), probe_(probe), a_(a), y_(y_mm), r_(r_deg), sim_(tw, twin::DeriveSeed(seed, 1)),
        rng_(twin::DeriveSeed(seed, 6)), mm_per_deg_(spec.surface_radius_mm * std::numbers::pi / 180.0) {
    decode::PipelineConfig config;
    config.baseline = decode::BaselineFor(model, a.rate_hz);
    pipeline_ = link::MakePipeline(model, spec, config, link::DecoderChoice{});
    // The decoder service's default picking: each peak to the nearest grating's band.
    Wavelengths centre{};
    for (std::size_t i = 0; i < kGratings; ++i) centre[i] = spec.gratings[i].wavelength_nm;
    ingest::DecoderConfig codec;
    codec.pick = ingest::NearestGratingBands(0, centre);
    stream_ = std::make_unique<ingest::StreamDecoder>(codec);
    // The untouched start: the baseline capture (1 s) and a little more.
    for (int k = 0; k < static_cast<int>(1.2 * a.rate_hz); ++k) Frame(nullptr, 0.0);
  }

  struct Result {
    unsigned reported = 0, pressed = 0;
    std::vector<float> errors_mm;  // per reported-and-located press: its median location error
  };

  // Up to a_.presses presses of `force_n`; stops early once reliability can no longer be reached.
  Result Evaluate(double force_n) {
    Result r;
    const unsigned need = static_cast<unsigned>(std::ceil(a_.reliability * a_.presses - 1e-9));
    std::uniform_real_distribution<double> jitter(-a_.jitter_mm, a_.jitter_mm);
    const double extent_y = twin_.spec().extent_y_mm, extent_r = twin_.spec().extent_r_deg;
    for (unsigned k = 0; k < a_.presses; ++k) {
      if (r.pressed - r.reported > a_.presses - need) break;
      const double y = std::clamp(y_ + jitter(rng_), 0.0, extent_y);
      const double rd = std::clamp(r_ + jitter(rng_) / mm_per_deg_, 0.0, extent_r);
      const auto [reported, error] = Press(y, rd, force_n);
      ++r.pressed;
      r.reported += reported ? 1u : 0u;
      if (reported && std::isfinite(error)) r.errors_mm.push_back(error);
    }
    return r;
  }

 private:
  // rest 0.3 s, ramp 0.05 s, hold 0.15 s, release 0.05 s, and 0.05 s more watched for a late report.
  std::pair<bool, float> Press(double y_mm, double r_deg, double force_n) {
    const double rest = 0.3, ramp = 0.05, hold = 0.15, release = 0.05, tail = 0.05;
    for (int k = 0; k < static_cast<int>(rest * a_.rate_hz); ++k) Frame(nullptr, 0.0);
    bool reported = false;
    std::vector<float> errors;
    const int n = static_cast<int>((ramp + hold + release + tail) * a_.rate_hz);
    for (int k = 0; k < n; ++k) {
      const double t = k / a_.rate_hz;
      double w = 0.0;
      if (t < ramp) w = t / ramp;
      else if (t <= ramp + hold) w = 1.0;
      else if (t < ramp + hold + release) w = 1.0 - (t - ramp - hold) / release;
      const twin::Contact c{{y_mm, r_deg}, w * force_n, probe_};
      const decode::PipelineOutput o = Frame(w > 0 ? &c : nullptr, w);
      // What the aggregator's threshold rule stops on: a contact frame above the level (an over-range
      // contact carries its lower bound as force_n).
      if (o.in_contact && (o.valid || o.over_range) && o.force_n > a_.level_n) reported = true;
      if (o.valid && o.located && t >= ramp && t <= ramp + hold) {
        const double dy = o.y_mm - y_mm, da = (o.r_deg - r_deg) * mm_per_deg_;
        errors.push_back(static_cast<float>(std::hypot(dy, da)));
      }
    }
    float median = std::numeric_limits<float>::quiet_NaN();
    if (!errors.empty()) {
      std::nth_element(errors.begin(), errors.begin() + static_cast<std::ptrdiff_t>(errors.size() / 2), errors.end());
      median = errors[errors.size() / 2];
    }
    return {reported, median};
  }

  // One frame as the decoder service gets it: what ruffini-sim puts on the wire (the channel's peaks in
  // ascending order, a lost one left out: a Hyperion stream carries no saturation flag, so the twin's own flags
  // never reach the decoder), through the ingest codec, into the pipeline. A frame the codec rejects reports
  // nothing.
  decode::PipelineOutput Frame(const twin::Contact* c, double /*w*/) {
    twin::Shifts s{};
    std::uint32_t flags = 0;
    if (c != nullptr) twin_.StrainShiftsPm(std::span<const twin::Contact>(c, 1), s, flags);
    Wavelengths wl{};
    sim_.Read(t_s_, s, wl, flags);
    std::array<double, kGratings> seen{};
    std::size_t n = 0;
    for (double nm : wl) {
      if (!std::isnan(nm)) seen[n++] = nm;
    }
    std::sort(seen.begin(), seen.begin() + static_cast<std::ptrdiff_t>(n));
    ingest::PeakSample ps;
    ps.serial_number = serial_++;
    ps.timestamp_ns = 1'700'000'000'000'000'000 + static_cast<std::int64_t>(t_s_ * 1e9);
    ps.channel_peaks_nm[0] = std::span<const double>(seen.data(), n);
    t_s_ += 1.0 / a_.rate_hz;
    const std::vector<std::uint8_t> bytes = ingest::EncodePeaks(ps);
    std::span<const std::uint8_t> rest(bytes);
    decode::PipelineOutput out;
    while (!rest.empty()) {
      const auto r = stream_->Feed(rest);
      rest = rest.subspan(r.consumed);
      if (r.status == ingest::StreamDecoder::Status::kFrame) {
        out = pipeline_->Process(stream_->wavelength_nm(), stream_->flags());
      } else if (r.status == ingest::StreamDecoder::Status::kNeedsResync) {
        stream_->Reset();
        break;
      }
    }
    return out;
  }

  const twin::SkinTwin& twin_;
  twin::Probe probe_;
  const SensitivityArgs& a_;
  double y_, r_;
  twin::InterrogatorSim sim_;
  std::mt19937_64 rng_;
  double mm_per_deg_;
  std::unique_ptr<link::FramePipeline> pipeline_;
  std::unique_ptr<ingest::StreamDecoder> stream_;
  double t_s_ = 0.0;
  std::uint64_t serial_ = 0;
};

struct PointResult {
  float min_force_n = std::numeric_limits<float>::infinity();
  float error_mm = std::numeric_limits<float>::quiet_NaN();
};

// Bisection over the ladder for the smallest reliable force (the ladder is assumed monotone: a point reported
// reliably at some force is at every larger one; docs/coverage.md says what that assumption costs).
PointResult MeasurePoint(PointProbe& probe, const SensitivityArgs& a) {
  const unsigned need = static_cast<unsigned>(std::ceil(a.reliability * a.presses - 1e-9));
  const auto reliable = [&](std::size_t i, PointProbe::Result& r) {
    r = probe.Evaluate(a.forces[i]);
    return r.reported >= need;
  };
  PointResult out;
  PointProbe::Result top;
  std::size_t hi = a.forces.size() - 1;
  if (!reliable(hi, top)) return out;
  PointProbe::Result best = top;
  std::size_t lo = 0;  // the smallest index not yet excluded
  while (lo < hi) {
    const std::size_t mid = (lo + hi) / 2;
    PointProbe::Result r;
    if (reliable(mid, r)) {
      hi = mid;
      best = std::move(r);
    } else {
      lo = mid + 1;
    }
  }
  out.min_force_n = static_cast<float>(a.forces[hi]);
  if (!best.errors_mm.empty()) {
    auto& e = best.errors_mm;
    std::nth_element(e.begin(), e.begin() + static_cast<std::ptrdiff_t>(e.size() / 2), e.end());
    out.error_mm = e[e.size() / 2];
  }
  return out;
}

std::string Fmt(double v, const char* f = "%.2f") {
  if (std::isinf(v)) return "inf";
  if (std::isnan(v)) return "-";
  char buf[32];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

// A heat map of one value per grid point, drawn on a 1 mm (Y) x 1 mm of arc raster, each cell the nearest point.
void SaveHeat(const v1::SensitivityMap& m, double mm_per_deg, double extent_y, double extent_r, bool force,
              const std::string& title, const std::string& path) {
  plot::HeatLayer h;
  h.cols = static_cast<int>(std::ceil(extent_r * mm_per_deg));
  h.rows = static_cast<int>(std::ceil(extent_y));
  h.x_min = 0;
  h.x_max = extent_r;
  h.y_min = 0;
  h.y_max = extent_y;
  const auto nearest = [](const auto& axis, double v) {
    int best = 0;
    for (int i = 1; i < axis.size(); ++i) {
      if (std::abs(axis[i] - v) < std::abs(axis[best] - v)) best = i;
    }
    return best;
  };
  double top = 0;
  for (float f : m.min_force_n()) {
    if (std::isfinite(f)) top = std::max(top, static_cast<double>(f));
  }
  for (int row = 0; row < h.rows; ++row) {
    for (int col = 0; col < h.cols; ++col) {
      const double y = (row + 0.5) * extent_y / h.rows, r = (col + 0.5) * extent_r / h.cols;
      const int k = nearest(m.y_mm(), y) * m.r_deg_size() + nearest(m.r_deg(), r);
      const double v = force ? m.min_force_n(k) : m.location_error_mm(k);
      h.values.push_back(force ? (std::isfinite(v) ? std::log10(v) : std::numeric_limits<double>::quiet_NaN()) : v);
    }
  }
  h.colourbar_label = force ? "log10 smallest reliable force (N); grey: none up to " + Fmt(m.forces_n(m.forces_n_size() - 1), "%.0f") + " N"
                            : "median location error (mm); grey: not located";
  if (force) {
    h.v_min = std::log10(m.forces_n(0));
    h.v_max = std::log10(std::max(top, static_cast<double>(m.forces_n(0)) * 1.01));
  }
  plot::Figure fig(title, "R (deg, patch frame)", "Y (mm, patch frame)", 560, 720);
  fig.SetHeat(h);
  fig.SetXRange(0, extent_r).SetYRange(0, extent_y);
  fig.Save(path);
}

void RunSensitivity(const SensitivityArgs& a, const std::string& command) {
  twin::Scene scene = twin::LoadScene(a.scene);
  std::size_t index = scene.patches.size();
  for (std::size_t i = 0; i < scene.patches.size(); ++i) {
    if (scene.patches[i].name == a.patch || (a.patch.empty() && i == 0)) index = i;
  }
  if (index == scene.patches.size()) throw InputError(a.scene + ": no patch '" + a.patch + "'");
  const twin::ScenePatch& sp = scene.patches[index];
  const std::string model_path = a.model.empty() ? sp.model_path : a.model;
  if (model_path.empty()) throw InputError("patch " + sp.name + " names no model: give --model");
  v1::DecoderModel model = decode::LoadModel(model_path);
  decode::CheckModelMatchesPatch(model, sp.spec, model_path);
  if (scene.probe.shape != twin::Probe::Shape::kSphere) throw InputError(a.scene + ": the map needs a sphere probe");
  if (a.forces.empty() || !std::is_sorted(a.forces.begin(), a.forces.end()) || a.forces.front() <= 0) {
    throw InputError("--forces must be positive and ascending");
  }
  const auto mounts = sim::LoadMounts(scene);
  const twin::SkinTwin tw(sp.spec, sim::EffectsFor(scene, mounts.get(), index), {scene.probe.radius_mm});
  const double mm_per_deg = sp.spec.surface_radius_mm * std::numbers::pi / 180.0;
  const std::vector<double> ys = Axis(sp.spec.extent_y_mm, a.step_mm, a.edge_mm);
  std::vector<double> rs;
  for (double arc : Axis(sp.spec.extent_r_deg * mm_per_deg, a.step_mm, a.edge_mm)) rs.push_back(arc / mm_per_deg);
  const std::size_t n = ys.size() * rs.size();
  spdlog::info("sensitivity of {} ({}) in {} with {}: {} x {} points (Y every {} mm, arc every {} mm, {} mm from each "
               "edge), level {} N, {} presses per force, reliability {}, seeds from {} (held out: training used 1, "
               "calibration 2 and 10, test 3 and 4)",
               sp.name, sp.spec.name, a.scene, model_path, ys.size(), rs.size(), a.step_mm, a.step_mm, a.edge_mm,
               a.level_n, a.presses, a.reliability, a.seed);
  std::vector<PointResult> results(n);
  std::atomic<std::size_t> next{0}, done{0};
  std::mutex progress_mutex;
  ProgressBar bar("sensitivity " + sp.name, n);
  std::exception_ptr error;
  const auto worker = [&] {
    try {
      for (std::size_t k = next++; k < n; k = next++) {
        PointProbe probe(tw, model, sp.spec, scene.probe, a, ys[k / rs.size()], rs[k % rs.size()], twin::DeriveSeed(a.seed, k));
        results[k] = MeasurePoint(probe, a);
        const std::size_t d = ++done;
        std::lock_guard lock(progress_mutex);
        bar.Update(d);
      }
    } catch (...) {
      std::lock_guard lock(progress_mutex);
      error = std::current_exception();
    }
  };
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < a.threads; ++t) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
  bar.Finish();
  if (error) std::rethrow_exception(error);

  v1::SensitivityMap m;
  m.set_level_n(static_cast<float>(a.level_n));
  m.set_reliability(static_cast<float>(a.reliability));
  for (double y : ys) m.add_y_mm(y);
  for (double r : rs) m.add_r_deg(r);
  for (const PointResult& r : results) {
    m.add_min_force_n(r.min_force_n);
    m.add_location_error_mm(r.error_mm);
  }
  for (double f : a.forces) m.add_forces_n(static_cast<float>(f));
  m.set_presses(a.presses);
  m.set_probe_radius_mm(scene.probe.radius_mm);
  m.set_source("`" + command + "`: scene " + a.scene + ", patch " + sp.name + " (its edges as ruffini-sim makes them), " +
               "twin noise and position jitter +-" + Fmt(a.jitter_mm, "%.1f") + " mm from seed " + std::to_string(a.seed) +
               " (DeriveSeed per point; held out: training used seed 1, calibration 2 and 10, test 3 and 4)");
  decode::ValidateSensitivity(m, "measured map");
  // Store: replace a map of the same level, keep the others in ascending level.
  std::vector<v1::SensitivityMap> maps;
  for (const auto& old : model.sensitivity()) {
    if (old.level_n() != m.level_n()) maps.push_back(old);
  }
  maps.push_back(m);
  std::sort(maps.begin(), maps.end(), [](const auto& x, const auto& y) { return x.level_n() < y.level_n(); });
  model.clear_sensitivity();
  for (auto& x : maps) *model.add_sensitivity() = std::move(x);
  decode::ValidateModel(model, a.out);
  if (!a.out.empty()) decode::SaveModel(a.out, model);

  // Summary: stdout carries the results.
  std::size_t none = 0, at_factor = 0, edge_pts = 0, edge_ok = 0;
  std::vector<float> finite, errors, edge_errors;
  for (std::size_t k = 0; k < n; ++k) {
    const float f = results[k].min_force_n;
    const double y = ys[k / rs.size()], arc = rs[k % rs.size()] * mm_per_deg;
    const bool near_edge = y < 10 || y > sp.spec.extent_y_mm - 10 || arc < 10 || arc > sp.spec.extent_r_deg * mm_per_deg - 10;
    none += std::isinf(f) ? 1 : 0;
    at_factor += f <= 1.5 * a.level_n ? 1 : 0;
    edge_pts += near_edge ? 1 : 0;
    edge_ok += near_edge && f <= 1.5 * a.level_n ? 1 : 0;
    if (std::isfinite(f)) finite.push_back(f);
    if (std::isfinite(results[k].error_mm)) (near_edge ? edge_errors : errors).push_back(results[k].error_mm);
  }
  const auto median = [](std::vector<float> v) {
    if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
    return static_cast<double>(v[v.size() / 2]);
  };
  double worst = 0;
  for (const auto& r : results) worst = std::max(worst, static_cast<double>(r.min_force_n));
  std::ostringstream rep;
  rep << "# Sensitivity map: " << sp.name << " (" << sp.spec.name << "), level " << Fmt(a.level_n) << " N\n\n"
      << "Model: `" << model_path << "`" << (a.out.empty() ? "" : ", written to `" + a.out + "`") << ".\n"
      << "Measured by `" << command << "`.\n\n"
      << "At each of " << n << " grid points (Y: " << ys.size() << " rows every " << a.step_mm << " mm and " << a.edge_mm
      << " mm from each end; R: " << rs.size() << " columns every " << a.step_mm << " mm of arc and " << a.edge_mm
      << " mm from each edge), the smallest force of the ladder from which on at least " << Fmt(100 * a.reliability, "%.0f")
      << " % of " << a.presses << " presses (each jittered within +-" << Fmt(a.jitter_mm, "%.1f")
      << " mm, fresh interrogator noise; seeds from " << a.seed
      << ", held out) have a decoded contact frame above " << Fmt(a.level_n) << " N (or an over-range contact).\n\n"
      << "| measure | value |\n| --- | --- |\n"
      << "| points reliably reported at <= 1.5 x level (" << Fmt(1.5 * a.level_n) << " N) | " << at_factor << " of " << n
      << " (" << Fmt(100.0 * static_cast<double>(at_factor) / static_cast<double>(n), "%.1f") << " %) |\n"
      << "| of them within 10 mm of an edge | " << edge_ok << " of " << edge_pts << " |\n"
      << "| points not reliably reported up to " << Fmt(a.forces.back(), "%.0f") << " N | " << none << " |\n"
      << "| median smallest reliable force (finite points) | " << Fmt(median(finite)) << " N |\n"
      << "| largest smallest reliable force | " << Fmt(worst) << " N |\n"
      << "| median location error at that force, interior (> 10 mm from every edge) | " << Fmt(median(errors), "%.1f") << " mm |\n"
      << "| median location error at that force, within 10 mm of an edge | " << Fmt(median(edge_errors), "%.1f") << " mm |\n\n"
      << "Smallest reliable force, N (rows Y mm, columns R deg; inf: none up to " << Fmt(a.forces.back(), "%.0f") << " N):\n\n"
      << "| Y \\ R |";
  for (double r : rs) rep << " " << Fmt(r, "%.0f") << " |";
  rep << "\n|---|";
  for (std::size_t i = 0; i < rs.size(); ++i) rep << "---|";
  rep << "\n";
  for (std::size_t iy = 0; iy < ys.size(); ++iy) {
    rep << "| " << Fmt(ys[iy], "%.0f") << " |";
    for (std::size_t ir = 0; ir < rs.size(); ++ir) rep << " " << Fmt(results[iy * rs.size() + ir].min_force_n, "%.3g") << " |";
    rep << "\n";
  }
  std::printf("%s", rep.str().c_str());
  if (!a.report.empty()) {
    std::filesystem::create_directories(a.report);
    const std::string base = a.report + "/" + sp.name;
    std::ofstream(base + ".md") << rep.str() << "\nFigures: `" << sp.name << "-force.svg`, `" << sp.name << "-error.svg`.\n";
    SaveHeat(m, mm_per_deg, sp.spec.extent_y_mm, sp.spec.extent_r_deg, true,
             sp.name + ": smallest force reported above " + Fmt(a.level_n) + " N", base + "-force.svg");
    SaveHeat(m, mm_per_deg, sp.spec.extent_y_mm, sp.spec.extent_r_deg, false,
             sp.name + ": location error at that force", base + "-error.svg");
    spdlog::info("report: {}.md, {}-force.svg, {}-error.svg", base, base, base);
  }
}

void RegisterSensitivity(CLI::App& app) {
  auto a = std::make_shared<SensitivityArgs>();
  CLI::App* cmd = app.add_subcommand(
      "sensitivity",
      "Measure a patch's sensitivity map (smallest force reliably reported above a level, and the location error "
      "there, on a grid over the whole surface) on held-out twin presses, and store it in a model file");
  cmd->add_option("--scene", a->scene, "Scene YAML (its twin and the patch's edges)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--patch", a->patch, "Patch of the scene (default: the first)");
  cmd->add_option("--model", a->model, "Model file (default: the scene's for the patch)")->check(CLI::ExistingFile);
  cmd->add_option("--out", a->out, "Write the model with the map here (a map of the same level is replaced)");
  cmd->add_option("--report", a->report, "Report folder: PATCH.md, PATCH-force.svg, PATCH-error.svg");
  cmd->add_option("--level-n", a->level_n, "The level a press must be reported above (the region threshold), N")
      ->check(CLI::Range(0.01, 1000.0))->capture_default_str();
  cmd->add_option("--reliability", a->reliability, "Share of presses that must be reported above the level")
      ->check(CLI::Range(0.5, 1.0))->capture_default_str();
  cmd->add_option("--presses", a->presses, "Presses per point and force")->check(CLI::Range(1u, 1000u))->capture_default_str();
  cmd->add_option("--step-mm", a->step_mm, "Grid step in Y and in arc, mm")->check(CLI::Range(1.0, 50.0))->capture_default_str();
  cmd->add_option("--edge-mm", a->edge_mm, "Grid points this far from each edge, mm")->check(CLI::Range(0.5, 20.0))->capture_default_str();
  cmd->add_option("--jitter-mm", a->jitter_mm, "Each press lands within +- this of its point (Y and arc), mm")
      ->check(CLI::Range(0.0, 5.0))->capture_default_str();
  cmd->add_option("--forces", a->forces, "The force ladder, N (ascending)")->capture_default_str();
  cmd->add_option("--seed", a->seed, "First seed (keep it away from the training, calibration and test seeds)")->capture_default_str();
  cmd->add_option("--threads", a->threads, "Worker threads")->check(CLI::Range(1u, 64u))->capture_default_str();
  cmd->callback([a, cmd] {
    std::string command = "ruffini sensitivity";
    for (const auto* o : cmd->get_options()) {
      if (o->count() == 0 || o->get_name() == "--help") continue;
      command += " " + o->get_name();
      for (const auto& r : o->results()) command += " " + r;
    }
    RunSensitivity(*a, command);
  });
}

void RegisterCheckScene(CLI::App& app) {
  auto scene = std::make_shared<std::string>();
  auto points = std::make_shared<bool>(false);
  CLI::App* cmd = app.add_subcommand(
      "check-scene",
      "Per region, the smallest threshold its patches' sensitivity maps guarantee over their covered surface; "
      "exit 1 when a threshold is below it (the aggregator refuses such a scene)");
  cmd->add_option("scene", *scene, "Scene YAML")->required()->check(CLI::ExistingFile);
  cmd->add_flag("--points", *points, "List every covered map point that misses the guarantee");
  cmd->callback([scene, points] {
    const aggregator::SceneCoverage c = aggregator::CoverageOfScene(*scene);
    std::printf("%s", aggregator::DescribeCoverage(c, *points).c_str());
    if (!c.refusal.empty()) throw InputError(*scene + ": " + c.refusal);
    std::printf("ok: every region's threshold is guaranteed on its covered surface\n");
  });
}

}  // namespace

void RegisterCoverageCommands(CLI::App& app) {
  RegisterSensitivity(app);
  RegisterCheckScene(app);
}

}  // namespace ruffini::cli
