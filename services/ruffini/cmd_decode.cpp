// Decoder subcommands: train (libtorch builds only), evaluate, bench.
#include <spdlog/spdlog.h>

#include <chrono>
#include <cstdio>
#include <limits>
#include <optional>
#include <set>
#include <memory>
#include <sstream>

#include "commands.h"
#include "progress.h"
#include "ruffini/dataset/dataset.h"
#include "ruffini/decode/model_io.h"
#include "ruffini/decode/pipeline.h"
#include "ruffini/error.h"
#include "ruffini/decode/touches.h"
#include "ruffini/eval/calibrate.h"
#include "ruffini/eval/evaluation.h"
#include "ruffini/eval/stream.h"
#include "ruffini/eval/prepared.h"
#include "ruffini/patch/spec_loader.h"
#ifdef RUFFINI_HAVE_TORCH
#include "ruffini/train/trainer.h"
#include "scene_setup.h"
#endif

namespace ruffini::cli {
namespace {

// Writes a changed model, saying when its sensitivity maps no longer fit its decoder: no scene uses them until
// they are measured again (aggregator::CoverageOfScene compares SensitivityMap.model_sha256; review 10, finding 5).
void SaveChangedModel(const v1::DecoderModel& m, const std::string& out) {
  decode::ValidateModel(m, out);
  decode::SaveModel(out, m);
  const std::string digest = aggregator::DecoderSha256(m);
  int stale = 0;
  for (const auto& map : m.sensitivity()) stale += map.model_sha256() != digest ? 1 : 0;
  if (stale > 0) {
    spdlog::warn("{}: {} of its {} sensitivity maps were measured with another decoder; no scene uses them until "
                 "they are measured again (`ruffini sensitivity --scene SCENE --patch P --model {} --out {}`)",
                 out, stale, m.sensitivity_size(), out, out);
  }
}

#ifdef RUFFINI_HAVE_TORCH
void RegisterTrain(CLI::App& app) {
  struct Args {
    std::string data, out, patch_spec = RUFFINI_DEFAULT_PATCH;
    train::TrainOptions o;
  };
  auto a = std::make_shared<Args>();
  a->o.epochs_location = 0;  // as --epochs unless given
  CLI::App* cmd = app.add_subcommand("train", "Train the paper's decoders (CNN force + 4 grid MLPs) on a dataset");
  cmd->add_option("--data", a->data, "Dataset (.h5)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--out", a->out, "Model file to write (.rmodel)")->required();
  cmd->add_option("--patch-spec", a->patch_spec, "Patch spec the data comes from")->capture_default_str();
  cmd->add_option("--window", a->o.window, "W: frames the force CNN sees")->check(CLI::Range(1, 256))->capture_default_str();
  cmd->add_option("--mlp-widths", a->o.mlp_widths, "Hidden widths of the location MLPs (3)")->expected(3)->capture_default_str();
  cmd->add_option("--dropout", a->o.dropout, "Dropout of the location MLPs")->check(CLI::Range(0.0, 0.9))->capture_default_str();
  cmd->add_option("--epochs", a->o.epochs_force, "Epochs of every net")->check(CLI::Range(1, 10000))->capture_default_str();
  cmd->add_option("--epochs-location", a->o.epochs_location, "Epochs of the location nets (0: as --epochs)")
      ->check(CLI::Range(0, 10000))->capture_default_str();
  cmd->add_option("--frames-per-epoch", a->o.frames_per_epoch, "Samples drawn per epoch")->check(CLI::Range(256, 100000000))->capture_default_str();
  cmd->add_option("--batch", a->o.batch, "Minibatch size")->check(CLI::Range(1, 100000))->capture_default_str();
  cmd->add_option("--lr-force", a->o.lr_force, "Learning rate of the force net")->capture_default_str();
  cmd->add_option("--lr-location", a->o.lr_location, "Learning rate of the location nets")->capture_default_str();
  cmd->add_option("--optimizer", a->o.optimizer, "sgd (momentum 0.9, the paper's) | adam")
      ->check(CLI::IsMember({"sgd", "adam"}))->capture_default_str();
  cmd->add_option("--lr-schedule", a->o.lr_schedule, "constant | cosine (decays to 2 % over the epochs)")
      ->check(CLI::IsMember({"constant", "cosine"}))->capture_default_str();
  cmd->add_option("--force-loss", a->o.force_loss, "Force net loss: mse (the paper's) | l1 (targets the median error)")
      ->check(CLI::IsMember({"mse", "l1"}))->capture_default_str();
  cmd->add_option("--location-input", a->o.location_input,
                  "What the location MLPs see: raw shifts (the paper's) | unit (shifts over their norm: the pattern only)")
      ->check(CLI::IsMember({"raw", "unit"}))->capture_default_str();
  cmd->add_option("--label-sigma-mm", a->o.label_sigma_mm,
                  "Location labels: 0 = one cell (the paper's); > 0 = each cell's share of a Gaussian of this sigma")
      ->check(CLI::Range(0.0, 100.0))->capture_default_str();
  cmd->add_option("--drift-augment-pm", a->o.drift_augment_pm,
                  "Training only: per-sample per-grating offsets of this sigma (pm, median removed), for robustness to field drift")
      ->check(CLI::Range(0.0, 100.0))->capture_default_str();
  cmd->add_option("--unit-floor-pm", a->o.unit_floor_pm, "unit: norms below this (pm) are taken as this")
      ->check(CLI::Range(1e-3, 1e3))->capture_default_str();
  cmd->add_option("--area", a->o.area,
                  "What the location grids span: indented (the paper's grids over the spec's indented area) | whole (the patch's full extent, cells of the paper's size)")
      ->check(CLI::IsMember({"indented", "whole"}))->capture_default_str();
  cmd->add_option("--folds", a->o.folds, "Cross-validation folds inside the training part (0 = none)")->check(CLI::Range(0, 20))->capture_default_str();
  cmd->add_option("--seed", a->o.seed, "Seed (split, initialisation, sampling)")->capture_default_str();
  cmd->add_option("--threads", a->o.threads, "Fits trained at once (CV folds and the final fit), one core each")->check(CLI::Range(1, 64))->capture_default_str();
  cmd->callback([a]() {
    if (a->o.epochs_location == 0) a->o.epochs_location = a->o.epochs_force;
    const patch::PatchSpec spec = patch::LoadPatchSpec(a->patch_spec);
    const dataset::Dataset d = dataset::ReadDataset(a->data);
    if (d.info.patch_name != spec.name) {
      throw InputError(a->data + ": dataset is from patch '" + d.info.patch_name + "', the spec is '" + spec.name + "'");
    }
    spdlog::info("preparing {} frames (baseline tracking, common mode removed)", d.size());
    decode::BaselineConfig baseline;  // common_mode on: the nets never see uniform (temperature) shifts
    baseline.sample_rate_hz = d.info.sample_rate_hz;
    const eval::Prepared p = eval::PrepareFrames(d, baseline);
    // One bar over every epoch of every fit (CV folds and the final fit run in parallel, one per thread).
    std::unique_ptr<ProgressBar> bar;
    auto m = train::Train(p, spec, a->o, a->data, [&](const std::string& phase, int done, int total, double loss) {
      if (!bar) bar = std::make_unique<ProgressBar>("training epochs", static_cast<std::uint64_t>(total));
      char note[96];
      std::snprintf(note, sizeof note, "%s loss %.5f", phase.c_str(), loss);
      bar->SetNote(note);
      bar->Update(static_cast<std::uint64_t>(done));
      spdlog::debug("epoch {}/{}: {} loss {:.5f}", done, total, phase, loss);
    });
    if (bar) bar->Finish();
    m.mutable_preprocessing()->set_common_mode_removed(baseline.common_mode);
    decode::ValidateModel(m, a->out);
    decode::SaveModel(a->out, m);
    std::printf("wrote %s (%llu train / %llu test frames, %.0f s)\n", a->out.c_str(),
                static_cast<unsigned long long>(m.training().train_frames()),
                static_cast<unsigned long long>(m.training().test_frames()), m.training().seconds());
  });
}
#else
void RegisterTrain(CLI::App& app) {
  CLI::App* cmd = app.add_subcommand("train", "Train the decoders (this build has no libtorch)");
  cmd->allow_extras();
  cmd->callback([]() {
    throw InputError("this ruffini was built without libtorch: run deploy/install-deps.sh and rebuild to train");
  });
}
#endif

// The model, its patch spec and a dataset for it, checked against each other.
struct ModelAndData {
  patch::PatchSpec spec;
  v1::DecoderModel model;
  dataset::Dataset data;
};
ModelAndData LoadModelAndData(const std::string& model_path, const std::string& data_path, const std::string& spec_path) {
  ModelAndData r{patch::LoadPatchSpec(spec_path), decode::LoadModel(model_path), dataset::ReadDataset(data_path)};
  decode::CheckModelMatchesPatch(r.model, r.spec, model_path);
  if (r.data.info.patch_name != r.model.patch_name()) {
    throw InputError(data_path + ": dataset is from patch '" + r.data.info.patch_name + "', the model is for '" +
                     r.model.patch_name() + "'");
  }
  return r;
}

eval::StreamPredictions DecodeWithProgress(const v1::DecoderModel& m, const patch::PatchSpec& spec, const dataset::Dataset& d,
                                           const std::string& label, decode::PipelineConfig cfg = {},
                                           const std::string& thermal_field = "model") {
  const decode::BaselineConfig knobs = cfg.baseline;  // the caller's thermal-field knobs stay
  cfg.baseline = decode::BaselineFor(m, d.info.sample_rate_hz);
  if (thermal_field != "model") cfg.baseline.thermal_field = thermal_field == "on";
  cfg.baseline.field_tau_s = knobs.field_tau_s;
  cfg.baseline.field_trim = knobs.field_trim;
  cfg.baseline.field_exclude_mm = knobs.field_exclude_mm;
  cfg.baseline.field_max_rate_pm_s = knobs.field_max_rate_pm_s;
  cfg.baseline.field_far_tau_s = knobs.field_far_tau_s;
  const decode::Pipeline<float> pipe(m, spec, cfg);
  std::unique_ptr<ProgressBar> bar;
  auto pred = eval::DecodeStream(pipe, d, [&](std::uint64_t done, std::uint64_t total) {
    if (!bar) bar = std::make_unique<ProgressBar>(label, total);
    bar->Update(done);
  });
  if (bar) bar->Finish();
  return pred;
}


void RegisterEvaluate(CLI::App& app) {
  struct Args {
    std::string model, data, report, patch_spec = RUFFINI_DEFAULT_PATCH;
    std::vector<std::string> also;
    bool inversion = true;
    bool gate_freeze = true;
    double confirm_s = decode::PipelineConfig{}.contact_confirm_s;
    double quiet_pm = decode::PipelineConfig{}.quiet_release_pm;
    double quiet_drop = decode::PipelineConfig{}.quiet_release_drop;
    double faint_pm = decode::PipelineConfig{}.faint_pm;
    std::string faint_refuse = "model";
    double release_refuse_n = decode::PipelineConfig{}.release_refuse_n;
    double release_tau_s = decode::PipelineConfig{}.release_tau_s;
    decode::BaselineConfig field;
    std::string thermal_field = "model";
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand("evaluate", "Evaluate a model: decode as one stream, score honestly and as the paper did; write a report folder");
  cmd->add_option("--model", a->model, "Model file (.rmodel)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--data", a->data,
                  "Dataset (.h5) to score: the training data (its held-out indentations are scored) or unseen data (all of it)")
      ->required()->check(CLI::ExistingFile);
  cmd->add_option("--report", a->report, "Report folder (report.md, pictures, predictions.h5)")->required();
  cmd->add_option("--also", a->also, "More datasets scored as rows of the field table: LABEL=FILE.h5 (other casts, field protocol)");
  cmd->add_flag("--inversion,!--no-inversion", a->inversion, "Also score the inversion decoder (training data only)")->capture_default_str();
  cmd->add_option("--contact-confirm-s", a->confirm_s, "Report a contact once the force gate has been open this long")
      ->check(CLI::Range(0.0, 1.0))->capture_default_str();
  cmd->add_option("--quiet-release-pm", a->quiet_pm, "No contact on a frame where no grating moves by more than this (0: off)")
      ->check(CLI::Range(0.0, 100.0))->capture_default_str();
  cmd->add_option("--quiet-release-drop", a->quiet_drop,
                  "Quiet release only after a drop from this many times the threshold (0: always)")
      ->check(CLI::Range(0.0, 1000.0))->capture_default_str();
  cmd->add_flag("--gate-freeze,!--no-gate-freeze", a->gate_freeze,
                  "The decoder's gate freezes the baseline (--no-gate-freeze: only large shifts do, the old tracker)")
      ->capture_default_str();
  cmd->add_option("--faint-pm", a->faint_pm,
                  "Flag a contact frame whose largest smoothed shift is below this (pm; 0: off; docs/decoders.md)")
      ->check(CLI::Range(0.0, 100.0))->capture_default_str();
  cmd->add_option("--faint-refuse", a->faint_refuse, kFaintRefuseHelp)
      ->check(CLI::IsMember({"model", "on", "off"}))->capture_default_str();
  cmd->add_option("--release-refuse-n", a->release_refuse_n, kReleaseRefuseHelp)->check(CLI::Range(0.0, 10.0))->capture_default_str();
  cmd->add_option("--release-tau-s", a->release_tau_s, kReleaseTauHelp)->check(CLI::Range(0.01, 3600.0))->capture_default_str();
  cmd->add_option("--thermal-field", a->thermal_field,
                  "The baseline follows a thermal field across the patch: as the model says, on or off (docs/decoders.md)")
      ->check(CLI::IsMember({"model", "on", "off"}))->capture_default_str();
  cmd->add_option("--field-tau-s", a->field.field_tau_s, "Thermal field: the follower's time constant, s")
      ->check(CLI::Range(0.01, 1e4))->capture_default_str();
  cmd->add_option("--field-trim", a->field.field_trim, "Thermal field: gratings furthest from a first fit left out")
      ->check(CLI::Range(0, 10))->capture_default_str();
  cmd->add_option("--field-exclude-mm", a->field.field_exclude_mm, "Thermal field: gratings this near a placed touch left out")
      ->check(CLI::Range(0.0, 500.0))->capture_default_str();
  cmd->add_option("--field-far-tau-s", a->field.field_far_tau_s,
                 "Thermal field, touched: a grating far from the touch follows its own wavelength with this, s")
      ->check(CLI::Range(0.01, 1e4))->capture_default_str();
  cmd->add_option("--field-max-rate", a->field.field_max_rate_pm_s, "Thermal field: largest step per grating, pm/s")
      ->check(CLI::Range(0.0, 1e4))->capture_default_str();
  cmd->add_option("--patch-spec", a->patch_spec, "Patch spec")->capture_default_str();
  cmd->callback([a]() {
    const ModelAndData md = LoadModelAndData(a->model, a->data, a->patch_spec);
    const v1::DecoderModel& m = md.model;
    const dataset::Dataset& d = md.data;
    const patch::PatchSpec& spec = md.spec;
    const bool training_data = !m.training().dataset_source().empty() && d.info.source == m.training().dataset_source();
    const eval::Prepared p = eval::PrepareFrames(d, decode::BaselineFor(m, d.info.sample_rate_hz));
    std::vector<std::int32_t> test;
    if (training_data) {
      test.assign(m.test_indentations().begin(), m.test_indentations().end());
    } else {
      test = p.ids;  // unseen data: every indentation is test data
    }
    decode::PipelineConfig pcfg;
    pcfg.freeze_on_gate = a->gate_freeze;
    pcfg.contact_confirm_s = a->confirm_s;
    pcfg.quiet_release_pm = a->quiet_pm;
    pcfg.quiet_release_drop = a->quiet_drop;
    pcfg.faint_pm = a->faint_pm;
    pcfg.faint_refuse = ModelOnOff(a->faint_refuse);
    pcfg.release_refuse_n = a->release_refuse_n;
    pcfg.release_tau_s = a->release_tau_s;
    pcfg.baseline = a->field;
    const auto sp = DecodeWithProgress(m, spec, d, "decoding frames", pcfg, a->thermal_field);
    const auto mask = eval::MaskOfIndentations(d, test);
    eval::Predictions pred;
    pred.force_n.resize(d.size());
    pred.y_mm = sp.y_mm;
    pred.r_deg = sp.r_deg;
    pred.valid = sp.valid;
    pred.located = sp.located;
    pred.test = mask;
    for (std::size_t k = 0; k < d.size(); ++k) pred.force_n[k] = sp.valid[k] ? sp.force_n[k] : std::numeric_limits<float>::quiet_NaN();
    const auto ev = eval::Evaluate(p, pred, spec);
    const eval::StreamMetrics sm = eval::ScoreStream(d, sp, spec, mask, ev.rg_location_guess);

    // The honest section: streaming decode, misses scored as failures, false contacts, field rows.
    std::vector<eval::StreamReportRow> rows{{"`" + a->data + "`", sm}};
    std::vector<std::string> also_labels;
    for (const std::string& item : a->also) {
      const auto eq = item.find('=');
      if (eq == std::string::npos || eq == 0 || eq + 1 == item.size()) throw InputError("--also " + item + ": expected LABEL=FILE.h5");
      const std::string label = item.substr(0, eq), path = item.substr(eq + 1);
      const dataset::Dataset other = dataset::ReadDataset(path);
      if (other.info.patch_name != m.patch_name()) throw InputError(path + ": dataset is from patch '" + other.info.patch_name + "'");
      const auto osp = DecodeWithProgress(m, spec, other, "decoding " + label, pcfg, a->thermal_field);
      std::vector<std::int32_t> ids;
      for (std::size_t k = 0; k < other.size(); ++k) {
        if (other.indentation[k] >= 0 && (ids.empty() || ids.back() != other.indentation[k])) ids.push_back(other.indentation[k]);
      }
      also_labels.push_back(label);
      rows.push_back({label + " (`" + path + "`)",
                      eval::ScoreStream(other, osp, spec, eval::MaskOfIndentations(other, ids), ev.rg_location_guess)});
    }
    const eval::StreamMetrics whole = eval::ScoreStream(d, sp, spec, {}, ev.rg_location_guess);
    const std::string front = eval::StreamReportSection(rows, whole, training_data, m.has_uncertainty() ? &m.uncertainty() : nullptr);

    std::string extra;
    if (training_data && a->inversion) {
      // Beyond the paper: the physics-informed inversion decoder on the same test set.
      spdlog::info("fitting the inversion decoder's response map on the training part");
      const decode::InversionDecoder inv(eval::FitResponse(p, spec, test));
      eval::InversionFrameDecoder inv_dec(inv);
      const auto inv_pred = eval::RunDecoder(inv_dec, p, test, {}, /*test_only=*/true);
      const auto inv_ev = eval::Evaluate(p, inv_pred, spec);
      char buf[1024];
      std::snprintf(buf, sizeof buf,
                    "## Beyond the paper: physics-informed inversion\n\n"
                    "A per-grating response map learned from the training part (kernel regression of per-indentation sensitivities on 1.5 mm nodes, shift = F (1 + %.3f F) g(Y, R)) "
                    "inverted per frame by Levenberg-Marquardt (10 iterations after a coarse search), each test indentation decoded from a reset. Same test set:\n\n"
                    "| decoder | force median (IQR), mN | location median (IQR), mm | above-gate frames not located |\n|---|---|---|---|\n"
                    "| paper networks (W = %u, NIP union), streamed | %.1f (%.1f) | %.2f (%.2f) | %zu |\n"
                    "| inversion (LM, 10 iterations) | %.1f (%.1f) | %.2f (%.2f) | %zu |\n\n",
                    inv.model().stiffening, m.force().window(), ev.force_error_mn.median, ev.force_error_mn.iqr(),
                    ev.location_error_mm.median, ev.location_error_mm.iqr(), ev.location_missed, inv_ev.force_error_mn.median,
                    inv_ev.force_error_mn.iqr(), inv_ev.location_error_mm.median, inv_ev.location_error_mm.iqr(),
                    inv_ev.location_missed);
      extra = buf;
    }
    std::string command = "ruffini evaluate --model " + a->model + " --data " + a->data + " --report " + a->report;
    for (const auto& item : a->also) command += " --also " + item;
    if (!a->gate_freeze) command += " --no-gate-freeze";
    if (a->confirm_s != decode::PipelineConfig{}.contact_confirm_s) command += " --contact-confirm-s " + std::to_string(a->confirm_s);
    if (a->quiet_pm != decode::PipelineConfig{}.quiet_release_pm) command += " --quiet-release-pm " + std::to_string(a->quiet_pm);
    if (a->quiet_drop != decode::PipelineConfig{}.quiet_release_drop) command += " --quiet-release-drop " + std::to_string(a->quiet_drop);
    eval::WriteReport(a->report, m, a->data, p, pred, ev, spec, command, extra, front);
    eval::WriteStreamPredictions(a->report + "/stream_predictions.h5", sp, a->model, a->data);
    std::printf("honest: force %.1f mN all frames (%.1f mN against the load cell), %.1f mN above 50 mN; location above 50 mN %.2f mm (misses as failures), "
                "%.2f mm located only; miss rate above 100 mN %.2f %%; false contacts %.3f %%\n",
                sm.force_all_mn.median, sm.force_all_loadcell_mn.median, sm.force_above_mn.median, sm.location_above_mm.median, sm.location_located_mm.median,
                100.0 * sm.miss_rate_above_100mn, 100.0 * sm.false_contact_rate);
    for (std::size_t r = 1; r < rows.size(); ++r) {
      const std::string& label = also_labels[r - 1];
      const eval::StreamMetrics& om = rows[r].scored;
      std::printf("%s: force %.1f mN all, %.1f mN above 50 mN; location %.2f mm; false contacts %.3f %%\n", label.c_str(),
                  om.force_all_mn.median, om.force_above_mn.median, om.location_above_mm.median, 100.0 * om.false_contact_rate);
    }
    for (const auto& [zone, z] : {std::pair{"within 10 mm of an edge", &sm.near_edge}, std::pair{"interior", &sm.interior}}) {
      std::printf("pressed frames %s: %zu, force %.1f mN, reported/true above 1 N %.2f, location %.2f mm (misses as failures), "
                  "%.2f mm located only, %.2f mm above 1 N (misses as failures), not located %.1f %%, over range %.1f %%\n",
                  zone, z->frames, z->force_mn.median, z->force_ratio_above_1n, z->location_mm.median, z->location_located_mm.median,
                  z->location_above_1n_mm.median,
                  100.0 * static_cast<double>(z->missed) / std::max<double>(1.0, static_cast<double>(z->frames)),
                  100.0 * static_cast<double>(z->over_range) / std::max<double>(1.0, static_cast<double>(z->frames)));
    }
    std::printf("test set: force %.1f mN (IQR %.1f), location %.2f mm (IQR %.2f); report in %s/report.md\n",
                ev.force_error_mn.median, ev.force_error_mn.iqr(), ev.location_error_mm.median, ev.location_error_mm.iqr(),
                a->report.c_str());
  });
}

void RegisterDecode(CLI::App& app) {
  struct Args {
    std::string model, data, out, patch_spec = RUFFINI_DEFAULT_PATCH;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "decode", "Decode a dataset as one continuous stream (the decoder service's path) and write per-frame predictions");
  cmd->add_option("--model", a->model, "Model file (.rmodel)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--data", a->data, "Dataset (.h5): a recording or a twin run")->required()->check(CLI::ExistingFile);
  cmd->add_option("--out", a->out, "Predictions file to write (.h5, group /pred)")->required();
  cmd->add_option("--patch-spec", a->patch_spec, "Patch spec")->capture_default_str();
  cmd->callback([a]() {
    const ModelAndData md = LoadModelAndData(a->model, a->data, a->patch_spec);
    const eval::StreamPredictions pred = DecodeWithProgress(md.model, md.spec, md.data, "decoding frames");
    eval::WriteStreamPredictions(a->out, pred, a->model, a->data);
    const auto& c = pred.counters;
    std::printf("decoded %llu frames: %llu valid, %llu located, %llu contact onsets\n",
                static_cast<unsigned long long>(c.frames), static_cast<unsigned long long>(c.valid),
                static_cast<unsigned long long>(c.located), static_cast<unsigned long long>(c.onsets));
    for (std::size_t r = 1; r < decode::kReasonCount; ++r) {
      if (c.invalid[r] == 0) continue;
      std::printf("  invalid (%s): %llu\n", std::string(decode::ReasonName(static_cast<decode::Reason>(r))).c_str(),
                  static_cast<unsigned long long>(c.invalid[r]));
    }
    if (!md.model.has_uncertainty()) {
      spdlog::warn("{}: the model has no calibrated uncertainty (run `ruffini calibrate`): force_sd_n and pos_cov_mm2 are NaN", a->model);
    }
    std::printf("wrote %s\n", a->out.c_str());
  });
}

void RegisterUncertainty(CLI::App& app) {
  struct Args {
    std::string model, data, patch_spec = RUFFINI_DEFAULT_PATCH;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "uncertainty",
      "Where a model's calibrated uncertainty is honest: decode a recording as one stream and print the share of frames "
      "within 1 / 2 / 3 sigma by predicted force, press phase, true position and reported covariance size");
  cmd->add_option("--model", a->model, "Model file (.rmodel) with a calibrated uncertainty")->required()->check(CLI::ExistingFile);
  cmd->add_option("--data", a->data, "Dataset (.h5) with true positions (a twin run)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--patch-spec", a->patch_spec, "Patch spec")->capture_default_str();
  cmd->callback([a]() {
    const ModelAndData md = LoadModelAndData(a->model, a->data, a->patch_spec);
    if (!md.model.has_uncertainty()) throw InputError(a->model + ": the model has no calibrated uncertainty (run `ruffini calibrate`)");
    const eval::StreamPredictions sp = DecodeWithProgress(md.model, md.spec, md.data, "decoding frames");
    std::printf("%s on %s (every frame of the stream; position: located frames above 50 mN)\n\n%s", a->model.c_str(),
                a->data.c_str(), eval::CoverageTable(eval::CoverageBreakdown(md.data, sp, md.spec)).c_str());
  });
}

void RegisterCalibrate(CLI::App& app) {
  struct Args {
    std::string model, data, out, creep_data, patch_spec = RUFFINI_DEFAULT_PATCH;
    int indentations = 100;
    bool gains = true;
    bool creep = true;
    bool uncertainty_only = false;
    int sweeps = 3;
    std::string thermal_field = "keep";
    std::optional<double> faint_refuse_below_n;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "calibrate",
      "Fit a model to a cast from its first indentations: per-grating gains (another cast), the input range and the "
      "calibrated uncertainty. Use validation data (another seed or the new cast's calibration run), never test data");
  cmd->add_option("--model", a->model, "Model file (.rmodel)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--data", a->data, "Calibration recording (.h5) of the cast")->required()->check(CLI::ExistingFile);
  cmd->add_option("--out", a->out, "Calibrated model file to write")->required();
  cmd->add_option("--indentations", a->indentations, "Use the recording's first N indentations (0 = all)")
      ->check(CLI::Range(0, 1000000))->capture_default_str();
  cmd->add_flag("--gains,!--no-gains", a->gains, "Fit per-grating gains (cast adaptation)")->capture_default_str();
  cmd->add_option("--field-data", a->creep_data,
                  "A press-hold-release recording of the cast while the temperature moves (e.g. --protocol field): fits the "
                  "gratings' thermal ratios and the creep compensation")
      ->check(CLI::ExistingFile);
  cmd->add_flag("--creep,!--no-creep", a->creep, "With --field-data: also fit the creep compensation")->capture_default_str();
  cmd->add_option("--thermal-field", a->thermal_field,
                  "The decoder's baseline follows a thermal field across the patch (a cast whose cover sees gradients; "
                  "docs/decoders.md): keep the model's choice, on or off")
      ->check(CLI::IsMember({"keep", "on", "off"}))->capture_default_str();
  cmd->add_option("--faint-refuse-below-n", a->faint_refuse_below_n,
                  "A field cast with many false contacts: faint contact frames below this force are no contact "
                  "(Preprocessing.faint_refuse_below_n; 0: off; default: keep the model's; docs/decoders.md \"Faint frames\")")
      ->check(CLI::Range(0.0, 10.0));
  cmd->add_option("--sweeps", a->sweeps, "Coordinate sweeps of the gain fit")->check(CLI::Range(1, 20))->capture_default_str();
  cmd->add_flag("--uncertainty-only", a->uncertainty_only,
                "Refit only the calibrated uncertainty (and --thermal-field, --faint-refuse-below-n): networks, gains, input range, thermal ratios, "
                "creep, sensitivity and response maps stay as they are in --model");
  cmd->add_option("--patch-spec", a->patch_spec, "Patch spec")->capture_default_str();
  cmd->callback([a]() {
    const auto t0 = std::chrono::steady_clock::now();
    if (a->uncertainty_only && !a->creep_data.empty()) throw InputError("--uncertainty-only takes no --field-data (it fits nothing else)");
    ModelAndData md = LoadModelAndData(a->model, a->data, a->patch_spec);
    const dataset::Dataset cal = eval::FirstIndentations(md.data, a->indentations);
    std::set<std::int32_t> ids(cal.indentation.begin(), cal.indentation.end());
    ids.erase(-1);
    constexpr std::size_t kMinIndentations = 20;
    if (ids.size() < kMinIndentations) {
      throw InputError(a->data + ": calibration needs at least " + std::to_string(kMinIndentations) +
                       " indentations; the data hold " + std::to_string(ids.size()));
    }
    spdlog::info("calibrating on {} frames, {} indentations", cal.size(), ids.size());
    v1::DecoderModel m = md.model;
    const auto print_uncertainty = [](const v1::Uncertainty& u) {
      std::printf("uncertainty on the calibration data: force within 1/2 sd %.1f / %.1f %%, position %.1f / %.1f %% "
                  "(3 sigma: force %.1f %%, position %.1f %%; position floor %.2f mm^2)\n",
                  100.0 * u.force_within_1sd(), 100.0 * u.force_within_2sd(), 100.0 * u.position_within_1sd(),
                  100.0 * u.position_within_2sd(), 100.0 * u.force_within_3sd(), 100.0 * u.position_within_3sd(),
                  u.position_floor_mm2());
    };
    // The switch is set first, so everything fitted below sees the decoder's baseline as it will run.
    if (a->thermal_field != "keep") m.mutable_preprocessing()->set_thermal_field(a->thermal_field == "on");
    if (a->faint_refuse_below_n) m.mutable_preprocessing()->set_faint_refuse_below_n(static_cast<float>(*a->faint_refuse_below_n));
    if (a->uncertainty_only) {
      *m.mutable_uncertainty() = eval::FitUncertainty(m, md.spec, cal);
      SaveChangedModel(m, a->out);
      print_uncertainty(m.uncertainty());
      std::printf("wrote %s (uncertainty only, %.0f s)\n", a->out.c_str(),
                  std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
      return;
    }
    // Indentations after the ones calibrated on, held out from every fit: both models scored on them.
    constexpr std::size_t kHeldOutMax = 200;
    const std::vector<std::int32_t> held_out = eval::IndentationsAfter(md.data, a->indentations, kHeldOutMax);
    const std::optional<v1::CastScore> before =
        held_out.empty() ? std::nullopt : std::optional(eval::ScoreIndentations(md.model, md.spec, md.data, held_out));
    v1::CastCalibration summary;
    // The cast's thermal ratios and creep first: the gains are fitted through the cast's own preprocessing, and
    // against the strain force the creep compensation turns back into the applied force (FitGains).
    if (!a->creep_data.empty()) {
      const dataset::Dataset creep = dataset::ReadDataset(a->creep_data);
      if (creep.info.patch_name != m.patch_name()) throw InputError(a->creep_data + ": dataset is from patch '" + creep.info.patch_name + "'");
      const std::vector<float> ratio = eval::FitThermalRatio(m, md.spec, creep);
      m.mutable_preprocessing()->clear_thermal_ratio();
      std::string shown;
      for (float v : ratio) {
        m.mutable_preprocessing()->add_thermal_ratio(v);
        char b[16];
        std::snprintf(b, sizeof b, " %.3f", v);
        shown += b;
      }
      std::printf("thermal ratios:%s\n", shown.c_str());
      if (!a->creep) {
        m.clear_creep();
      } else {
        *m.mutable_creep() = eval::FitCreep(m, md.spec, creep);
        std::printf("creep compensation: g = %.4f / %.4f / %.4f at tau 1 / 10 / 100 s\n", m.creep().g(0), m.creep().g(1), m.creep().g(2));
      }
    } else if (a->gains && m.preprocessing().thermal_ratio_size() > 0) {
      // Thermal ratios belong to a cast: another cast's would be wrong. Unit ratios until --field-data.
      m.mutable_preprocessing()->clear_thermal_ratio();
      spdlog::warn("thermal ratios cleared (another cast's); fit this cast's with --field-data");
    }
    if (a->gains) {
      const eval::GainFit g = eval::FitGains(m, md.spec, cal, a->sweeps, [](int s, int n, double obj) {
        spdlog::info("gain fit: sweep {}/{}, objective {:.2f}", s, n, obj);
      });
      eval::ApplyGains(m, g.gain);
      auto* cc = m.mutable_cast_calibration();
      cc->clear_grating_gain();
      for (float v : g.gain) cc->add_grating_gain(v);
      std::printf("gains fitted: objective %.2f -> %.2f (%d evaluations)\n", g.before, g.after, g.evaluations);
      summary.set_objective_before(g.before);
      summary.set_objective_after(g.after);
    }
    *m.mutable_input_range() = eval::FitInputRange(m, md.spec, cal);
    *m.mutable_uncertainty() = eval::FitUncertainty(m, md.spec, cal);
    if (before) {
      const v1::CastScore after = eval::ScoreIndentations(m, md.spec, md.data, held_out);
      std::printf("on %u held-out indentations of %s: median force error %.1f -> %.1f mN, location error %.2f -> %.2f mm\n",
                  after.indentations(), a->data.c_str(), before->force_error_mn(), after.force_error_mn(),
                  before->location_error_mm(), after.location_error_mm());
      *summary.mutable_held_out_before() = *before;
      *summary.mutable_held_out_after() = after;
    } else if (a->indentations > 0) {
      spdlog::warn("{}: no indentations after the first {} to score the calibration on", a->data, a->indentations);
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    auto* cc = m.mutable_cast_calibration();
    cc->set_indentations(static_cast<std::uint32_t>(a->indentations));
    cc->set_dataset(a->data);
    cc->set_seconds(seconds);
    cc->set_start_model(a->model);
    cc->set_objective_before(summary.objective_before());
    cc->set_objective_after(summary.objective_after());
    if (summary.has_held_out_before()) {
      *cc->mutable_held_out_before() = summary.held_out_before();
      *cc->mutable_held_out_after() = summary.held_out_after();
    } else {
      cc->clear_held_out_before();
      cc->clear_held_out_after();
    }
    SaveChangedModel(m, a->out);
    print_uncertainty(m.uncertainty());
    std::printf("wrote %s (%.0f s)\n", a->out.c_str(), seconds);
  });
}

}  // namespace

void RegisterFitResponse(CLI::App& app) {
  struct Args {
    std::string model, data, out, area = "indented", patch_spec = RUFFINI_DEFAULT_PATCH;
    int indentations = 0;
    double multiple_misfit = 0.0;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "fit-response",
      "Learn one touch's response map from a recording's indentations and store it in a model file: the decoder then "
      "flags frames no single touch explains (two touches) and fits two (docs/decoders.md, \"Two touches\"). Use "
      "validation data, never test data");
  cmd->add_option("--model", a->model, "Model file (.rmodel)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--data", a->data, "Recording (.h5) of the model's cast")->required()->check(CLI::ExistingFile);
  cmd->add_option("--out", a->out, "Model file to write (may be --model)")->required();
  cmd->add_option("--indentations", a->indentations, "Use the recording's first N indentations (0 = all)")
      ->check(CLI::Range(0, 1000000))->capture_default_str();
  cmd->add_option("--area", a->area, "The map's grid: indented (the spec's indented area) | whole (the patch)")
      ->check(CLI::IsMember({"indented", "whole"}))->capture_default_str();
  cmd->add_option("--multiple-misfit", a->multiple_misfit,
                  "Misfit above which a frame is not one touch (0..1; 0: the map is stored for the re-tare and checks nothing: the "
                  "gratings' groups flag two touches, as without a map)")
      ->check(CLI::Range(0.0, 1.0))->required();
  cmd->add_option("--patch-spec", a->patch_spec, "Patch spec")->capture_default_str();
  cmd->callback([a]() {
    ModelAndData md = LoadModelAndData(a->model, a->data, a->patch_spec);
    const dataset::Dataset cal = eval::FirstIndentations(md.data, a->indentations);
    const eval::Prepared p = eval::PrepareFrames(cal, decode::BaselineFor(md.model, cal.info.sample_rate_hz));
    const patch::Region whole = md.spec.Extent();
    const decode::ResponseModel r = eval::FitResponse(p, md.spec, {}, a->area == "whole" ? &whole : nullptr);
    v1::DecoderModel m = md.model;
    const std::string source = "ruffini fit-response --data " + a->data + " --indentations " + std::to_string(a->indentations) +
                               " --area " + a->area + " --multiple-misfit " + std::to_string(a->multiple_misfit);
    *m.mutable_response() = decode::ToProto(r, a->multiple_misfit, source);
    SaveChangedModel(m, a->out);
    std::printf("response map: %d x %d nodes (Y %.1f.., R %.1f..), stiffening %.3f; wrote %s\n", r.ny, r.nr, r.y0_mm, r.r0_deg,
                r.stiffening, a->out.c_str());
  });
}

void RegisterDecodeCommands(CLI::App& app) {
  RegisterFitResponse(app);
  RegisterTrain(app);
  RegisterEvaluate(app);
  RegisterDecode(app);
  RegisterCalibrate(app);
  RegisterUncertainty(app);
}

}  // namespace ruffini::cli
