#pragma once
// Patch geometry on a cylindrical limb of radius surface_radius_mm around the patch-frame y axis.
// Patch frame: origin on the limb axis at the elbow edge (Y = 0); +y toward the wrist; R = 0 lies on +z
// and R grows toward +x (a right-handed rotation about +y). 3-D quantities are in metres, as URDF has them.
// Unrolled surface: (Y mm, arc mm) with arc = surface_radius_mm * R in radians. On a cylinder the
// unrolled Euclidean distance is the exact geodesic distance on the surface.
#include <Eigen/Core>
#include <numbers>

#include "ruffini/patch/spec.h"

namespace ruffini::patch {

inline constexpr double kDegToRad = std::numbers::pi / 180.0;

struct UnrolledPoint {
  double y_mm = 0.0;
  double arc_mm = 0.0;
};

class Geometry {
 public:
  explicit Geometry(double surface_radius_mm) noexcept : radius_mm_(surface_radius_mm) {}
  explicit Geometry(const PatchSpec& spec) noexcept : radius_mm_(spec.surface_radius_mm) {}

  [[nodiscard]] double radius_mm() const noexcept { return radius_mm_; }
  [[nodiscard]] double ArcMm(double r_deg) const noexcept { return radius_mm_ * r_deg * kDegToRad; }
  [[nodiscard]] double RDeg(double arc_mm) const noexcept { return arc_mm / radius_mm_ / kDegToRad; }
  [[nodiscard]] UnrolledPoint Unroll(const SurfacePoint& p) const noexcept {
    return {p.y_mm, ArcMm(p.r_deg)};
  }
  [[nodiscard]] SurfacePoint Roll(const UnrolledPoint& u) const noexcept { return {u.y_mm, RDeg(u.arc_mm)}; }

  // Point on (or depth_mm below) the surface, in metres, patch frame.
  [[nodiscard]] Eigen::Vector3d PointM(const SurfacePoint& p, double depth_mm = 0.0) const noexcept;
  // Outward unit normal of the surface at p, patch frame.
  [[nodiscard]] Eigen::Vector3d NormalAt(const SurfacePoint& p) const noexcept;
  // The surface point whose normal line passes through p_m (p_m off the limb axis).
  [[nodiscard]] SurfacePoint Project(const Eigen::Vector3d& p_m) const noexcept;
  // Geodesic distance on the surface, mm.
  [[nodiscard]] double SurfaceDistanceMm(const SurfacePoint& a, const SurfacePoint& b) const noexcept;

 private:
  double radius_mm_;
};

}  // namespace ruffini::patch
