#pragma once
// Patch mounts: where a skin patch sits on a robot link, and the maps between patch coordinates (Y mm along
// the limb, R deg around it) and the link frame.
//
// The patch frame P is the one patches/core already uses (ruffini/patch/geometry.h), so the twin, the
// decoders and the robot side share one definition:
//   - origin on the limb's axis, level with the patch's elbow edge (Y = 0);
//   - +y along the limb axis toward the wrist (the +Y direction); a surface point sits at y = Y;
//   - R = 0 on +z; R grows toward +x, i.e. right-handed about +y; the surface is the cylinder of radius
//     surface_radius_mm about the y axis, so the point (Y, R) is
//       p_P = (rho sin R, Y, rho cos R) with rho = surface_radius_mm (in metres), and
//     its outward normal is n_P = (sin R, 0, cos R);
//   - arc length on the surface = surface_radius_mm x R in radians.
// A mount gives X_LP, the pose of P in the link frame L. Example for srs7.urdf: forearm_link has its origin
// at the elbow and +z toward the wrist, so a patch whose elbow edge is 60 mm down the forearm, with R = 0
// on the link's -y side, is X_LP = translation (0, 0, 0.060) * rotation Rx(+90 deg) (P's +y -> L's +z,
// P's +z -> L's -y).
//
// Everything here is pure and real-time safe (no allocation, no lock, no throw) except ValidateMount.
#include <Eigen/Geometry>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "ruffini/patch/spec.h"
#include "ruffini/robot/model.h"

namespace ruffini::robot {

struct PatchMount {
  std::string link;                                       // URDF link the patch is bonded to
  Eigen::Isometry3d X_LP = Eigen::Isometry3d::Identity();  // pose of the patch frame P in the link frame L
  double surface_radius_mm = 37.4;                         // the patch spec's surface_radius_mm
};

// A point of the skin's surface and its outward unit normal, both in the link frame.
struct SurfaceInLink {
  Eigen::Vector3d p_LS_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d n_L = Eigen::Vector3d::UnitZ();
};

// Where a link-frame point lies relative to the patch surface.
struct PatchProjection {
  patch::SurfacePoint point;  // the surface point whose normal line passes through the query point;
                              // r_deg in (-90, 270] so the patch's 0..145 deg span stays continuous
  double height_mm = 0.0;     // signed distance from the surface along that normal: > 0 outside the limb
};

// Patch coordinates -> the surface point and its outward normal in the link frame.
[[nodiscard]] SurfaceInLink PatchToLink(const PatchMount& mount, const patch::SurfacePoint& s) noexcept;

// A link-frame point (on or near the surface) -> patch coordinates. nullopt when the point is not finite or
// lies on the limb axis (within 1e-9 m), where R is undefined.
[[nodiscard]] std::optional<PatchProjection> LinkToPatch(const PatchMount& mount,
                                                         const Eigen::Vector3d& p_LQ_m) noexcept;

// Checks a mount against a model: the link exists, X_LP is finite and a proper rotation plus translation,
// the radius is finite and in (0, 1000] mm. Returns the link's index; throws InputError whose message
// starts with `where` (e.g. "config/scenes/arm.yaml: patches[0].mount").
std::size_t ValidateMount(const Model& model, const PatchMount& mount, std::string_view where);

// The four edges of a patch's surface, in the order twin::EdgeEffects uses: Y = 0 (elbow), Y = extent_y,
// R = 0, R = extent_r.
enum class PatchEdge : std::uint8_t { kYMin = 0, kYMax = 1, kRMin = 2, kRMax = 3 };
[[nodiscard]] const char* ToString(PatchEdge e) noexcept;

// A mounted patch's surface, for finding seams.
struct MountedSurface {
  PatchMount mount;
  double extent_y_mm = 150.0, extent_r_deg = 145.0;
};

// Two patches whose covers meet: edge_a of patch a continues into edge_b of patch b (indices into the list
// given to FindSeams, a < b).
struct Seam {
  std::size_t a = 0, b = 0;
  PatchEdge edge_a = PatchEdge::kRMax, edge_b = PatchEdge::kRMin;
};

// The seams among `patches`: a point 1 mm outside an edge of one patch (five along it, 10 to 90 %) on another's
// surface (same link, within 1 mm of its cylinder, inside its extent and within 2 mm of one of its edges: not
// an overlap) makes a seam between that edge and the other's edge nearest the point (each pair of edges once,
// a < b). Covers meeting across a joint (two links) are not seams here. The same test sim::EffectsFor uses to make the twin's edge `continued`.
// Configure-time (allocates).
[[nodiscard]] std::vector<Seam> FindSeams(std::span<const MountedSurface> patches);

// Distance from a surface point to one edge of the patch, mm on the surface (arc length for R edges;
// negative outside).
[[nodiscard]] double DistanceToEdgeMm(const MountedSurface& p, PatchEdge edge, const patch::SurfacePoint& s) noexcept;

}  // namespace ruffini::robot
