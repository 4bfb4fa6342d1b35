#pragma once
// The aggregator's setup from a scene file: its safety section (regions, thresholds, deadlines), the robot and
// the patch mounts, and what each decoder must announce (spec fingerprint, model SHA-256 of the scene's model).
#include <cstdint>
#include <string>

#include "ruffini/aggregate/core.h"
#include "ruffini/decode/sensitivity.h"

namespace ruffini::aggregator {

// Throws InputError naming the file, the key and what was expected (a scene without a `safety:` section
// cannot run an aggregator: it names no thresholds), and when a region's threshold is below what its patches'
// sensitivity maps guarantee outside the scene's accepted uncovered bands (CoverageOfScene's refusal).
// Setup.robot_name is the scene's `name`; Setup.run_id a fresh DrawRunId().
aggregate::Setup SetupFromScene(const std::string& scene_path);
// The seams between the setup's patches (robot::FindSeams over their mounts) with each side's band from its
// model's sensitivity map at its region's threshold (decode::EdgeReachMm; 0: no map). Empty without mounts.
std::vector<fusion::FusionConfig::SeamBand> SeamsOf(const aggregate::Setup& setup);
// A random nonzero 64-bit run id (std::random_device), drawn once per aggregator start.
std::uint64_t DrawRunId();
// One line for the log: patches, regions and thresholds (with their guarantees and accepted bands), robot.
std::string Describe(const aggregate::Setup& setup);

// What a scene's regions can guarantee (docs/coverage.md): each patch's model's sensitivity maps (the map of
// the smallest level at or above its region's threshold), less the scene's `safety.coverage.accepted_uncovered`
// bands. Not real-time (reads every model file once).
struct SceneCoverage {
  std::vector<v1::RegionCoverage> regions;             // the scene's region order (AggregatorStatus.coverage)
  std::vector<decode::RegionGuarantee> guarantees;     // the same order, with the uncovered points
  // Per scene patch, its model's maps that fit it (measured on it, with its decoder): the guarantee, GetStatus and
  // the seams' bands (SeamsOf) use these alone.
  std::vector<std::vector<v1::SensitivityMap>> maps;
  // Per scene patch, why some of its model's maps are not used here ("": all fit): measured on another patch
  // (cast, mounting, spec) or with another decoder than the model's (review 10, finding 5).
  std::vector<std::string> map_problems;
  std::string refusal;                                 // empty: every region's threshold is guaranteed
};
// Throws InputError for a malformed scene or model, or a band beyond its patch's extent; a threshold below
// its guarantee is not thrown but said in `refusal`. Only the maps bound to the patch as the scene mounts it
// and to the model's own decoder count (SensitivityMap.measured_on, model_sha256); the others are named in
// `map_problems`, and a patch left without a map is unmapped.
SceneCoverage CoverageOfScene(const std::string& scene_path);
// SHA-256 (hex) of a model without its sensitivity maps: what a map's model_sha256 names.
std::string DecoderSha256(const v1::DecoderModel& model);
// Binds a map measured on patch `patch` of the scene (with mounts, as ruffini-sim builds it) with `model`'s
// decoder: sets measured_on (sim::MeasuredOn) and model_sha256 (DecoderSha256). Throws InputError for an
// unknown patch.
void BindMap(v1::SensitivityMap& map, const std::string& scene_path, const std::string& patch,
             const v1::DecoderModel& model);

// Lines for people (the log, `ruffini check-scene`): per region its threshold, the guarantee, the accepted
// bands; with `points`, every covered grid point that misses the guarantee.
std::string DescribeCoverage(const SceneCoverage& coverage, bool points = false);

}  // namespace ruffini::aggregator
