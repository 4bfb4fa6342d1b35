#pragma once
// The safety part of a scene: the scene's `safety:` section and every patch's `region:` (and optional
// `silence_deadline_ms:`), read into a safety::Config. The file's shape is the root reader's
// (ruffini/scene_file.h); the format is in docs/safety.md, "The scene's safety section".
//
//   patches:
//     - {name: forearm_a, spec: ..., region: forearm}            # + silence_deadline_ms: 40 to override
//   safety:
//     regions:
//       - {name: forearm, threshold_n: 1.5, source: "why this number"}
//     silence_deadline_ms: 30        # every patch's, unless its entry says otherwise (default 30)
//     joint_state_max_age_ms: 50     # only in a scene with a robot (default 50)
//     healthy_before_reset_ms: 200   # default 200
//     new_epoch_per_cause: true      # Config::new_epoch_per_cause (default true)
//     # Optional, each with a required `source:` when written (defaults in policy.h):
//     contact_release: {fraction: 0.1, hold_ms: 100, source: ...}  # every region's; a region may
//                                    # override it with its own `release: {fraction, hold_ms, source}`
//     negative_force_tolerance: {force_n: 0.05, source: ...}        # InputLimits
//     time_skew: {max_ms: 2000, source: ...}                        # frames and joint states vs arrival
//     position_tolerance: {y_mm: 5, r_deg: 5, source: ...}          # beyond the spec's extents
//     decoders: {sample_rate_hz: 1000, config_sha256: ..., source: ...}  # hello expectations
//     coverage:                      # CoverageConfig: what the patches' sensitivity maps must guarantee
//       press_factor: 1.5            # a press of 1.5 x a region's threshold stops on its covered surface
//       source: ...
//       accepted_uncovered:          # named parts of patches outside the guarantee, each with its reason
//         - {name: wrist-end, patch: forearm_a, y_mm: [130, 150], r_deg: [0, 145], source: ...}
//
// Times are written in ms and kept in ns. joint_states_required is true exactly when the scene names a robot.
// Every region needs a `source:` (FACTS.md: ISO/TS 15066 values vary between sources, so a number carries
// where it came from); thresholds are finite, above 0 and at most 1000 N; every patch's region must exist.
//
// Loading is not real-time: it throws InputError "<scene>:<line>:<col>: '<key>' (<value>) <what>".
#include <string>

#include "ruffini/safety/policy.h"
#include "ruffini/scene_file.h"

namespace ruffini::safety {

inline constexpr double kMaxThresholdN = 1000.0;

// The scene's safety Config, validated (also by Validate()). Throws InputError, also when the scene has no
// safety section.
[[nodiscard]] Config ConfigFromScene(const SceneFile& scene);
[[nodiscard]] Config ConfigFromScene(const std::string& scene_path);

}  // namespace ruffini::safety
