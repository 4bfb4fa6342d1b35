#pragma once
// The aggregator's setup from a scene file: its safety section (regions, thresholds, deadlines), the robot and
// the patch mounts, and what each decoder must announce (spec fingerprint, model SHA-256 of the scene's model).
#include <string>

#include "ruffini/aggregate/core.h"

namespace ruffini::aggregator {

// Throws InputError naming the file, the key and what was expected (a scene without a `safety:` section
// cannot run an aggregator: it names no thresholds).
aggregate::Setup SetupFromScene(const std::string& scene_path);
// One line for the log: patches, regions and thresholds, robot.
std::string Describe(const aggregate::Setup& setup);

}  // namespace ruffini::aggregator
