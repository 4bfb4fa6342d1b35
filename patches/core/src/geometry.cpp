#include "ruffini/patch/geometry.h"

#include <cmath>

namespace ruffini::patch {

Eigen::Vector3d Geometry::PointM(const SurfacePoint& p, double depth_mm) const noexcept {
  const double rho_m = (radius_mm_ - depth_mm) * 1e-3;
  const double a = p.r_deg * kDegToRad;
  return {rho_m * std::sin(a), p.y_mm * 1e-3, rho_m * std::cos(a)};
}

Eigen::Vector3d Geometry::NormalAt(const SurfacePoint& p) const noexcept {
  const double a = p.r_deg * kDegToRad;
  return {std::sin(a), 0.0, std::cos(a)};
}

SurfacePoint Geometry::Project(const Eigen::Vector3d& p_m) const noexcept {
  double r_deg = std::atan2(p_m.x(), p_m.z()) / kDegToRad;
  if (r_deg < -90.0) r_deg += 360.0;  // keep the patch's 0..145 deg span continuous
  return {p_m.y() * 1e3, r_deg};
}

double Geometry::SurfaceDistanceMm(const SurfacePoint& a, const SurfacePoint& b) const noexcept {
  return std::hypot(a.y_mm - b.y_mm, ArcMm(a.r_deg - b.r_deg));
}

}  // namespace ruffini::patch
