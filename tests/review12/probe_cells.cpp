// Review 12: decode::GuaranteeRegion on synthetic maps: grid on 0/extent, bands on grid lines +-1e-9, many bands.
#include <chrono>
#include <cmath>
#include <string>
#include <cstdio>
#include <cstdlib>
#include <vector>
#include "ruffini/decode/sensitivity.h"
using namespace ruffini;
static google::protobuf::RepeatedPtrField<v1::SensitivityMap> Map(std::vector<double> ys, std::vector<double> rs, float weak_y = -1) {
  google::protobuf::RepeatedPtrField<v1::SensitivityMap> maps;
  auto* m = maps.Add();
  m->set_level_n(1.5f); m->set_reliability(0.95f); m->set_presses(20); m->add_forces_n(1.0f); m->add_forces_n(2.25f);
  for (double y : ys) m->add_y_mm(y);
  for (double r : rs) m->add_r_deg(r);
  for (double y : ys) for (double r : rs) { (void)r; m->add_min_force_n(y == weak_y ? 200.0f : 1.0f); m->add_location_error_mm(1.0f); }
  decode::ValidateSensitivity(*m, "probe");
  return maps;
}
static std::vector<double> Grid(double from, double to, double step) { std::vector<double> v; for (double x = from; x <= to + 1e-9; x += step) v.push_back(x); return v; }
static bool Run(const char* name, const google::protobuf::RepeatedPtrField<v1::SensitivityMap>& maps, std::vector<decode::UncoveredBand> bands, bool want_ok) {
  decode::CoveragePatch p{"p", &maps, 150.0, 145.0, 37.4 * 3.14159265358979 / 180.0};
  auto t0 = std::chrono::steady_clock::now();
  auto g = decode::GuaranteeRegion({p}, bands, 1.5, 1.5);
  double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  bool good = g.ok() == want_ok;
  std::printf("%-58s ok=%d (want %d) judged %u of %u, unmeasured %zu, %.3f s %s\n", name, g.ok(), want_ok, g.covered_points, g.points, g.unmeasured.size(), s, good ? "" : "<-- WRONG");
  return good;
}
int main(int argc, char** argv) {
  const int nb = argc > 1 ? std::atoi(argv[1]) : 400;
  bool all = true;
  // Grid Y 0..150 step 5 (values at exactly 0 and the extent), R 0..145 deg step 5 deg (3.26 mm).
  auto ys = Grid(0, 150, 5), rs = Grid(0, 145, 5);
  all &= Run("grid on 0 and the extent, all strong", Map(ys, rs), {}, true);
  // Weak row at Y 50: a band [45,55] holds its cells... no: cells [45,50],[50,55] are inside; cells [40,45] and [55,60]
  // have corners 45 / 55 only, so the weak row is not judged.
  all &= Run("weak row Y50, band Y 45..55 (on grid lines)", Map(ys, rs, 50), {{"b", "", 45, 55, 0, 145, ""}}, true);
  all &= Run("weak row Y50, band Y 45+1e-9..55", Map(ys, rs, 50), {{"b", "", 45 + 1e-9, 55, 0, 145, ""}}, false);
  all &= Run("weak row Y50, band Y 45-1e-9..55", Map(ys, rs, 50), {{"b", "", 45 - 1e-9, 55, 0, 145, ""}}, true);
  all &= Run("weak row Y50, band Y 45..55, R 1e-9..145", Map(ys, rs, 50), {{"b", "", 45, 55, 1e-9, 145, ""}}, false);
  all &= Run("weak row Y50, two bands meeting at R 70", Map(ys, rs, 50), {{"a", "", 45, 55, 0, 70, ""}, {"b", "", 45, 55, 70, 145, ""}}, true);
  all &= Run("weak row Y50, two bands, gap 1e-9 at R 70", Map(ys, rs, 50), {{"a", "", 45, 55, 0, 70, ""}, {"b", "", 45, 55, 70 + 1e-9, 145, ""}}, false);
  all &= Run("weak row Y50, reversed band (55..45)", Map(ys, rs, 50), {{"b", "", 55, 45, 0, 145, ""}}, false);
  all &= Run("weak row Y50, NaN band", Map(ys, rs, 50), {{"b", "", 45, std::nan(""), 0, 145, ""}}, false);
  // Many bands: nb thin Y strips tiling Y 40..45 plus nb thin R strips tiling R 0..145 inside Y 40..45
  std::vector<decode::UncoveredBand> many;
  for (int i = 0; i < nb; ++i) many.push_back({"y" + std::to_string(i), "", 40 + 5.0 * i / nb, 40 + 5.0 * (i + 1) / nb, 0, 145, ""});
  for (int i = 0; i < nb; ++i) many.push_back({"r" + std::to_string(i), "", 40, 45, 145.0 * i / nb, 145.0 * (i + 1) / nb, ""});
  all &= Run(("2 x " + std::to_string(nb) + " bands tiling Y 40..45 (strong map)").c_str(), Map(ys, rs), many, true);
  return all ? 0 : 1;
}
