#include "ruffini/eval/stop_score.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

#include "ruffini/error.h"
#include "ruffini/safety/policy.h"

namespace ruffini::eval {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

struct Press {
  std::int32_t id = -1;
  std::size_t start = 0, end = 0;  // first and last frame
  std::size_t peak_at = 0;
  float peak_n = 0;
  std::int64_t crossing = -1;      // first frame above the threshold (-1: none)
};

}  // namespace

std::string_view EpisodeKindName(EpisodeKind k) {
  switch (k) {
    case EpisodeKind::kContact: return "STOP";
    case EpisodeKind::kOverRange: return "STOP (over range)";
    case EpisodeKind::kNegativeForce: return "STOP (doubt: force below 0)";
    case EpisodeKind::kBeyondPatch: return "STOP (doubt: beyond the patch)";
    case EpisodeKind::kFault: return "FAULT";
  }
  return "?";
}

std::string_view EpisodeCauseName(EpisodeCause c) {
  switch (c) {
    case EpisodeCause::kDuePress: return "due press";
    case EpisodeCause::kGreyPress: return "grey-band press";
    case EpisodeCause::kLightPress: return "light press";
    case EpisodeCause::kRest: return "rest";
  }
  return "?";
}

int StopScore::CountEpisodes(EpisodeCause c) const {
  return static_cast<int>(std::count_if(episodes.begin(), episodes.end(), [c](const StopEpisode& e) { return e.cause == c; }));
}

int StopScore::due_stopped() const {
  return static_cast<int>(std::count_if(due_presses.begin(), due_presses.end(), [](const DuePress& p) { return p.stopped; }));
}

int StopScore::due_fault_only() const {
  return static_cast<int>(
      std::count_if(due_presses.begin(), due_presses.end(), [](const DuePress& p) { return p.stopped && p.fault_only; }));
}

std::vector<double> StopScore::Delays() const {
  std::vector<double> v;
  for (const DuePress& p : due_presses) {
    if (p.stopped) v.push_back(p.delay_ms);
  }
  std::sort(v.begin(), v.end());
  return v;
}

StopScore ScoreStops(const dataset::Dataset& d, const StreamPredictions& p, const patch::PatchSpec& spec,
                     const StopRuleModel& rule) {
  const std::size_t n = d.size();
  if (p.size() != n || p.over_range.size() != n) {
    throw InputError("stop score: the predictions have " + std::to_string(p.size()) + " frames, the dataset " +
                     std::to_string(n));
  }
  if (d.true_force_n.size() != n ||
      std::none_of(d.true_force_n.begin(), d.true_force_n.end(), [](float f) { return std::isfinite(f); })) {
    throw InputError("stop score: the dataset has no applied (true) force; per-press scoring needs the twin's labels");
  }
  if (!(d.info.sample_rate_hz > 0)) throw InputError("stop score: the dataset's sample rate must be above 0");
  if (!(rule.threshold_n > 0) || !(rule.due_factor >= 1) || !(rule.light_factor <= 1) || !(rule.tail_s >= 0) ||
      !(rule.operator_latch_s >= 0)) {
    throw InputError("stop score: threshold_n must be above 0, due_factor >= 1 >= light_factor, tail and latch >= 0");
  }
  const double dt = 1.0 / d.info.sample_rate_hz;
  const auto thr = static_cast<float>(rule.threshold_n);
  const int reject_frames =
      std::max(rule.reject_fault_min_frames, static_cast<int>(std::ceil(rule.reject_fault_s * d.info.sample_rate_hz - 1e-9)));
  const auto capturing = static_cast<std::uint8_t>(decode::Reason::kCapturing);
  const auto stale = static_cast<std::uint8_t>(decode::Reason::kBaselineStale);
  safety::Config::StopRule sr;
  sr.sd_k = static_cast<float>(rule.sd_k);
  sr.max_sd_n = static_cast<float>(rule.max_sd_n);

  // 1. Replay the decoder service (link::Monitor::OnFrame/Update) and the policy (Policy::OnContact and the
  // healthy heartbeat that ends a contact) frame by frame: is a cause present after frame k?
  std::vector<std::uint8_t> contact_cause(n, 0), fault(n, 0);
  std::vector<EpisodeKind> why(n, EpisodeKind::kContact);  // what last raised the contact cause
  EpisodeKind raised = EpisodeKind::kContact;
  std::vector<float> reported(n, 0.0f);
  std::size_t first = n;  // the first frame after the start-up capture
  int reject_run = 0;
  bool monitor_in_contact = false, contact_over = false;
  std::int64_t below_since = -1;
  auto judge = [&](std::size_t k, float force, float sd, bool over_range, bool released, bool located) {
    const bool beyond = located && (!std::isfinite(p.y_mm[k]) || !std::isfinite(p.r_deg[k]) ||
                                    p.y_mm[k] < -rule.position_tolerance_y_mm ||
                                    p.y_mm[k] > spec.extent_y_mm + rule.position_tolerance_y_mm ||
                                    p.r_deg[k] < -rule.position_tolerance_r_deg ||
                                    p.r_deg[k] > spec.extent_r_deg + rule.position_tolerance_r_deg);
    if (!std::isfinite(force) || force < -rule.negative_tolerance_n || beyond) {
      if (!contact_over) raised = beyond ? EpisodeKind::kBeyondPatch : EpisodeKind::kNegativeForce;
      contact_over = true;  // a doubt counts as above the threshold
      below_since = -1;
      return;
    }
    const float judged = safety::JudgedForce(std::max(force, 0.0f), sd, over_range, sr);
    const float release_force = std::max(judged, std::max(force, 0.0f));
    const bool over = judged > thr;
    if (released) {
      contact_over = false;
      below_since = -1;
    } else if (over) {
      if (!contact_over) raised = over_range ? EpisodeKind::kOverRange : EpisodeKind::kContact;
      contact_over = true;
      below_since = -1;
    } else if (contact_over) {
      if (release_force < thr * (1.0f - static_cast<float>(rule.release_fraction))) {
        if (below_since < 0) below_since = static_cast<std::int64_t>(k);
        if (static_cast<double>(static_cast<std::int64_t>(k) - below_since) * dt >= rule.release_hold_s - 1e-9) {
          contact_over = false;
          below_since = -1;
        }
      } else {
        below_since = -1;
      }
    }
  };
  for (std::size_t k = 0; k < n; ++k) {
    const std::uint8_t reason = p.reason[k];
    if (first == n) {
      if (reason == capturing) continue;
      first = k;
    }
    bool message = false;
    if (p.over_range[k] != 0) {
      reject_run = 0;
      monitor_in_contact = true;
      reported[k] = p.force_n[k];
      judge(k, p.force_n[k], 0.0f, true, false, false);  // sent without an sd (link::Monitor::OnFrame)
      message = true;
    } else if (p.valid[k] != 0) {
      reject_run = 0;
      if (p.in_contact[k] != 0 || monitor_in_contact) {
        if (p.in_contact[k] != 0) reported[k] = p.force_n[k];
        // A release is sent clamped at 0 (link::Monitor::OnFrame).
        const float sent = p.in_contact[k] != 0 ? p.force_n[k] : std::max(0.0f, p.force_n[k]);
        judge(k, sent, p.force_sd_n[k], false, p.in_contact[k] == 0, p.located[k] != 0);
        monitor_in_contact = p.in_contact[k] != 0;
        message = true;
      }
    } else if (reason != capturing) {
      ++reject_run;
      if (reason == stale) monitor_in_contact = false;
    }
    fault[k] = (reason == stale || reject_run >= reject_frames) ? 1 : 0;
    // A healthy heartbeat out of contact ends a contact cause (the heartbeat comes every 10 ms; here with
    // every frame that sent no contact).
    if (!message && fault[k] == 0 && !monitor_in_contact) {
      contact_over = false;
      below_since = -1;
    }
    contact_cause[k] = contact_over ? 1 : 0;
    why[k] = raised;
  }

  StopScore s;
  if (first == n) return s;
  s.frames = n - first;
  s.hours = static_cast<double>(s.frames) * dt / 3600.0;

  // 2. Presses: the twin's indentations, judged by their true peak.
  std::map<std::int32_t, Press> by_id;
  for (std::size_t k = first; k < n; ++k) {
    const std::int32_t id = d.indentation[k];
    if (id < 0) continue;
    auto [it, fresh] = by_id.try_emplace(id);
    Press& pr = it->second;
    if (fresh) {
      pr.id = id;
      pr.start = k;
    }
    pr.end = k;
    const float f = d.true_force_n[k];
    if (std::isfinite(f) && f > pr.peak_n) {
      pr.peak_n = f;
      pr.peak_at = k;
    }
    if (pr.crossing < 0 && std::isfinite(f) && f > thr) pr.crossing = static_cast<std::int64_t>(k);
  }
  std::vector<Press> presses;
  for (auto& [id, pr] : by_id) presses.push_back(pr);
  std::sort(presses.begin(), presses.end(), [](const Press& a, const Press& b) { return a.start < b.start; });
  const auto tail = static_cast<std::size_t>(std::llround(rule.tail_s / dt));
  auto classify = [&](const Press& pr) {
    if (pr.peak_n >= rule.due_factor * rule.threshold_n) return EpisodeCause::kDuePress;
    if (pr.peak_n <= rule.light_factor * rule.threshold_n) return EpisodeCause::kLightPress;
    return EpisodeCause::kGreyPress;
  };
  s.presses = static_cast<int>(presses.size());
  for (const Press& pr : presses) {
    const EpisodeCause c = classify(pr);
    if (c == EpisodeCause::kLightPress) ++s.light;
    if (c == EpisodeCause::kGreyPress) ++s.grey;
    if (c != EpisodeCause::kDuePress) continue;
    ++s.due;
    DuePress dp;
    dp.press = pr.id;
    const auto kc = pr.crossing >= 0 ? static_cast<std::size_t>(pr.crossing) : pr.peak_at;
    dp.t_s = d.t_s[kc];
    dp.peak_n = pr.peak_n;
    dp.y_mm = d.y_mm[pr.peak_at];
    dp.r_deg = d.r_deg[pr.peak_at];
    const std::size_t last = std::min(n - 1, pr.end + tail);
    bool any_contact = false;
    for (std::size_t k = pr.start; k <= last; ++k) {
      dp.reported_max_n = std::max(dp.reported_max_n, reported[k]);
      if (contact_cause[k] == 0 && fault[k] == 0) continue;
      any_contact = any_contact || contact_cause[k] != 0;
      if (!dp.stopped) {
        dp.stopped = true;
        dp.delay_ms = (static_cast<double>(k) - static_cast<double>(kc)) * dt * 1000.0;
      }
    }
    dp.fault_only = dp.stopped && !any_contact;
    s.due_presses.push_back(dp);
  }

  // 3. STOP episodes, each attributed to the press in whose window it started (the latest started), or a rest.
  std::size_t press_i = 0;
  std::int64_t last_present = -1;
  std::int32_t last_light_stopped = -1;
  for (std::size_t k = first; k < n; ++k) {
    const bool present = contact_cause[k] != 0 || fault[k] != 0;
    if (!present) continue;
    const bool same = last_present >= 0 &&
                      static_cast<double>(static_cast<std::int64_t>(k) - last_present) * dt <= rule.operator_latch_s + 1e-9;
    if (same) {
      StopEpisode& e = s.episodes.back();
      e.end_s = d.t_s[k];
      e.reported_max_n = std::max(e.reported_max_n, reported[k]);
    } else {
      StopEpisode e;
      e.t_s = e.end_s = d.t_s[k];
      e.kind = contact_cause[k] != 0 ? why[k] : EpisodeKind::kFault;
      e.reported_max_n = reported[k];
      e.y_mm = e.r_deg = kNaN;
      // The latest press started by frame k, or the one before it (a rest of at least a second follows every
      // press, so no earlier window reaches k).
      while (press_i + 1 < presses.size() && presses[press_i + 1].start <= k) ++press_i;
      const Press* in = nullptr;
      for (std::size_t back = 0; back < 2 && back <= press_i && press_i < presses.size(); ++back) {
        const Press& pr = presses[press_i - back];
        if (pr.start <= k && k <= pr.end + tail) {
          in = &pr;
          break;
        }
      }
      if (in != nullptr) {
        e.cause = classify(*in);
        if (e.cause == EpisodeCause::kLightPress && in->id != last_light_stopped) {
          ++s.light_stopped;
          last_light_stopped = in->id;
        }
        e.press = in->id;
        e.press_peak_n = in->peak_n;
        e.y_mm = d.y_mm[in->peak_at];
        e.r_deg = d.r_deg[in->peak_at];
      }
      s.episodes.push_back(e);
    }
    last_present = static_cast<std::int64_t>(k);
  }

  // 4. FAULT time (and the part with no press above the threshold), false contacts.
  double run_no_cause = 0;
  for (std::size_t k = first; k < n; ++k) {
    const float truth = d.true_force_n[k];
    if (fault[k] != 0) {
      s.fault_s += dt;
      if (!(truth > thr)) {
        s.fault_no_cause_s += dt;
        run_no_cause += dt;
        s.longest_fault_no_cause_s = std::max(s.longest_fault_no_cause_s, run_no_cause);
      }
    } else {
      run_no_cause = 0;
    }
    const bool reported_contact = (p.valid[k] != 0 && p.in_contact[k] != 0) || p.over_range[k] != 0;
    if (std::isfinite(truth) && truth > 0.1f) {
      ++s.pressed_frames;
      if (!reported_contact) ++s.unseen_frames;
    }
    if (std::isfinite(truth) && truth < rule.quiet_n) {
      ++s.quiet_frames;
      if (reported_contact) ++s.false_contact_frames;
    }
  }
  return s;
}

}  // namespace ruffini::eval
