#include "ruffini/twin/protocols.h"

#include <cmath>
#include <limits>
#include <random>

#include "ruffini/error.h"
#include "ruffini/patch/edge_distance.h"
#include "ruffini/yaml_reader.h"
#include "ruffini/twin/viscoelastic.h"

namespace ruffini::twin {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr std::size_t kBlock = 4096;

// Turns contacts into frames (twin -> interrogator -> labels) and hands them to the sink in blocks.
class Recorder {
 public:
  Recorder(const SkinTwin& twin, std::uint64_t seed, double rate_hz, const FrameSink& sink)
      : twin_(twin), sim_(twin, seed), dt_(1.0 / rate_hz), sink_(sink) {
    block_.reserve(kBlock);
  }
  // No flush here: a sink that threw must not be called again while unwinding. Callers Flush() at the end.
  ~Recorder() = default;

  // Returns the frame's flags.
  std::uint32_t Emit(std::span<const Contact> contacts, float force_label, float true_force, float y, float r, int indentation) {
    dataset::Frame f;
    Shifts s;
    std::uint32_t flags = 0;
    twin_.StrainShiftsPm(contacts, s, flags);
    const double t = static_cast<double>(serial_) * dt_;
    sim_.Read(t, s, f.wavelength_nm, flags);
    f.t_s = t;
    f.serial = serial_++;
    f.flags = flags;
    f.force_n = force_label;
    f.true_force_n = true_force;
    f.y_mm = y;
    f.r_deg = r;
    f.indentation = indentation;
    block_.push_back(f);
    if (block_.size() == kBlock) Flush();
    return flags;
  }
  void Flush() {
    if (block_.empty()) return;
    std::vector<dataset::Frame> out;
    out.swap(block_);  // if the sink throws, the block is gone and nothing is written twice
    block_.reserve(kBlock);
    sink_(out);
  }
  [[nodiscard]] std::uint64_t frames() const { return serial_; }

 private:
  const SkinTwin& twin_;
  InterrogatorSim sim_;
  double dt_;
  const FrameSink& sink_;
  std::vector<dataset::Frame> block_;
  std::uint64_t serial_ = 0;
};

class LoadCellModel {
 public:
  LoadCellModel(const LoadCell& lc, std::uint64_t seed) : lc_(lc), rng_(seed) {}
  float Read(double force_n) {
    double v = force_n + lc_.noise_n * normal_(rng_);
    if (lc_.resolution_n > 0) v = std::round(v / lc_.resolution_n) * lc_.resolution_n;
    return static_cast<float>(v);
  }

 private:
  LoadCell lc_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
};

// The force-controlled protocols move a spherical probe through the contact law; anything else is an error.
const ContactLaw* RequireSphere(const SkinTwin& twin, const Scene& scene, const char* protocol) {
  const ContactLaw* law = scene.probe.shape == Probe::Shape::kSphere ? twin.contact_law(scene.probe) : nullptr;
  if (law == nullptr) {
    throw InputError(scene.source + ": the " + std::string(protocol) +
                     " protocol needs a spherical probe the twin was built for (twin.probe.shape: sphere)");
  }
  return law;
}

// What the probe does -> the contacts the twin sees. Without the viscoelastic effect: the applied contact
// itself, exactly as the protocols always emitted it. With it: the filtered force at the current site plus
// the fading residuals of the sites pressed before.
class Loads {
 public:
  Loads(const SkinTwin& twin, double rate_hz, const Probe& probe)
      : visco_(twin.effects().viscoelastic.has_value()),
        sites_(visco_ ? &*twin.effects().viscoelastic : nullptr, 1.0 / rate_hz, probe), probe_(probe) {}
  void MoveTo(const patch::SurfacePoint& at) {
    at_ = at;
    sites_.MoveTo(at);
  }
  // Probe on the skin at the current site with this force (0 allowed: touching, not pressing).
  std::span<const Contact> Press(double force_n) {
    if (visco_) return sites_.Step(force_n);
    applied_ = Contact{at_, force_n, probe_};
    return {&applied_, 1};
  }
  // Probe off the skin.
  std::span<const Contact> Release() { return visco_ ? sites_.Step(0.0) : std::span<const Contact>{}; }

 private:
  bool visco_;
  ViscoelasticSites sites_;
  Probe probe_;
  patch::SurfacePoint at_{};
  Contact applied_{};
};

patch::SurfacePoint UniformIn(const patch::Region& a, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const double y = a.y_min_mm + (a.y_max_mm - a.y_min_mm) * u(rng);
  const double r = a.r_min_deg + (a.r_max_deg - a.r_min_deg) * u(rng);
  return {y, r};
}

}  // namespace

dataset::DatasetInfo TwinDatasetInfo(const SkinTwin& twin, const Scene& scene, const std::string& protocol,
                                     std::uint64_t seed, double rate_hz) {
  dataset::DatasetInfo info;
  info.sample_rate_hz = rate_hz;
  info.source = "twin: scene=" + scene.name + ", seed=" + std::to_string(seed) + ", effects=" + twin.effects().Summary();
  info.patch_name = twin.spec().name;
  info.surface_radius_mm = twin.spec().surface_radius_mm;
  info.reference_wavelength_nm = twin.reference_wavelength_nm();
  info.attributes = {{"protocol", protocol}, {"scene", scene.name}, {"seed", std::to_string(seed)},
                     {"effects", twin.effects().Summary()}, {"patch_fingerprint", twin.spec().Fingerprint()}};
  return info;
}

ProtocolRun RunPaper(const SkinTwin& twin, const Scene& scene, const PaperProtocol& p, std::uint64_t seed,
                     const FrameSink& sink, const ProgressFn& progress) {
  Recorder rec(twin, DeriveSeed(seed, 1), p.rate_hz, sink);
  LoadCellModel cell(scene.load_cell, DeriveSeed(seed, 2));
  std::mt19937_64 rng(DeriveSeed(seed, 3));
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const ContactLaw* law = RequireSphere(twin, scene, "paper");
  const patch::Region area = twin.spec().indented_area;

  Loads loads(twin, p.rate_hz, scene.probe);
  for (int i = 0; i < p.rest_frames; ++i) rec.Emit(loads.Release(), cell.Read(0.0), 0.0f, kNaN, kNaN, -1);
  for (int k = 0; k < p.indentations; ++k) {
    const patch::SurfacePoint at = UniformIn(area, rng);
    const double gap = p.approach_mm * (1.0 + p.approach_jitter * (2.0 * u(rng) - 1.0));
    loads.MoveTo(at);
    for (int n = 0;; ++n) {
      const double travel = p.speed_mm_s * n / p.rate_hz - gap;
      const double depth = std::max(0.0, travel);
      const double force = law->ForceN(depth);
      if (force > p.max_force_n) break;  // only the increasing-load phase is kept
      rec.Emit(loads.Press(force), cell.Read(force), static_cast<float>(force),
               static_cast<float>(at.y_mm), static_cast<float>(at.r_deg), k);
    }
    if (progress && (k % 16 == 15 || k + 1 == p.indentations)) progress(static_cast<std::uint64_t>(k + 1), static_cast<std::uint64_t>(p.indentations));
  }
  rec.Flush();
  return {rec.frames(), p.indentations};
}

void CoverageProtocol::Validate() const {
  auto fail = [](const std::string& what) { throw InputError("coverage protocol: " + what); };
  if (indentations < 1) fail("indentations (" + std::to_string(indentations) + ") must be at least 1");
  if (!(rate_hz > 0.0) || !std::isfinite(rate_hz)) fail("rate_hz (" + FormatNumber(rate_hz) + ") must be positive");
  if (!(speed_mm_s > 0.0) || !std::isfinite(speed_mm_s)) fail("speed_mm_s (" + FormatNumber(speed_mm_s) + ") must be positive");
  if (!(force_min_n > 0.0) || !std::isfinite(force_min_n)) fail("force_min_n (" + FormatNumber(force_min_n) + ") must be positive");
  if (!(force_max_n == 0.0 || (force_max_n >= force_min_n && std::isfinite(force_max_n)))) {
    fail("force_max_n (" + FormatNumber(force_max_n) + ") must be 0 (the linear limit) or at least force_min_n (" +
         FormatNumber(force_min_n) + ")");
  }
  if (!(edge_fraction >= 0.0 && edge_fraction <= 1.0)) fail("edge_fraction (" + FormatNumber(edge_fraction) + ") must be 0..1");
  if (!(edge_band_mm > 0.0) || !std::isfinite(edge_band_mm)) fail("edge_band_mm (" + FormatNumber(edge_band_mm) + ") must be positive");
  if (!(approach_mm >= 0.0) || !std::isfinite(approach_mm)) fail("approach_mm (" + FormatNumber(approach_mm) + ") must be >= 0");
  if (!(approach_jitter >= 0.0 && approach_jitter < 1.0)) fail("approach_jitter (" + FormatNumber(approach_jitter) + ") must be 0..1");
  if (rest_frames < 0) fail("rest_frames (" + std::to_string(rest_frames) + ") must be >= 0");
}

ProtocolRun RunCoverage(const SkinTwin& twin, const Scene& scene, const CoverageProtocol& p, std::uint64_t seed,
                        const FrameSink& sink, const ProgressFn& progress) {
  p.Validate();
  Recorder rec(twin, DeriveSeed(seed, 1), p.rate_hz, sink);
  LoadCellModel cell(scene.load_cell, DeriveSeed(seed, 2));
  std::mt19937_64 rng(DeriveSeed(seed, 6));
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const ContactLaw* law = RequireSphere(twin, scene, "coverage");
  const patch::PatchSpec& spec = twin.spec();
  const patch::Region whole = spec.Extent();
  const double f_lo = p.force_min_n;
  const double f_hi = p.force_max_n > 0.0 ? p.force_max_n : law->linear_limit_force_n();
  if (!(f_hi >= f_lo)) {
    throw InputError("coverage protocol: force_min_n (" + FormatNumber(f_lo) + " N) exceeds the contact law's linear limit (" +
                     FormatNumber(f_hi) + " N)");
  }
  // Points within the band: drawn uniformly over the patch until one lies in it (the band is a third of the
  // paper patch: a few draws). A band wider than half the patch is all of it.
  auto in_band = [&] {
    for (;;) {
      const patch::SurfacePoint at = UniformIn(whole, rng);
      if (patch::EdgeDistanceMm(spec, at) < p.edge_band_mm) return at;
    }
  };

  Loads loads(twin, p.rate_hz, scene.probe);
  for (int i = 0; i < p.rest_frames; ++i) rec.Emit(loads.Release(), cell.Read(0.0), 0.0f, kNaN, kNaN, -1);
  for (int k = 0; k < p.indentations; ++k) {
    // Every draw of a press, in a fixed order, before any frame: the same seed gives the same presses.
    const bool edge = u(rng) < p.edge_fraction;
    const patch::SurfacePoint at = edge ? in_band() : UniformIn(whole, rng);
    const double peak = std::exp(std::log(f_lo) + (std::log(f_hi) - std::log(f_lo)) * u(rng));
    const double gap = p.approach_mm * (1.0 + p.approach_jitter * (2.0 * u(rng) - 1.0));
    loads.MoveTo(at);
    for (int n = 0;; ++n) {
      const double travel = p.speed_mm_s * n / p.rate_hz - gap;
      const double force = law->ForceN(std::max(0.0, travel));
      if (force > peak) break;  // only the increasing-load phase is kept
      const std::uint32_t flags = rec.Emit(loads.Press(force), cell.Read(force), static_cast<float>(force),
                                           static_cast<float>(at.y_mm), static_cast<float>(at.r_deg), k);
      if (flags & kFlagSaturated) break;  // over range from here on: one such frame is kept
    }
    if (progress && (k % 16 == 15 || k + 1 == p.indentations)) progress(static_cast<std::uint64_t>(k + 1), static_cast<std::uint64_t>(p.indentations));
  }
  rec.Flush();
  return {rec.frames(), p.indentations};
}

ProtocolRun RunVonFrey(const SkinTwin& twin, const VonFreyProtocol& p, std::uint64_t seed, const FrameSink& sink,
                       const ProgressFn& progress) {
  Recorder rec(twin, DeriveSeed(seed, 1), p.rate_hz, sink);
  std::mt19937_64 rng(DeriveSeed(seed, 4));
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const patch::Region area = twin.spec().indented_area;
  const patch::Geometry& geo = twin.geometry();
  const int total = static_cast<int>(p.filaments_g.size()) * p.subjects * p.sites;
  Loads loads(twin, p.rate_hz, Probe{Probe::Shape::kPoint, p.tip_radius_mm});
  int index = 0;
  for (int s = 0; s < p.subjects; ++s) {
    for (double grams : p.filaments_g) {
      for (int k = 0; k < p.sites; ++k) {
        patch::SurfacePoint at;
        if (p.near_grating_mm > 0) {
          const auto g = static_cast<std::size_t>(u(rng) * patch::kGratings) % patch::kGratings;
          const double rad = p.near_grating_mm * std::sqrt(u(rng)), ang = 2 * std::numbers::pi * u(rng);
          at = twin.grating_centres()[g];
          at.y_mm += rad * std::cos(ang);
          at.r_deg += geo.RDeg(rad * std::sin(ang));
        } else {
          at = UniformIn(area, rng);
        }
        const double f_nom = GramsToNewtons(grams);
        const auto y = static_cast<float>(at.y_mm), r = static_cast<float>(at.r_deg);
        for (int n = 0; n < p.rest_frames; ++n) rec.Emit(loads.Release(), 0.0f, 0.0f, kNaN, kNaN, -1);
        loads.MoveTo(at);
        auto emit_force = [&](double f) {
          rec.Emit(loads.Press(f), static_cast<float>(f), static_cast<float>(f), y, r, index);
        };
        for (int n = 1; n <= p.ramp_frames; ++n) emit_force(f_nom * n / p.ramp_frames);
        for (int n = 0; n < p.hold_frames; ++n) emit_force(f_nom);
        for (int n = p.release_frames - 1; n >= 0; --n) emit_force(f_nom * n / p.release_frames);
        ++index;
      }
      if (progress) progress(static_cast<std::uint64_t>(index), static_cast<std::uint64_t>(total));
    }
  }
  rec.Flush();
  return {rec.frames(), index};
}

ProtocolRun RunReceptiveField(const SkinTwin& twin, const Scene& scene, const ReceptiveFieldProtocol& p,
                              std::uint64_t seed, const FrameSink& sink, const ProgressFn& progress) {
  Recorder rec(twin, DeriveSeed(seed, 1), p.rate_hz, sink);
  LoadCellModel cell(scene.load_cell, DeriveSeed(seed, 2));
  (void)RequireSphere(twin, scene, "receptive-field");
  const patch::Region area = twin.spec().indented_area;
  const patch::Geometry& geo = twin.geometry();
  const double arc0 = geo.ArcMm(area.r_min_deg), arc1 = geo.ArcMm(area.r_max_deg);
  const int ny = static_cast<int>(std::floor((area.y_max_mm - area.y_min_mm) / p.step_mm)) + 1;
  const int na = static_cast<int>(std::floor((arc1 - arc0) / p.step_mm)) + 1;
  Loads loads(twin, p.rate_hz, scene.probe);
  int index = 0;
  for (int i = 0; i < ny; ++i) {
    for (int j = 0; j < na; ++j) {
      const patch::SurfacePoint at{area.y_min_mm + i * p.step_mm, geo.RDeg(arc0 + j * p.step_mm)};
      loads.MoveTo(at);
      for (int n = 0; n <= p.ramp_frames; ++n) {
        const double f = p.max_force_n * n / p.ramp_frames;
        rec.Emit(loads.Press(f), cell.Read(f), static_cast<float>(f), static_cast<float>(at.y_mm),
                 static_cast<float>(at.r_deg), index);
      }
      ++index;
    }
    if (progress) progress(static_cast<std::uint64_t>(i + 1), static_cast<std::uint64_t>(ny));
  }
  rec.Flush();
  return {rec.frames(), index};
}

void FieldProtocol::Validate() const {
  auto fail = [](const std::string& what) { throw InputError("field protocol: " + what); };
  auto positive = [&](const char* name, double v) {
    if (!(v > 0.0) || !std::isfinite(v)) fail(std::string(name) + " (" + FormatNumber(v) + ") must be positive");
  };
  auto range = [&](const char* lo_name, double lo, const char* hi_name, double hi) {
    if (!(lo >= 0.0) || !std::isfinite(hi)) {
      fail(std::string(lo_name) + " (" + FormatNumber(lo) + ") and " + hi_name + " must be finite and >= 0");
    }
    if (lo > hi) {
      fail(std::string(lo_name) + " (" + FormatNumber(lo) + ") must not exceed " + hi_name + " (" + FormatNumber(hi) + ")");
    }
  };
  positive("duration_s", duration_s);
  positive("rate_hz", rate_hz);
  range("first_rest_s", first_rest_s, "duration_s", duration_s);
  range("rest_min_s", rest_min_s, "rest_max_s", rest_max_s);
  range("ramp_up_min_s", ramp_up_min_s, "ramp_up_max_s", ramp_up_max_s);
  range("hold_min_s", hold_min_s, "hold_max_s", hold_max_s);
  range("ramp_down_min_s", ramp_down_min_s, "ramp_down_max_s", ramp_down_max_s);
  positive("force_min_n", force_min_n);
  range("force_min_n", force_min_n, "force_max_n", force_max_n);
}

ProtocolRun RunField(const SkinTwin& twin, const Scene& scene, const FieldProtocol& p, std::uint64_t seed,
                     const FrameSink& sink, const ProgressFn& progress) {
  p.Validate();
  Recorder rec(twin, DeriveSeed(seed, 1), p.rate_hz, sink);
  LoadCellModel cell(scene.load_cell, DeriveSeed(seed, 2));
  std::mt19937_64 rng(DeriveSeed(seed, 5));
  std::uniform_real_distribution<double> u(0.0, 1.0);
  (void)RequireSphere(twin, scene, "field");
  const patch::Region area = twin.spec().indented_area;
  Loads loads(twin, p.rate_hz, scene.probe);
  const auto total = static_cast<std::uint64_t>(std::llround(p.duration_s * p.rate_hz));
  auto frames_of = [&](double s) { return static_cast<std::uint64_t>(std::llround(s * p.rate_hz)); };
  auto uniform = [&](double lo, double hi) { return lo + (hi - lo) * u(rng); };
  auto report = [&] {
    if (progress) {
      progress(static_cast<std::uint64_t>(static_cast<double>(rec.frames()) / p.rate_hz),
               static_cast<std::uint64_t>(p.duration_s));
    }
  };
  auto rest = [&](std::uint64_t n) {
    for (std::uint64_t i = 0; i < n && rec.frames() < total; ++i) rec.Emit(loads.Release(), cell.Read(0.0), 0.0f, kNaN, kNaN, -1);
  };

  rest(frames_of(p.first_rest_s));
  int cycles = 0;
  while (rec.frames() < total) {
    // Every draw of a cycle, in a fixed order, before any frame: the same seed gives the same cycles.
    const double rest_s = uniform(p.rest_min_s, p.rest_max_s);
    const patch::SurfacePoint at = UniformIn(area, rng);
    const double up_s = uniform(p.ramp_up_min_s, p.ramp_up_max_s);
    const double target_n = std::exp(uniform(std::log(p.force_min_n), std::log(p.force_max_n)));
    const double hold_s = uniform(p.hold_min_s, p.hold_max_s);
    const double down_s = uniform(p.ramp_down_min_s, p.ramp_down_max_s);
    rest(frames_of(rest_s));
    if (rec.frames() >= total) break;
    loads.MoveTo(at);
    const int k = cycles++;
    const auto y = static_cast<float>(at.y_mm), r = static_cast<float>(at.r_deg);
    auto press = [&](double f) {
      if (rec.frames() < total) rec.Emit(loads.Press(f), cell.Read(f), static_cast<float>(f), y, r, k);
    };
    const std::uint64_t n_up = std::max<std::uint64_t>(1, frames_of(up_s));
    const std::uint64_t n_hold = frames_of(hold_s);
    const std::uint64_t n_down = std::max<std::uint64_t>(1, frames_of(down_s));
    for (std::uint64_t i = 1; i <= n_up; ++i) press(target_n * static_cast<double>(i) / static_cast<double>(n_up));
    for (std::uint64_t i = 0; i < n_hold; ++i) press(target_n);
    for (std::uint64_t i = 1; i <= n_down; ++i) {
      press(target_n * static_cast<double>(n_down - i) / static_cast<double>(n_down));
    }
    report();
  }
  rec.Flush();
  report();
  return {rec.frames(), cycles};
}

}  // namespace ruffini::twin
