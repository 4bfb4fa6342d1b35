// Review 11: which presses move no grating by more than 6 pm after the rest check's common mode (median x ratio 1)?
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include "ruffini/twin/scene.h"
#include "ruffini/twin/twin.h"
using namespace ruffini;
int main(int argc, char** argv) {
  auto scene = twin::LoadScene(argv[1]);
  double forces[] = {1.5, 2.25, 5, 10, 20, 50};
  for (std::size_t p = 0; p < scene.patches.size(); ++p) {
    const auto& sp = scene.patches[p];
    twin::SkinTwin tw(sp.spec, scene.EffectsOf(p), {scene.probe.radius_mm});
    
    for (double f : forces) {
      int n = 0, low = 0; double worst = 1e9; double wy = 0, wr = 0, wmax = 0;
      for (double y = 23.0; y <= 122.0; y += 1.0)
        for (double r = 20.0; r <= 126.0; r += 1.0) {
          twin::Contact c{{y, r}, f, scene.probe};
          auto s = tw.StrainShiftsPm(c);
          double d[16], so[16]; int k = 0;
          for (int i = 0; i < 16; ++i) { d[i] = s[i]; if (std::isfinite(d[i])) so[k++] = d[i]; }
          std::sort(so, so + k);
          double med = k % 2 ? so[k / 2] : 0.5 * (so[k / 2 - 1] + so[k / 2]);
          double res = 0, mx = 0;
          for (int i = 0; i < 16; ++i) if (std::isfinite(d[i])) { res = std::max(res, std::abs(d[i] - med)); mx = std::max(mx, std::abs(d[i])); }
          ++n; if (res <= 6.0) ++low;
          if (std::isfinite(res) && res < worst) { worst = res; wy = y; wr = r; wmax = mx; }
          if (argc > 2 && res <= 6.0 && f >= 2.25) std::printf("  %s F %.2f Y %.1f R %.1f residual %.2f max %.2f\n", sp.name.c_str(), f, y, r, res, mx);
        }
      std::printf("%s F %5.2f N: %d of %d points residual <= 6 pm; least %.2f pm at Y %.1f R %.1f (max shift %.2f)\n",
                  sp.name.c_str(), f, low, n, worst, wy, wr, wmax);
    }
  }
}
