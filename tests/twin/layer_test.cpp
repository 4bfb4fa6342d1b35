#include <gtest/gtest.h>

#include <cmath>

#include "ruffini/twin/layer.h"

namespace ruffini::twin {
namespace {

TEST(LayerTest, FastBesselMatchesTheLibrary) {
  for (double x = 0.0; x < 400.0; x += 0.0137) {
    double j0 = 0, j1 = 0;
    BesselJ01(x, j0, j1);
    ASSERT_NEAR(j0, std::cyl_bessel_j(0.0, x), 2e-7) << x;
    ASSERT_NEAR(j1, std::cyl_bessel_j(1.0, x), 2e-7) << x;
  }
}

// In the half-space limit the bonded-layer solution must reproduce Boussinesq's point-load strains.
TEST(LayerTest, ThickLayerMatchesBoussinesq) {
  LayerParams thick{400.0, 4.0, 152.0, 0.49};
  const auto prof = ComputeStrainProfiles(thick, {0.0}, 30.0, 0.1);
  for (double r : {0.0, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0, 20.0}) {
    const auto b = Boussinesq(152.0, 0.49, 4.0, r);
    const double peak = Boussinesq(152.0, 0.49, 4.0, 0.0).eps_tt;
    EXPECT_NEAR(prof[0].Tt(r), b.eps_tt, 0.01 * peak) << "r = " << r;
    EXPECT_NEAR(prof[0].Rr(r), b.eps_rr, 0.01 * peak) << "r = " << r;
  }
}

// The rigid base confines the nearly incompressible layer: right under the load it squeezes out sideways
// (more hoop strain than a half-space), and far away the field dies faster than Boussinesq's.
TEST(LayerTest, BondedBaseConfinesTheField) {
  LayerParams layer{8.0, 4.0, 152.0, 0.49};
  const auto prof = ComputeStrainProfiles(layer, {0.0, 3.0}, 30.0, 0.1);
  EXPECT_GT(prof[0].Tt(0.0), Boussinesq(152.0, 0.49, 4.0, 0.0).eps_tt);
  EXPECT_LT(prof[0].Tt(20.0), 0.8 * Boussinesq(152.0, 0.49, 4.0, 20.0).eps_tt);
  // Beyond ~3 mm the radial strain turns compressive (the weak compressive tail along the fibre).
  EXPECT_LT(prof[0].Rr(5.0), 0.0);
  // A spread (Hertz) load has a lower peak than a point load of the same force.
  EXPECT_LT(prof[1].Tt(0.0), prof[0].Tt(0.0));
  // Far field decays.
  EXPECT_LT(std::abs(prof[0].Tt(25.0)), 0.01 * prof[0].Tt(0.0));
}

}  // namespace
}  // namespace ruffini::twin
