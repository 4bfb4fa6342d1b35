// field-hours: field hours of the twin, decoded as the service decodes them, scored press by press and STOP
// episode by STOP episode against the robot's stop rule (issue 17's targets: spurious STOPs per hour, hours
// stuck in FAULT, true crossing to STOP, false contact frames). eval::ScoreStops says what is counted.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>

#include "commands.h"
#include "progress.h"
#include "ruffini/dataset/dataset.h"
#include "ruffini/decode/model_io.h"
#include "ruffini/decode/pipeline.h"
#include "ruffini/error.h"
#include "ruffini/eval/stop_score.h"
#include "ruffini/eval/stream.h"
#include "ruffini/plot/svg.h"
#include "ruffini/stats.h"
#include "ruffini/twin/protocols.h"
#include "ruffini/twin/scene.h"
#include "ruffini/twin/twin.h"

namespace ruffini::cli {
namespace {

// The report's name for each model (or scene) given: its file name (or stem) when that tells them apart, else the
// path as given. The tables pool hours by this name, so two files named alike (old/m.rmodel, new/m.rmodel) once
// pooled into one row of twice the hours, silently. The same path given twice is an error, not two columns.
std::vector<std::string> ReportLabels(const std::vector<std::string>& paths, const char* option, bool stem) {
  std::vector<std::string> labels;
  for (const auto& p : paths) {
    const std::filesystem::path fp(p);
    labels.push_back(stem ? fp.stem().string() : fp.filename().string());
  }
  const auto unique = [](std::vector<std::string> v) {
    std::sort(v.begin(), v.end());
    return std::adjacent_find(v.begin(), v.end()) == v.end();
  };
  if (unique(labels)) return labels;
  if (!unique(paths)) throw InputError(std::string(option) + ": the same file is given twice");
  return paths;
}

// "901-910", "4,777-786": the seeds, in order, each once.
std::vector<std::uint64_t> ParseSeeds(const std::string& text) {
  std::vector<std::uint64_t> out;
  std::stringstream ss(text);
  std::string part;
  while (std::getline(ss, part, ',')) {
    const auto dash = part.find('-');
    try {
      std::size_t used = 0;
      const std::uint64_t a = std::stoull(part.substr(0, dash), &used);
      if (used != (dash == std::string::npos ? part.size() : dash)) throw std::invalid_argument(part);
      std::uint64_t b = a;
      if (dash != std::string::npos) {
        b = std::stoull(part.substr(dash + 1), &used);
        if (used != part.size() - dash - 1) throw std::invalid_argument(part);
      }
      if (b < a || b - a > 10000) throw std::invalid_argument(part);
      for (std::uint64_t s = a; s <= b; ++s) {
        if (std::find(out.begin(), out.end(), s) == out.end()) out.push_back(s);
      }
    } catch (const std::logic_error&) {
      throw InputError("--seeds: '" + part + "' is not a seed or a range A-B (A <= B, at most 10001 seeds)");
    }
  }
  if (out.empty()) throw InputError("--seeds: no seed given");
  return out;
}

std::string F(const char* fmt, double v) {
  char b[64];
  std::snprintf(b, sizeof b, fmt, v);
  return b;
}

std::string Pct(double a, double b) { return b > 0 ? F("%.2f %%", 100.0 * a / b) : "n/a"; }

double Quantile(const std::vector<double>& sorted, double q) {
  if (sorted.empty()) return std::nan("");
  const auto i = static_cast<std::size_t>(std::ceil(q * static_cast<double>(sorted.size()))) - 1;
  return sorted[std::min(sorted.size() - 1, i)];
}

struct Hour {
  std::string scene;
  std::uint64_t seed = 0;
  std::string model;  // label
  eval::StopScore score;
  eval::OperatorRetare retare;  // the operator's requests (when --retare)
};

// Pooled over hours.
struct Pool {
  double hours = 0, fault_s = 0, fault_no_cause_s = 0;
  int n_hours = 0, stuck = 0, presses = 0, due = 0, grey = 0, light = 0, due_stopped = 0, fault_only = 0;
  int spurious = 0, rest = 0, light_fired = 0;
  std::size_t quiet = 0, false_contacts = 0, pressed = 0, unseen = 0;
  double false_contact_min = 1e9, false_contact_max = 0;
  std::vector<double> delays;
  std::array<int, 5> by_kind{};  // spurious episodes by what started them (EpisodeKind)
  void Add(const eval::StopScore& s, const eval::StopRuleModel& rule) {
    ++n_hours;
    hours += s.hours;
    fault_s += s.fault_s;
    fault_no_cause_s += s.fault_no_cause_s;
    stuck += s.stuck(rule) ? 1 : 0;
    presses += s.presses;
    due += s.due;
    grey += s.grey;
    light += s.light;
    due_stopped += s.due_stopped();
    fault_only += s.due_fault_only();
    spurious += s.spurious();
    rest += s.CountEpisodes(eval::EpisodeCause::kRest);
    light_fired += s.light_stopped;
    for (const auto& e : s.episodes) {
      const bool sp = e.cause == eval::EpisodeCause::kLightPress || e.cause == eval::EpisodeCause::kRest;
      if (!sp) continue;
      ++by_kind[static_cast<std::size_t>(e.kind)];
    }
    quiet += s.quiet_frames;
    false_contacts += s.false_contact_frames;
    pressed += s.pressed_frames;
    unseen += s.unseen_frames;
    const double fc = s.quiet_frames > 0 ? static_cast<double>(s.false_contact_frames) / static_cast<double>(s.quiet_frames) : 0;
    false_contact_min = std::min(false_contact_min, fc);
    false_contact_max = std::max(false_contact_max, fc);
    const auto d = s.Delays();
    delays.insert(delays.end(), d.begin(), d.end());
  }
};

void RegisterFieldHours(CLI::App& app) {
  struct Args {
    std::vector<std::string> models, scenes;
    std::string seeds = "901-910", out = "field-hours-report";
    double duration_s = 3600.0, rate_hz = 100.0;
    eval::StopRuleModel rule;
    std::string thermal_field = "model";
    bool retare = false, retare_field = false;
    double gate_on_n = 0;  // 0: the model's
    std::string faint_refuse = "model";
    double release_refuse_n = decode::PipelineConfig{}.release_refuse_n;
    double release_tau_s = decode::PipelineConfig{}.release_tau_s;
    std::string patch;
    double retare_every_s = 10.0;
    double retare_level_n = decode::RetareConfig{}.min_force_n;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "field-hours",
      "Field hours of the twin decoded as the service decodes them, scored against the stop rule press by press: "
      "spurious STOP episodes per hour, hours stuck in FAULT, true crossing to STOP, missed presses, false contacts");
  cmd->add_option("--model", a->models, "Decoder model(s); each scores every hour")->required()->check(CLI::ExistingFile);
  cmd->add_option("--scene", a->scenes, "Field scene(s) (one patch each); every seed runs in every scene")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--seeds", a->seeds, "Seeds of the field protocol: 901-910, or 4,777-786")->capture_default_str();
  cmd->add_option("--duration-s", a->duration_s, "Length of each run")->check(CLI::Range(10.0, 36000.0))->capture_default_str();
  cmd->add_option("--rate-hz", a->rate_hz, "Frame rate")->check(CLI::Range(10.0, 10000.0))->capture_default_str();
  cmd->add_option("--threshold-n", a->rule.threshold_n, "The region's stop threshold")->check(CLI::Range(0.01, 1000.0))->capture_default_str();
  cmd->add_option("--sd-k", a->rule.sd_k, "The scene's stop_rule.sd_k (judged force = force + k sd)")
      ->check(CLI::Range(-3.0, 3.0))
      ->capture_default_str();
  cmd->add_option("--thermal-field", a->thermal_field, "The thermal-field follower: model (as the file says) | on | off")
      ->check(CLI::IsMember({"model", "on", "off"}))
      ->capture_default_str();
  cmd->add_option("--gate-on-n", a->gate_on_n,
                  "Experiment: the force gate's on level for every model (off at 0.8 x on, as trained); 0: each model's")
      ->check(CLI::Range(0.0, 2.0))
      ->capture_default_str();
  cmd->add_option("--patch", a->patch,
                  "The patch of a many-patch scene to run alone, on the bench, with its own cast (default: the scene's only one)");
  cmd->add_option("--faint-refuse", a->faint_refuse, kFaintRefuseHelp)
      ->check(CLI::IsMember({"model", "on", "off"}))->capture_default_str();
  cmd->add_option("--release-refuse-n", a->release_refuse_n, kReleaseRefuseHelp)->check(CLI::Range(0.0, 10.0))->capture_default_str();
  cmd->add_option("--release-tau-s", a->release_tau_s, kReleaseTauHelp)->check(CLI::Range(0.01, 3600.0))->capture_default_str();
  cmd->add_flag("--retare", a->retare,
                "The operator re-tares a stale patch (RetarePatch, judged against the model's response map) when it "
                "goes stale and every --retare-every-s while it stays so (docs/experiments/retare.md)");
  cmd->add_flag("--retare-field", a->retare_field,
                "Experiment, with --retare: the judge separates a first-order temperature field from a touch "
                "(RetareConfig::separate_field; off in the decoder service: review 6, docs/reviews/retare-field.md)");
  cmd->add_option("--retare-every-s", a->retare_every_s, "With --retare: seconds between requests")
      ->check(CLI::Range(0.5, 3600.0))
      ->capture_default_str();
  cmd->add_option("--retare-level-n", a->retare_level_n, "With --retare: a touch explaining this force refuses it")
      ->check(CLI::Range(0.05, 10.0))
      ->capture_default_str();
  cmd->add_option("--out", a->out, "Report directory (report.md, hours.csv, episodes.csv, spurious.svg)")->capture_default_str();
  cmd->callback([a]() {
    const std::vector<std::uint64_t> seeds = ParseSeeds(a->seeds);
    std::vector<std::pair<std::string, v1::DecoderModel>> models;
    const std::vector<std::string> model_labels = ReportLabels(a->models, "--model", false);
    const std::vector<std::string> scene_labels = ReportLabels(a->scenes, "--scene", true);
    for (std::size_t i = 0; i < a->models.size(); ++i) {
      const std::string& m = a->models[i];
      models.emplace_back(model_labels[i], decode::LoadModel(m));
      if (a->gate_on_n > 0) {
        models.back().second.mutable_gating()->set_on_n(static_cast<float>(a->gate_on_n));
        models.back().second.mutable_gating()->set_off_n(static_cast<float>(0.8 * a->gate_on_n));
      }
    }
    std::filesystem::create_directories(a->out);
    std::vector<Hour> hours;
    ProgressBar bar("field hours", a->scenes.size() * seeds.size());
    std::uint64_t done = 0;
    for (std::size_t si = 0; si < a->scenes.size(); ++si) {
      const std::string& scene_path = a->scenes[si];
      const twin::Scene scene = twin::LoadScene(scene_path);
      const twin::ScenePatch& patch = scene.Patch(a->patch);  // throws when unknown, or when none is named of many
      const twin::SkinTwin twin(patch.spec, scene.EffectsOf(static_cast<std::size_t>(&patch - scene.patches.data())),
                                {scene.probe.radius_mm});
      for (const auto& [label, m] : models) decode::CheckModelMatchesPatch(m, patch.spec, label);
      const std::string& scene_name = scene_labels[si];
      for (const std::uint64_t seed : seeds) {
        twin::FieldProtocol fp;
        fp.duration_s = a->duration_s;
        fp.rate_hz = a->rate_hz;
        fp.first_rest_s = std::min(fp.first_rest_s, fp.duration_s);
        fp.Validate();
        dataset::Dataset d;
        d.info = twin::TwinDatasetInfo(twin, scene, "field", seed, fp.rate_hz);
        twin::RunField(twin, scene, fp, seed, [&](std::span<const dataset::Frame> frames) {
          for (const auto& f : frames) d.Append(f);
        });
        for (const auto& [label, m] : models) {
          decode::PipelineConfig cfg;
          cfg.baseline = decode::BaselineFor(m, d.info.sample_rate_hz);
          if (a->thermal_field != "model") cfg.baseline.thermal_field = a->thermal_field == "on";
          cfg.faint_refuse = ModelOnOff(a->faint_refuse);
          cfg.release_refuse_n = a->release_refuse_n;
          cfg.release_tau_s = a->release_tau_s;
          const decode::Pipeline<float> pipe(m, patch.spec, cfg);
          eval::OperatorRetare op;
          op.map = m.has_response() ? &m.response() : nullptr;
          op.config.min_force_n = a->retare_level_n;
          op.every_s = a->retare_every_s;
          if (a->retare_field) op.config.SeparateField(patch.spec);  // off in the decoder service
          const eval::StreamPredictions p = a->retare ? eval::DecodeStream(pipe, d, op) : eval::DecodeStream(pipe, d);
          hours.push_back({scene_name, seed, label, eval::ScoreStops(d, p, patch.spec, a->rule), op});
        }
        bar.Update(++done);
      }
    }
    bar.Finish();

    // Tables.
    std::ostringstream r;
    const eval::StopRuleModel& rule = a->rule;
    r << "# Field hours scored against the stop rule\n\n"
      << "Reproduce: `ruffini field-hours";
    for (const auto& m : a->models) r << " --model " << m;
    for (const auto& s : a->scenes) r << " --scene " << s;
    if (!a->patch.empty()) r << " --patch " << a->patch;
    r << " --seeds " << a->seeds << " --duration-s " << a->duration_s << " --rate-hz " << a->rate_hz << " --threshold-n "
      << rule.threshold_n;
    if (rule.sd_k != 0) r << " --sd-k " << rule.sd_k;
    if (a->thermal_field != "model") r << " --thermal-field " << a->thermal_field;
    if (a->gate_on_n > 0) r << " --gate-on-n " << a->gate_on_n;
    if (a->faint_refuse != "model") r << " --faint-refuse " << a->faint_refuse;
    if (a->release_refuse_n != decode::PipelineConfig{}.release_refuse_n) r << " --release-refuse-n " << a->release_refuse_n;
    if (a->release_tau_s != decode::PipelineConfig{}.release_tau_s) r << " --release-tau-s " << a->release_tau_s;
    if (a->retare) r << " --retare --retare-every-s " << a->retare_every_s << " --retare-level-n " << a->retare_level_n;
    if (a->retare && a->retare_field) r << " --retare-field";
    r << " --out " << a->out << "`\n\n"
      << "Each run is `ruffini simulate --protocol field` (press, hold up to 120 s, release, rest; log-uniform peaks "
         "0.1-2.5 N; the same seed gives the same run), decoded by `decode::Pipeline` as the decoder service does, "
         "and replayed through the decoder service's FAULT rules and the safety policy's contact rule "
         "(threshold "
      << F("%.2f", rule.threshold_n) << " N, strictly above; judged force = force + " << F("%.1f", rule.sd_k)
      << " sd; a cause ends when the gate closes or after " << F("%.0f", rule.release_hold_s * 1000)
      << " ms below " << F("%.0f", 100 * (1 - rule.release_fraction))
      << " % of the threshold; a doubt, a negative force beyond 50 mN or a place beyond the patch, counts as above). "
         "A STOP episode is a run of frames with a cause (a contact cause or a FAULT); causes within "
      << F("%.1f", rule.operator_latch_s)
      << " s of each other are one episode (the STOP is latched until the operator resets).\n\n"
      << "- **due press**: true peak >= " << F("%.2f", rule.due_factor * rule.threshold_n)
      << " N; it must stop, from its start to " << F("%.1f", rule.tail_s)
      << " s after its end. Delay: from the true crossing of the threshold to the first frame with a cause "
         "(negative: before the true crossing). Stopped by a FAULT only: the arm stopped, the press was not seen.\n"
      << "- **spurious**: an episode starting during a rest or in a **light press** (true peak <= "
      << F("%.2f", rule.light_factor * rule.threshold_n)
      << " N) window: a STOP on a contact, or a FAULT no press caused (a stale baseline, a rejected run).\n"
      << "- **stuck**: a FAULT that lasts longer than " << F("%.0f", rule.stuck_s)
      << " s while no press is above the threshold.\n"
      << "- **false contact frames**: frames reported in contact whose true force is below 20 mN, over every such "
         "frame.\n\n";
    r << "## Pooled over the hours\n\n"
      << "| scene | model | hours | spurious STOPs per hour | rest episodes / light presses that STOP | "
         "spurious episodes started by: force above / force below 0 / place beyond / over range / FAULT | "
         "due presses: missed / stopped by FAULT only | true crossing to STOP, ms: p50 / "
         "p99 / max | hours stuck in FAULT | FAULT min per hour with no cause | false contact frames (range over hours) | frames above 100 mN not in contact |\n"
      << "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n";
    std::map<std::pair<std::string, std::string>, Pool> pools;
    std::vector<std::pair<std::string, std::string>> order;
    for (const Hour& h : hours) {
      const auto key = std::make_pair(h.scene, h.model);
      if (!pools.count(key)) order.push_back(key);
      pools[key].Add(h.score, rule);
    }
    for (const auto& key : order) {
      Pool& p = pools[key];
      std::sort(p.delays.begin(), p.delays.end());
      r << "| " << key.first << " | `" << key.second << "` | " << F("%.1f", p.hours) << " | "
        << F("%.2f", p.spurious / std::max(1e-9, p.hours)) << " | " << p.rest << " / " << p.light_fired
        << " of " << p.light << " | " << p.by_kind[0] << " / " << p.by_kind[2] << " / " << p.by_kind[3] << " / "
        << p.by_kind[1] << " / " << p.by_kind[4] << " | " << (p.due - p.due_stopped) << " of " << p.due << " / "
        << p.fault_only << " | " << F("%.0f", Quantile(p.delays, 0.5)) << " / " << F("%.0f", Quantile(p.delays, 0.99))
        << " / " << F("%.0f", p.delays.empty() ? std::nan("") : p.delays.back()) << " | " << p.stuck << " of "
        << p.n_hours << " | " << F("%.2f", p.fault_no_cause_s / 60.0 / std::max(1e-9, p.hours)) << " | "
        << Pct(static_cast<double>(p.false_contacts), static_cast<double>(p.quiet)) << " ("
        << F("%.1f", 100 * p.false_contact_min) << "-" << F("%.1f", 100 * p.false_contact_max) << " %) | "
        << Pct(static_cast<double>(p.unseen), static_cast<double>(p.pressed)) << " |\n";
    }
    if (a->retare) {
      r << "\nThe operator re-tares a stale patch (`--retare`): asked when the patch goes `baseline_stale` and every "
        << F("%.0f", a->retare_every_s) << " s while it stays so, judged against the model's response map (a touch of "
        << F("%.2f", a->retare_level_n) << " N or more refuses it; "
        << (a->retare_field ? "experiment: a smooth temperature field separated from the touch (off in the service)"
                            : "the touch takes every shift, as the decoder service judges")
        << ").\n\n"
        << "| scene | model | re-tares asked | accepted | refused: something presses (of them while nothing did) / other | accepted while a press "
           "was on (largest true force in the window) |\n| --- | --- | --- | --- | --- | --- |\n";
      for (const auto& key : order) {
        int asked = 0, acc = 0, pressing = 0, nothing = 0, other = 0, acc_pressed = 0;
        double acc_max = 0;
        for (const Hour& h : hours) {
          if (h.scene != key.first || h.model != key.second) continue;
          asked += h.retare.requests;
          acc += h.retare.accepted;
          pressing += h.retare.refused_pressing;
          nothing += h.retare.refused_pressing_nothing;
          other += h.retare.refused_other;
          acc_pressed += h.retare.accepted_while_pressed;
          acc_max = std::max(acc_max, h.retare.accepted_max_true_n);
        }
        r << "| " << key.first << " | `" << key.second << "` | " << asked << " | " << acc << " | " << pressing << " (" << nothing << ") / "
          << other << " | " << acc_pressed << " (" << F("%.2f", acc_max) << " N) |\n";
      }
    }
    r << "\nTargets (issue 17): spurious STOPs <= 0.1 per hour; 0 hours stuck; due presses: none missed, p99 <= "
         "100 ms; false contact frames <= 1 %.\n\n";

    r << "## Hour by hour\n\n| scene | seed | model | presses (due / grey / light) | spurious (rest / light) | due missed | "
         "delay p50 / max ms | FAULT s (no cause) | longest no-cause FAULT s | false contacts |\n"
      << "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n";
    std::ofstream csv(a->out + "/hours.csv");
    csv << "scene,seed,model,hours,presses,due,grey,light,spurious_rest_episodes,spurious_light_episodes,light_presses_stopped,"
           "due_missed,due_fault_only,delay_p50_ms,delay_max_ms,fault_s,fault_no_cause_s,longest_fault_no_cause_s,"
           "quiet_frames,false_contact_frames\n";
    std::ofstream eps(a->out + "/episodes.csv");
    eps << "scene,seed,model,t_s,end_s,kind,cause,press,press_peak_n,reported_max_n,y_mm,r_deg\n";
    for (const Hour& h : hours) {
      const auto& s = h.score;
      const auto d = s.Delays();
      const int rest = s.CountEpisodes(eval::EpisodeCause::kRest), light = s.CountEpisodes(eval::EpisodeCause::kLightPress);
      r << "| " << h.scene << " | " << h.seed << " | `" << h.model << "` | " << s.presses << " (" << s.due << " / "
        << s.grey << " / " << s.light << ") | " << s.spurious() << " (" << rest << " / " << light << ") | "
        << s.due_missed() << " | " << F("%.0f", Quantile(d, 0.5)) << " / "
        << F("%.0f", d.empty() ? std::nan("") : d.back()) << " | " << F("%.0f", s.fault_s) << " ("
        << F("%.0f", s.fault_no_cause_s) << ") | " << F("%.0f", s.longest_fault_no_cause_s) << " | "
        << Pct(static_cast<double>(s.false_contact_frames), static_cast<double>(s.quiet_frames)) << " |\n";
      csv << h.scene << "," << h.seed << "," << h.model << "," << s.hours << "," << s.presses << "," << s.due << ","
          << s.grey << "," << s.light << "," << rest << "," << light << ","
          << s.light_stopped << "," << s.due_missed() << "," << s.due_fault_only() << "," << Quantile(d, 0.5) << ","
          << (d.empty() ? std::nan("") : d.back()) << "," << s.fault_s << "," << s.fault_no_cause_s << ","
          << s.longest_fault_no_cause_s << "," << s.quiet_frames << "," << s.false_contact_frames << "\n";
      for (const auto& e : s.episodes) {
        eps << h.scene << "," << h.seed << "," << h.model << "," << e.t_s << "," << e.end_s << ","
            << eval::EpisodeKindName(e.kind) << "," << eval::EpisodeCauseName(e.cause)
            << "," << e.press << "," << e.press_peak_n << "," << e.reported_max_n << "," << e.y_mm << "," << e.r_deg << "\n";
      }
    }

    r << "\n## Spurious STOPs and missed presses (first 40 of each)\n\n"
      << "| scene | seed | model | t (s) | what | press peak (N) | reported max (N) | place (Y mm, R deg) | lasted (s) |\n"
      << "| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n";
    int listed = 0;
    for (const Hour& h : hours) {
      for (const auto& e : h.score.episodes) {
        if (e.cause != eval::EpisodeCause::kLightPress && e.cause != eval::EpisodeCause::kRest) continue;
        if (++listed > 40) break;
        r << "| " << h.scene << " | " << h.seed << " | `" << h.model << "` | " << F("%.1f", e.t_s) << " | "
          << eval::EpisodeKindName(e.kind) << " in a " << eval::EpisodeCauseName(e.cause)
          << " | " << F("%.2f", e.press_peak_n) << " | " << F("%.2f", e.reported_max_n) << " | ("
          << F("%.1f", e.y_mm) << ", " << F("%.1f", e.r_deg) << ") | " << F("%.1f", e.end_s - e.t_s) << " |\n";
      }
    }
    r << "\n| scene | seed | model | t (s) | missed due press: peak (N) | reported max (N) | place (Y mm, R deg) |\n"
      << "| --- | --- | --- | --- | --- | --- | --- |\n";
    listed = 0;
    for (const Hour& h : hours) {
      for (const auto& dp : h.score.due_presses) {
        if (dp.stopped || ++listed > 40) continue;
        r << "| " << h.scene << " | " << h.seed << " | `" << h.model << "` | " << F("%.1f", dp.t_s) << " | "
          << F("%.2f", dp.peak_n) << " | " << F("%.2f", dp.reported_max_n) << " | (" << F("%.1f", dp.y_mm) << ", "
          << F("%.1f", dp.r_deg) << ") |\n";
      }
    }

    // The figure: spurious STOPs per hour, per model, hour by hour.
    plot::Figure fig("Spurious STOP episodes per field hour", "hour (scene, seed)", "spurious STOPs in the hour");
    for (const auto& [label, m] : models) {
      plot::Series s{label, {}, {}, "", plot::Series::Style::kLinePoints};
      int i = 0;
      for (const Hour& h : hours) {
        if (h.model != label) continue;
        s.x.push_back(++i);
        s.y.push_back(h.score.spurious());
      }
      fig.Add(std::move(s));
    }
    fig.AddHLine(0.1, "target 0.1 per hour");
    fig.SetYRange(0, std::max(1.0, static_cast<double>(std::max_element(hours.begin(), hours.end(), [](const Hour& x, const Hour& y) {
                                                           return x.score.spurious() < y.score.spurious();
                                                         })->score.spurious()) + 1));
    fig.Save(a->out + "/spurious.svg");
    r << "\n![spurious STOPs per hour](spurious.svg)\n";
    std::ofstream(a->out + "/report.md") << r.str();
    std::printf("%s", r.str().substr(0, r.str().find("## Hour by hour")).c_str());
    std::printf("wrote %s/report.md, hours.csv, episodes.csv, spurious.svg\n", a->out.c_str());
  });
}

}  // namespace

void RegisterFieldHoursCommand(CLI::App& app) { RegisterFieldHours(app); }

}  // namespace ruffini::cli
