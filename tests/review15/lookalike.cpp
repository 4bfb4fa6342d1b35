// Review 15, finding 1: how far apart, in units of the interrogator's noise, are the look-alikes of pair.md section 4?
// Noise-free twin shifts, common mode removed (a) as the test does (sorted[8], the upper median) and (b) as the
// decoder does (decode::MedianOfPresent: mean of the two middle values of 16). Prints per pair: |hard|^2, |diff|^2,
// the single-frame separation d' = |diff| / sigma (sigma 0.3 pm per grating, white), the error rate of a
// likelihood-ratio test between the two on one frame (Phi(-d'/2)) and the separation integrated over the 0.3 s ramp
// and the 0.5 s hold at 1 kHz. Exits 1 when any pair is separable on one frame at d' >= 3 (the "no decoder of these
// 16 shifts can" claim does not hold in the twin).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "../decode/hard_press.h"
#include "ruffini/decode/baseline.h"
#include "ruffini/twin/scene.h"

using namespace ruffini;

int main() {
  const twin::Scene scene = twin::LoadScene("config/scenes/cobot.yaml");
  std::size_t p = 0;
  while (scene.patches[p].name != "upper_arm_a") ++p;
  const v1::DecoderModel model = decode::LoadModel(scene.patches[p].model_path);
  testing::HardPressRig rig(scene, p, model);
  const auto shifts = [&](double y, double r, double f, bool decoder_median) {
    const std::vector<twin::Contact> c{twin::Contact{{y, r}, f, scene.probe}};
    twin::Shifts raw{};
    std::uint32_t flags = 0;
    rig.twin().StrainShiftsPm(c, raw, flags);
    std::vector<double> v(raw.begin(), raw.end());
    double cm;
    if (decoder_median) {
      decode::ShiftsPm s{};
      for (std::size_t i = 0; i < 16; ++i) s[i] = static_cast<float>(raw[i]);
      cm = decode::MedianOfPresent(s, 1);
    } else {
      std::vector<double> sorted = v;
      std::nth_element(sorted.begin(), sorted.begin() + 8, sorted.end());
      cm = sorted[8];
    }
    for (double& x : v) x -= cm;
    return v;
  };
  const double sigma = 0.3;
  struct L { double y, r, f, ly, lr, lf; };
  int bad = 0;
  for (const L& c : {L{119.5, 23.5, 5.0, 117.5, 47.0, 0.75}, L{119.5, 23.5, 3.0, 116.0, 48.5, 0.5},
                     L{119.5, 122.0, 5.0, 119.0, 101.0, 0.75}}) {
    for (int dm = 0; dm < 2; ++dm) {
      const auto h = shifts(c.y, c.r, c.f, dm), l = shifts(c.ly, c.lr, c.lf, dm);
      double hh = 0, d = 0;
      for (std::size_t i = 0; i < 16; ++i) { hh += h[i] * h[i]; d += (h[i] - l[i]) * (h[i] - l[i]); }
      // Ramp (300 frames, linear in force) and hold (500 frames): summed squared difference over sigma^2.
      double ramp = 0;
      for (int k = 1; k <= 300; ++k) {
        const double a = k / 300.0;
        const auto hk = shifts(c.y, c.r, a * c.f, dm), lk = shifts(c.ly, c.lr, a * c.lf, dm);
        for (std::size_t i = 0; i < 16; ++i) ramp += (hk[i] - lk[i]) * (hk[i] - lk[i]);
      }
      const double dprime = std::sqrt(d) / sigma;
      const double perr = 0.5 * std::erfc(dprime / 2 / std::sqrt(2.0));
      std::printf("%s: %.2f N at Y %.1f R %.1f vs %.2f N at Y %.1f R %.1f: |hard|^2 %.2f pm^2, |diff|^2 %.3f pm^2 "
                  "(16 sigma^2 = %.2f), one-frame d' %.2f, LR-test error %.3f; ramp d' %.1f, hold (500 frames) d' %.1f, "
                  "first 10 hold frames d' %.1f\n",
                  dm ? "decoder median" : "test's median ", c.f, c.y, c.r, c.lf, c.ly, c.lr, hh, d, 16 * sigma * sigma,
                  dprime, perr, std::sqrt(ramp) / sigma, std::sqrt(500 * d) / sigma, std::sqrt(10 * d) / sigma);
      if (dprime >= 3) bad = 1;
    }
  }
  // Nearest light press (0.3-1.5 N, 0.05 N steps, 0.5 mm / 0.5 deg grid near the look-alike) to the 5 N corner press.
  const auto h = shifts(119.5, 23.5, 5.0, true);
  double best = 1e9, by = 0, br = 0, bf = 0;
  for (double y = 110; y <= 120.01; y += 0.5)
    for (double r = 35; r <= 60.01; r += 0.5)
      for (double f = 0.3; f <= 1.501; f += 0.05) {
        const auto l = shifts(y, r, f, true);
        double d = 0;
        for (std::size_t i = 0; i < 16; ++i) d += (h[i] - l[i]) * (h[i] - l[i]);
        if (d < best) { best = d; by = y; br = r; bf = f; }
      }
  std::printf("nearest light press (<= 1.5 N) to 5 N at Y 119.5 R 23.5: %.2f N at Y %.1f R %.1f, |diff|^2 %.3f pm^2, d' %.2f\n",
              bf, by, br, best, std::sqrt(best) / sigma);
  return bad;
}
