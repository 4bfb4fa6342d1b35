#include "ruffini/robot/mount.h"

#include <cmath>
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

}  // namespace ruffini::robot
