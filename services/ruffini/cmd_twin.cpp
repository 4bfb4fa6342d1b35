// Twin subcommands: simulate, import-csv, twin-report, twin-calibrate.
#include <spdlog/spdlog.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>

#include "commands.h"
#include "figures.h"
#include "progress.h"
#include "ruffini/dataset/csv_import.h"
#include "ruffini/dataset/dataset.h"
#include "ruffini/error.h"
#include "ruffini/patch/spec_loader.h"
#include "ruffini/twin/protocols.h"
#include "ruffini/twin/report.h"
#include "ruffini/twin/scene.h"

namespace ruffini::cli {
namespace {

const char* kDefaultScene = RUFFINI_DEFAULT_SCENE;

struct SceneArgs {
  std::string scene = kDefaultScene;
  std::string patch;
  std::optional<std::uint64_t> skin_sample;
};

void AddSceneOptions(CLI::App* cmd, SceneArgs& a) {
  cmd->add_option("--scene", a.scene, "Scene file (YAML)")->capture_default_str();
  cmd->add_option("--patch", a.patch, "Patch of the scene to use (default: the only one)");
  cmd->add_option("--skin-sample", a.skin_sample, "Skin sample (cast) seed; overrides the scene's and every patch's own (casts:)")
      ->check(CLI::Range(0.0, 1099511627776.0));
}

twin::Scene LoadSceneArgs(const SceneArgs& a) {
  twin::Scene s = twin::LoadScene(a.scene);
  if (a.skin_sample) {
    twin::OverrideSkinSample(s, *a.skin_sample);
    for (twin::ScenePatch& p : s.patches) p.cast_seed.reset();  // the override is every patch's cast
  }
  return s;
}

// The patch's effects with its own cast (the twin section's `casts:`), as ruffini-sim builds its twin.
twin::TwinEffects EffectsOf(const twin::Scene& s, const twin::ScenePatch& p) {
  return s.EffectsOf(static_cast<std::size_t>(&p - s.patches.data()));
}

std::unique_ptr<twin::SkinTwin> BuildTwin(const twin::Scene& s, const std::string& patch) {
  const twin::ScenePatch& p = s.Patch(patch);
  return std::make_unique<twin::SkinTwin>(p.spec, EffectsOf(s, p), std::vector<double>{s.probe.radius_mm});
}

twin::ProgressFn Bar(std::unique_ptr<ProgressBar>& bar, const std::string& label) {
  return [&bar, label](std::uint64_t done, std::uint64_t total) {
    if (!bar) bar = std::make_unique<ProgressBar>(label, total);
    bar->Update(done);
  };
}

void RegisterSimulate(CLI::App& app) {
  struct Args {
    SceneArgs scene;
    std::string protocol = "paper";
    std::uint64_t seed = 1;
    std::optional<int> indentations;
    std::string out;
    int compression = 0;
    double step_mm = 2.0;
    double duration_s = twin::FieldProtocol{}.duration_s;
    double rate_hz = twin::FieldProtocol{}.rate_hz;
    double force_min_n = twin::CoverageProtocol{}.force_min_n;
    double force_max_n = twin::CoverageProtocol{}.force_max_n;
    double edge_fraction = twin::CoverageProtocol{}.edge_fraction;
    double edge_band_mm = twin::CoverageProtocol{}.edge_band_mm;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand("simulate", "Run a protocol on the skin twin and write an HDF5 dataset");
  AddSceneOptions(cmd, args->scene);
  cmd->add_option("--protocol", args->protocol,
                  "paper | coverage (the paper's ramps over the whole patch, edge to edge) | vonfrey | receptive-field | field")
      ->check(CLI::IsMember({"paper", "coverage", "vonfrey", "receptive-field", "field"}))
      ->capture_default_str();
  cmd->add_option("--seed", args->seed, "Seed: the same seed gives a bit-identical file")
      ->check(CLI::NonNegativeNumber)->capture_default_str();
  cmd->add_option("--indentations", args->indentations, "paper, coverage: number of indentations (default 2700)")
      ->check(CLI::Range(1, 1000000));
  cmd->add_option("--duration-s", args->duration_s, "field: length of the recording")
      ->check(CLI::Range(1.0, 1e7))->capture_default_str();
  cmd->add_option("--rate-hz", args->rate_hz, "field: frame rate")->check(CLI::Range(1.0, 100000.0))->capture_default_str();
  cmd->add_option("--force-min-n", args->force_min_n, "coverage: smallest peak force (peaks are log-uniform between the two)")
      ->check(CLI::Range(1e-4, 1000.0))->capture_default_str();
  cmd->add_option("--force-max-n", args->force_max_n,
                  "coverage: largest peak force (0: the contact law's linear limit, beyond which frames are over range)")
      ->check(CLI::Range(0.0, 1000.0))->capture_default_str();
  cmd->add_option("--edge-fraction", args->edge_fraction, "coverage: share of presses drawn within --edge-band-mm of an edge")
      ->check(CLI::Range(0.0, 1.0))->capture_default_str();
  cmd->add_option("--edge-band-mm", args->edge_band_mm, "coverage: width of the edge band")
      ->check(CLI::Range(0.1, 1000.0))->capture_default_str();
  cmd->add_option("--step-mm", args->step_mm, "receptive-field: grid step")->check(CLI::Range(0.2, 50.0))->capture_default_str();
  cmd->add_option("--compression", args->compression, "0 none, 1..9 shuffle+deflate")->check(CLI::Range(0, 9))->capture_default_str();
  cmd->add_option("--out", args->out, "Output dataset (.h5)")->required();
  cmd->callback([args]() {
    const twin::Scene scene = LoadSceneArgs(args->scene);
    const auto twin = BuildTwin(scene, args->scene.patch);
    const auto t0 = std::chrono::steady_clock::now();
    double rate = 100.0;
    std::unique_ptr<ProgressBar> bar;
    std::unique_ptr<dataset::DatasetWriter> writer;
    auto open = [&](double r) {
      writer = std::make_unique<dataset::DatasetWriter>(
          args->out, twin::TwinDatasetInfo(*twin, scene, args->protocol, args->seed, r), args->compression);
    };
    auto sink = [&](std::span<const dataset::Frame> f) { writer->Append(f); };
    twin::ProtocolRun run;
    if (args->protocol == "paper") {
      twin::PaperProtocol p;
      if (args->indentations) p.indentations = *args->indentations;
      rate = p.rate_hz;
      open(rate);
      run = twin::RunPaper(*twin, scene, p, args->seed, sink, Bar(bar, "indentations"));
    } else if (args->protocol == "coverage") {
      twin::CoverageProtocol p;
      if (args->indentations) p.indentations = *args->indentations;
      p.force_min_n = args->force_min_n;
      p.force_max_n = args->force_max_n;
      p.edge_fraction = args->edge_fraction;
      p.edge_band_mm = args->edge_band_mm;
      p.Validate();
      rate = p.rate_hz;
      open(rate);
      run = twin::RunCoverage(*twin, scene, p, args->seed, sink, Bar(bar, "indentations"));
    } else if (args->protocol == "vonfrey") {
      twin::VonFreyProtocol p;
      rate = p.rate_hz;
      open(rate);
      run = twin::RunVonFrey(*twin, p, args->seed, sink, Bar(bar, "stimulations"));
    } else if (args->protocol == "field") {
      twin::FieldProtocol p;
      p.duration_s = args->duration_s;
      p.rate_hz = args->rate_hz;
      p.first_rest_s = std::min(p.first_rest_s, p.duration_s);
      p.Validate();
      rate = p.rate_hz;
      open(rate);
      run = twin::RunField(*twin, scene, p, args->seed, sink, Bar(bar, "seconds"));
    } else {
      twin::ReceptiveFieldProtocol p;
      p.step_mm = args->step_mm;
      rate = p.rate_hz;
      open(rate);
      run = twin::RunReceptiveField(*twin, scene, p, args->seed, sink, Bar(bar, "grid rows"));
    }
    writer->Close();
    if (bar) bar->Finish();
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const auto bytes = std::filesystem::file_size(args->out);
    std::printf("wrote %s: %llu frames, %d indentations, %.2f s, %.1f bytes/frame\n", args->out.c_str(),
                static_cast<unsigned long long>(run.frames), run.indentations, s,
                static_cast<double>(bytes) / static_cast<double>(std::max<std::uint64_t>(1, run.frames)));
  });
}

void RegisterImportCsv(CLI::App& app) {
  struct Args {
    std::string in, out, patch_spec = RUFFINI_DEFAULT_PATCH;
    int compression = 0;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand("import-csv", "Turn a CSV recording (time, 16 wavelengths[, force[, Y, R]]) into a dataset");
  cmd->add_option("--in", args->in, "CSV recording")->required()->check(CLI::ExistingFile);
  cmd->add_option("--out", args->out, "Output dataset (.h5)")->required();
  cmd->add_option("--patch-spec", args->patch_spec, "Patch spec giving the patch name and reference wavelengths")
      ->capture_default_str();
  cmd->add_option("--compression", args->compression, "0 none, 1..9 shuffle+deflate")->check(CLI::Range(0, 9));
  cmd->callback([args]() {
    const patch::PatchSpec spec = patch::LoadPatchSpec(args->patch_spec);
    dataset::CsvImportOptions o;
    o.patch_name = spec.name;
    o.surface_radius_mm = spec.surface_radius_mm;
    for (std::size_t i = 0; i < patch::kGratings; ++i) o.reference_wavelength_nm[i] = spec.gratings[i].wavelength_nm;
    const dataset::Dataset d = dataset::ImportCsv(args->in, o);
    dataset::WriteDataset(args->out, d, args->compression);
    std::printf("wrote %s: %zu frames at %.1f Hz\n", args->out.c_str(), d.size(), d.info.sample_rate_hz);
  });
}

void RegisterTwinReport(CLI::App& app) {
  struct Args {
    SceneArgs scene;
    std::uint64_t seed = 1;
    int indentations = 2700;
    std::string json, out_dir = "twin-report";
    bool no_figures = false;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand("twin-report", "Measure the twin against the paper's statistics (T1-T3, protocol)");
  AddSceneOptions(cmd, args->scene);
  cmd->add_option("--seed", args->seed, "Seed of the simulated protocols")->capture_default_str();
  cmd->add_option("--indentations", args->indentations, "Indentations of the paper protocol to simulate")
      ->check(CLI::Range(10, 1000000))->capture_default_str();
  cmd->add_option("--json", args->json, "Also write the measurements as JSON to this file");
  cmd->add_option("--out-dir", args->out_dir, "Folder for the pictures (hot-spot maps, detection curve)")->capture_default_str();
  cmd->add_flag("--no-figures", args->no_figures, "Skip the pictures");
  cmd->callback([args]() {
    const twin::Scene scene = LoadSceneArgs(args->scene);
    const auto twin = BuildTwin(scene, args->scene.patch);
    twin::ReportOptions opt;
    opt.seed = args->seed;
    opt.paper_indentations = args->indentations;
    std::unique_ptr<ProgressBar> bar;
    spdlog::info("measuring hot spots, cross-talk, detection and the paper protocol ({} indentations)", args->indentations);
    const twin::TwinReport r = twin::MeasureTwin(*twin, scene, opt, Bar(bar, "paper protocol"));
    if (bar) bar->Finish();
    std::fputs(twin::FormatReport(r).c_str(), stdout);
    if (!args->json.empty()) {
      std::ofstream out(args->json);
      out << twin::ReportJson(r);
      out.close();
      if (!out) throw InputError(args->json + ": cannot write the JSON report");
      std::printf("\nwrote %s\n", args->json.c_str());
    }
    if (!args->no_figures) {
      std::filesystem::create_directories(args->out_dir);
      const auto maps = twin::MeasureHotSpotMaps(*twin, scene.probe, 2.5, opt.hot_spot_shift_pm, 0.5);
      const auto paths = WriteHotSpotFigures(*twin, maps, r, opt.hot_spot_force_n, args->out_dir);
      const std::string det = WriteDetectionFigure(r, args->out_dir);
      std::printf("wrote %zu hot-spot maps and %s\n", paths.size(), det.c_str());
    }
  });
}

void RegisterCalibrate(CLI::App& app) {
  struct Args {
    SceneArgs scene;
    double target_mm2 = twin::Targets::kHotSpotMedianMm2;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand("twin-calibrate",
                                     "Fit the patch's strain_transfer so the median hot-spot area meets the paper's");
  AddSceneOptions(cmd, args->scene);
  cmd->add_option("--target-mm2", args->target_mm2, "Median hot-spot area to reach")->capture_default_str();
  cmd->callback([args]() {
    const twin::Scene scene = LoadSceneArgs(args->scene);
    const auto& sp = scene.Patch(args->scene.patch);
    const double t = twin::CalibrateStrainTransfer(sp.spec, EffectsOf(scene, sp), scene.probe, args->target_mm2);
    std::printf("strain_transfer: %.4g   # put this into %s (fibre.strain_transfer)\n", t, sp.spec_path.c_str());
  });
}

}  // namespace

void RegisterTwinCommands(CLI::App& app) {
  RegisterSimulate(app);
  RegisterImportCsv(app);
  RegisterTwinReport(app);
  RegisterCalibrate(app);
}

}  // namespace ruffini::cli
