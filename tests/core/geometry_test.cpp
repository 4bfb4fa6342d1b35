#include <gtest/gtest.h>

#include <cmath>

#include "ruffini/patch/geometry.h"
#include "ruffini/stats.h"

namespace ruffini::patch {
namespace {

TEST(GeometryTest, UnrollRoundTrip) {
  const Geometry g(37.4);
  for (double y : {0.0, 12.5, 150.0}) {
    for (double r : {0.0, 45.0, 145.0}) {
      const SurfacePoint p = g.Roll(g.Unroll({y, r}));
      EXPECT_NEAR(p.y_mm, y, 1e-12);
      EXPECT_NEAR(p.r_deg, r, 1e-12);
    }
  }
  EXPECT_NEAR(g.ArcMm(90.0), 37.4 * M_PI / 2, 1e-12);  // 58.7 mm: the indented area's width
}

TEST(GeometryTest, PointNormalAndProjection) {
  const Geometry g(37.4);
  const SurfacePoint p{80.0, 30.0};
  const Eigen::Vector3d x = g.PointM(p);
  EXPECT_NEAR(std::hypot(x.x(), x.z()), 0.0374, 1e-12);
  EXPECT_NEAR(x.y(), 0.080, 1e-12);
  const Eigen::Vector3d n = g.NormalAt(p);
  EXPECT_NEAR(n.norm(), 1.0, 1e-12);
  EXPECT_NEAR(n.dot(Eigen::Vector3d(x.x(), 0, x.z()).normalized()), 1.0, 1e-12);  // radial, outward
  const SurfacePoint back = g.Project(x + 0.01 * n);                               // any point on the normal line
  EXPECT_NEAR(back.y_mm, p.y_mm, 1e-9);
  EXPECT_NEAR(back.r_deg, p.r_deg, 1e-9);
  // R = 0 on +z, growing toward +x.
  EXPECT_NEAR(g.PointM({0, 0}).z(), 0.0374, 1e-12);
  EXPECT_NEAR(g.PointM({0, 90}).x(), 0.0374, 1e-12);
  // Depth goes inward.
  EXPECT_NEAR(g.PointM(p, 4.0).norm() < x.norm(), 1.0, 0.0);
}

TEST(GeometryTest, SurfaceDistanceIsTheCylinderGeodesic) {
  const Geometry g(37.4);
  EXPECT_NEAR(g.SurfaceDistanceMm({10, 0}, {10, 90}), 37.4 * M_PI / 2, 1e-9);
  EXPECT_NEAR(g.SurfaceDistanceMm({0, 10}, {30, 10}), 30.0, 1e-12);
  const double d = g.SurfaceDistanceMm({0, 0}, {40, 90});
  EXPECT_NEAR(d, std::hypot(40.0, 37.4 * M_PI / 2), 1e-9);
  EXPECT_GE(d, (g.PointM({0, 0}) - g.PointM({40, 90})).norm() * 1e3);  // never shorter than the chord
}

TEST(StatsTest, QuantilesMatchKnownValues) {
  // Type-7 quantiles as NumPy's default: for 1..10, q1 = 3.25, median 5.5, q3 = 7.75.
  std::vector<double> v{10, 1, 9, 2, 8, 3, 7, 4, 6, 5, std::nan("")};
  const auto s = stats::Summarize(v);
  EXPECT_DOUBLE_EQ(s.median, 5.5);
  EXPECT_DOUBLE_EQ(s.q1, 3.25);
  EXPECT_DOUBLE_EQ(s.q3, 7.75);
  EXPECT_TRUE(std::isnan(stats::Median({})));
  EXPECT_DOUBLE_EQ(stats::Quantile({4.0}, 0.9), 4.0);
}

}  // namespace
}  // namespace ruffini::patch
