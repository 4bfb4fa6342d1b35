// Coverage subcommands (issue 16, docs/coverage.md):
//   sensitivity       measure a patch's sensitivity map on held-out twin presses and store it in a model file
//   coverage-targets  measure the light-press (no STOP) and slow-press (STOP at the threshold) targets
//   check-scene       what each region's patches guarantee, and whether the scene's thresholds are met
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
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
#include <span>
#include <sstream>
#include <thread>
#include <utility>

#include "commands.h"
#include "progress.h"
#include "ruffini/decode/model_io.h"
#include "ruffini/decode/sensitivity.h"
#include "ruffini/error.h"
#include "ruffini/ingest/hyperion.h"
#include "ruffini/link/monitor.h"
#include "ruffini/plot/svg.h"
#include "ruffini/safety/scene.h"
#include "ruffini/scene_file.h"
#include "ruffini/sim/scenario.h"
#include "ruffini/twin/scene.h"
#include "ruffini/twin/twin.h"
#include "scene_setup.h"

namespace ruffini::cli {
namespace {

// The Unix time of the simulated streams' time 0 (their timestamps only need to be plausible).
constexpr std::int64_t kEpochNs = 1'700'000'000'000'000'000;

// The patch of a scene under test, as ruffini-sim builds it: its spec, its model (checked against the spec)
// and its twin (the scene's effects and cast, its edges: free where the cover ends, continued at a seam found
// through the mounts). Not movable: the twin was built from the scene and mounts it keeps.
class PatchUnderTest {
 public:
  PatchUnderTest(const std::string& scene_path, const std::string& patch, const std::string& model)
      : scene_(twin::LoadScene(scene_path)), index_(scene_.patches.size()) {
    for (std::size_t i = 0; i < scene_.patches.size(); ++i) {
      if (scene_.patches[i].name == patch || (patch.empty() && i == 0)) index_ = i;
    }
    if (index_ == scene_.patches.size()) throw InputError(scene_path + ": no patch '" + patch + "'");
    model_path_ = model.empty() ? spec_patch().model_path : model;
    if (model_path_.empty()) throw InputError("patch " + spec_patch().name + " names no model: give --model");
    model_ = decode::LoadModel(model_path_);
    decode::CheckModelMatchesPatch(model_, spec(), model_path_);
    if (scene_.probe.shape != twin::Probe::Shape::kSphere) throw InputError(scene_path + ": the measurement needs a sphere probe");
    mounts_ = sim::LoadMounts(scene_);
    twin_ = std::make_unique<twin::SkinTwin>(spec(), sim::EffectsFor(scene_, mounts_.get(), index_),
                                             std::vector<double>{scene_.probe.radius_mm});
    mm_per_deg_ = spec().surface_radius_mm * std::numbers::pi / 180.0;
  }
  PatchUnderTest(const PatchUnderTest&) = delete;
  PatchUnderTest& operator=(const PatchUnderTest&) = delete;

  [[nodiscard]] const twin::Scene& scene() const noexcept { return scene_; }
  [[nodiscard]] std::size_t index() const noexcept { return index_; }
  [[nodiscard]] const twin::ScenePatch& spec_patch() const noexcept { return scene_.patches[index_]; }
  [[nodiscard]] const patch::PatchSpec& spec() const noexcept { return spec_patch().spec; }
  [[nodiscard]] const std::string& name() const noexcept { return spec_patch().name; }
  [[nodiscard]] const std::string& model_path() const noexcept { return model_path_; }
  [[nodiscard]] v1::DecoderModel& model() noexcept { return model_; }
  [[nodiscard]] const v1::DecoderModel& model() const noexcept { return model_; }
  [[nodiscard]] const twin::SkinTwin& twin() const noexcept { return *twin_; }
  [[nodiscard]] double mm_per_deg() const noexcept { return mm_per_deg_; }

 private:
  twin::Scene scene_;
  std::size_t index_;
  std::string model_path_;
  v1::DecoderModel model_;
  std::unique_ptr<sim::MountedScene> mounts_;
  std::unique_ptr<twin::SkinTwin> twin_;
  double mm_per_deg_ = 0;
};

// One frame as ruffini-sim puts it on the wire: the twin's shifts under `c` (or none) read by the interrogator
// simulation, the channel's peaks in ascending order, a lost one left out (a Hyperion stream carries no
// saturation flag, so the twin's own flags never reach the decoder), encoded as Hyperion bytes.
std::vector<std::uint8_t> WireFrame(const twin::SkinTwin& tw, twin::InterrogatorSim& sim,
                                    std::span<const twin::Contact> contacts, double t_s, std::uint64_t serial) {
  twin::Shifts s{};
  std::uint32_t flags = 0;
  if (!contacts.empty()) tw.StrainShiftsPm(contacts, s, flags);
  Wavelengths wl{};
  sim.Read(t_s, s, wl, flags);
  return ingest::EncodeWavelengths(serial, kEpochNs + static_cast<std::int64_t>(t_s * 1e9), 0, wl);
}

// Runs fn(k) for k in [0, n) on `threads` threads (the caller's one of them), with a progress bar on stderr;
// rethrows the first error once every thread has stopped.
template <typename Fn>
void ParallelFor(std::size_t n, unsigned threads, const std::string& label, Fn fn) {
  std::atomic<std::size_t> next{0}, done{0};
  std::mutex progress_mutex;
  ProgressBar bar(label, n);
  std::exception_ptr error;
  std::atomic<bool> failed{false};
  const auto worker = [&] {
    try {
      for (std::size_t k = next++; k < n && !failed; k = next++) {
        fn(k);
        const std::size_t d = ++done;
        std::lock_guard lock(progress_mutex);
        bar.Update(d);
      }
    } catch (...) {
      std::lock_guard lock(progress_mutex);
      if (!error) error = std::current_exception();
      failed = true;
    }
  };
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < threads; ++t) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
  bar.Finish();
  if (error) std::rethrow_exception(error);
}

// The command as typed, for the reports: the subcommand and every option given.
std::string CommandLine(const std::string& name, const CLI::App& cmd) {
  std::string command = "ruffini " + name;
  for (const auto* o : cmd.get_options()) {
    if (o->count() == 0 || o->get_name() == "--help") continue;
    command += " " + o->get_name();
    for (const auto& r : o->results()) command += " " + r;
  }
  return command;
}

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

  // One frame as the decoder service gets it: what ruffini-sim puts on the wire (WireFrame), through the
  // ingest codec, into the pipeline. A frame the codec rejects reports nothing.
  decode::PipelineOutput Frame(const twin::Contact* c, double /*w*/) {
    const std::vector<std::uint8_t> bytes =
        WireFrame(twin_, sim_, c == nullptr ? std::span<const twin::Contact>() : std::span<const twin::Contact>(c, 1), t_s_, serial_++);
    t_s_ += 1.0 / a_.rate_hz;
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
  PatchUnderTest put(a.scene, a.patch, a.model);
  const twin::ScenePatch& sp = put.spec_patch();
  const std::string& model_path = put.model_path();
  v1::DecoderModel& model = put.model();
  const twin::Scene& scene = put.scene();
  if (a.forces.empty() || !std::is_sorted(a.forces.begin(), a.forces.end()) || a.forces.front() <= 0) {
    throw InputError("--forces must be positive and ascending");
  }
  const twin::SkinTwin& tw = put.twin();
  const double mm_per_deg = put.mm_per_deg();
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
  ParallelFor(n, a.threads, "sensitivity " + sp.name, [&](std::size_t k) {
    PointProbe probe(tw, model, sp.spec, scene.probe, a, ys[k / rs.size()], rs[k % rs.size()], twin::DeriveSeed(a.seed, k));
    results[k] = MeasurePoint(probe, a);
  });

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
  // What the map is valid for: this patch as the scene mounts it, and the model's decoder (review 10, finding 5).
  aggregator::BindMap(m, a.scene, sp.name, model);
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
      ->check(CLI::Range(0.01, 1000.0))->check(FiniteNumber())->capture_default_str();
  cmd->add_option("--reliability", a->reliability, "Share of presses that must be reported above the level")
      ->check(CLI::Range(0.5, 1.0))->check(FiniteNumber())->capture_default_str();
  cmd->add_option("--presses", a->presses, "Presses per point and force")->check(CLI::Range(1u, 1000u))->capture_default_str();
  cmd->add_option("--step-mm", a->step_mm, "Grid step in Y and in arc, mm")->check(CLI::Range(1.0, 50.0))->check(FiniteNumber())->capture_default_str();
  cmd->add_option("--edge-mm", a->edge_mm, "Grid points this far from each edge, mm")->check(CLI::Range(0.5, 20.0))->check(FiniteNumber())->capture_default_str();
  cmd->add_option("--jitter-mm", a->jitter_mm, "Each press lands within +- this of its point (Y and arc), mm")
      ->check(CLI::Range(0.0, 5.0))->check(FiniteNumber())->capture_default_str();
  cmd->add_option("--forces", a->forces, "The force ladder, N (ascending)")->check(FiniteNumber())->capture_default_str();
  cmd->add_option("--seed", a->seed, "First seed (keep it away from the training, calibration and test seeds)")->capture_default_str();
  cmd->add_option("--threads", a->threads, "Worker threads")->check(CLI::Range(1u, 64u))->capture_default_str();
  cmd->callback([a, cmd] { RunSensitivity(*a, CommandLine("sensitivity", *cmd)); });
}

// ---- coverage-targets: issue 16's "light presses do not stop" and "a slow press stops at the threshold" ----

struct TargetsArgs {
  std::string scene, patch, model, report, target = "both";
  double level_n = 0.0;   // 0: the threshold of the patch's region in the scene
  double force_n = -1.0;  // < 0: light_factor x level
  double light_factor = 0.5, step_mm = 5.0, edge_mm = 2.0, jitter_mm = 1.0, hold_s = 0.15, rate_hz = 1000.0;
  double slow_step_mm = 10.0, slow_rate_n_per_s = 0.15, slow_top_n = 3.0, band = 0.15;
  double reliability = 0.95;  // firm presses: as the sensitivity map's
  unsigned presses = 20, threads = 1;
  std::uint64_t seed = 1100;  // light presses; slow seed + 1, firm seed + 2, pair seed + 3 (grid points), + 4 (cell centres), + 5 (border)
  std::vector<double> pair_forces_n{5.0, 20.0, 50.0, 200.0};
  std::array<double, 2> pair_light_n{0.5, 1.2};
  unsigned pair_presses = 3;
  std::string pair_at = "all";  // grid, centres, border or all
  double sd_k = 0.0;  // with sd_k_set: overrides the scene's safety.stop_rule.sd_k
  bool sd_k_set = false;
};

// Why the aggregator would STOP on one message of a decoder, or kNone: its threshold rule
// (safety::Policy::OnContact: a contact above the threshold, strictly; an over-range contact carries its lower
// bound as force_n), its doubts (a non-finite or negative force beyond the tolerance; aggregate::Core::
// CheckContact: a located position off the patch, a covariance that is not PSD) and a fault (a fault message,
// or a heartbeat naming an active fault).
enum class StopCause : std::uint8_t { kNone, kForce, kOverRange, kDoubt, kFault };
constexpr std::size_t kStopCauses = 5;
constexpr std::array<const char*, kStopCauses> kStopCauseName = {"none", "force", "over range", "doubt", "fault"};

struct StopRule {
  double threshold_n = 0;
  safety::Config::StopRule stop;  // the scene's stop_rule (force + sd_k x sd, safety::JudgedForce)
  safety::InputLimits input;
  double extent_y_mm = 0, extent_r_deg = 0;

  [[nodiscard]] StopCause Judge(const link::Message& m) const noexcept {
    switch (m.kind) {
      case link::Message::Kind::kFault:
        return m.fault.code != link::FaultCode::kNone ? StopCause::kFault : StopCause::kNone;
      case link::Message::Kind::kHeartbeat:
        return m.health.active_fault != link::FaultCode::kNone ? StopCause::kFault : StopCause::kNone;
      case link::Message::Kind::kRetare: return StopCause::kNone;  // an operator's request's answer: none here
      case link::Message::Kind::kContact: break;
    }
    const link::Contact& c = m.contact;
    if (!std::isfinite(c.force_n) || c.force_n < -input.negative_force_tolerance_n) return StopCause::kDoubt;
    if (c.located) {
      const double y = c.y_mm, r = c.r_deg, yy = c.cov_yy_mm2, yr = c.cov_yr_mm2, rr = c.cov_rr_mm2;
      if (!std::isfinite(y) || !std::isfinite(r) || y < -input.position_tolerance_y_mm ||
          y > extent_y_mm + input.position_tolerance_y_mm || r < -input.position_tolerance_r_deg ||
          r > extent_r_deg + input.position_tolerance_r_deg) {
        return StopCause::kDoubt;
      }
      if (!std::isfinite(yy) || !std::isfinite(yr) || !std::isfinite(rr) || yy < 0 || rr < 0 ||
          yy * rr - yr * yr < -1e-6 * std::max(1.0, yy * rr)) {
        return StopCause::kDoubt;
      }
    }
    const float judged = safety::JudgedForce(std::max(c.force_n, 0.0f), c.uncertainty ? c.force_sd_n : 0.0f, c.over_range, stop);
    if (judged > threshold_n) return c.over_range ? StopCause::kOverRange : StopCause::kForce;
    return StopCause::kNone;
  }
};

// One grid point's stream through the whole decoder service without sockets (as tests/decode/hard_press.h):
// WireFrame -> the ingest codec with the service's default picking -> link::Monitor over the service's default
// pipeline -> the messages the aggregator would get, each judged by the StopRule as it is sent.
class MonitoredStream {
 public:
  MonitoredStream(const PatchUnderTest& put, const StopRule& rule, double rate_hz, std::uint64_t seed)
      : twin_(put.twin()), rate_hz_(rate_hz), sim_(put.twin(), twin::DeriveSeed(seed, 1)) {
    sink_.rule = &rule;
    decode::PipelineConfig config;
    config.baseline = decode::BaselineFor(put.model(), rate_hz);
    pipeline_ = link::MakePipeline(put.model(), put.spec(), config, link::DecoderChoice{});
    link::MonitorConfig mc;
    mc.sample_rate_hz = rate_hz;
    monitor_ = std::make_unique<link::Monitor>(*pipeline_, link::Resolved(mc), Clock());
    Wavelengths centre{};
    for (std::size_t i = 0; i < kGratings; ++i) centre[i] = put.spec().gratings[i].wavelength_nm;
    ingest::DecoderConfig codec;
    codec.pick = ingest::NearestGratingBands(0, centre);
    stream_ = std::make_unique<ingest::StreamDecoder>(codec);
    monitor_->OnConnected(Clock(), sink_);
  }

  // One frame under `c` (or untouched); the first stop cause among the messages it made.
  StopCause Frame(const twin::Contact* c) {
    return Frame(c == nullptr ? std::span<const twin::Contact>() : std::span<const twin::Contact>(c, 1));
  }
  // One frame under every probe of `contacts` at once (none: untouched).
  StopCause Frame(std::span<const twin::Contact> contacts) {
    const std::vector<std::uint8_t> bytes = WireFrame(twin_, sim_, contacts, t_s_, serial_);
    const link::Now now = Clock();
    sink_.first = StopCause::kNone;
    std::span<const std::uint8_t> rest(bytes);
    while (!rest.empty()) {
      const auto r = stream_->Feed(rest);
      rest = rest.subspan(r.consumed);
      if (r.status == ingest::StreamDecoder::Status::kFrame) {
        link::FrameIn f;
        f.serial = serial_;
        f.t_ns = now.unix_ns;
        f.flags = stream_->flags();
        f.wavelength_nm = stream_->wavelength_nm();
        monitor_->OnFrame(f, now, sink_);
      } else if (r.status == ingest::StreamDecoder::Status::kRejected) {
        monitor_->OnStreamRejected(r.reason, now, sink_);
      } else if (r.status == ingest::StreamDecoder::Status::kNeedsResync) {
        monitor_->OnStreamRejected(r.reason, now, sink_);
        stream_->Reset();
        break;
      }
    }
    monitor_->Tick(now, sink_);
    ++serial_;
    t_s_ += 1.0 / rate_hz_;
    return sink_.first;
  }

  // The contact forces sent since the last call: the largest (0 if none), their mean and standard deviation
  // (NaN if none).
  struct Forces {
    float max_n = 0.0f;
    double mean_n = std::numeric_limits<double>::quiet_NaN(), sd_n = std::numeric_limits<double>::quiet_NaN();
    std::size_t count = 0;
  };
  Forces TakeForces() noexcept {
    Forces f;
    f.max_n = std::exchange(sink_.max_force_n, 0.0f);
    f.count = std::exchange(sink_.count, 0);
    const double sum = std::exchange(sink_.sum_n, 0.0), sum2 = std::exchange(sink_.sum2_n2, 0.0);
    if (f.count > 0) {
      f.mean_n = sum / static_cast<double>(f.count);
      f.sd_n = std::sqrt(std::max(0.0, sum2 / static_cast<double>(f.count) - f.mean_n * f.mean_n));
    }
    return f;
  }

 private:
  struct Sink final : link::MessageSink {
    const StopRule* rule = nullptr;
    StopCause first = StopCause::kNone;
    float max_force_n = 0.0f;
    double sum_n = 0.0, sum2_n2 = 0.0;
    std::size_t count = 0;
    void Push(const link::Message& m) noexcept override {
      if (m.kind == link::Message::Kind::kContact && std::isfinite(m.contact.force_n)) {
        max_force_n = std::max(max_force_n, m.contact.force_n);
        sum_n += m.contact.force_n;
        sum2_n2 += static_cast<double>(m.contact.force_n) * m.contact.force_n;
        ++count;
      }
      if (first == StopCause::kNone) first = rule->Judge(m);
    }
  };
  [[nodiscard]] link::Now Clock() const noexcept {
    const auto ns = static_cast<std::int64_t>(t_s_ * 1e9);
    return link::Now{ns, kEpochNs + ns};
  }

  const twin::SkinTwin& twin_;
  double rate_hz_;
  twin::InterrogatorSim sim_;
  Sink sink_;
  std::unique_ptr<link::FramePipeline> pipeline_;
  std::unique_ptr<link::Monitor> monitor_;
  std::unique_ptr<ingest::StreamDecoder> stream_;
  double t_s_ = 0.0;
  std::uint64_t serial_ = 0;
};

// The untouched start of every stream: the baseline capture (1 s) and a little more. Returns the first stop.
StopCause UntouchedStart(MonitoredStream& s, double rate_hz) {
  StopCause first = StopCause::kNone;
  for (int k = 0; k < static_cast<int>(1.2 * rate_hz); ++k) {
    const StopCause c = s.Frame(nullptr);
    if (first == StopCause::kNone) first = c;
  }
  s.TakeForces();
  return first;
}

struct LightPoint {
  unsigned stopped = 0;                          // presses with a stop (the start's counted in start)
  std::array<unsigned, kStopCauses> by_cause{};  // each stopped press by its first cause
  StopCause start = StopCause::kNone;            // a stop during the untouched start
  float max_force_n = 0.0f;                      // the largest contact force sent over all presses
  [[nodiscard]] bool clean() const noexcept { return stopped == 0 && start == StopCause::kNone; }
};

// `presses` light presses at one point, each jittered within +-jitter_mm (Y and arc) as sensitivity's: rest
// 0.3 s, ramp 0.05 s, hold hold_s, release 0.05 s, 0.05 s more watched. A press stops when any message from
// its rest to its end would (the aggregator latches, so one is enough).
LightPoint MeasureLight(const PatchUnderTest& put, const StopRule& rule, const TargetsArgs& a, double force_n,
                        double y_mm, double r_deg, std::uint64_t seed) {
  MonitoredStream s(put, rule, a.rate_hz, seed);
  std::mt19937_64 rng(twin::DeriveSeed(seed, 6));
  std::uniform_real_distribution<double> jitter(-a.jitter_mm, a.jitter_mm);
  LightPoint out;
  out.start = UntouchedStart(s, a.rate_hz);
  const double rest = 0.3, ramp = 0.05, release = 0.05, tail = 0.05;
  for (unsigned p = 0; p < a.presses; ++p) {
    const double y = std::clamp(y_mm + jitter(rng), 0.0, put.spec().extent_y_mm);
    const double rd = std::clamp(r_deg + jitter(rng) / put.mm_per_deg(), 0.0, put.spec().extent_r_deg);
    StopCause first = StopCause::kNone;
    for (int k = 0; k < static_cast<int>(rest * a.rate_hz); ++k) {
      const StopCause c = s.Frame(nullptr);
      if (first == StopCause::kNone) first = c;
    }
    const int n = static_cast<int>((ramp + a.hold_s + release + tail) * a.rate_hz);
    for (int k = 0; k < n; ++k) {
      const double t = k / a.rate_hz;
      double w = 0.0;
      if (t < ramp) w = t / ramp;
      else if (t <= ramp + a.hold_s) w = 1.0;
      else if (t < ramp + a.hold_s + release) w = 1.0 - (t - ramp - a.hold_s) / release;
      const twin::Contact contact{{y, rd}, w * force_n, put.scene().probe};
      const StopCause c = s.Frame(w > 0 ? &contact : nullptr);
      if (first == StopCause::kNone) first = c;
    }
    out.max_force_n = std::max(out.max_force_n, s.TakeForces().max_n);
    if (first != StopCause::kNone) {
      ++out.stopped;
      ++out.by_cause[static_cast<std::size_t>(first)];
    }
  }
  return out;
}

struct SlowPoint {
  StopCause cause = StopCause::kNone;  // the first stop's
  double t_s = std::numeric_limits<double>::quiet_NaN();        // its time from the start of the ramp
  double true_force_n = std::numeric_limits<double>::quiet_NaN();  // the true force then (NaN: none in the ramp)
  bool in_release = false;             // the first stop came after the ramp's top
  float max_force_n = 0.0f;            // the largest contact force sent during the ramp
  // The contact forces sent while the true force was within +-kNearThreshold of the threshold: their mean
  // (the decoder's bias there) and standard deviation (its noise); NaN when none was sent.
  double near_mean_n = std::numeric_limits<double>::quiet_NaN(), near_sd_n = std::numeric_limits<double>::quiet_NaN();
};
constexpr double kNearThreshold = 0.03;

// One slow press at the point (no jitter): 0 -> slow_top_n at slow_rate_n_per_s, released over 0.3 s, 0.5 s
// of rest. The first stop's time and the true force then (a stop during the untouched start is one at 0 N),
// and the decoded force around the true crossing (the whole ramp is pressed, whenever the first stop came).
SlowPoint MeasureSlow(const PatchUnderTest& put, const StopRule& rule, const TargetsArgs& a, double y_mm, double r_deg,
                      std::uint64_t seed) {
  MonitoredStream s(put, rule, a.rate_hz, seed);
  SlowPoint out;
  if (const StopCause c = UntouchedStart(s, a.rate_hz); c != StopCause::kNone) {
    out.cause = c;
    out.t_s = 0.0;
    out.true_force_n = 0.0;
  }
  const double ramp = a.slow_top_n / a.slow_rate_n_per_s, release = 0.3, rest = 0.5;
  const double near_lo = (1 - kNearThreshold) * rule.threshold_n, near_hi = (1 + kNearThreshold) * rule.threshold_n;
  const int n = static_cast<int>((ramp + release + rest) * a.rate_hz);
  // The stream's parts: 0 the ramp below the window around the threshold, 1 the window, 2 the ramp above it,
  // 3 the release and rest. The forces sent are taken at each change (a frame's messages belong to its part).
  int part = 0;
  const auto take = [&] {
    const MonitoredStream::Forces f = s.TakeForces();
    if (part <= 2) out.max_force_n = std::max(out.max_force_n, f.max_n);
    if (part == 1) {
      out.near_mean_n = f.mean_n;
      out.near_sd_n = f.sd_n;
    }
  };
  for (int k = 0; k < n; ++k) {
    const double t = k / a.rate_hz;
    double f = 0.0;
    if (t <= ramp) f = a.slow_rate_n_per_s * t;
    else if (t < ramp + release) f = a.slow_top_n * (1.0 - (t - ramp) / release);
    const int now = t > ramp ? 3 : f > near_hi ? 2 : f >= near_lo ? 1 : 0;
    while (part < now) {  // a window shorter than a frame is passed through, and taken empty
      take();
      ++part;
    }
    const twin::Contact contact{{y_mm, r_deg}, f, put.scene().probe};
    const StopCause c = s.Frame(f > 0 ? &contact : nullptr);
    if (c != StopCause::kNone && out.cause == StopCause::kNone) {
      out.cause = c;
      out.t_s = t;
      if (t <= ramp) out.true_force_n = f;
      else out.in_release = true;
    }
  }
  return out;
}

// The q-quantile (nearest rank) of v; NaN when empty.
double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(v.begin(), v.end());
  const auto i = static_cast<std::size_t>(std::ceil(q * static_cast<double>(v.size())));
  return v[std::min(v.size() - 1, i == 0 ? 0 : i - 1)];
}

// A heat map of one value per grid point (ys x rs, row-major), on a 1 mm (Y) x 1 mm of arc raster, each cell
// the nearest point; NaN cells are grey.
void SaveGridHeat(const std::vector<double>& ys, const std::vector<double>& rs, const std::vector<double>& values,
                  const PatchUnderTest& put, double v_min, double v_max, const std::string& label,
                  const std::string& title, const std::string& path) {
  const double extent_y = put.spec().extent_y_mm, extent_r = put.spec().extent_r_deg;
  plot::HeatLayer h;
  h.cols = static_cast<int>(std::ceil(extent_r * put.mm_per_deg()));
  h.rows = static_cast<int>(std::ceil(extent_y));
  h.x_max = extent_r;
  h.y_max = extent_y;
  const auto nearest = [](const std::vector<double>& axis, double v) {
    std::size_t best = 0;
    for (std::size_t i = 1; i < axis.size(); ++i) {
      if (std::abs(axis[i] - v) < std::abs(axis[best] - v)) best = i;
    }
    return best;
  };
  for (int row = 0; row < h.rows; ++row) {
    for (int col = 0; col < h.cols; ++col) {
      const double y = (row + 0.5) * extent_y / h.rows, r = (col + 0.5) * extent_r / h.cols;
      h.values.push_back(values[nearest(ys, y) * rs.size() + nearest(rs, r)]);
    }
  }
  h.v_min = v_min;
  h.v_max = v_max;
  h.colourbar_label = label;
  plot::Figure fig(title, "R (deg, patch frame)", "Y (mm, patch frame)", 560, 720);
  fig.SetHeat(h);
  fig.SetXRange(0, extent_r).SetYRange(0, extent_y);
  fig.Save(path);
}

// The scene's accepted uncovered bands on the patch (safety.coverage.accepted_uncovered, docs/coverage.md):
// where the scene admits its threshold is not guaranteed. The reports give every figure also for the covered
// surface, the grid points outside them.
struct Bands {
  std::vector<safety::CoverageConfig::Band> bands;
  // The first band holding the point, or nullptr.
  [[nodiscard]] const safety::CoverageConfig::Band* Holding(double y_mm, double r_deg) const noexcept {
    for (const auto& b : bands) {
      if (y_mm >= b.y_min_mm && y_mm <= b.y_max_mm && r_deg >= b.r_min_deg && r_deg <= b.r_max_deg) return &b;
    }
    return nullptr;
  }
  [[nodiscard]] std::string Name(double y_mm, double r_deg) const {
    const auto* b = Holding(y_mm, r_deg);
    return b == nullptr ? "-" : b->name;
  }
};

// The grid of a target: Y and arc every step_mm, edge_mm from each edge (as sensitivity's).
struct Grid {
  std::vector<double> ys, rs;
  [[nodiscard]] std::size_t size() const noexcept { return ys.size() * rs.size(); }
  [[nodiscard]] double y(std::size_t k) const { return ys[k / rs.size()]; }
  [[nodiscard]] double r(std::size_t k) const { return rs[k % rs.size()]; }
};
Grid MakeGrid(const PatchUnderTest& put, double step_mm, double edge_mm) {
  Grid g;
  g.ys = Axis(put.spec().extent_y_mm, step_mm, edge_mm);
  for (double arc : Axis(put.spec().extent_r_deg * put.mm_per_deg(), step_mm, edge_mm)) g.rs.push_back(arc / put.mm_per_deg());
  return g;
}

std::string Pct(std::size_t part, std::size_t whole) {
  return whole == 0 ? "-" : Fmt(100.0 * static_cast<double>(part) / static_cast<double>(whole), "%.1f") + " %";
}

std::string GridText(const Grid& g, double step_mm, double edge_mm) {
  std::ostringstream s;
  s << g.size() << " grid points (Y: " << g.ys.size() << " rows every " << Fmt(step_mm, "%g") << " mm and "
    << Fmt(edge_mm, "%g") << " mm from each end; R: " << g.rs.size() << " columns every " << Fmt(step_mm, "%g")
    << " mm of arc and " << Fmt(edge_mm, "%g") << " mm from each edge)";
  return s.str();
}

std::string RunLight(const PatchUnderTest& put, const StopRule& rule, const Bands& bands, const TargetsArgs& a,
                     const std::string& base) {
  const double force_n = a.force_n >= 0 ? a.force_n : a.light_factor * rule.threshold_n;
  const Grid g = MakeGrid(put, a.step_mm, a.edge_mm);
  const std::size_t n = g.size();
  spdlog::info("light presses on {}: {} points x {} presses of {} N, threshold {} N, seeds DeriveSeed({}, point)",
               put.name(), n, a.presses, force_n, rule.threshold_n, a.seed);
  std::vector<LightPoint> res(n);
  ParallelFor(n, a.threads, "light presses " + put.name(), [&](std::size_t k) {
    res[k] = MeasureLight(put, rule, a, force_n, g.y(k), g.r(k), twin::DeriveSeed(a.seed, k));
  });
  std::size_t clean = 0, stopped = 0, start = 0, covered = 0, covered_clean = 0, covered_stopped = 0;
  std::array<std::size_t, kStopCauses> by_cause{};
  std::vector<std::size_t> failing;
  for (std::size_t k = 0; k < n; ++k) {
    if (bands.Holding(g.y(k), g.r(k)) == nullptr) {
      ++covered;
      covered_clean += res[k].clean() ? 1 : 0;
      covered_stopped += res[k].stopped;
    }
    clean += res[k].clean() ? 1 : 0;
    stopped += res[k].stopped;
    start += res[k].start != StopCause::kNone ? 1 : 0;
    for (std::size_t c = 0; c < kStopCauses; ++c) by_cause[c] += res[k].by_cause[c];
    if (!res[k].clean()) failing.push_back(k);
  }
  std::stable_sort(failing.begin(), failing.end(), [&](std::size_t x, std::size_t y) { return res[x].stopped > res[y].stopped; });
  const std::size_t presses = n * a.presses;
  std::ostringstream rep;
  rep << "## Light presses: " << Fmt(force_n) << " N (" << Fmt(force_n / rule.threshold_n, "%.2g")
      << " x the threshold " << Fmt(rule.threshold_n) << " N)\n\n"
      << "At each of " << GridText(g, a.step_mm, a.edge_mm) << ", " << a.presses << " presses of " << Fmt(force_n)
      << " N (each jittered within +-" << Fmt(a.jitter_mm, "%.1f") << " mm; rest 0.3 s, ramp 0.05 s, hold "
      << Fmt(a.hold_s, "%g") << " s, release 0.05 s) in one stream per point after a 1.2 s untouched start; "
      << "interrogator noise and jitter from seed DeriveSeed(" << a.seed << ", point) (held out). A press stops "
      << "when a message of the decoder from its rest to its end would stop the aggregator: a contact above the "
      << "threshold (an over-range contact carries its lower bound), a doubt (negative force, position off the "
      << "patch, bad covariance) or a fault.\n\n"
      << "| measure | value |\n| --- | --- |\n"
      << "| points with no STOP in any press (target >= 99 %) | " << clean << " of " << n << " (" << Pct(clean, n) << ") |\n"
      << "| presses that STOP (false stops) | " << stopped << " of " << presses << " (" << Pct(stopped, presses) << ") |\n"
      << "| on the covered surface: points with no STOP / presses that STOP | " << covered_clean << " of " << covered
      << " (" << Pct(covered_clean, covered) << ") / " << covered_stopped << " of " << covered * a.presses << " ("
      << Pct(covered_stopped, covered * a.presses) << ") |\n"
      << "| of them by cause: force above the threshold / over range / doubt / fault | " << by_cause[1] << " / "
      << by_cause[2] << " / " << by_cause[3] << " / " << by_cause[4] << " |\n"
      << "| points with a STOP in the untouched start | " << start << " |\n\n";
  if (!failing.empty()) {
    rep << "Points with a STOP (" << failing.size() << ", most stops first):\n\n"
        << "| Y mm | R deg | presses that STOP | largest force sent, N | causes (force / over range / doubt / fault) | "
           "accepted band |\n"
        << "| --- | --- | --- | --- | --- | --- |\n";
    for (std::size_t k : failing) {
      const LightPoint& p = res[k];
      rep << "| " << Fmt(g.y(k), "%.0f") << " | " << Fmt(g.r(k), "%.0f") << " | " << p.stopped << " of " << a.presses
          << (p.start != StopCause::kNone ? std::string(" (and the start: ") + kStopCauseName[static_cast<std::size_t>(p.start)] + ")" : "")
          << " | " << Fmt(p.max_force_n) << " | " << p.by_cause[1] << " / " << p.by_cause[2] << " / " << p.by_cause[3]
          << " / " << p.by_cause[4] << " | " << bands.Name(g.y(k), g.r(k)) << " |\n";
    }
    rep << "\n";
  }
  if (!base.empty()) {
    std::vector<double> share(n);
    for (std::size_t k = 0; k < n; ++k) {
      share[k] = static_cast<double>(res[k].stopped + (res[k].start != StopCause::kNone ? 1 : 0)) / a.presses;
    }
    SaveGridHeat(g.ys, g.rs, share, put, 0.0, 1.0,
                 "share of presses that STOP (0: none; a stop in the untouched start adds one)",
                 put.name() + ": presses of " + Fmt(force_n) + " N that STOP (threshold " + Fmt(rule.threshold_n) + " N)",
                 base + "-light.svg");
    rep << "Figure: `" << put.name() << "-light.svg` (the share of presses that stop at each point).\n\n";
  }
  return rep.str();
}

// The guarantee between the map's grid points (docs/coverage.md, "Between the grid points"): the scene check judges
// a cell of the map's grid by its corners, so the cell's centre, the point farthest from every corner, is where
// that could be wrong. Presses of press_factor x the threshold (the scene's promise) at every cell centre of the
// map's grid; on the covered surface each must stop in at least `reliability` of its presses, as a map point.
std::string RunFirm(const PatchUnderTest& put, const StopRule& rule, const Bands& bands, const TargetsArgs& a,
                    double press_factor, const std::string& base) {
  const double force_n = a.force_n >= 0 ? a.force_n : press_factor * rule.threshold_n;
  const Grid corners = MakeGrid(put, a.step_mm, a.edge_mm);
  Grid g;  // the cells' centres
  for (std::size_t i = 0; i + 1 < corners.ys.size(); ++i) g.ys.push_back(0.5 * (corners.ys[i] + corners.ys[i + 1]));
  for (std::size_t i = 0; i + 1 < corners.rs.size(); ++i) g.rs.push_back(0.5 * (corners.rs[i] + corners.rs[i + 1]));
  const std::size_t n = g.size();
  const std::uint64_t seed = a.seed + 2;
  spdlog::info("firm presses on {}: {} cell centres x {} presses of {} N, threshold {} N, seeds DeriveSeed({}, point)",
               put.name(), n, a.presses, force_n, rule.threshold_n, seed);
  std::vector<LightPoint> res(n);
  ParallelFor(n, a.threads, "firm presses " + put.name(), [&](std::size_t k) {
    res[k] = MeasureLight(put, rule, a, force_n, g.y(k), g.r(k), twin::DeriveSeed(seed, k));
  });
  // A point is reliable as a map point is: at most (1 - reliability) x presses presses without a stop.
  const auto allowed = static_cast<unsigned>(std::floor((1.0 - a.reliability) * a.presses + 1e-9));
  std::size_t covered = 0, covered_ok = 0, covered_missed = 0, all_ok = 0, start = 0;
  std::vector<std::size_t> failing;
  for (std::size_t k = 0; k < n; ++k) {
    const unsigned missed = a.presses - res[k].stopped;
    const bool ok = missed <= allowed;
    all_ok += ok ? 1 : 0;
    start += res[k].start != StopCause::kNone ? 1 : 0;
    if (bands.Holding(g.y(k), g.r(k)) != nullptr) continue;
    ++covered;
    covered_ok += ok ? 1 : 0;
    covered_missed += missed;
    if (!ok) failing.push_back(k);
  }
  std::stable_sort(failing.begin(), failing.end(), [&](std::size_t x, std::size_t y) { return res[x].stopped < res[y].stopped; });
  std::ostringstream rep;
  rep << "## Firm presses between the map's points: " << Fmt(force_n) << " N (" << Fmt(force_n / rule.threshold_n, "%.3g")
      << " x the threshold " << Fmt(rule.threshold_n) << " N)\n\n"
      << "At the centre of each of the " << n << " cells of the map's grid (" << GridText(corners, a.step_mm, a.edge_mm)
      << "), where the map measured nothing and the scene check takes the cell's weakest corner to stand for it, "
      << a.presses << " presses of " << Fmt(force_n) << " N (the map's press shape: jittered within +-"
      << Fmt(a.jitter_mm, "%.1f") << " mm; rest 0.3 s, ramp 0.05 s, hold " << Fmt(a.hold_s, "%g")
      << " s, release 0.05 s) in one stream per point after a 1.2 s untouched start; seeds DeriveSeed(" << seed
      << ", point) (held out). A centre is reliable when at least " << Fmt(100 * a.reliability, "%.0f") << " % of its presses stop (at most "
      << allowed << " of " << a.presses << " without a stop), as a map point must be.\n\n"
      << "| measure | value |\n| --- | --- |\n"
      << "| covered cell centres (outside the accepted bands) reliably stopped (the guarantee: all) | " << covered_ok
      << " of " << covered << " (" << Pct(covered_ok, covered) << ") |\n"
      << "| presses on the covered surface without a stop | " << covered_missed << " of " << covered * a.presses << " ("
      << Pct(covered_missed, covered * a.presses) << ") |\n"
      << "| all cell centres reliably stopped (the bands included) | " << all_ok << " of " << n << " (" << Pct(all_ok, n) << ") |\n"
      << "| cell centres with a STOP in the untouched start | " << start << " |\n\n";
  if (!failing.empty()) {
    rep << "Covered cell centres not reliably stopped (" << failing.size() << ", fewest stops first):\n\n"
        << "| Y mm | R deg | presses that STOP | largest force sent, N |\n| --- | --- | --- | --- |\n";
    for (std::size_t k : failing) {
      rep << "| " << Fmt(g.y(k), "%.1f") << " | " << Fmt(g.r(k), "%.1f") << " | " << res[k].stopped << " of " << a.presses
          << " | " << Fmt(res[k].max_force_n) << " |\n";
    }
    rep << "\n";
  }
  if (!base.empty()) {
    std::vector<double> share(n);
    for (std::size_t k = 0; k < n; ++k) share[k] = static_cast<double>(res[k].stopped) / a.presses;
    SaveGridHeat(g.ys, g.rs, share, put, 0.0, 1.0, "share of presses that STOP (1: all)",
                 put.name() + ": presses of " + Fmt(force_n) + " N at the map's cell centres that STOP",
                 base + "-firm.svg");
    rep << "Figure: `" << put.name() << "-firm.svg` (the share of presses that stop at each cell centre).\n\n";
  }
  return rep.str();
}

// Hard presses with a light second touch (review 10 finding 2: a light touch elsewhere on the patch hid a 20 N
// press at a covered corner). At every point of the map's grid, each force of pair_forces_n pressed
// pair_presses times, each time while a light touch (pair_light_n, uniform) is held at a random point of the
// patch at least kPairApartMm away: the light touch comes on 0.3 s before the hard press (ramp 0.05 s), the
// hard press ramps over 0.3 s, holds 0.5 s and releases over 0.3 s, then the light touch is lifted. A hard
// press stops when a message from its start to the end of its release would stop the aggregator. A press
// whose light touch alone would stop the aggregator before the hard press comes is not judged (its light
// touch's own stops would be counted for the hard press): it is counted apart, as a false stop.
constexpr double kPairApartMm = 30.0;

struct PairPoint {
  std::vector<unsigned> judged;     // per force: hard presses whose light touch alone did not stop before them
  std::vector<unsigned> stopped;    // per force: of those, hard presses with a stop from their start
  std::vector<float> max_force_n;   // per force: the largest contact force sent while a judged hard press was on
  unsigned light_stops = 0;         // presses whose light touch alone stopped before the hard press came
  StopCause start = StopCause::kNone;
};

PairPoint MeasurePair(const PatchUnderTest& put, const StopRule& rule, const TargetsArgs& a, double y_mm, double r_deg,
                      std::uint64_t seed) {
  MonitoredStream s(put, rule, a.rate_hz, seed);
  std::mt19937_64 rng(twin::DeriveSeed(seed, 7));
  std::uniform_real_distribution<double> uy(0.0, put.spec().extent_y_mm), ur(0.0, put.spec().extent_r_deg),
      lf(a.pair_light_n[0], a.pair_light_n[1]);
  PairPoint out;
  out.judged.assign(a.pair_forces_n.size(), 0);
  out.stopped.assign(a.pair_forces_n.size(), 0);
  out.max_force_n.assign(a.pair_forces_n.size(), 0.0f);
  out.start = UntouchedStart(s, a.rate_hz);
  const double rest = 0.3, lead = 0.3, ramp = 0.3, hold = 0.5, release = 0.3, lift = 0.05, tail = 0.05;
  std::vector<twin::Contact> on;  // the frame's probes (reused: no allocation per frame)
  on.reserve(2);
  for (std::size_t f = 0; f < a.pair_forces_n.size(); ++f) {
    for (unsigned p = 0; p < a.pair_presses; ++p) {
      double ly = 0, lr = 0;
      for (int tries = 0; tries < 1000; ++tries) {
        ly = uy(rng);
        lr = ur(rng);
        if (std::hypot(ly - y_mm, (lr - r_deg) * put.mm_per_deg()) >= kPairApartMm) break;
      }
      const double light_n = lf(rng);
      for (int k = 0; k < static_cast<int>(rest * a.rate_hz); ++k) s.Frame(nullptr);
      s.TakeForces();
      StopCause before = StopCause::kNone, during = StopCause::kNone;
      float max_during = 0.0f;
      const double t_hard = lead, t_end = lead + ramp + hold + release;
      const int n = static_cast<int>((t_end + lift + tail) * a.rate_hz);
      for (int k = 0; k < n; ++k) {
        const double t = k / a.rate_hz;
        double wl = std::min(1.0, t / 0.05), wh = 0.0;
        if (t > t_end) wl = std::max(0.0, 1.0 - (t - t_end) / lift);
        if (t >= t_hard && t < t_hard + ramp) wh = (t - t_hard) / ramp;
        else if (t >= t_hard + ramp && t <= t_hard + ramp + hold) wh = 1.0;
        else if (t > t_hard + ramp + hold && t < t_end) wh = 1.0 - (t - t_hard - ramp - hold) / release;
        on.clear();
        if (wl > 0) on.push_back(twin::Contact{{ly, lr}, wl * light_n, put.scene().probe});
        if (wh > 0) on.push_back(twin::Contact{{y_mm, r_deg}, wh * a.pair_forces_n[f], put.scene().probe});
        if (k == static_cast<int>(t_hard * a.rate_hz)) s.TakeForces();
        const StopCause c = s.Frame(on);
        if (t < t_hard) {
          if (before == StopCause::kNone) before = c;
        } else if (t <= t_end && during == StopCause::kNone) {
          during = c;
        }
        if (k + 1 == static_cast<int>(t_end * a.rate_hz)) max_during = s.TakeForces().max_n;
      }
      if (before != StopCause::kNone) {
        ++out.light_stops;
        continue;
      }
      ++out.judged[f];
      out.stopped[f] += during != StopCause::kNone ? 1 : 0;
      out.max_force_n[f] = std::max(out.max_force_n[f], max_during);
    }
  }
  return out;
}

// The covered surface's border: the points of a 1 mm lattice (Y and arc, 0.5 mm from each edge) that are covered
// while a neighbour 1 mm away is not (held by a band, or off the patch), every 5th along the lattice. The grid
// points and cell centres stop 2.5 mm short of a band that ends on a grid line; this is the strip between.
std::vector<std::array<double, 2>> CoveredBorder(const PatchUnderTest& put, const Bands& bands) {
  const double ly = put.spec().extent_y_mm, la = put.spec().extent_r_deg * put.mm_per_deg();
  const auto ny = static_cast<int>(std::floor(ly - 1.0)) + 1, na = static_cast<int>(std::floor(la - 1.0)) + 1;
  const auto covered = [&](int iy, int ia) {
    if (iy < 0 || ia < 0 || iy >= ny || ia >= na) return false;
    return bands.Holding(0.5 + iy, (0.5 + ia) / put.mm_per_deg()) == nullptr;
  };
  std::vector<std::array<double, 2>> out;
  for (int iy = 0; iy < ny; ++iy) {
    for (int ia = 0; ia < na; ++ia) {
      if (!covered(iy, ia) || (iy + ia) % 5 != 0) continue;
      if (covered(iy - 1, ia) && covered(iy + 1, ia) && covered(iy, ia - 1) && covered(iy, ia + 1)) continue;
      out.push_back({0.5 + iy, (0.5 + ia) / put.mm_per_deg()});
    }
  }
  return out;
}

enum class PairAt { kGrid, kCentres, kBorder };

// One set of hard points: the map's grid points (seed + 3), its cells' centres (seed + 4) or the covered surface's
// border (seed + 5).
std::string RunPairOn(const PatchUnderTest& put, const StopRule& rule, const Bands& bands, const TargetsArgs& a,
                      PairAt at, const std::string& base) {
  const Grid corners = MakeGrid(put, a.step_mm, a.edge_mm);
  Grid g = corners;
  const bool centres = at == PairAt::kCentres;
  if (centres) {
    g = Grid{};
    for (std::size_t i = 0; i + 1 < corners.ys.size(); ++i) g.ys.push_back(0.5 * (corners.ys[i] + corners.ys[i + 1]));
    for (std::size_t i = 0; i + 1 < corners.rs.size(); ++i) g.rs.push_back(0.5 * (corners.rs[i] + corners.rs[i + 1]));
  }
  std::vector<std::array<double, 2>> pts;
  if (at == PairAt::kBorder) {
    pts = CoveredBorder(put, bands);
  } else {
    for (std::size_t k = 0; k < g.size(); ++k) pts.push_back({g.y(k), g.r(k)});
  }
  std::string where;
  if (at == PairAt::kGrid) where = GridText(g, a.step_mm, a.edge_mm);
  if (centres) where = "the centres of the " + std::to_string(g.size()) + " cells of the map's grid (" + GridText(corners, a.step_mm, a.edge_mm) + ")";
  if (at == PairAt::kBorder) {
    where = std::to_string(pts.size()) + " points on the border of the covered surface (of a 1 mm lattice in Y and arc, "
            "0.5 mm from each edge, the covered points next to a band or an edge, every 5th)";
  }
  const std::size_t n = pts.size(), nf = a.pair_forces_n.size();
  const std::uint64_t seed = a.seed + (at == PairAt::kGrid ? 3 : centres ? 4 : 5);
  spdlog::info("hard presses with a light touch on {}: {} points x {} forces x {} presses, light touch {}-{} N, seeds "
               "DeriveSeed({}, point)", put.name(), n, nf, a.pair_presses, a.pair_light_n[0], a.pair_light_n[1], seed);
  std::vector<PairPoint> res(n);
  ParallelFor(n, a.threads, "hard + light " + put.name(), [&](std::size_t k) {
    res[k] = MeasurePair(put, rule, a, pts[k][0], pts[k][1], twin::DeriveSeed(seed, k));
  });
  std::ostringstream rep;
  rep << "## Hard presses with a light second touch, at "
      << (at == PairAt::kGrid ? "the map's grid points" : centres ? "the map's cell centres" : "the covered surface's border") << "\n\n"
      << "At each of " << where << ", " << a.pair_presses << " presses of each of";
  for (double f : a.pair_forces_n) rep << " " << Fmt(f, "%g");
  rep << " N, each while a light touch of " << Fmt(a.pair_light_n[0], "%g") << "-" << Fmt(a.pair_light_n[1], "%g")
      << " N (uniform) is held at a random point of the patch at least " << Fmt(kPairApartMm, "%g")
      << " mm away (it comes on 0.3 s before; the hard press ramps 0.3 s, holds 0.5 s, releases 0.3 s; one stream per "
         "point after a 1.2 s untouched start; seeds DeriveSeed(" << seed << ", point), held out). A hard press stops "
         "when a message from its start to the end of its release would stop the aggregator. A press whose light "
         "touch alone stopped before the hard press came is not judged (the light touch's own stops would count for "
         "it): those are counted apart, as false stops. A point passes a force when every judged press stopped and "
         "at least one was judged.\n\n"
      << "| force, N | covered points that pass (target: all) | judged presses on the covered surface without a stop "
         "| covered points with no press judged | all points that pass |\n| --- | --- | --- | --- | --- |\n";
  const auto passes = [&](std::size_t k, std::size_t f) { return res[k].judged[f] > 0 && res[k].stopped[f] == res[k].judged[f]; };
  std::vector<std::size_t> failing;
  std::size_t covered = 0;
  for (std::size_t k = 0; k < n; ++k) covered += bands.Holding(pts[k][0], pts[k][1]) == nullptr ? 1 : 0;
  for (std::size_t f = 0; f < nf; ++f) {
    std::size_t covered_ok = 0, covered_missed = 0, covered_judged = 0, covered_unjudged = 0, all_ok = 0;
    for (std::size_t k = 0; k < n; ++k) {
      all_ok += passes(k, f) ? 1 : 0;
      if (bands.Holding(pts[k][0], pts[k][1]) != nullptr) continue;
      covered_ok += passes(k, f) ? 1 : 0;
      covered_unjudged += res[k].judged[f] == 0 ? 1 : 0;
      covered_judged += res[k].judged[f];
      covered_missed += res[k].judged[f] - res[k].stopped[f];
    }
    rep << "| " << Fmt(a.pair_forces_n[f], "%g") << " | " << covered_ok << " of " << covered << " (" << Pct(covered_ok, covered)
        << ") | " << covered_missed << " of " << covered_judged << " | " << covered_unjudged << " | " << all_ok << " of "
        << n << " (" << Pct(all_ok, n) << ") |\n";
  }
  std::size_t light_stops = 0, start = 0;
  for (std::size_t k = 0; k < n; ++k) {
    light_stops += res[k].light_stops;
    start += res[k].start != StopCause::kNone ? 1 : 0;
    if (bands.Holding(pts[k][0], pts[k][1]) != nullptr) continue;
    for (std::size_t f = 0; f < nf; ++f) {
      if (res[k].stopped[f] < res[k].judged[f]) {
        failing.push_back(k);
        break;
      }
    }
  }
  rep << "\nThe light touch alone stopped before the hard press (not judged) in " << light_stops << " of "
      << n * nf * a.pair_presses << " presses (" << Pct(light_stops, n * nf * a.pair_presses) << "); " << start
      << " streams stopped in their untouched start.\n\n";
  if (!failing.empty()) {
    rep << "Covered points where a judged hard press did not stop (" << failing.size() << "):\n\n| Y mm | R deg |";
    for (double f : a.pair_forces_n) rep << " " << Fmt(f, "%g") << " N: stopped of judged, largest force sent |";
    rep << "\n| --- | --- |";
    for (std::size_t f = 0; f < nf; ++f) rep << " --- |";
    rep << "\n";
    for (std::size_t k : failing) {
      rep << "| " << Fmt(pts[k][0], "%.1f") << " | " << Fmt(pts[k][1], "%.1f") << " |";
      for (std::size_t f = 0; f < nf; ++f) {
        rep << " " << res[k].stopped[f] << " of " << res[k].judged[f] << ", " << Fmt(res[k].max_force_n[f]) << " N |";
      }
      rep << "\n";
    }
    rep << "\n";
  }
  if (!base.empty() && at != PairAt::kBorder) {
    std::vector<double> share(n);
    for (std::size_t k = 0; k < n; ++k) {
      double least = 1.0;  // NaN (grey) where a force had no judged press
      for (std::size_t f = 0; f < nf; ++f) {
        least = res[k].judged[f] == 0 ? std::numeric_limits<double>::quiet_NaN()
                                      : std::min(least, static_cast<double>(res[k].stopped[f]) / res[k].judged[f]);
        if (std::isnan(least)) break;
      }
      share[k] = least;
    }
    const std::string file = put.name() + (centres ? "-pair-centres.svg" : "-pair.svg");
    SaveGridHeat(g.ys, g.rs, share, put, 0.0, 1.0, "share of judged hard presses that STOP, the weakest force's (1: all; grey: none judged)",
                 put.name() + ": hard presses with a light second touch that STOP" + (centres ? " (cell centres)" : ""),
                 a.report + "/" + file);
    rep << "Figure: `" << file << "` (at each point, the share of presses that stop at its weakest force).\n\n";
  }
  return rep.str();
}

std::string RunPair(const PatchUnderTest& put, const StopRule& rule, const Bands& bands, const TargetsArgs& a,
                    const std::string& base) {
  std::string rep;
  if (a.pair_at == "grid" || a.pair_at == "all") rep += RunPairOn(put, rule, bands, a, PairAt::kGrid, base);
  if (a.pair_at == "centres" || a.pair_at == "all") rep += RunPairOn(put, rule, bands, a, PairAt::kCentres, base);
  if (a.pair_at == "border" || a.pair_at == "all") rep += RunPairOn(put, rule, bands, a, PairAt::kBorder, base);
  return rep;
}

std::string RunSlow(const PatchUnderTest& put, const StopRule& rule, const Bands& bands, const TargetsArgs& a,
                    const std::string& base) {
  if (a.slow_top_n <= rule.threshold_n * (1 + a.band)) {
    throw InputError("--slow-top-n (" + Fmt(a.slow_top_n) + " N) must lie above the band's top (" +
                     Fmt(rule.threshold_n * (1 + a.band)) + " N)");
  }
  const Grid g = MakeGrid(put, a.slow_step_mm, a.edge_mm);
  const std::size_t n = g.size();
  const std::uint64_t seed = a.seed + 1;
  spdlog::info("slow presses on {}: {} points, 0 to {} N at {} N/s, threshold {} N, seeds DeriveSeed({}, point)",
               put.name(), n, a.slow_top_n, a.slow_rate_n_per_s, rule.threshold_n, seed);
  std::vector<SlowPoint> res(n);
  ParallelFor(n, a.threads, "slow presses " + put.name(), [&](std::size_t k) {
    res[k] = MeasureSlow(put, rule, a, g.y(k), g.r(k), twin::DeriveSeed(seed, k));
  });
  const double lo = (1 - a.band) * rule.threshold_n, hi = (1 + a.band) * rule.threshold_n;
  const double t_cross = rule.threshold_n / a.slow_rate_n_per_s;
  std::size_t within = 0, early = 0, late = 0, in_release = 0, never = 0;
  std::array<std::size_t, kStopCauses> by_cause{};
  std::vector<double> forces, delays, near_means, near_sds;
  std::vector<std::size_t> failing;
  std::size_t early_biased = 0, covered = 0, covered_within = 0, covered_never = 0;
  std::vector<double> covered_forces;
  for (std::size_t k = 0; k < n; ++k) {
    const SlowPoint& p = res[k];
    if (bands.Holding(g.y(k), g.r(k)) == nullptr) {
      ++covered;
      covered_within += std::isfinite(p.true_force_n) && p.true_force_n >= lo && p.true_force_n <= hi ? 1 : 0;
      covered_never += std::isfinite(p.true_force_n) ? 0 : 1;
      if (std::isfinite(p.true_force_n)) covered_forces.push_back(p.true_force_n);
    }
    ++by_cause[static_cast<std::size_t>(p.cause)];
    if (std::isfinite(p.near_mean_n)) {
      near_means.push_back(p.near_mean_n);
      near_sds.push_back(p.near_sd_n);
    }
    if (std::isfinite(p.true_force_n) && p.true_force_n < lo && p.near_mean_n > rule.threshold_n) ++early_biased;
    if (std::isfinite(p.true_force_n)) {
      forces.push_back(p.true_force_n);
      delays.push_back(p.t_s - t_cross);
    }
    if (p.cause == StopCause::kNone) ++never;
    else if (p.in_release) ++in_release;
    else if (p.true_force_n < lo) ++early;
    else if (p.true_force_n > hi) ++late;
    else ++within;
    if (!(std::isfinite(p.true_force_n) && p.true_force_n >= lo && p.true_force_n <= hi)) failing.push_back(k);
  }
  std::ostringstream rep;
  rep << "## Slow press: 0 to " << Fmt(a.slow_top_n) << " N at " << Fmt(a.slow_rate_n_per_s) << " N/s, threshold "
      << Fmt(rule.threshold_n) << " N\n\n"
      << "At each of " << GridText(g, a.slow_step_mm, a.edge_mm) << ", one press exactly at the point (after a 1.2 s "
      << "untouched start): the force ramps from 0 to " << Fmt(a.slow_top_n) << " N in "
      << Fmt(a.slow_top_n / a.slow_rate_n_per_s, "%g") << " s, then is released over 0.3 s; interrogator noise from "
      << "seed DeriveSeed(" << seed << ", point) (held out). The true force when the first message that would stop "
      << "the aggregator is sent (as for the light presses) must lie within +-" << Fmt(100 * a.band, "%.0f")
      << " % of the threshold, [" << Fmt(lo, "%.3f") << ", " << Fmt(hi, "%.3f") << "] N.\n\n"
      << "| measure | value |\n| --- | --- |\n"
      << "| points whose first STOP is within the band (target >= 95 %) | " << within << " of " << n << " ("
      << Pct(within, n) << ") |\n"
      << "| on the covered surface: within the band; no STOP in the ramp; true force at the first STOP p5 / p50 / p95 | "
      << covered_within << " of " << covered << " (" << Pct(covered_within, covered) << "); " << covered_never << "; "
      << Fmt(Quantile(covered_forces, 0.05), "%.3f") << " / " << Fmt(Quantile(covered_forces, 0.5), "%.3f") << " / "
      << Fmt(Quantile(covered_forces, 0.95), "%.3f") << " N |\n"
      << "| first STOP below the band (early) / above it in the ramp (late) / only in the release / none | " << early
      << " / " << late << " / " << in_release << " / " << never << " |\n"
      << "| first STOP by cause: force above the threshold / over range / doubt / fault | " << by_cause[1] << " / "
      << by_cause[2] << " / " << by_cause[3] << " / " << by_cause[4] << " |\n"
      << "| true force at the first STOP, p5 / p50 / p95 (the " << forces.size() << " points stopped in the ramp) | "
      << Fmt(Quantile(forces, 0.05), "%.3f") << " / " << Fmt(Quantile(forces, 0.5), "%.3f") << " / "
      << Fmt(Quantile(forces, 0.95), "%.3f") << " N |\n"
      << "| delay after the true crossing, p50 / p95 (same points; negative: before it) | "
      << Fmt(1e3 * Quantile(delays, 0.5), "%.0f") << " / " << Fmt(1e3 * Quantile(delays, 0.95), "%.0f") << " ms |\n"
      << "| decoded force while the true force is within +-" << Fmt(100 * kNearThreshold, "%.0f")
      << " % of the threshold: its mean per point, p5 / p50 / p95 (the " << near_means.size()
      << " points with contact frames there) | " << Fmt(Quantile(near_means, 0.05), "%.3f") << " / "
      << Fmt(Quantile(near_means, 0.5), "%.3f") << " / " << Fmt(Quantile(near_means, 0.95), "%.3f") << " N |\n"
      << "| its standard deviation per point (frame to frame), p50 / p95 | " << Fmt(Quantile(near_sds, 0.5), "%.3f")
      << " / " << Fmt(Quantile(near_sds, 0.95), "%.3f") << " N |\n"
      << "| early points whose mean there is above the threshold (biased high; the others stopped on the noise) | "
      << early_biased << " of " << early << " |\n\n";
  if (!failing.empty()) {
    rep << "Points outside the band (" << failing.size() << "):\n\n"
        << "| Y mm | R deg | true force at the first STOP, N | cause | largest force sent in the ramp, N | decoded "
           "force at the true threshold (+-" << Fmt(100 * kNearThreshold, "%.0f") << " %), mean +- sd, N | accepted band |\n"
        << "| --- | --- | --- | --- | --- | --- | --- |\n";
    for (std::size_t k : failing) {
      const SlowPoint& p = res[k];
      rep << "| " << Fmt(g.y(k), "%.0f") << " | " << Fmt(g.r(k), "%.0f") << " | "
          << (p.cause == StopCause::kNone ? "no STOP" : p.in_release ? "only in the release" : Fmt(p.true_force_n, "%.3f"))
          << " | " << kStopCauseName[static_cast<std::size_t>(p.cause)] << " | " << Fmt(p.max_force_n) << " | "
          << (std::isfinite(p.near_mean_n) ? Fmt(p.near_mean_n) + " +- " + Fmt(p.near_sd_n) : "no contact") << " | "
          << bands.Name(g.y(k), g.r(k)) << " |\n";
    }
    rep << "\n";
  }
  if (!base.empty()) {
    std::vector<double> ratio(n);
    for (std::size_t k = 0; k < n; ++k) ratio[k] = res[k].true_force_n / rule.threshold_n;
    SaveGridHeat(g.ys, g.rs, ratio, put, 0.5, 1.5,
                 "true force at the first STOP / threshold (band " + Fmt(1 - a.band) + ".." + Fmt(1 + a.band) +
                     ", scale clipped to 0.5..1.5); grey: none in the ramp",
                 put.name() + ": slow press (" + Fmt(a.slow_rate_n_per_s) + " N/s), true force at the first STOP",
                 base + "-slow.svg");
    // The distribution: every point's ratio, sorted; the points without a stop in the ramp sit at the top.
    plot::Figure fig(put.name() + ": slow press, true force at the first STOP (sorted points)", "share of points",
                     "true force / threshold", 640, 420);
    plot::Series pts{"points stopped in the ramp", {}, {}, "#1f77b4", plot::Series::Style::kPoints};
    std::vector<double> sorted = ratio;
    std::sort(sorted.begin(), sorted.end(), [](double x, double y) { return std::isnan(y) ? !std::isnan(x) : x < y; });
    for (std::size_t k = 0; k < sorted.size() && std::isfinite(sorted[k]); ++k) {
      pts.x.push_back((static_cast<double>(k) + 0.5) / static_cast<double>(n));
      pts.y.push_back(sorted[k]);
    }
    fig.Add(pts);
    fig.AddHLine(1 - a.band, "band");
    fig.AddHLine(1 + a.band, "band");
    fig.AddHLine(1.0, "threshold");
    fig.SetXRange(0, 1).SetYRange(0, a.slow_top_n / rule.threshold_n);
    fig.Save(base + "-slow-sorted.svg");
    rep << "Figures: `" << put.name() << "-slow.svg` (the ratio at each point), `" << put.name()
        << "-slow-sorted.svg` (all points' ratios, sorted).\n\n";
  }
  return rep.str();
}

void RunTargets(const TargetsArgs& a, const std::string& command) {
  if (a.target != "light" && a.target != "slow" && a.target != "both" && a.target != "firm" && a.target != "pair" &&
      a.target != "all") {
    throw InputError("--target must be light, slow, both (light and slow), firm, pair or all (got '" + a.target + "')");
  }
  if (a.pair_at != "grid" && a.pair_at != "centres" && a.pair_at != "border" && a.pair_at != "all") {
    throw InputError("--pair-at must be grid, centres, border or all (got '" + a.pair_at + "')");
  }
  // CLI11's Range lets NaN through (every comparison with it is false): each force is checked here.
  if (!(std::isfinite(a.pair_light_n[0]) && std::isfinite(a.pair_light_n[1]) && a.pair_light_n[0] >= 0 &&
        a.pair_light_n[1] >= a.pair_light_n[0])) {
    throw InputError("--pair-light-n: the light touch's range must be two finite forces >= 0, the first not above the second");
  }
  for (double f : a.pair_forces_n) {
    if (!(std::isfinite(f) && f > 0)) throw InputError("--pair-forces-n: every hard force must be finite and above 0 N (got " + Fmt(f, "%g") + ")");
  }
  const PatchUnderTest put(a.scene, a.patch, a.model);
  // The scene's safety section (thresholds, input limits, accepted bands); a scene without one needs
  // --level-n and is judged with the default input limits, no band accepted.
  const SceneFile file = LoadSceneFile(a.scene);
  safety::Config safety;
  if (file.safety) safety = safety::ConfigFromScene(file);
  else if (!(a.level_n > 0)) throw InputError(a.scene + " has no safety section: give --level-n");
  StopRule rule;
  rule.input = safety.input;
  rule.stop = safety.stop_rule;
  if (a.sd_k_set) rule.stop.sd_k = static_cast<float>(a.sd_k);
  rule.extent_y_mm = put.spec().extent_y_mm;
  rule.extent_r_deg = put.spec().extent_r_deg;
  std::string region;
  for (const auto& p : safety.patches) {
    if (p.id == put.name()) region = p.region;
  }
  for (const auto& r : safety.regions) {
    if (r.name == region) rule.threshold_n = r.threshold_n;
  }
  if (a.level_n > 0) rule.threshold_n = a.level_n;
  if (!(rule.threshold_n > 0)) throw InputError(a.scene + ": patch " + put.name() + " has no region threshold: give --level-n");
  std::string base;
  if (!a.report.empty()) {
    std::filesystem::create_directories(a.report);
    base = a.report + "/" + put.name();
  }
  std::ostringstream rep;
  rep << "# Targets: " << put.name() << " (" << put.spec().name << "), threshold " << Fmt(rule.threshold_n) << " N\n\n"
      << "Stop rule: force + " << Fmt(rule.stop.sd_k, "%.2f") << " x sd above the threshold (safety::JudgedForce; an sd "
      << "counted at most " << Fmt(rule.stop.max_sd_n, "%.2f") << " N when lowering).\n\n"
      << "Model: `" << put.model_path() << "`. Scene: `" << a.scene << "` (the patch's twin as ruffini-sim builds it, "
      << "its edges included). Measured by `" << command << "`.\n\n"
      << "Each point is one stream through the decoder service's whole path without sockets: the twin, the "
      << "interrogator simulation, Hyperion bytes, the ingest codec, link::Monitor over the default pipeline "
      << "(paper-float). Seeds are held out: training used 1, calibration 2 and field 10, test 3 and field 4.\n\n";
  Bands bands;
  for (const auto& b : safety.coverage.accepted_uncovered) {
    if (b.patch.empty() || b.patch == put.name()) bands.bands.push_back(b);
  }
  rep << "The covered surface: the grid points outside the scene's " << bands.bands.size()
      << " accepted uncovered bands on this patch (safety.coverage.accepted_uncovered";
  for (std::size_t i = 0; i < bands.bands.size(); ++i) {
    const auto& b = bands.bands[i];
    rep << (i == 0 ? ": " : ", ") << b.name << " Y " << Fmt(b.y_min_mm, "%g") << ".." << Fmt(b.y_max_mm, "%g") << " R "
        << Fmt(b.r_min_deg, "%g") << ".." << Fmt(b.r_max_deg, "%g");
  }
  rep << "), where the scene admits its threshold is not guaranteed.\n\n";
  if (a.target == "light" || a.target == "both" || a.target == "all") rep << RunLight(put, rule, bands, a, base);
  if (a.target == "slow" || a.target == "both" || a.target == "all") rep << RunSlow(put, rule, bands, a, base);
  if (a.target == "firm" || a.target == "all") rep << RunFirm(put, rule, bands, a, safety.coverage.press_factor, base);
  if (a.target == "pair" || a.target == "all") rep << RunPair(put, rule, bands, a, base);
  std::printf("%s", rep.str().c_str());
  if (!base.empty()) {
    std::ofstream(base + ".md") << rep.str();
    spdlog::info("report: {}.md", base);
  }
}

void RegisterTargets(CLI::App& app) {
  auto a = std::make_shared<TargetsArgs>();
  CLI::App* cmd = app.add_subcommand(
      "coverage-targets",
      "Measure issue 16's light-press and slow-press targets on held-out twin presses over a patch: light presses "
      "(0.5 x the threshold) must not STOP, a slow press must STOP within +-15 % of the threshold, and (firm) presses of "
      "the scene's press factor x the threshold STOP between the sensitivity map's points");
  cmd->add_option("--scene", a->scene, "Scene YAML (its twin, the patch's edges, its region thresholds)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--patch", a->patch, "Patch of the scene (default: the first)");
  cmd->add_option("--model", a->model, "Model file (default: the scene's for the patch)")->check(CLI::ExistingFile);
  cmd->add_option("--report", a->report, "Report folder: PATCH.md, PATCH-light.svg, PATCH-slow.svg, PATCH-slow-sorted.svg");
  cmd->add_option("--target", a->target,
                  "light, slow, both (light and slow), firm (presses of the scene's press_factor x the threshold at the "
                  "centres of the map grid's cells: the guarantee between the map's points), pair (hard presses at every "
                  "grid point, each with a light touch held elsewhere on the patch) or all")
      ->capture_default_str();
  cmd->add_option("--pair-forces-n", a->pair_forces_n, "Pair: the hard presses' forces, N")
      ->check(CLI::Range(0.01, 1000.0))->check(FiniteNumber())->capture_default_str();
  cmd->add_option("--pair-light-n", a->pair_light_n, "Pair: the light touch's force range, N (uniform)")
      ->check(CLI::Range(0.0, 100.0))->check(FiniteNumber())->capture_default_str();
  cmd->add_option("--pair-presses", a->pair_presses, "Pair: presses per force per point")
      ->check(CLI::Range(1u, 100u))->capture_default_str();
  cmd->add_option("--pair-at", a->pair_at, "Pair: the hard presses at the map's grid points, its cells' centres, the covered surface's border (1 mm "
                  "inside the accepted bands and the edges) or all")
      ->capture_default_str();
  cmd->add_option("--reliability", a->reliability, "Firm presses: the share of a cell centre's presses that must stop")
      ->check(CLI::Range(0.5, 1.0))->check(FiniteNumber())->capture_default_str();
  cmd->add_option("--level-n", a->level_n, "The threshold, N (default: the patch's region threshold in the scene)")
      ->check(CLI::Range(0.01, 1000.0))->check(FiniteNumber());
  cmd->add_option("--force-n", a->force_n, "Light presses' force, N (default: --light-factor x the threshold)")
      ->check(CLI::Range(0.0, 1000.0))->check(FiniteNumber());
  cmd->add_option("--light-factor", a->light_factor, "Light presses' force as a multiple of the threshold")
      ->check(CLI::Range(0.0, 10.0))->check(FiniteNumber())->capture_default_str();
  cmd->add_option("--presses", a->presses, "Light presses per point")->check(CLI::Range(1u, 1000u))->capture_default_str();
  cmd->add_option("--hold-s", a->hold_s, "Light presses' hold, s")->check(CLI::Range(0.01, 10.0))->check(FiniteNumber())->capture_default_str();
  cmd->add_option("--step-mm", a->step_mm, "Light presses' grid step in Y and in arc, mm")->check(CLI::Range(1.0, 50.0))->check(FiniteNumber())->capture_default_str();
  cmd->add_option("--slow-step-mm", a->slow_step_mm, "Slow presses' grid step in Y and in arc, mm")
      ->check(CLI::Range(1.0, 50.0))->check(FiniteNumber())->capture_default_str();
  cmd->add_option("--edge-mm", a->edge_mm, "Grid points this far from each edge, mm")->check(CLI::Range(0.5, 40.0))->check(FiniteNumber())->capture_default_str();
  cmd->add_option("--jitter-mm", a->jitter_mm, "Each light press lands within +- this of its point (Y and arc), mm")
      ->check(CLI::Range(0.0, 5.0))->check(FiniteNumber())->capture_default_str();
  cmd->add_option("--slow-rate", a->slow_rate_n_per_s, "Slow press's rate, N/s")->check(CLI::Range(0.01, 100.0))->check(FiniteNumber())->capture_default_str();
  cmd->add_option("--slow-top-n", a->slow_top_n, "Slow press's top force, N")->check(CLI::Range(0.1, 1000.0))->check(FiniteNumber())->capture_default_str();
  cmd->add_option("--band", a->band, "Slow press: the first STOP's true force within +- this share of the threshold")
      ->check(CLI::Range(0.01, 1.0))->check(FiniteNumber())->capture_default_str();
  cmd->add_option("--seed", a->seed, "Light presses' seed (slow: seed + 1, firm: seed + 2, pair: seed + 3, 4 and 5); keep it away from the training, calibration "
                                     "and test seeds")->capture_default_str();
  cmd->add_option("--threads", a->threads, "Worker threads")->check(CLI::Range(1u, 64u))->capture_default_str();
  cmd->add_option_function<double>("--sd-k", [a](double k) { a->sd_k = k; a->sd_k_set = true; },
                                   "The stop rule's sd_k (default: the scene's safety.stop_rule): stop when force + sd_k x sd "
                                   "is above the threshold")
      ->check(CLI::Range(-3.0, 3.0))->check(FiniteNumber());
  cmd->callback([a, cmd] { RunTargets(*a, CommandLine("coverage-targets", *cmd)); });
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
    std::size_t covered = 0;
    for (const auto& g : c.guarantees) covered += g.covered_points;
    // A scene whose bands accept everything promises nothing; it loads, and says so (review 10, finding 7).
    std::printf(covered == 0 ? "ok, but nothing is covered: every patch is accepted as uncovered, nothing is promised\n"
                             : "ok: every region's threshold is guaranteed on its covered surface\n");
  });
}

}  // namespace

void RegisterCoverageCommands(CLI::App& app) {
  RegisterSensitivity(app);
  RegisterTargets(app);
  RegisterCheckScene(app);
}

}  // namespace ruffini::cli
