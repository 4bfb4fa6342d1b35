#pragma once
// Two touches on one patch (issue 16, docs/decoders.md "Two touches"): how one press's hold frames are judged.
// Shared by the test (two_touch_test.cpp) and the measurement (two_touch_eval.cpp).
#include <cmath>
#include <numbers>
#include <span>

#include "hard_press.h"

namespace ruffini::testing {

// One contact frame against the probes that were really there.
struct FrameJudgement {
  bool located = false;
  bool multiple = false;
  // Every probe within `k_sigma` of the reported place under the reported covariance (with uncertainty), or
  // within `radius_mm` of it (without).
  bool covers_all = false;
};

inline FrameJudgement Judge(const link::Contact& c, std::span<const ProbeAt> probes, double mm_per_deg,
                            double k_sigma = 3.0, double radius_mm = 10.0) {
  FrameJudgement j;
  j.located = c.located;
  j.multiple = c.multiple;
  if (!c.located) return j;
  j.covers_all = true;
  for (const ProbeAt& p : probes) {
    const double dy = p.y_mm - c.y_mm, da = (p.r_deg - c.r_deg) * mm_per_deg;
    bool in = false;
    if (c.uncertainty) {
      const double a = c.cov_yy_mm2, b = c.cov_yr_mm2, d = c.cov_rr_mm2, det = a * d - b * b;
      if (det > 0 && a > 0) {
        const double m2 = (d * dy * dy - 2 * b * dy * da + a * da * da) / det;  // Mahalanobis squared
        in = m2 <= k_sigma * k_sigma;
      }
    } else {
      in = std::hypot(dy, da) <= radius_mm;
    }
    if (!in) j.covers_all = false;
  }
  return j;
}

struct PressJudgement {
  int located = 0;          // located hold frames
  int flagged = 0;          // of them flagged multiple
  int confident_wrong = 0;  // of them NOT flagged and not covering every probe
  int flagged_uncovering = 0;  // flagged, yet some probe outside the widened covariance
};

inline PressJudgement JudgePress(const PressOutcome& o, std::span<const ProbeAt> probes, double mm_per_deg) {
  PressJudgement p;
  for (const link::Contact& c : o.hold) {
    const FrameJudgement j = Judge(c, probes, mm_per_deg);
    if (!j.located) continue;
    ++p.located;
    if (j.multiple) {
      ++p.flagged;
      if (!j.covers_all) ++p.flagged_uncovering;
    } else if (!j.covers_all) {
      ++p.confident_wrong;
    }
  }
  return p;
}

inline double MmPerDeg(const twin::Scene& scene, std::size_t patch) {
  return scene.patches[patch].spec.surface_radius_mm * std::numbers::pi / 180.0;
}

}  // namespace ruffini::testing
