// Decoder subcommands: train (libtorch builds only), evaluate, bench.
#include <spdlog/spdlog.h>

#include <cstdio>
#include <memory>
#include <sstream>

#include "commands.h"
#include "progress.h"
#include "ruffini/dataset/dataset.h"
#include "ruffini/decode/model_io.h"
#include "ruffini/error.h"
#include "ruffini/eval/evaluation.h"
#include "ruffini/eval/prepared.h"
#include "ruffini/patch/spec_loader.h"
#ifdef RUFFINI_HAVE_TORCH
#include "ruffini/train/trainer.h"
#endif

namespace ruffini::cli {
namespace {

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
  cmd->add_option("--unit-floor-pm", a->o.unit_floor_pm, "unit: norms below this (pm) are taken as this")
      ->check(CLI::Range(1e-3, 1e3))->capture_default_str();
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
    spdlog::info("preparing {} frames (baseline tracking)", d.size());
    const eval::Prepared p = eval::PrepareFrames(d);
    // One bar over every epoch of every fit (CV folds and the final fit run in parallel, one per thread).
    std::unique_ptr<ProgressBar> bar;
    const auto m = train::Train(p, spec, a->o, a->data, [&](const std::string& phase, int done, int total, double loss) {
      if (!bar) bar = std::make_unique<ProgressBar>("training epochs", static_cast<std::uint64_t>(total));
      char note[96];
      std::snprintf(note, sizeof note, "%s loss %.5f", phase.c_str(), loss);
      bar->SetNote(note);
      bar->Update(static_cast<std::uint64_t>(done));
      spdlog::debug("epoch {}/{}: {} loss {:.5f}", done, total, phase, loss);
    });
    if (bar) bar->Finish();
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

void RegisterEvaluate(CLI::App& app) {
  struct Args {
    std::string model, data, report, patch_spec = RUFFINI_DEFAULT_PATCH;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand("evaluate", "Evaluate a model on a dataset as the paper did; write a report folder");
  cmd->add_option("--model", a->model, "Model file (.rmodel)")->required()->check(CLI::ExistingFile);
  cmd->add_option("--data", a->data, "Dataset (.h5) the model was trained on (its held-out indentations are the test set)")
      ->required()->check(CLI::ExistingFile);
  cmd->add_option("--report", a->report, "Report folder (report.md, pictures, predictions.h5)")->required();
  cmd->add_option("--patch-spec", a->patch_spec, "Patch spec")->capture_default_str();
  cmd->callback([a]() {
    const patch::PatchSpec spec = patch::LoadPatchSpec(a->patch_spec);
    const v1::DecoderModel m = decode::LoadModel(a->model);
    decode::CheckModelMatchesPatch(m, spec, a->model);
    const dataset::Dataset d = dataset::ReadDataset(a->data);
    if (d.info.patch_name != m.patch_name()) {
      throw InputError(a->data + ": dataset is from patch '" + d.info.patch_name + "', the model is for '" + m.patch_name() + "'");
    }
    const eval::Prepared p = eval::PrepareFrames(d);
    std::vector<std::int32_t> test(m.test_indentations().begin(), m.test_indentations().end());
    eval::NetworkFrameDecoder<float> dec(m);
    std::unique_ptr<ProgressBar> bar;
    const auto pred = eval::RunDecoder(dec, p, test, [&](std::uint64_t done, std::uint64_t total) {
      if (!bar) bar = std::make_unique<ProgressBar>("decoding frames", total);
      bar->Update(done);
    });
    if (bar) bar->Finish();
    const auto ev = eval::Evaluate(p, pred, spec);
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
                  "inverted per frame by Levenberg-Marquardt (10 iterations after a coarse search). Same test set:\n\n"
                  "| decoder | force median (IQR), mN | location median (IQR), mm | above-gate frames not located |\n|---|---|---|---|\n"
                  "| paper networks (W = %u, NIP union) | %.1f (%.1f) | %.2f (%.2f) | %zu |\n"
                  "| inversion (LM, 10 iterations) | %.1f (%.1f) | %.2f (%.2f) | %zu |\n\n"
                  "The inversion decoder also reports a covariance (location sigma) and a confidence from the fit's reduced "
                  "chi-square, which drops when the shifts fit no single contact (two touches; see the decode tests).\n\n",
                  inv.model().stiffening, m.force().window(), ev.force_error_mn.median, ev.force_error_mn.iqr(),
                  ev.location_error_mm.median, ev.location_error_mm.iqr(), ev.location_missed, inv_ev.force_error_mn.median,
                  inv_ev.force_error_mn.iqr(), inv_ev.location_error_mm.median, inv_ev.location_error_mm.iqr(),
                  inv_ev.location_missed);
    const std::string command = "ruffini evaluate --model " + a->model + " --data " + a->data + " --report " + a->report;
    eval::WriteReport(a->report, m, a->data, p, pred, ev, spec, command, buf);
    std::printf("inversion decoder: force %.1f mN (IQR %.1f), location %.2f mm (IQR %.2f)\n", inv_ev.force_error_mn.median,
                inv_ev.force_error_mn.iqr(), inv_ev.location_error_mm.median, inv_ev.location_error_mm.iqr());
    std::printf("test set: force %.1f mN (IQR %.1f), location %.2f mm (IQR %.2f); report in %s/report.md\n",
                ev.force_error_mn.median, ev.force_error_mn.iqr(), ev.location_error_mm.median, ev.location_error_mm.iqr(),
                a->report.c_str());
  });
}

}  // namespace

void RegisterDecodeCommands(CLI::App& app) {
  RegisterTrain(app);
  RegisterEvaluate(app);
}

}  // namespace ruffini::cli
