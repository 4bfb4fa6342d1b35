#include "ruffini/twin/twin.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <limits>
#include <map>
#include <mutex>
#include <tuple>

#include "ruffini/error.h"
#include "ruffini/twin/layer.h"

namespace ruffini::twin {

std::uint64_t DeriveSeed(std::uint64_t seed, std::uint64_t stream) noexcept {
  std::uint64_t z = seed + 0x9E3779B97F4A7C15ull * (stream + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

// Grating-averaged axial strain per newton, K_a(u, v), on a grid of contact radii a.
class KernelTables {
 public:
  static constexpr double kStepMm = 0.25;      // u, v grid step
  static constexpr double kExtentMm = 40.0;    // |u|, |v| beyond this: no response
  static constexpr double kRadiusStepMm = 0.5;
  static constexpr int kRadii = 13;            // 0 .. 6 mm
  static constexpr int kN = static_cast<int>(kExtentMm / kStepMm) + 1;

  KernelTables(const LayerParams& layer, double grating_length_mm) {
    std::vector<double> radii;
    for (int i = 0; i < kRadii; ++i) radii.push_back(i * kRadiusStepMm);
    const double half = grating_length_mm / 2.0;
    const double r_max = std::hypot(kExtentMm + half, kExtentMm) + 1.0;
    const std::vector<StrainProfile> prof = ComputeStrainProfiles(layer, radii, r_max, 0.1);
    const int ns = 33;  // samples along the grating (trapezoid over [-L/2, L/2])
    table_.assign(static_cast<std::size_t>(kRadii) * kN * kN, 0.0f);
    for (int a = 0; a < kRadii; ++a) {
      const StrainProfile& p = prof[static_cast<std::size_t>(a)];
      for (int iu = 0; iu < kN; ++iu) {
        for (int iv = 0; iv < kN; ++iv) {
          const double u = iu * kStepMm, v = iv * kStepMm;
          double acc = 0.0;
          for (int k = 0; k < ns; ++k) {
            const double x = u - half + grating_length_mm * k / (ns - 1);
            const double rho2 = x * x + v * v;
            const double rho = std::sqrt(rho2);
            const double e = rho2 < 1e-12 ? p.Rr(0.0) : (p.Rr(rho) * x * x + p.Tt(rho) * v * v) / rho2;
            acc += (k == 0 || k == ns - 1) ? 0.5 * e : e;
          }
          table_[Index(a, iu, iv)] = static_cast<float>(acc / (ns - 1));
        }
      }
    }
  }

  // Bilinear in (u, v), linear in the contact radius. Real-time safe.
  [[nodiscard]] double Lookup(double radius_mm, double u, double v) const noexcept {
    u = std::abs(u);
    v = std::abs(v);
    if (u >= kExtentMm || v >= kExtentMm) return 0.0;
    const double ra = std::clamp(radius_mm / kRadiusStepMm, 0.0, static_cast<double>(kRadii - 1) - 1e-9);
    const int a = static_cast<int>(ra);
    const double wa = ra - a;
    const double xu = u / kStepMm, xv = v / kStepMm;
    const int iu = static_cast<int>(xu), iv = static_cast<int>(xv);
    const double wu = xu - iu, wv = xv - iv;
    auto at = [&](int aa) {
      const float* t = &table_[Index(aa, iu, iv)];
      return (1 - wu) * ((1 - wv) * t[0] + wv * t[1]) + wu * ((1 - wv) * t[kN] + wv * t[kN + 1]);
    };
    return (1 - wa) * at(a) + (wa > 0 ? wa * at(a + 1) : 0.0);
  }

 private:
  static std::size_t Index(int a, int iu, int iv) {
    return (static_cast<std::size_t>(a) * kN + static_cast<std::size_t>(iu)) * kN + static_cast<std::size_t>(iv);
  }
  std::vector<float> table_;
};

namespace {

// Tables depend only on the layer and the grating length: share them between twins (tests build many).
std::shared_ptr<const KernelTables> CachedTables(const LayerParams& l, double length_mm) {
  static std::mutex mu;
  static std::map<std::tuple<double, double, double, double, double>, std::shared_ptr<const KernelTables>> cache;
  const auto key = std::make_tuple(l.thickness_mm, l.depth_mm, l.youngs_modulus_kpa, l.poisson_ratio, length_mm);
  std::lock_guard<std::mutex> lock(mu);
  auto it = cache.find(key);
  if (it != cache.end()) return it->second;
  auto t = std::make_shared<const KernelTables>(l, length_mm);
  cache.emplace(key, t);
  return t;
}

void CheckGrating(int g, const char* what) {
  if (g < 1 || g > static_cast<int>(patch::kGratings)) {
    throw InputError(std::string("twin effect '") + what + "' names grating " + std::to_string(g) +
                     "; gratings are numbered 1.." + std::to_string(patch::kGratings));
  }
}

}  // namespace

SkinTwin::~SkinTwin() = default;
SkinTwin::SkinTwin(SkinTwin&&) noexcept = default;

SkinTwin::SkinTwin(const patch::PatchSpec& spec, const TwinEffects& effects, std::vector<double> sphere_radii)
    : spec_(spec), effects_(effects), geometry_(spec), thickness_mm_(spec.layer.thickness_mm),
      depth_radius_mm_(spec.surface_radius_mm - spec.layer.fibre_depth_mm) {
  // Fabrication draws come from the skin sample seed, in a fixed order.
  std::mt19937_64 fab(DeriveSeed(effects.fabrication_seed(), 100));
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  for (std::size_t i = 0; i < patch::kGratings; ++i) {
    const double n_gain = normal(fab), n_temp = normal(fab);
    const double u_pos_r = uniform(fab), u_pos_a = uniform(fab), u_wl = uniform(fab);
    gain_[i] = effects.gain_spread ? std::max(0.2, 1.0 + effects.gain_spread->sigma * n_gain) : 1.0;
    temp_coeff_[i] = effects.temperature
                         ? effects.temperature->coefficient_pm_per_c * (1.0 + effects.temperature->spread * n_temp) +
                               effects.temperature->strain_pm_per_c
                         : 0.0;
    centres_[i] = spec.gratings[i].centre;
    reference_nm_[i] = spec.gratings[i].wavelength_nm;
    if (effects.skin_sample) {
      const auto& s = *effects.skin_sample;
      const double rad = s.position_mm * std::sqrt(u_pos_r), ang = 2.0 * std::numbers::pi * u_pos_a;
      centres_[i].y_mm += rad * std::cos(ang);
      centres_[i].r_deg += geometry_.RDeg(rad * std::sin(ang));
      reference_nm_[i] += s.wavelength_nm * (2.0 * u_wl - 1.0);
    }
  }
  for (std::size_t i = 1; i < patch::kGratings; ++i) {
    const double gap = reference_nm_[i] - reference_nm_[i - 1];
    if (gap < 2.0 * spec.fibre.band_half_width_nm) {
      throw InputError("skin sample: FBG " + std::to_string(i) + " and " + std::to_string(i + 1) + " references are " +
                       std::to_string(gap) + " nm apart, less than two band half-widths (" +
                       std::to_string(2.0 * spec.fibre.band_half_width_nm) +
                       " nm); lower skin_sample.wavelength_nm or widen the spacing");
    }
  }
  if (effects.skin_sample) {
    const double n = std::clamp(normal(fab), -3.0, 3.0);
    thickness_mm_ *= 1.0 + effects.skin_sample->thickness_sigma * n;
  }

  LayerParams layer{thickness_mm_, spec.layer.fibre_depth_mm, spec.layer.material.youngs_modulus_kpa,
                    spec.layer.material.poisson_ratio};
  tables_ = CachedTables(layer, spec.gratings[0].length_mm);
  for (double r : sphere_radii) {
    law_radii_mm_.push_back(r);
    const auto& m = spec.layer.material;
    laws_.emplace_back(thickness_mm_, m.youngs_modulus_kpa, m.poisson_ratio, r,
                       Yeoh{m.yeoh_c1_kpa * 1e3, m.yeoh_c2_pa, m.yeoh_c3_pa});
  }
  // The fibre path at the fibre's depth (unrolled), its cumulative length, and where each grating sits on it
  // (the light enters at the path's first point): a pinch at path length s darkens the gratings beyond s.
  for (const auto& p : spec.fibre.path) {
    path_y_mm_.push_back(p.y_mm);
    path_arc_mm_.push_back(depth_radius_mm_ * p.r_deg * patch::kDegToRad);
  }
  path_s_mm_.assign(path_y_mm_.size(), 0.0);
  for (std::size_t k = 1; k < path_y_mm_.size(); ++k) {
    path_s_mm_[k] = path_s_mm_[k - 1] + std::hypot(path_y_mm_[k] - path_y_mm_[k - 1], path_arc_mm_[k] - path_arc_mm_[k - 1]);
  }
  for (std::size_t i = 0; i < patch::kGratings; ++i) {
    const double gy = spec.gratings[i].centre.y_mm, ga = depth_radius_mm_ * spec.gratings[i].centre.r_deg * patch::kDegToRad;
    double best = std::numeric_limits<double>::infinity();
    grating_s_mm_[i] = 0.0;
    for (std::size_t k = 1; k < path_y_mm_.size(); ++k) {
      const double dy = path_y_mm_[k] - path_y_mm_[k - 1], da = path_arc_mm_[k] - path_arc_mm_[k - 1];
      const double len2 = dy * dy + da * da;
      const double t = len2 > 0 ? std::clamp(((gy - path_y_mm_[k - 1]) * dy + (ga - path_arc_mm_[k - 1]) * da) / len2, 0.0, 1.0) : 0.0;
      const double d = std::hypot(path_y_mm_[k - 1] + t * dy - gy, path_arc_mm_[k - 1] + t * da - ga);
      if (d < best) {
        best = d;
        grating_s_mm_[i] = path_s_mm_[k - 1] + t * std::sqrt(len2);
      }
    }
  }
  // Point-like probes saturate where the paper's 11 mm sphere does (a conservative, documented choice).
  point_force_limit_n_ = ContactLaw(thickness_mm_, spec.layer.material.youngs_modulus_kpa,
                                    spec.layer.material.poisson_ratio, 5.5)
                             .linear_limit_force_n();

  const double pm_per_strain = spec.fibre.strain_optic_pm_per_microstrain * 1e6;
  for (std::size_t i = 0; i < patch::kGratings; ++i) {
    const double th = spec.gratings[i].direction_deg * patch::kDegToRad;
    const double c = std::cos(th), s = std::sin(th);
    std::vector<Lobe> lobes{Lobe{}};
    if (effects.irregular) {
      for (const auto& ig : effects.irregular->gratings) {
        if (ig.grating == static_cast<int>(i) + 1) lobes = ig.lobes;
      }
    }
    for (const Lobe& l : lobes) {
      const double dy = l.along_mm * c - l.across_mm * s;
      const double darc = l.along_mm * s + l.across_mm * c;  // at the fibre depth
      lobes_[i].push_back(LobeGeo{centres_[i].y_mm + dy, centres_[i].r_deg * patch::kDegToRad + darc / depth_radius_mm_,
                                  c, s, gain_[i] * l.gain * spec.fibre.strain_transfer * pm_per_strain});
    }
  }
  if (effects.irregular) {
    for (const auto& ig : effects.irregular->gratings) CheckGrating(ig.grating, "irregular_gratings");
  }
  for (const auto& f : effects.faults) CheckGrating(f.grating, "faults");
}

const ContactLaw* SkinTwin::contact_law(const Probe& p) const noexcept {
  for (std::size_t i = 0; i < laws_.size(); ++i) {
    if (std::abs(law_radii_mm_[i] - p.radius_mm) < 1e-9) return &laws_[i];
  }
  return nullptr;
}

double SkinTwin::StiffeningFactor(double depth_mm) const noexcept {
  // Yeoh secant shear modulus at the nominal compression under the probe, relative to the small-strain
  // modulus: strain at the fibre scales with 1 / modulus.
  const auto& m = spec_.layer.material;
  const double lambda = 1.0 - std::min(depth_mm / thickness_mm_, 0.9);
  const double i1 = lambda * lambda + 2.0 / lambda - 3.0;
  const double c1 = m.yeoh_c1_kpa * 1e3, c2 = m.yeoh_c2_pa, c3 = m.yeoh_c3_pa;
  const double mu = c1 + 2.0 * c2 * i1 + 3.0 * c3 * i1 * i1;
  return mu > 0 ? c1 / mu : 1.0;
}

void SkinTwin::Pinch(const patch::SurfacePoint& at, double contact_radius_mm, double& pinched_from_s_mm) const noexcept {
  const double cy = at.y_mm, ca = depth_radius_mm_ * at.r_deg * patch::kDegToRad;
  const double reach = contact_radius_mm + effects_.hard_press.pinch_margin_mm;
  for (std::size_t k = 1; k < path_y_mm_.size(); ++k) {
    const double y0 = path_y_mm_[k - 1], a0 = path_arc_mm_[k - 1];
    const double dy = path_y_mm_[k] - y0, da = path_arc_mm_[k] - a0;
    const double len = std::hypot(dy, da);
    if (!(len > 0)) continue;
    const double t = std::clamp(((cy - y0) * dy + (ca - a0) * da) / (len * len), 0.0, 1.0);
    const double d = std::hypot(y0 + t * dy - cy, a0 + t * da - ca);
    if (d > reach) continue;
    // The first point of this segment within reach of the contact: the pinch starts there.
    const double half_chord = std::sqrt(std::max(0.0, reach * reach - d * d));
    const double s = path_s_mm_[k - 1] + std::max(0.0, t * len - half_chord);
    pinched_from_s_mm = std::min(pinched_from_s_mm, s);
    return;  // segments come in order along the light's way: the first one in reach is the pinch
  }
}

namespace {
// The share of a Hertz footprint of radius a on the cover side of a straight edge the centre lies e inside
// of (e < 0: outside): its parabolic line load integrated, 1/2 + 3/4 (s - s^3/3), s = e / a in [-1, 1].
double FootprintFraction(double e_mm, double a_mm) noexcept {
  if (!(a_mm > 0.0)) return e_mm >= 0.0 ? 1.0 : 0.0;
  const double s = e_mm / a_mm;
  if (s >= 1.0) return 1.0;
  if (s <= -1.0) return 0.0;
  return 0.5 + 0.75 * (s - s * s * s / 3.0);
}
}  // namespace

double SkinTwin::CoverFraction(const patch::SurfacePoint& at, double contact_radius_mm) const noexcept {
  const EdgeEffect& e = *effects_.edges;
  const double dist[4] = {at.y_mm, spec_.extent_y_mm - at.y_mm, geometry_.ArcMm(at.r_deg),
                          geometry_.ArcMm(spec_.extent_r_deg - at.r_deg)};
  double f = 1.0;
  for (std::size_t k = 0; k < 4; ++k) {
    if (e.kind[k] == EdgeEffect::Kind::kFree) f *= FootprintFraction(dist[k], contact_radius_mm);
  }
  return std::max(f, 0.25);  // a contact on a corner: at least a quarter of the footprint bears
}

std::size_t SkinTwin::Sources(const patch::SurfacePoint& at, std::array<Source, 4>& out) const noexcept {
  out[0] = Source{at.y_mm, at.r_deg, 1.0};
  if (!effects_.edges) return 1;
  const EdgeEffect& e = *effects_.edges;
  auto gain = [&](std::size_t k, double dist_mm) {
    if (e.kind[k] == EdgeEffect::Kind::kContinued || !(dist_mm < e.zone_mm)) return 0.0;
    const double g = e.kind[k] == EdgeEffect::Kind::kFree ? e.free_image_gain : e.bonded_image_gain;
    const double half = 0.5 * e.zone_mm;
    return dist_mm <= half ? g : g * (e.zone_mm - dist_mm) / half;
  };
  // The nearer Y edge and the nearer R edge (a patch is far wider than two zones).
  const bool y_low = at.y_mm <= 0.5 * spec_.extent_y_mm, r_low = at.r_deg <= 0.5 * spec_.extent_r_deg;
  const double dy = y_low ? at.y_mm : spec_.extent_y_mm - at.y_mm;
  const double dr = r_low ? geometry_.ArcMm(at.r_deg) : geometry_.ArcMm(spec_.extent_r_deg - at.r_deg);
  const double gy = gain(y_low ? 0 : 1, dy), gr = gain(r_low ? 2 : 3, dr);
  const double y_img = y_low ? -at.y_mm : 2.0 * spec_.extent_y_mm - at.y_mm;
  const double r_img = r_low ? -at.r_deg : 2.0 * spec_.extent_r_deg - at.r_deg;
  std::size_t n = 1;
  if (gy != 0.0) out[n++] = Source{y_img, at.r_deg, gy};
  if (gr != 0.0) out[n++] = Source{at.y_mm, r_img, gr};
  if (gy != 0.0 && gr != 0.0) out[n++] = Source{y_img, r_img, gy * gr};  // the corner's image of the images
  return n;
}

void SkinTwin::StrainShiftsPm(std::span<const Contact> contacts, Shifts& out, std::uint32_t& flags) const noexcept {
  out.fill(0.0);
  double pinched = std::numeric_limits<double>::infinity();  // path length from which the fibre is dark
  const patch::Region extent = spec_.Extent();
  for (const Contact& c : contacts) {
    if (!std::isfinite(c.force_n) || c.force_n < 0.0 || !std::isfinite(c.at.y_mm) || !std::isfinite(c.at.r_deg) ||
        !(c.probe.radius_mm > 0.0 && c.probe.radius_mm <= kMaxProbeRadiusMm)) {
      flags |= kFlagBadContact;
      continue;
    }
    if (!extent.Contains(c.at)) {
      flags |= kFlagOffPatch;
      continue;
    }
    if (c.force_n == 0.0) continue;
    double radius = c.probe.radius_mm;
    double depth = 0.0;
    double force = c.force_n;
    if (c.probe.shape == Probe::Shape::kSphere) {
      const ContactLaw* law = contact_law(c.probe);
      if (law == nullptr) {
        flags |= kFlagBadContact;
        continue;
      }
      // Beyond the linear range the cover stiffens until it bottoms out (ContactLaw::HardForceN); the strain
      // field is the linear layer's at the same depth. Flagged: the frame is beyond the linear range.
      if (force > law->linear_limit_force_n()) flags |= kFlagSaturated;
      // At a free edge the part of the footprint still on the cover carries the whole force: it is indented
      // as deep as the whole footprint would be by force / fraction (only the hard range sees a difference).
      const double on_cover = effects_.edges ? CoverFraction(c.at, law->ContactRadiusMm(std::min(force, law->linear_limit_force_n())))
                                             : 1.0;
      depth = law->HardDepthMm(force / on_cover);
      radius = std::min(c.probe.radius_mm, std::sqrt(c.probe.radius_mm * depth));
      const double d_lin = ContactLaw::kLinearCompressionLimit * law->thickness_mm();
      force = law->StrainForceN(force / on_cover) * on_cover *
              (effects_.stiffening ? StiffeningFactor(std::min(depth, d_lin)) : 1.0);
      if (depth > effects_.hard_press.microbend_compression * thickness_mm_) Pinch(c.at, radius, pinched);
    } else if (force > point_force_limit_n_) {
      force = point_force_limit_n_;
      flags |= kFlagSaturated;
    }
    const double f = c.probe.shape == Probe::Shape::kSphere ? force
                                                            : force * (effects_.stiffening ? StiffeningFactor(depth) : 1.0);
    // The contact and, near a free or bonded edge, its images across the edges (at most 4 sources).
    std::array<Source, 4> sources{};
    const std::size_t n_sources = Sources(c.at, sources);
    for (std::size_t i = 0; i < patch::kGratings; ++i) {
      double acc = 0.0;
      for (std::size_t k = 0; k < n_sources; ++k) {
        const Source& src = sources[k];
        const double cr = src.r_deg * patch::kDegToRad;
        for (const LobeGeo& l : lobes_[i]) {
          const double dy = l.y_mm - src.y_mm;
          const double darc = depth_radius_mm_ * (l.r_rad - cr);
          const double u = dy * l.cos_d + darc * l.sin_d;
          const double v = -dy * l.sin_d + darc * l.cos_d;
          acc += src.weight * l.scale * tables_->Lookup(radius, u, v);
        }
      }
      out[i] += f * acc;
    }
  }
  if (pinched < std::numeric_limits<double>::infinity()) {
    // Microbending at the pinch: every grating from there on along the fibre is dark (its peak is lost); a
    // grating reaching into the pinch (half its length) is split by the transverse load.
    const double half = spec_.gratings[0].length_mm / 2.0;
    for (std::size_t i = 0; i < patch::kGratings; ++i) {
      if (grating_s_mm_[i] + half >= pinched) out[i] = std::numeric_limits<double>::quiet_NaN();
    }
    flags |= kFlagPeakMissing;
  }
}

Shifts SkinTwin::StrainShiftsPm(const Contact& c) const noexcept {
  Shifts s{};
  std::uint32_t flags = 0;
  StrainShiftsPm(std::span<const Contact>(&c, 1), s, flags);
  return s;
}

InterrogatorSim::InterrogatorSim(const SkinTwin& twin, std::uint64_t seed)
    : twin_(twin), rng_(DeriveSeed(seed, 7)) {
  const TwinEffects& e = twin.effects();
  const double sigma = e.noise ? e.noise->sigma_pm : 0.0;
  noise_pm_.fill(sigma);
  if (e.temperature) {
    const double extent_y = twin.spec().extent_y_mm;
    for (std::size_t i = 0; i < patch::kGratings; ++i) {
      const patch::SurfacePoint& c = twin.grating_centres()[i];
      field_c_[i] = e.temperature->FieldC(c.y_mm / extent_y, c.r_deg);
    }
  }
  for (const FaultEffect& f : e.faults) {
    const auto i = static_cast<std::size_t>(f.grating - 1);
    if (f.kind == FaultEffect::Kind::kDead) {
      dead_[i] = true;
    } else {
      dropout_[i] = f.dropout;
      noise_pm_[i] = sigma * f.noise_factor;
    }
  }
}

double TemperatureEffect::AtC(double t) const noexcept {
  double c = offset_c + amplitude_c * std::sin(2.0 * std::numbers::pi * t / period_s) + ramp_c_per_s * t;
  if (triangle_rate_c_per_h != 0.0) {
    // Zero-mean triangle: up for a quarter period, down for a half, up for the last quarter.
    const double rate_c_per_s = triangle_rate_c_per_h / 3600.0;
    const double p = t - triangle_period_s * std::floor(t / triangle_period_s);  // phase in [0, period)
    const double q = triangle_period_s / 4.0;
    c += rate_c_per_s * (p < q ? p : p < 3.0 * q ? 2.0 * q - p : p - 4.0 * q);
  }
  if (!knots.empty()) {
    if (t <= knots.front().t_s) {
      c += knots.front().c;
    } else if (t >= knots.back().t_s) {
      c += knots.back().c;
    } else {
      const auto hi = std::upper_bound(knots.begin(), knots.end(), t,
                                       [](double x, const TemperatureKnot& k) { return x < k.t_s; });
      const auto lo = hi - 1;
      const double w = (t - lo->t_s) / (hi->t_s - lo->t_s);
      c += lo->c + w * (hi->c - lo->c);
    }
  }
  return c;
}

double TemperatureEffect::GradientScale(double t_s) const noexcept {
  if (!(gradient_tau_s > 0.0)) return 1.0;
  return t_s <= 0.0 ? 0.0 : 1.0 - std::exp(-t_s / gradient_tau_s);
}

double TemperatureEffect::FieldC(double y_frac, double r_deg) const noexcept {
  return gradient_along_c * (0.5 - y_frac) +
         0.5 * gradient_around_c * std::cos((r_deg - gradient_around_r_deg) * std::numbers::pi / 180.0);
}

double InterrogatorSim::TemperatureC(double t) const noexcept {
  const auto& te = twin_.effects().temperature;
  if (!te) return 0.0;
  return te->AtC(t);
}

void InterrogatorSim::Read(double t_s, const Shifts& strain, std::array<double, patch::kGratings>& wl,
                           std::uint32_t& flags) noexcept {
  const double dt_c = TemperatureC(t_s);
  const double field_scale = twin_.effects().temperature ? twin_.effects().temperature->GradientScale(t_s) : 0.0;
  const double band_pm = twin_.spec().fibre.band_half_width_nm * 1e3;
  const double window_min_nm = twin_.spec().interrogator.window_min_nm, window_max_nm = twin_.spec().interrogator.window_max_nm;
  const auto& ref = twin_.reference_wavelength_nm();
  const auto& tc = twin_.temperature_pm_per_c();
  for (std::size_t i = 0; i < patch::kGratings; ++i) {
    // Draw every random number every frame, whatever the effects, so streams stay aligned across scenes.
    const double n = normal_(rng_);
    const double u = uniform_(rng_);
    double shift = strain[i] + tc[i] * (dt_c + field_scale * field_c_[i]) + noise_pm_[i] * n;
    if (dead_[i] || u < dropout_[i] || std::isnan(shift)) {
      wl[i] = std::numeric_limits<double>::quiet_NaN();
      flags |= kFlagPeakMissing;
      continue;
    }
    // A raw peak stream reports a peak where it is: one that has left its band is sent at its wavelength
    // (flagged in the twin's frame flags, which no interrogator stream carries); beyond the instrument's
    // window it is not seen at all (lost).
    if (!(std::abs(shift) <= band_pm)) flags |= kFlagSaturated;
    const double nm = ref[i] + shift * 1e-3;
    if (!(nm >= window_min_nm && nm <= window_max_nm)) {
      wl[i] = std::numeric_limits<double>::quiet_NaN();
      flags |= kFlagPeakMissing;
      continue;
    }
    wl[i] = nm;
  }
}

std::string TwinEffects::Summary() const {
  std::string s;
  auto add = [&](const std::string& x) { s += (s.empty() ? "" : ",") + x; };
  if (noise) add("noise");
  if (gain_spread) add("gain_spread");
  if (irregular) add("irregular_gratings");
  if (stiffening) add("stiffening");
  if (temperature) add("temperature");
  if (viscoelastic) add("viscoelastic");
  if (!faults.empty()) add("faults");
  if (skin_sample) add("skin_sample=" + std::to_string(skin_sample->seed));
  if (hard_press_named) add("hard_press");
  if (edges) add("edges");
  return s.empty() ? "none" : s;
}

}  // namespace ruffini::twin
