#include "scene_setup.h"

#include <random>
#include <sstream>

#include "ruffini/error.h"
#include "ruffini/robot/scene.h"
#include "ruffini/safety/scene.h"
#include "ruffini/scene_file.h"
#include "ruffini/service/common.h"
#include "ruffini/twin/scene.h"

namespace ruffini::aggregator {

std::uint64_t DrawRunId() {
  // std::random_device is the OS's entropy source on Linux (getrandom); two draws make 64 bits.
  std::random_device rd;
  std::uint64_t id = 0;
  while (id == 0) id = (static_cast<std::uint64_t>(rd()) << 32) ^ static_cast<std::uint64_t>(rd());
  return id;
}

aggregate::Setup SetupFromScene(const std::string& scene_path) {
  const SceneFile file = LoadSceneFile(scene_path);
  if (!file.safety) {
    throw InputError(scene_path + ": the scene has no `safety:` section (body regions and their thresholds); "
                     "the aggregator cannot judge contacts without it");
  }
  aggregate::Setup setup;
  setup.safety = safety::ConfigFromScene(file);
  const twin::Scene scene = twin::LoadScene(scene_path);
  std::optional<robot::RobotScene> robot;
  if (file.robot) {
    robot = robot::LoadRobotScene(file);
    setup.robot = robot->model;
  }
  for (const auto& p : scene.patches) {
    aggregate::PatchExpectation e;
    e.id = p.name;
    e.spec_name = p.spec.name;
    e.spec_fingerprint = p.spec.Fingerprint();
    e.extent_y_mm = p.spec.extent_y_mm;
    e.extent_r_deg = p.spec.extent_r_deg;
    if (!p.model_path.empty()) e.model_sha256 = service::Sha256OfFile(p.model_path);
    if (robot) {
      const robot::MountedPatch* m = robot->FindPatch(p.name);
      if (m == nullptr) throw InputError(scene_path + ": patch '" + p.name + "' has no mount");
      e.mount = m->mount;
    }
    setup.patches.push_back(std::move(e));
  }
  setup.instance = service::InstanceName();
  setup.robot_name = file.name;
  setup.run_id = DrawRunId();
  return setup;
}

std::string Describe(const aggregate::Setup& setup) {
  std::ostringstream out;
  out << setup.patches.size() << " patches (";
  for (std::size_t i = 0; i < setup.safety.patches.size(); ++i) {
    const auto& p = setup.safety.patches[i];
    out << (i ? ", " : "") << p.id << " in " << p.region;
    if (setup.patches[i].mount) out << " on " << setup.patches[i].mount->link;
  }
  out << "); regions:";
  for (const auto& r : setup.safety.regions) out << " " << r.name << " > " << r.threshold_n << " N stops;";
  out << " robot name '" << setup.robot_name << "', run id " << std::hex << setup.run_id << std::dec << ";";
  out << " robot: " << (setup.robot ? setup.robot->name() + " (" + std::to_string(setup.robot->num_dof()) + " joints)" : "none");
  return out.str();
}

}  // namespace ruffini::aggregator
