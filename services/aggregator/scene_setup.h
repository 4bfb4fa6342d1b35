#pragma once
// The aggregator's setup from a scene file: its safety section (regions, thresholds, deadlines), the robot and
// the patch mounts, and what each decoder must announce (spec fingerprint, model SHA-256 of the scene's model).
#include <cstdint>
#include <string>

#include "ruffini/aggregate/core.h"

namespace ruffini::aggregator {

// Throws InputError naming the file, the key and what was expected (a scene without a `safety:` section
// cannot run an aggregator: it names no thresholds).
// Setup.robot_name is the scene's `name`; Setup.run_id a fresh DrawRunId().
aggregate::Setup SetupFromScene(const std::string& scene_path);
// A random nonzero 64-bit run id (std::random_device), drawn once per aggregator start.
std::uint64_t DrawRunId();
// One line for the log: patches, regions and thresholds, robot.
std::string Describe(const aggregate::Setup& setup);

}  // namespace ruffini::aggregator
