#include "ruffini/safety/scene.h"

#include <cmath>
#include <limits>

#include "ruffini/error.h"

namespace ruffini::safety {
namespace {

constexpr double kNsPerMs = 1e6;
constexpr double kMaxDeadlineMs = 60'000.0;
constexpr double kMaxHealthyMs = 600'000.0;

std::int64_t ToNs(double ms) { return static_cast<std::int64_t>(std::llround(ms * kNsPerMs)); }
double ToMs(std::int64_t ns) { return static_cast<double>(ns) / kNsPerMs; }

// `{fraction: F, hold_ms: T, source: "..."}`: the hysteresis of a contact cause (ContactRelease).
ContactRelease ReadRelease(YamlReader m, const ContactRelease& fallback) {
  ContactRelease r = fallback;
  r.fraction = static_cast<float>(m.NumberOr("fraction", fallback.fraction, 0.0, 0.9));
  r.hold_ns = ToNs(m.NumberOr("hold_ms", ToMs(fallback.hold_ns), 0.0, kMaxDeadlineMs));
  if (!m.Has("source")) {
    m.Fail("source", "is missing: say why this release level and hold time (a number carries where it comes from)");
  }
  r.source = m.String("source");
  m.Finish();
  return r;
}

// A mapping's `source:` is required whenever the mapping is written.
std::string Source(YamlReader& m, const char* what) {
  if (!m.Has("source")) m.Fail("source", std::string("is missing: say where ") + what + " comes from, or why");
  return m.String("source");
}

}  // namespace

Config ConfigFromScene(const SceneFile& scene) {
  if (!scene.safety) {
    throw InputError(scene.source + ": 'safety' is missing (a mapping with regions and deadlines expected)");
  }
  YamlReader s = *scene.safety;
  Config c;
  ContactRelease release;  // the section's default for every region
  if (auto m = s.MapOr("contact_release")) release = ReadRelease(*m, release);
  for (YamlReader& reg : s.Sequence("regions")) {
    RegionConfig rc;
    rc.name = reg.String("name");
    for (const RegionConfig& other : c.regions) {
      if (other.name == rc.name) reg.Fail("name", "is used by two regions; region names must be unique");
    }
    const double threshold_n =
        reg.Number("threshold_n", std::numeric_limits<double>::lowest(), std::numeric_limits<double>::max());
    if (!(threshold_n > 0.0 && threshold_n <= kMaxThresholdN)) {
      reg.Fail("threshold_n", "must be a force above 0 N and at most 1000 N (a contact above it stops the robot)");
    }
    rc.threshold_n = static_cast<float>(threshold_n);
    if (!reg.Has("source")) {
      reg.Fail("source", "is missing: say where the threshold comes from (ISO/TS 15066 values vary between "
                         "sources, FACTS.md), or why it was chosen");
    }
    rc.source = reg.String("source");
    rc.release = release;
    if (auto m = reg.MapOr("release")) rc.release = ReadRelease(*m, release);
    reg.Finish();
    c.regions.push_back(std::move(rc));
  }
  if (c.regions.empty()) s.Fail("regions", "must list at least one body region ({name, threshold_n, source})");

  const double deadline_ms =
      s.NumberOr("silence_deadline_ms", ToMs(PatchConfig{}.silence_deadline_ns), 0.001, kMaxDeadlineMs);
  if (scene.robot) {
    c.joint_state_max_age_ns =
        ToNs(s.NumberOr("joint_state_max_age_ms", ToMs(c.joint_state_max_age_ns), 0.001, kMaxDeadlineMs));
  } else {
    c.joint_states_required = false;
    if (s.Has("joint_state_max_age_ms")) {
      s.Fail("joint_state_max_age_ms", "needs a robot: the scene has no 'robot' section, so no joint states");
    }
  }
  c.healthy_before_reset_ns =
      ToNs(s.NumberOr("healthy_before_reset_ms", ToMs(c.healthy_before_reset_ns), 0.0, kMaxHealthyMs));
  c.new_epoch_per_cause = s.BoolOr("new_epoch_per_cause", c.new_epoch_per_cause);
  InputLimits& in = c.input;
  std::string sources;
  auto add_source = [&](const std::string& key, const std::string& text) {
    sources += (sources.empty() ? "" : "; ") + key + ": " + text;
  };
  if (auto m = s.MapOr("negative_force_tolerance")) {
    in.negative_force_tolerance_n = static_cast<float>(m->Number("force_n", 0.0, 1.0));
    add_source("negative_force_tolerance", Source(*m, "this tolerance"));
    m->Finish();
  }
  if (auto m = s.MapOr("time_skew")) {
    in.max_time_skew_ns = ToNs(m->Number("max_ms", 0.001, 3'600'000.0));
    add_source("time_skew", Source(*m, "this bound"));
    m->Finish();
  }
  if (auto m = s.MapOr("position_tolerance")) {
    in.position_tolerance_y_mm = m->NumberOr("y_mm", in.position_tolerance_y_mm, 0.0, 100.0);
    in.position_tolerance_r_deg = m->NumberOr("r_deg", in.position_tolerance_r_deg, 0.0, 90.0);
    add_source("position_tolerance", Source(*m, "this tolerance"));
    m->Finish();
  }
  if (auto m = s.MapOr("decoders")) {
    in.sample_rate_hz = m->NumberOr("sample_rate_hz", 0.0, 1.0, 1e6);
    in.decoder_config_sha256 = m->StringOr("config_sha256", "");
    if (!in.decoder_config_sha256.empty() &&
        (in.decoder_config_sha256.size() != 64 ||
         in.decoder_config_sha256.find_first_not_of("0123456789abcdef") != std::string::npos)) {
      m->Fail("config_sha256", "must be a SHA-256 in lower-case hex (64 characters), as PatchHello sends it");
    }
    add_source("decoders", Source(*m, "this expectation"));
    m->Finish();
  }
  in.source = sources;
  if (auto m = s.MapOr("link_layer")) {
    Config::LinkLayer& l = c.link;
    l.freshness_budget_ns = ToNs(m->NumberOr("freshness_budget_ms", ToMs(l.freshness_budget_ns), 0.1, kMaxDeadlineMs));
    l.error_window_ns = ToNs(1000.0 * m->NumberOr("error_window_s", static_cast<double>(l.error_window_ns) / 1e9, 0.001, 86'400.0));
    const double limit = m->NumberOr("error_limit", l.error_limit, 1.0, 8.0);
    if (limit != std::floor(limit)) m->Fail("error_limit", "must be a whole number of errors (1 to 8)");
    l.error_limit = static_cast<int>(limit);
    l.source = Source(*m, "these budgets");
    m->Finish();
  }
  if (auto m = s.MapOr("stop_rule")) {
    Config::StopRule& r = c.stop_rule;
    r.sd_k = static_cast<float>(m->NumberOr("sd_k", r.sd_k, -3.0, 3.0));
    r.max_sd_n = static_cast<float>(m->NumberOr("max_sd_n", r.max_sd_n, 0.001, 10.0));
    r.source = Source(*m, "this stop rule (what it costs in false stops and misses)");
    m->Finish();
  }
  if (auto m = s.MapOr("seam_sum")) {
    c.seam_sum.enabled = m->BoolOr("enabled", c.seam_sum.enabled);
    c.seam_sum.source = Source(*m, "judging seam contacts on their sum (what it costs in false stops)");
    m->Finish();
  }
  if (auto m = s.MapOr("coverage")) {
    CoverageConfig& cov = c.coverage;
    cov.press_factor = m->NumberOr("press_factor", cov.press_factor, 1.0, 100.0);
    cov.source = Source(*m, "this press factor");
    if (m->Has("accepted_uncovered")) {
      std::vector<YamlReader> bands = m->Sequence("accepted_uncovered");
      // The scene check cuts every map cell at the band edges inside it, a cost that grows with the cube of the
      // bands crossing one cell (review 12: 2 x 1600 bands took 7 s a load); a scene names a handful.
      constexpr std::size_t kMaxBands = 256;
      if (bands.size() > kMaxBands) {
        m->Fail("accepted_uncovered", "names " + std::to_string(bands.size()) + " bands; at most " +
                                          std::to_string(kMaxBands) + " (merge them into fewer, larger bands)");
      }
      for (YamlReader& b : bands) {
        CoverageConfig::Band band;
        band.name = b.String("name");
        for (const auto& other : cov.accepted_uncovered) {
          if (other.name == band.name) b.Fail("name", "is used by two bands; band names must be unique");
        }
        band.patch = b.StringOr("patch", "");  // none: the band lies on every patch of the scene
        bool known = band.patch.empty();
        for (const SceneFilePatch& p : scene.patches) known = known || p.name == band.patch;
        if (!known) b.Fail("patch", "names no patch of the scene");
        const auto range = [&](const char* key, double& lo, double& hi) {
          const std::vector<double> v = b.Numbers(key, 0.0, 1000.0);
          if (v.size() != 2 || !(v[0] <= v[1])) b.Fail(key, "must be [min, max] with min <= max (patch frame)");
          lo = v[0];
          hi = v[1];
        };
        range("y_mm", band.y_min_mm, band.y_max_mm);
        range("r_deg", band.r_min_deg, band.r_max_deg);
        if (!b.Has("source")) b.Fail("source", "is missing: say why this band may stay uncovered");
        band.source = b.String("source");
        b.Finish();
        cov.accepted_uncovered.push_back(std::move(band));
      }
    }
    m->Finish();
  }
  s.Finish();

  for (const SceneFilePatch& p : scene.patches) {
    YamlReader entry = p.entry;
    PatchConfig pc;
    pc.id = p.name;
    pc.region = entry.String("region");
    bool known = false;
    std::string names;
    for (const RegionConfig& r : c.regions) {
      known = known || r.name == pc.region;
      names += (names.empty() ? "" : ", ") + r.name;
    }
    if (!known) entry.Fail("region", "names no region in safety.regions (regions: " + names + ")");
    pc.silence_deadline_ns = ToNs(entry.NumberOr("silence_deadline_ms", deadline_ms, 0.001, kMaxDeadlineMs));
    c.patches.push_back(std::move(pc));
  }
  try {
    Validate(c);
  } catch (const InputError& e) {
    throw InputError(scene.source + ": " + e.what());
  }
  return c;
}

Config ConfigFromScene(const std::string& scene_path) { return ConfigFromScene(LoadSceneFile(scene_path)); }

}  // namespace ruffini::safety
