#include "ruffini/robot/mount.h"

#include <cmath>
#include <limits>
#include <sstream>

#include "ruffini/error.h"
#include "ruffini/patch/geometry.h"

namespace ruffini::robot {

SurfaceInLink PatchToLink(const PatchMount& mount, const patch::SurfacePoint& s) noexcept {
  const patch::Geometry g(mount.surface_radius_mm);
  return {mount.X_LP * g.PointM(s), mount.X_LP.linear() * g.NormalAt(s)};
}

std::optional<PatchProjection> LinkToPatch(const PatchMount& mount, const Eigen::Vector3d& p_LQ_m) noexcept {
  if (!p_LQ_m.allFinite()) return std::nullopt;
  const Eigen::Vector3d p_PQ_m = mount.X_LP.inverse(Eigen::Isometry) * p_LQ_m;
  const double rho_m = std::hypot(p_PQ_m.x(), p_PQ_m.z());
  if (!std::isfinite(rho_m) || rho_m < 1e-9) return std::nullopt;
  const patch::Geometry g(mount.surface_radius_mm);
  return PatchProjection{g.Project(p_PQ_m), rho_m * 1e3 - mount.surface_radius_mm};
}

std::size_t ValidateMount(const Model& model, const PatchMount& mount, std::string_view where) {
  const std::string w(where);
  const auto link = model.FindLink(mount.link);
  if (!link) {
    std::string known;
    for (std::size_t i = 0; i < model.num_links(); ++i) known += (i ? ", " : "") + model.link(i).name;
    throw InputError(w + ": link '" + mount.link + "' is not in " + model.source() + " (links: " + known + ")");
  }
  const Eigen::Matrix3d R = mount.X_LP.linear();
  if (!R.allFinite() || !mount.X_LP.translation().allFinite()) throw InputError(w + ": the pose must be finite");
  const double orthogonality = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (orthogonality > 1e-9 || R.determinant() < 0) {
    std::ostringstream s;
    s << w << ": the pose's rotation is not a proper rotation (|R^T R - I| = " << orthogonality
      << ", det = " << R.determinant() << ")";
    throw InputError(s.str());
  }
  if (!std::isfinite(mount.surface_radius_mm) || mount.surface_radius_mm <= 0 || mount.surface_radius_mm > 1000) {
    std::ostringstream s;
    s << w << ": surface_radius_mm (" << mount.surface_radius_mm << ") must lie in (0, 1000]";
    throw InputError(s.str());
  }
  return *link;
}

const char* ToString(PatchEdge e) noexcept {
  switch (e) {
    case PatchEdge::kYMin: return "y_min";
    case PatchEdge::kYMax: return "y_max";
    case PatchEdge::kRMin: return "r_min";
    case PatchEdge::kRMax: return "r_max";
  }
  return "unknown";
}

double DistanceToEdgeMm(const MountedSurface& p, PatchEdge edge, const patch::SurfacePoint& s) noexcept {
  const patch::Geometry g(p.mount.surface_radius_mm);
  switch (edge) {
    case PatchEdge::kYMin: return s.y_mm;
    case PatchEdge::kYMax: return p.extent_y_mm - s.y_mm;
    case PatchEdge::kRMin: return g.ArcMm(s.r_deg);
    case PatchEdge::kRMax: return g.ArcMm(p.extent_r_deg - s.r_deg);
  }
  return 0.0;
}

std::vector<Seam> FindSeams(std::span<const MountedSurface> patches) {
  std::vector<Seam> seams;
  for (std::size_t a = 0; a < patches.size(); ++a) {
    const MountedSurface& pa = patches[a];
    const patch::Geometry ga(pa.mount.surface_radius_mm);
    const double out_deg = ga.RDeg(1.0);
    // Five points along each edge (10 to 90 % of it): covers that meet along part of an edge are found too.
    for (std::size_t q = 0; q < 20; ++q) {
      const std::size_t k = q / 5;
      const double f = 0.1 + 0.2 * static_cast<double>(q % 5);
      const double y = f * pa.extent_y_mm, r = f * pa.extent_r_deg;
      const patch::SurfacePoint outside[4] = {{-1.0, r}, {pa.extent_y_mm + 1.0, r}, {y, -out_deg},
                                              {y, pa.extent_r_deg + out_deg}};
      const Eigen::Vector3d p_L = PatchToLink(pa.mount, outside[k]).p_LS_m;
      for (std::size_t b = 0; b < patches.size(); ++b) {
        if (b == a) continue;
        const MountedSurface& pb = patches[b];
        if (pb.mount.link != pa.mount.link) continue;
        const auto proj = LinkToPatch(pb.mount, p_L);
        if (!proj || std::abs(proj->height_mm) > 1.0) continue;
        patch::SurfacePoint s = proj->point;
        if (s.r_deg > pb.extent_r_deg + 180.0) s.r_deg -= 360.0;  // the value nearest the span
        if (s.y_mm < 0 || s.y_mm > pb.extent_y_mm || s.r_deg < 0 || s.r_deg > pb.extent_r_deg) continue;
        PatchEdge nearest = PatchEdge::kYMin;
        double d_min = std::numeric_limits<double>::infinity();
        // Only an edge parallel to this one (Y with Y, R with R): near a corner the nearest edge may be the other kind.
        const bool r_edge = k >= 2;
        for (const PatchEdge e : {PatchEdge::kYMin, PatchEdge::kYMax, PatchEdge::kRMin, PatchEdge::kRMax}) {
          if ((e == PatchEdge::kRMin || e == PatchEdge::kRMax) != r_edge) continue;
          const double d = DistanceToEdgeMm(pb, e, s);
          if (d < d_min) {
            d_min = d;
            nearest = e;
          }
        }
        if (d_min > 2.0) continue;  // inside b, not where its cover ends: an overlap, not a seam
        // Probed from both sides: keep one record per pair of edges, the lower index as a.
        const Seam seam = a < b ? Seam{a, b, static_cast<PatchEdge>(k), nearest} : Seam{b, a, nearest, static_cast<PatchEdge>(k)};
        bool known = false;
        for (const Seam& o : seams) known = known || (o.a == seam.a && o.b == seam.b && o.edge_a == seam.edge_a && o.edge_b == seam.edge_b);
        if (!known) seams.push_back(seam);
      }
    }
  }
  return seams;
}

}  // namespace ruffini::robot
