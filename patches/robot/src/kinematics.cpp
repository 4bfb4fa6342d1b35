#include "ruffini/robot/kinematics.h"

#include <cmath>

namespace ruffini::robot {

const char* ToString(FkStatus s) noexcept {
  switch (s) {
    case FkStatus::kOk: return "ok";
    case FkStatus::kWrongJointCount: return "wrong number of joint values";
    case FkStatus::kNotFinite: return "a joint value is not finite";
    case FkStatus::kOutOfRange: return "a joint value exceeds 1e6 (rad or m)";
  }
  return "?";
}

namespace {

FkStatus Check(const Model& model, std::span<const double> q) noexcept {
  if (q.size() != model.num_dof()) return FkStatus::kWrongJointCount;
  for (const double v : q) {
    if (!std::isfinite(v)) return FkStatus::kNotFinite;
  }
  for (const double v : q) {
    if (std::abs(v) > kMaxAbsJointValue) return FkStatus::kOutOfRange;
  }
  return FkStatus::kOk;
}

// Pose of the child link in the joint frame for coordinate value v.
Eigen::Isometry3d Motion(const Joint& j, double v) noexcept {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  switch (j.type) {
    case JointType::kRevolute:
    case JointType::kContinuous: X.linear() = Eigen::AngleAxisd(v, j.axis_J).toRotationMatrix(); break;
    case JointType::kPrismatic: X.translation() = v * j.axis_J; break;
    case JointType::kFixed: break;
  }
  return X;
}

}  // namespace

FkStatus ForwardKinematics(const Model& model, std::span<const double> q, Data& data) noexcept {
  const FkStatus status = Check(model, q);
  if (status != FkStatus::kOk) return status;
  data.X_BL[0] = Eigen::Isometry3d::Identity();
  for (std::size_t k = 1; k < model.num_links(); ++k) {
    const Joint& j = model.joint(k);
    const Eigen::Isometry3d& X_BP = data.X_BL[j.parent_link];
    if (j.type == JointType::kFixed) {
      data.X_BL[k] = X_BP * j.X_PJ;
    } else {
      data.X_BL[k] = X_BP * j.X_PJ * Motion(j, q[j.q_index]);
    }
  }
  return FkStatus::kOk;
}

bool WithinLimits(const Model& model, std::span<const double> q, double tolerance) noexcept {
  if (q.size() != model.num_dof()) return false;
  for (std::size_t i = 0; i < q.size(); ++i) {
    const JointLimits& l = model.dof_joint(i).limits;
    if (!std::isfinite(q[i]) || q[i] < l.lower - tolerance || q[i] > l.upper + tolerance) return false;
  }
  return true;
}

}  // namespace ruffini::robot
