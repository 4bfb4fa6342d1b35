// URDF -> Model: urdfdom parses, we validate and flatten. urdfdom reports its errors through console_bridge
// and returns null; we capture that output for the InputError.
#include "ruffini/robot/model.h"

#include <console_bridge/console.h>
#include <urdf_parser/urdf_parser.h>

#include <cmath>
#include <exception>
#include <fstream>
#include <iterator>
#include <limits>
#include <mutex>
#include <sstream>
#include <utility>

#include "ruffini/error.h"

namespace ruffini::robot {

const char* ToString(JointType t) noexcept {
  switch (t) {
    case JointType::kFixed: return "fixed";
    case JointType::kRevolute: return "revolute";
    case JointType::kContinuous: return "continuous";
    case JointType::kPrismatic: return "prismatic";
  }
  return "?";
}

std::optional<std::size_t> Model::FindLink(std::string_view name) const noexcept {
  for (std::size_t i = 0; i < num_links_; ++i) {
    if (links_[i].name == name) return i;
  }
  return std::nullopt;
}

std::optional<std::size_t> Model::FindJoint(std::string_view name) const noexcept {
  for (std::size_t k = 1; k < num_links_; ++k) {
    if (joints_[k].name == name) return k;
  }
  return std::nullopt;
}

namespace {

// Collects console_bridge output while a parse runs. console_bridge's handler is process-wide, so parses are
// serialised (loading is configure-time, never on a hot path).
class CaptureOutput : public console_bridge::OutputHandler {
 public:
  CaptureOutput() { console_bridge::useOutputHandler(this); }
  ~CaptureOutput() override { console_bridge::restorePreviousOutputHandler(); }
  CaptureOutput(const CaptureOutput&) = delete;
  CaptureOutput& operator=(const CaptureOutput&) = delete;

  void log(const std::string& text, console_bridge::LogLevel level, const char*, int) override {
    if (level < console_bridge::CONSOLE_BRIDGE_LOG_WARN) return;
    if (!text_.empty()) text_ += "; ";
    text_ += text;
  }
  [[nodiscard]] const std::string& text() const { return text_; }

 private:
  std::string text_;
};

std::mutex& ParseMutex() {
  static std::mutex m;
  return m;
}

bool Finite(const urdf::Vector3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

}  // namespace

// Builds a Model from urdfdom's tree; every check names the source and the element.
class ModelBuilder {
 public:
  explicit ModelBuilder(std::string source) { m_.source_ = std::move(source); }

  Model Build(const urdf::ModelInterface& urdf) {
    m_.name_ = urdf.getName();
    if (urdf.links_.size() > kMaxLinks) {
      Fail("has " + std::to_string(urdf.links_.size()) + " links; at most " + std::to_string(kMaxLinks) +
           " are supported");
    }
    const auto root = urdf.getRoot();
    if (!root) Fail("has no root link");
    AddLink(*root, kNoIndex, nullptr);
    if (m_.num_links_ != urdf.links_.size()) {
      Fail("has " + std::to_string(urdf.links_.size() - m_.num_links_) + " link(s) not connected to the root '" +
           root->name + "'");
    }
    return std::move(m_);
  }

 private:
  [[noreturn]] void Fail(const std::string& what) const { throw InputError(m_.source_ + ": " + what); }

  void AddLink(const urdf::Link& l, std::size_t parent, const urdf::Joint* j) {
    if (m_.num_links_ >= kMaxLinks) Fail("more than " + std::to_string(kMaxLinks) + " links are not supported");
    const std::size_t k = m_.num_links_++;
    m_.links_[k].name = l.name;
    m_.links_[k].parent = parent;
    if (j != nullptr) AddJoint(*j, parent, k);
    for (const auto& cj : l.child_joints) {
      urdf::LinkConstSharedPtr child;
      for (const auto& cl : l.child_links) {
        if (cl && cl->name == cj->child_link_name) child = cl;
      }
      if (!child) Fail("joint '" + cj->name + "': child link '" + cj->child_link_name + "' not found");
      AddLink(*child, k, cj.get());
    }
  }

  void AddJoint(const urdf::Joint& u, std::size_t parent, std::size_t child) {
    Joint& j = m_.joints_[child];
    j.name = u.name;
    j.parent_link = parent;
    j.child_link = child;
    const std::string where = "joint '" + u.name + "'";
    switch (u.type) {
      case urdf::Joint::FIXED: j.type = JointType::kFixed; break;
      case urdf::Joint::REVOLUTE: j.type = JointType::kRevolute; break;
      case urdf::Joint::CONTINUOUS: j.type = JointType::kContinuous; break;
      case urdf::Joint::PRISMATIC: j.type = JointType::kPrismatic; break;
      case urdf::Joint::FLOATING: Fail(where + ": type 'floating' is not supported (fixed, revolute, continuous, prismatic are)");
      case urdf::Joint::PLANAR: Fail(where + ": type 'planar' is not supported (fixed, revolute, continuous, prismatic are)");
      default: Fail(where + ": unknown joint type");
    }
    if (u.mimic) Fail(where + ": mimic joints are not supported");

    const auto& o = u.parent_to_joint_origin_transform;
    const auto& r = o.rotation;
    if (!Finite(o.position) || !std::isfinite(r.x) || !std::isfinite(r.y) || !std::isfinite(r.z) ||
        !std::isfinite(r.w)) {
      Fail(where + ": <origin> must be finite");
    }
    Eigen::Quaterniond quat(r.w, r.x, r.y, r.z);
    if (quat.norm() < 0.5) Fail(where + ": <origin> has a degenerate rotation");
    quat.normalize();
    j.X_PJ = Eigen::Isometry3d::Identity();
    j.X_PJ.linear() = quat.toRotationMatrix();
    j.X_PJ.translation() = Eigen::Vector3d(o.position.x, o.position.y, o.position.z);

    if (j.type == JointType::kFixed) return;

    if (!Finite(u.axis)) Fail(where + ": <axis> must be finite");
    const Eigen::Vector3d axis(u.axis.x, u.axis.y, u.axis.z);
    if (axis.norm() < 1e-9) Fail(where + ": <axis> has zero length");
    j.axis_J = axis.normalized();

    if (m_.num_dof_ >= kMaxDof) Fail("more than " + std::to_string(kMaxDof) + " moving joints are not supported");
    j.q_index = m_.num_dof_;
    m_.dof_link_[m_.num_dof_++] = child;

    if (u.limits) {
      j.limits.lower = u.limits->lower;
      j.limits.upper = u.limits->upper;
      j.limits.velocity = u.limits->velocity;
      j.limits.effort = u.limits->effort;
      if (!std::isfinite(j.limits.velocity) || !std::isfinite(j.limits.effort) || j.limits.velocity < 0 ||
          j.limits.effort < 0) {
        Fail(where + ": <limit> velocity and effort must be finite and >= 0");
      }
    } else if (j.type != JointType::kContinuous) {
      Fail(where + ": a " + std::string(ToString(j.type)) + " joint needs a <limit>");
    }
    if (j.type == JointType::kContinuous) {
      j.limits.lower = -std::numeric_limits<double>::infinity();
      j.limits.upper = std::numeric_limits<double>::infinity();
    } else if (!std::isfinite(j.limits.lower) || !std::isfinite(j.limits.upper) ||
               j.limits.lower > j.limits.upper) {
      std::ostringstream s;
      s << where << ": <limit> lower (" << j.limits.lower << ") and upper (" << j.limits.upper
        << ") must be finite with lower <= upper";
      Fail(s.str());
    }
  }

  Model m_;
};

Model Model::FromUrdfString(std::string_view xml, std::string_view source) {
  const std::string src(source);
  urdf::ModelInterfaceSharedPtr urdf;
  std::string log;
  {
    const std::lock_guard lock(ParseMutex());
    CaptureOutput capture;
    try {
      urdf = urdf::parseURDF(std::string(xml));
    } catch (const std::exception& e) {
      throw InputError(src + ": not a valid URDF: " + e.what());
    }
    log = capture.text();
  }
  if (!urdf) {
    throw InputError(src + ": not a valid URDF: " + (log.empty() ? std::string("urdfdom gave no reason") : log));
  }
  return ModelBuilder(src).Build(*urdf);
}

Model Model::FromUrdfFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path.string() + ": cannot open the robot description (URDF) file");
  std::string xml((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw InputError(path.string() + ": read error");
  if (xml.empty()) throw InputError(path.string() + ": the URDF file is empty");
  return FromUrdfString(xml, path.string());
}

}  // namespace ruffini::robot
