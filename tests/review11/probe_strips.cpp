// Review 11: decode::GuaranteeRegion (the scene check's core) on synthetic maps.
#include <cstdio>
#include <initializer_list>
#include "ruffini/decode/sensitivity.h"
using namespace ruffini;
static void Run(const char* name, std::initializer_list<float> ys, std::initializer_list<float> rs,
                std::vector<decode::UncoveredBand> bands = {}) {
  google::protobuf::RepeatedPtrField<v1::SensitivityMap> maps;
  auto* m = maps.Add();
  m->set_level_n(1.5f); m->set_reliability(0.95f); m->set_presses(20); m->add_forces_n(1.0f); m->add_forces_n(2.25f);
  for (float y : ys) m->add_y_mm(y);
  for (float r : rs) m->add_r_deg(r);
  for (int i = 0; i < m->y_mm_size() * m->r_deg_size(); ++i) { m->add_min_force_n(1.0f); m->add_location_error_mm(1.0f); }
  try { decode::ValidateSensitivity(*m, name); } catch (const std::exception& e) { std::printf("%-40s invalid: %s\n", name, e.what()); return; }
  decode::CoveragePatch p{"p", &maps, 150.0, 145.0, 37.4 * 3.14159265 / 180.0};
  auto g = decode::GuaranteeRegion({p}, bands, 1.5, 1.5);
  std::printf("%-40s ok=%d guaranteed %.2f N, %u points, unmeasured %zu%s%s\n", name, g.ok(), g.guaranteed_threshold_n, g.points,
              g.unmeasured.size(), g.unmeasured.empty() ? "" : ": ", g.unmeasured.empty() ? "" : g.unmeasured[0].c_str());
}
int main() {
  Run("full grid 2..148 / 2..143 step ~", {2, 40, 75, 110, 148}, {2, 40, 75, 110, 143});
  Run("2x2 grid at the corners only", {2, 148}, {2, 143});
  Run("grid outside the patch (-100, 250)", {-100, 250}, {-50, 200});
  Run("grid far outside one side (200..300)", {200, 300}, {200, 300});
  Run("grid stops 20 mm short (control)", {20, 130}, {30, 115});
  std::vector<decode::UncoveredBand> pieces = {{"a", "", 0, 10.0, 0, 145, ""}, {"b", "", 10.2, 150, 0, 145, ""}};
  Run("Y0 strip 20mm, bands in pieces gap 0.2", {20, 148}, {2, 143}, pieces);
  std::vector<decode::UncoveredBand> pieces2 = {{"a", "", 0, 20, 0, 70.0, ""}, {"b", "", 0, 20, 70.2, 145, ""}};
  Run("Y0 strip, bands split in R gap 0.2 deg", {20, 148}, {2, 143}, pieces2);
}
