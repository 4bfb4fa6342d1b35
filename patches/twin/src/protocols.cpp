#include "ruffini/twin/protocols.h"

#include <cmath>
#include <limits>
#include <random>

#include "ruffini/error.h"

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

  void Emit(std::span<const Contact> contacts, float force_label, float true_force, float y, float r, int indentation) {
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

  for (int i = 0; i < p.rest_frames; ++i) rec.Emit({}, cell.Read(0.0), 0.0f, kNaN, kNaN, -1);
  for (int k = 0; k < p.indentations; ++k) {
    const patch::SurfacePoint at = UniformIn(area, rng);
    const double gap = p.approach_mm * (1.0 + p.approach_jitter * (2.0 * u(rng) - 1.0));
    for (int n = 0;; ++n) {
      const double travel = p.speed_mm_s * n / p.rate_hz - gap;
      const double depth = std::max(0.0, travel);
      const double force = law->ForceN(depth);
      if (force > p.max_force_n) break;  // only the increasing-load phase is kept
      const Contact c{at, force, scene.probe};
      rec.Emit(std::span<const Contact>(&c, 1), cell.Read(force), static_cast<float>(force),
               static_cast<float>(at.y_mm), static_cast<float>(at.r_deg), k);
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
        const Probe probe{Probe::Shape::kPoint, p.tip_radius_mm};
        const auto y = static_cast<float>(at.y_mm), r = static_cast<float>(at.r_deg);
        for (int n = 0; n < p.rest_frames; ++n) rec.Emit({}, 0.0f, 0.0f, kNaN, kNaN, -1);
        auto emit_force = [&](double f) {
          const Contact c{at, f, probe};
          rec.Emit(std::span<const Contact>(&c, 1), static_cast<float>(f), static_cast<float>(f), y, r, index);
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
  int index = 0;
  for (int i = 0; i < ny; ++i) {
    for (int j = 0; j < na; ++j) {
      const patch::SurfacePoint at{area.y_min_mm + i * p.step_mm, geo.RDeg(arc0 + j * p.step_mm)};
      for (int n = 0; n <= p.ramp_frames; ++n) {
        const double f = p.max_force_n * n / p.ramp_frames;
        const Contact c{at, f, scene.probe};
        rec.Emit(std::span<const Contact>(&c, 1), cell.Read(f), static_cast<float>(f), static_cast<float>(at.y_mm),
                 static_cast<float>(at.r_deg), index);
      }
      ++index;
    }
    if (progress) progress(static_cast<std::uint64_t>(i + 1), static_cast<std::uint64_t>(ny));
  }
  rec.Flush();
  return {rec.frames(), index};
}

}  // namespace ruffini::twin
