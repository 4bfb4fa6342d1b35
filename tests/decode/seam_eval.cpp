// One probe across a seam (issue 16 §4: "seam press (one probe): fused, located, error <= 1.5x interior"):
// random probes whose footprint loads both patches of the scene's seam, through both decode paths and the
// aggregator's fusion (seam.h), and random interior presses on the seam's first patch as the reference.
// Prints a markdown report.
//
//   seam_eval SCENE SEED PRESSES INTERIOR [band=MM|map] [near=MM] [q=X] [threshold=N]
//
// band: map (default: each side's band from its model's sensitivity map, decode::EdgeReachMm with near/q) or a
// fixed band on both sides (0: the plain gate). Seam probes: Y uniform in 15..135 mm, the probe's centre within
// +-6 mm of the seam (uniform; those whose footprint does not reach both covers are counted and skipped),
// force log-uniform in 2..50 N, each with its own noise seed (DeriveSeed(SEED, k)). Interior presses: Y 30..120,
// R 40..105 deg of the first patch, the same forces. near/q were chosen on SEED 2000 and scored once on 3000
// (docs/fusion.md, "Seams").
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "ruffini/twin/protocols.h"
#include "seam.h"

namespace {

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5)];
}

double Pct(double a, double b) { return b > 0 ? 100.0 * a / b : 0.0; }

}  // namespace

int main(int argc, char** argv) {
  using namespace ruffini;
  if (argc < 5) {
    std::fprintf(stderr, "usage: %s SCENE SEED PRESSES INTERIOR [band=MM|map] [near=MM] [q=X] [threshold=N]\n", argv[0]);
    return 2;
  }
  try {
    const twin::Scene scene = twin::LoadScene(argv[1]);
    const std::uint64_t seed = std::stoull(argv[2]);
    const int presses = std::stoi(argv[3]), interior = std::stoi(argv[4]);
    double band = -1, near = 5.0, q = 0.9, threshold = 1.5;
    for (int i = 5; i < argc; ++i) {
      const std::string kv = argv[i];
      const auto eq = kv.find('=');
      if (eq == std::string::npos) throw std::runtime_error("expected key=value, got '" + kv + "'");
      const std::string k = kv.substr(0, eq), v = kv.substr(eq + 1);
      if (k == "band") band = v == "map" ? -1.0 : std::stod(v);
      else if (k == "near") near = std::stod(v);
      else if (k == "q") q = std::stod(v);
      else if (k == "threshold") threshold = std::stod(v);
      else throw std::runtime_error("unknown knob '" + k + "'");
    }
    const testing::SeamRig rig(scene, threshold, band, near, q);
    const robot::Seam& seam = rig.seam();
    const robot::MountedSurface& sa = rig.surface(seam.a);
    if (seam.edge_a != robot::PatchEdge::kRMax) throw std::runtime_error("seam_eval draws probes across an R = extent edge of the first patch");
    const double mm_per_deg = sa.mount.surface_radius_mm * std::numbers::pi / 180.0;
    std::printf("# One probe across a seam: %s, %s %s | %s %s, seed %llu\n\n", argv[1], scene.patches[seam.a].name.c_str(),
                robot::ToString(seam.edge_a), scene.patches[seam.b].name.c_str(), robot::ToString(seam.edge_b),
                static_cast<unsigned long long>(seed));
    std::printf("Bands (how far from the seam each side's decoder may place a touch on it): %.1f / %.1f mm (%s).\n\n",
                rig.band_mm(0), rig.band_mm(1),
                band < 0 ? ("from the models' maps at " + std::to_string(threshold) + " N, near " + std::to_string(near) +
                            " mm, quantile " + std::to_string(q)).c_str()
                         : "fixed");
    std::mt19937_64 rng(twin::DeriveSeed(seed, 0));
    std::uniform_real_distribution<double> uy(15.0, 135.0), uoff(-6.0, 6.0), ulog(std::log(2.0), std::log(50.0));
    std::uniform_real_distribution<double> iy(30.0, 120.0), ir(40.0, 105.0);
    std::uint64_t k = 0;
    int used = 0, one_sided = 0, fused_presses = 0, plain_fused_presses = 0, stopped = 0, own_stops = 0, judged_stops = 0;
    long both_frames = 0, fused_frames = 0, plain_fused_frames = 0;
    std::vector<double> err, plain_err, force_ratio, fused_err, fused_ratio;
    for (int i = 0; i < presses; ++i) {
      const double y = uy(rng), off = uoff(rng), f = std::exp(ulog(rng));
      const double r = sa.extent_r_deg + off / mm_per_deg;
      const auto frames = rig.Press(y, r, f, threshold, twin::DeriveSeed(seed, ++k));
      if (!frames) {
        ++one_sided;
        continue;
      }
      ++used;
      long both = 0, fused = 0, plain_fused = 0;
      bool stop = false, own_stop = false, judged_stop = false;
      std::vector<double> press_err, press_plain;
      for (const testing::SeamFrame& fr : *frames) {
        own_stop = own_stop || fr.own_max_n > threshold;
        judged_stop = judged_stop || fr.judged_n > threshold;
        if (fr.patches_in_contact == 2) {
          ++both;
          fused += fr.fused;
          plain_fused += fr.plain_fused;
        }
        if (fr.located) {
          err.push_back(fr.error_mm);
          force_ratio.push_back(fr.force_n / f);
          stop = stop || fr.force_n > threshold;
          if (fr.fused) {
            fused_err.push_back(fr.error_mm);
            fused_ratio.push_back(fr.force_n / f);
          }
        }
        if (std::isfinite(fr.plain_error_mm)) plain_err.push_back(fr.plain_error_mm);
      }
      both_frames += both;
      fused_frames += fused;
      plain_fused_frames += plain_fused;
      if (both > 0 && 2 * fused > both) ++fused_presses;
      if (both > 0 && 2 * plain_fused > both) ++plain_fused_presses;
      stopped += stop;
      own_stops += own_stop;
      judged_stops += judged_stop;
      if (std::getenv("SEAM_VERBOSE")) {
        std::fprintf(stderr, "probe Y %.1f off %+.1f mm %.1f N: %ld of %zu frames both, %ld fused\n", y, off, f, both,
                     frames->size(), fused);
      }
    }
    std::vector<double> interior_err;
    for (int i = 0; i < interior; ++i) {
      const double y = iy(rng), r = ir(rng), f = std::exp(ulog(rng));
      const std::vector<double> e = rig.InteriorErrors(y, r, f, threshold, twin::DeriveSeed(seed, ++k));
      interior_err.insert(interior_err.end(), e.begin(), e.end());
    }
    std::printf("%d seam probes loaded both covers (%d drawn ones reached only one and were skipped); %d interior presses.\n\n",
                used, one_sided, interior);
    std::printf("| | seam rule (bands) | plain gate |\n| --- | --- | --- |\n");
    std::printf("| probes fused (most hold frames with both patches in contact) | %d of %d (%.1f %%) | %d (%.1f %%) |\n",
                fused_presses, used, Pct(fused_presses, used), plain_fused_presses, Pct(plain_fused_presses, used));
    std::printf("| hold frames fused, of those with both patches in contact | %ld of %ld (%.1f %%) | %ld (%.1f %%) |\n",
                fused_frames, both_frames, Pct(static_cast<double>(fused_frames), static_cast<double>(both_frames)),
                plain_fused_frames, Pct(static_cast<double>(plain_fused_frames), static_cast<double>(both_frames)));
    std::printf("| position error, nearest located body contact, median / p90 (mm) | %.1f / %.1f | %.1f / %.1f |\n",
                Quantile(err, 0.5), Quantile(err, 0.9), Quantile(plain_err, 0.5), Quantile(plain_err, 0.9));
    std::printf("| of it, over fused frames (mm) | %.1f / %.1f | |\n", Quantile(fused_err, 0.5), Quantile(fused_err, 0.9));
    std::printf("| interior presses (one patch), median / p90 (mm) | %.1f / %.1f | |\n", Quantile(interior_err, 0.5),
                Quantile(interior_err, 0.9));
    std::printf("| seam median / interior median | %.2f | %.2f |\n", Quantile(err, 0.5) / Quantile(interior_err, 0.5),
                Quantile(plain_err, 0.5) / Quantile(interior_err, 0.5));
    std::printf("| body contact force / probe force, median (p10-p90) | %.2f (%.2f-%.2f) | |\n", Quantile(force_ratio, 0.5),
                Quantile(force_ratio, 0.1), Quantile(force_ratio, 0.9));
    std::printf("| of it, over fused frames | %.2f (%.2f-%.2f) | |\n", Quantile(fused_ratio, 0.5), Quantile(fused_ratio, 0.1),
                Quantile(fused_ratio, 0.9));
    std::printf("| probes with a located body contact above %.2f N | %d of %d | |\n", threshold, stopped, used);
    std::printf("| probes that STOP: a patch's own force above %.2f N (hold frames) / with the seam sum (aggregate::Core) | %d (%.1f %%) / %d (%.1f %%) | |\n",
                threshold, own_stops, Pct(own_stops, used), judged_stops, Pct(judged_stops, used));
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "seam_eval: %s\n", e.what());
    return 1;
  }
}
