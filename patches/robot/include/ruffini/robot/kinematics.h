#pragma once
// Forward kinematics: joint coordinates q -> the pose of every link in the base frame B (the URDF root).
// Pinocchio's forwardKinematics(model, data, q): the Model is const and shared, the Data belongs to one
// thread and holds no reference to its Model.
#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <span>

#include "ruffini/robot/model.h"

namespace ruffini::robot {

// Per-thread workspace and result; fixed-size, so making one never allocates either.
struct Data {
  // X_BL[k]: pose of link k in the base frame B (metres), valid for k < model.num_links() after the
  // last ForwardKinematics that returned kOk. Identity until then.
  std::array<Eigen::Isometry3d, kMaxLinks> X_BL;
  Data() { X_BL.fill(Eigen::Isometry3d::Identity()); }
};

// Joint values beyond this magnitude (rad or m) are refused: no real joint gets there, and it keeps every
// pose finite.
inline constexpr double kMaxAbsJointValue = 1e6;

enum class FkStatus : std::uint8_t {
  kOk,
  kWrongJointCount,  // q.size() != model.num_dof()
  kNotFinite,        // some q[i] is NaN or infinite
  kOutOfRange,       // some |q[i]| > kMaxAbsJointValue
};
[[nodiscard]] const char* ToString(FkStatus s) noexcept;

// Computes data.X_BL for q (q[i] drives model.dof_joint(i)). On any status but kOk, data is left exactly as
// it was and nothing is computed. Joint position limits are not enforced here (a controller's reading may
// sit a hair beyond them): ask WithinLimits.
// Real-time safe: no allocation, no lock, no throw.
[[nodiscard]] FkStatus ForwardKinematics(const Model& model, std::span<const double> q, Data& data) noexcept;

// True when q has num_dof() finite values, each inside its joint's [lower - tolerance, upper + tolerance].
// Real-time safe: no allocation, no lock, no throw.
[[nodiscard]] bool WithinLimits(const Model& model, std::span<const double> q, double tolerance = 0.0) noexcept;

}  // namespace ruffini::robot
