// Review 11: the release refusal (fdd1649) against two touches: the same twin frames through a field model's
// pipeline with release_refuse_n 0.2 (default) and 0 (off); any frame whose outputs differ at a reported force of
// 0.2 N or more, or a stop-worthy (> 1.5 N) frame only the "off" pipeline reports.
#include <cmath>
#include <cstdio>
#include <random>
#include <array>
#include <algorithm>
#include "ruffini/decode/model_io.h"
#include "ruffini/decode/pipeline.h"
#include "ruffini/twin/scene.h"
#include "ruffini/twin/twin.h"
using namespace ruffini;
int main(int argc, char** argv) {
  auto scene = twin::LoadScene(argv[1]);
  const std::size_t pi = std::min<std::size_t>(2, scene.patches.size() - 1);
  const auto& sp = scene.patches[pi];
  twin::SkinTwin tw(sp.spec, scene.EffectsOf(pi), {scene.probe.radius_mm});
  auto model = decode::LoadModel(argv[2]);
  decode::PipelineConfig on;
  on.baseline = decode::BaselineFor(model, 1000.0);
  decode::PipelineConfig off = on;
  off.release_refuse_n = 0.0;
  decode::Pipeline<float> pon(model, sp.spec, on), poff(model, sp.spec, off);
  std::printf("faint_refuse %d faint_max %.2f release_refuse %.2f\n", (int)*pon.config().faint_refuse, pon.config().faint_max_n,
              pon.config().release_refuse_n);
  const auto& ref = tw.reference_wavelength_nm();
  std::mt19937 rng(argc > 3 ? atoi(argv[3]) : 1);
  std::uniform_real_distribution<double> uy(25, 120), ur(22, 123);
  int cases = argc > 4 ? atoi(argv[4]) : 40, bad = 0, differ = 0;
  for (int k = 0; k < cases; ++k) {
    decode::Pipeline<float>::Data don(pon), doff(poff);
    const double y0 = uy(rng), r0 = ur(rng), y1 = uy(rng), r1 = ur(rng), y2 = uy(rng), r2 = ur(rng);
    const double fprev = 1.0 + 4.0 * (k % 3), f1 = std::array<double, 5>{2.25, 5.0, 20.0, 50.0, 1.8}[k % 5], f2 = 0.3 + 0.3 * (k % 4);
    double max_on = 0, max_off = 0; int ndiff = 0; double worst_diff_force = 0;
    for (int i = 0; i < 9000; ++i) {
      const double t = i / 1000.0;
      std::vector<twin::Contact> cs;
      auto ramp = [](double t, double a, double b) { return t < a ? 0.0 : t < a + 0.3 ? (t - a) / 0.3 : t < b ? 1.0 : t < b + 0.3 ? 1 - (t - b) / 0.3 : 0.0; };
      const double a = ramp(t, 3.0, 4.5);  // the earlier press: 3.0-4.8 s
      if (a > 0) cs.push_back({{y0, r0}, fprev * a, scene.probe});
      const double b = ramp(t, 5.3, 8.0);  // two touches from 5.3 s: 0.5 s after the release
      const double c = ramp(t, 5.0, 8.0);  // the light one a little earlier
      if (b > 0) cs.push_back({{y1, r1}, f1 * b, scene.probe});
      if (c > 0) cs.push_back({{y2, r2}, f2 * c, scene.probe});
      twin::Shifts s{}; std::uint32_t flags = 0;
      if (!cs.empty()) tw.StrainShiftsPm(cs, s, flags); 
      Wavelengths wl{};
      for (int g = 0; g < 16; ++g) wl[g] = ref[g] + s[g] * 1e-3;
      const auto o1 = pon.Process(wl, flags, don);
      const auto o2 = poff.Process(wl, flags, doff);
      if (t >= 5.0) {
        if (o1.in_contact) max_on = std::max(max_on, (double)o1.force_n);
        if (o2.in_contact) max_off = std::max(max_off, (double)o2.force_n);
        if (o1.in_contact != o2.in_contact || o1.force_n != o2.force_n || o1.over_range != o2.over_range) {
          ++ndiff; if (o2.in_contact) worst_diff_force = std::max(worst_diff_force, (double)o2.force_n);
        }
      }
    }
    if (ndiff) ++differ;
    const bool hide = max_off > 1.5 && !(max_on > 1.5);
    if (hide || worst_diff_force >= 0.2) ++bad;
    if (hide || worst_diff_force >= 0.2 || argc > 5)
      std::printf("case %d prev %.0fN@(%.0f,%.0f) two %.0fN@(%.0f,%.0f)+%.1fN@(%.0f,%.0f): max on %.2f off %.2f, %d frames differ, largest off force among them %.2f%s\n",
                  k, fprev, y0, r0, f1, y1, r1, f2, y2, r2, max_on, max_off, ndiff, worst_diff_force, hide ? "  HIDDEN STOP" : "");
  }
  std::printf("%d cases: %d with differing frames, %d with a difference at >= 0.2 N or a hidden stop\n", cases, differ, bad);
}
