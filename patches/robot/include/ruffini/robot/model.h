#pragma once
// The robot's kinematic Model, read once from a URDF (Pinocchio's Model/Data split: the Model is immutable
// after loading and shared by every thread; each thread that computes kinematics owns a Data, see
// kinematics.h).
//
// The Model is flat and fixed-size: links in topological order (link 0 is the URDF root, the base frame B;
// every other link's parent has a smaller index), one joint per non-root link (joint(k) is the joint whose
// child is link k, k >= 1), at most kMaxLinks links and kMaxDof degrees of freedom, checked at load.
// Joint coordinates q: one per revolute, continuous or prismatic joint, in the links' topological order
// (depth first from the root, siblings by joint name as urdfdom orders them); radians or metres.
// For a serial arm that is simply base to tip. Fixed joints take no coordinate.
//
// Loading is not real-time: it reads the file, parses it with urdfdom and throws InputError naming the
// file and what is wrong. The accessors are real-time safe: no allocation, no lock, no throw.
#include <Eigen/Geometry>
#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

namespace ruffini::robot {

inline constexpr std::size_t kMaxLinks = 32;
inline constexpr std::size_t kMaxDof = 16;
inline constexpr std::size_t kNoIndex = static_cast<std::size_t>(-1);

enum class JointType : std::uint8_t { kFixed, kRevolute, kContinuous, kPrismatic };
[[nodiscard]] const char* ToString(JointType t) noexcept;

struct JointLimits {
  double lower = 0.0;     // rad or m; -inf for a continuous joint
  double upper = 0.0;     // rad or m; +inf for a continuous joint
  double velocity = 0.0;  // rad/s or m/s, as the URDF gives it (0: none given)
  double effort = 0.0;    // N m or N, as the URDF gives it (0: none given)
};

struct Link {
  std::string name;
  std::size_t parent = kNoIndex;  // parent link index; kNoIndex for the root
};

struct Joint {
  std::string name;
  JointType type = JointType::kFixed;
  std::size_t parent_link = kNoIndex;
  std::size_t child_link = kNoIndex;
  // Pose of the joint frame J (at q = 0) in the parent link's frame P; the child link's frame is J moved by
  // the joint: X_PC(q) = X_PJ * rotation about (or translation along) axis_J by q.
  Eigen::Isometry3d X_PJ = Eigen::Isometry3d::Identity();
  Eigen::Vector3d axis_J = Eigen::Vector3d::UnitZ();  // unit; meaningless for a fixed joint
  std::size_t q_index = kNoIndex;                     // coordinate index; kNoIndex for a fixed joint
  JointLimits limits;
};

class Model {
 public:
  // Reads and validates a URDF file; throws InputError ("<path>: <what is wrong>").
  [[nodiscard]] static Model FromUrdfFile(const std::filesystem::path& path);
  // Parses URDF text; `source` names it in error messages (a file name, or e.g. "<string>").
  [[nodiscard]] static Model FromUrdfString(std::string_view xml, std::string_view source);

  [[nodiscard]] const std::string& name() const noexcept { return name_; }
  [[nodiscard]] const std::string& source() const noexcept { return source_; }
  [[nodiscard]] std::size_t num_links() const noexcept { return num_links_; }
  [[nodiscard]] std::size_t num_dof() const noexcept { return num_dof_; }
  [[nodiscard]] const Link& link(std::size_t i) const noexcept { return links_[i]; }
  // The joint whose child is link k, 1 <= k < num_links().
  [[nodiscard]] const Joint& joint(std::size_t k) const noexcept { return joints_[k]; }
  // The joint that coordinate i drives, i < num_dof().
  [[nodiscard]] const Joint& dof_joint(std::size_t i) const noexcept { return joints_[dof_link_[i]]; }

  // Configure-time lookups (string compares): resolve names once, keep the indices.
  [[nodiscard]] std::optional<std::size_t> FindLink(std::string_view name) const noexcept;
  [[nodiscard]] std::optional<std::size_t> FindJoint(std::string_view name) const noexcept;  // child link index

 private:
  friend class ModelBuilder;
  std::string name_;
  std::string source_;
  std::size_t num_links_ = 0;
  std::size_t num_dof_ = 0;
  std::array<Link, kMaxLinks> links_{};
  std::array<Joint, kMaxLinks> joints_{};  // joints_[0] unused (the root has no parent joint)
  std::array<std::size_t, kMaxDof> dof_link_{};
};

}  // namespace ruffini::robot
