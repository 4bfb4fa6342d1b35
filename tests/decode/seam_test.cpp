// One probe across the forearm seam of config/scenes/cobot.yaml (issue 16: "a seam press fuses"), through both
// patches' decode paths and the aggregator's fusion (seam.h): with the bands from the shipped models' maps the
// two patches' contacts become one body contact on the seam; with the plain gate they stay two, 20 mm off.
#include <gtest/gtest.h>

#include <algorithm>
#include <vector>

#include "seam.h"

namespace ruffini::testing {
namespace {

const std::string kCobot = RUFFINI_SOURCE_DIR "/config/scenes/cobot.yaml";

double Median(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

TEST(Seam, AProbeOnTheForearmSeamIsOneBodyContactOnTheSeam) {
  const twin::Scene scene = twin::LoadScene(kCobot);
  const SeamRig rig(scene, 1.5);
  // The maps put both bands near 30 mm (a touch on the seam is decoded up to that far inside either patch).
  EXPECT_GT(rig.band_mm(0), 15.0);
  EXPECT_GT(rig.band_mm(1), 15.0);
  const robot::MountedSurface& a = rig.surface(rig.seam().a);
  for (const double y : {60.0, 75.0, 90.0}) {
    const auto frames = rig.Press(y, a.extent_r_deg, 20.0, 1.5, 7 + static_cast<std::uint64_t>(y));
    ASSERT_TRUE(frames.has_value()) << "a probe on the seam loads both covers";
    long both = 0, fused = 0, plain_fused = 0;
    std::vector<double> err, plain_err;
    for (const SeamFrame& f : *frames) {
      if (f.patches_in_contact != 2) continue;
      ++both;
      fused += f.fused;
      plain_fused += f.plain_fused;
      if (f.fused && f.located) err.push_back(f.error_mm);
      if (std::isfinite(f.plain_error_mm)) plain_err.push_back(f.plain_error_mm);
    }
    ASSERT_GT(both, static_cast<long>(frames->size()) / 2) << "Y " << y;
    EXPECT_GT(fused, both * 8 / 10) << "Y " << y;
    EXPECT_LT(plain_fused, both / 10) << "Y " << y << ": the plain gate keeps them apart";
    EXPECT_LT(Median(err), 10.0) << "Y " << y;
    EXPECT_LT(Median(err), Median(plain_err)) << "Y " << y;
  }
}

}  // namespace
}  // namespace ruffini::testing
