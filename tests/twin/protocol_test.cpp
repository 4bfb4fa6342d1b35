// The indentation protocols (reproducibility, structure of the paper, von Frey and receptive-field runs)
// and scene loading.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <numbers>
#include <regex>
#include <set>
#include <string>
#include <vector>

#include "ruffini/dataset/dataset.h"
#include "ruffini/error.h"
#include "ruffini/patch/edge_distance.h"
#include "ruffini/twin/protocols.h"
#include "ruffini/twin/scene.h"
#include "ruffini/twin/twin.h"

#include "fixtures.h"

namespace ruffini::twin {
namespace {

namespace fs = std::filesystem;
constexpr std::size_t kN = patch::kGratings;

using fixtures::DefaultScene;
using fixtures::DefaultTwin;

std::vector<dataset::Frame> Collect(const std::function<ProtocolRun(const FrameSink&)>& run, ProtocolRun* out) {
  std::vector<dataset::Frame> frames;
  const ProtocolRun r = run([&](std::span<const dataset::Frame> block) { frames.insert(frames.end(), block.begin(), block.end()); });
  if (out) *out = r;
  return frames;
}

// A fresh folder per test, removed afterwards.
class TempDirTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::path(::testing::TempDir()) / (std::to_string(::getpid()) + "_ruffini_twin_" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  [[nodiscard]] std::string Path(const std::string& name) const { return (dir_ / name).string(); }
  std::string Write(const std::string& name, const std::string& text) const {
    const std::string p = Path(name);
    std::ofstream(p) << text;
    return p;
  }
  fs::path dir_;
};

std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// ---------------------------------------------------------------------------------------------------
// 11. Reproducible files.

class ProtocolFiles : public TempDirTest {
 protected:
  std::string RunToFile(const std::string& name, std::uint64_t seed) {
    const SkinTwin& twin = DefaultTwin();
    PaperProtocol p;
    p.indentations = 20;
    const std::string path = Path(name);
    dataset::DatasetWriter w(path, TwinDatasetInfo(twin, DefaultScene(), "paper", seed, p.rate_hz));
    const ProtocolRun run = RunPaper(twin, DefaultScene(), p, seed, [&](std::span<const dataset::Frame> f) { w.Append(f); });
    w.Close();
    EXPECT_EQ(w.frames_written(), run.frames);
    EXPECT_GT(run.frames, 20u * 500u);
    return path;
  }
};

TEST_F(ProtocolFiles, SameSeedGivesBitIdenticalFiles) {
  const std::string a = ReadBytes(RunToFile("a.h5", 7));
  const std::string b = ReadBytes(RunToFile("b.h5", 7));
  const std::string c = ReadBytes(RunToFile("c.h5", 8));
  ASSERT_GT(a.size(), 100000u);
  EXPECT_TRUE(a == b) << "same seed, different bytes";
  EXPECT_FALSE(a == c) << "different seed, same bytes";
  const dataset::Dataset d = dataset::ReadDataset(Path("a.h5"));
  EXPECT_NE(d.info.source.find("seed=7"), std::string::npos);
  EXPECT_EQ(d.info.reference_wavelength_nm, DefaultTwin().reference_wavelength_nm());
}

// ---------------------------------------------------------------------------------------------------
// 12. Paper protocol structure.

TEST(Protocols, PaperProtocolStructure) {
  const SkinTwin& twin = DefaultTwin();
  PaperProtocol p;
  p.indentations = 40;
  ProtocolRun run;
  const auto frames = Collect([&](const FrameSink& s) { return RunPaper(twin, DefaultScene(), p, 3, s); }, &run);
  ASSERT_EQ(run.frames, frames.size());
  EXPECT_EQ(run.indentations, p.indentations);
  ASSERT_GT(frames.size(), static_cast<std::size_t>(p.rest_frames));
  const patch::Region area = twin.spec().indented_area;

  for (int k = 0; k < p.rest_frames; ++k) {
    const auto& f = frames[static_cast<std::size_t>(k)];
    EXPECT_EQ(f.indentation, -1);
    EXPECT_TRUE(std::isnan(f.y_mm));
    EXPECT_TRUE(std::isnan(f.r_deg));
    EXPECT_EQ(f.true_force_n, 0.0f);
  }
  int current = -1;
  std::size_t in_indent = 0, zero_force = 0;
  float last_force = 0.0f, y = 0.0f, r = 0.0f;
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const auto& f = frames[k];
    ASSERT_EQ(f.serial, k);
    ASSERT_NEAR(f.t_s, static_cast<double>(k) / 100.0, 1e-9);
    if (k < static_cast<std::size_t>(p.rest_frames)) continue;
    ASSERT_GE(f.indentation, 0) << "frame " << k;
    ++in_indent;
    zero_force += f.true_force_n == 0.0f ? 1 : 0;
    if (f.indentation != current) {
      ASSERT_EQ(f.indentation, current + 1) << "indentations contiguous, frame " << k;
      current = f.indentation;
      EXPECT_EQ(f.true_force_n, 0.0f) << "indentation " << current << " starts at rest";
      y = f.y_mm;
      r = f.r_deg;
      EXPECT_TRUE(area.Contains({y, r}, 1e-4)) << y << ", " << r;
    } else {
      ASSERT_GE(f.true_force_n, last_force) << "indentation " << current;
      ASSERT_EQ(f.y_mm, y);
      ASSERT_EQ(f.r_deg, r);
    }
    ASSERT_LE(f.true_force_n, 2.5f);
    ASSERT_TRUE(std::isfinite(f.force_n));
    last_force = f.true_force_n;
  }
  EXPECT_EQ(current, p.indentations - 1);
  const double frac0 = static_cast<double>(zero_force) / static_cast<double>(in_indent);
  EXPECT_GE(frac0, 0.25);
  EXPECT_LE(frac0, 0.50);
  // The probe positions spread over the area (not all in one spot).
  std::set<float> ys;
  for (const auto& f : frames) if (f.indentation >= 0) ys.insert(f.y_mm);
  EXPECT_EQ(ys.size(), static_cast<std::size_t>(p.indentations));
}

// ---------------------------------------------------------------------------------------------------
// 12b. Coverage protocol (issue 16): the paper's ramps over the whole patch, edge to edge.

struct Press {
  float y = 0, r = 0, peak = 0;
  std::size_t frames = 0;
};

// Every press of a run: position, largest applied force; checks each press's structure on the way.
std::vector<Press> PressesOf(const std::vector<dataset::Frame>& frames, int rest_frames) {
  std::vector<Press> out;
  float last = 0.0f;
  for (std::size_t k = static_cast<std::size_t>(rest_frames); k < frames.size(); ++k) {
    const auto& f = frames[k];
    EXPECT_GE(f.indentation, 0) << "frame " << k;
    if (f.indentation != static_cast<int>(out.size()) - 1) {
      EXPECT_EQ(f.indentation, static_cast<int>(out.size())) << "presses contiguous, frame " << k;
      EXPECT_EQ(f.true_force_n, 0.0f) << "a press starts at rest, frame " << k;
      out.push_back({f.y_mm, f.r_deg, 0.0f, 0});
    } else {
      EXPECT_GE(f.true_force_n, last) << "increasing load only, frame " << k;
      EXPECT_EQ(f.y_mm, out.back().y);
      EXPECT_EQ(f.r_deg, out.back().r);
    }
    EXPECT_TRUE(std::isfinite(f.force_n));
    last = f.true_force_n;
    out.back().peak = std::max(out.back().peak, f.true_force_n);
    ++out.back().frames;
  }
  return out;
}

TEST(Protocols, CoverageReachesEveryEdgeAndTheForcesSpanTheRange) {
  const SkinTwin& twin = DefaultTwin();
  const patch::PatchSpec& spec = twin.spec();
  CoverageProtocol p;
  p.indentations = 400;
  ProtocolRun run;
  const auto frames = Collect([&](const FrameSink& s) { return RunCoverage(twin, DefaultScene(), p, 5, s); }, &run);
  ASSERT_EQ(run.frames, frames.size());
  ASSERT_EQ(run.indentations, p.indentations);
  for (int k = 0; k < p.rest_frames; ++k) EXPECT_EQ(frames[static_cast<std::size_t>(k)].indentation, -1);
  const auto presses = PressesOf(frames, p.rest_frames);
  ASSERT_EQ(presses.size(), static_cast<std::size_t>(p.indentations));

  // Positions: all on the patch, edge to edge; some within 2 mm of each of the four edges; beyond the
  // indented area (where the paper protocol never presses) on all four sides.
  const double mm_per_deg = spec.surface_radius_mm * std::numbers::pi / 180.0;
  std::array<int, 4> within_2mm{}, beyond_area{};
  int in_band = 0;
  for (const auto& q : presses) {
    ASSERT_TRUE(spec.Extent().Contains({q.y, q.r}, 1e-4)) << q.y << ", " << q.r;
    within_2mm[0] += q.y <= 2.0;
    within_2mm[1] += spec.extent_y_mm - q.y <= 2.0;
    within_2mm[2] += q.r * mm_per_deg <= 2.0;
    within_2mm[3] += (spec.extent_r_deg - q.r) * mm_per_deg <= 2.0;
    beyond_area[0] += q.y < spec.indented_area.y_min_mm;
    beyond_area[1] += q.y > spec.indented_area.y_max_mm;
    beyond_area[2] += q.r < spec.indented_area.r_min_deg;
    beyond_area[3] += q.r > spec.indented_area.r_max_deg;
    in_band += patch::EdgeDistanceMm(spec, {q.y, q.r}) < p.edge_band_mm;
  }
  for (int e = 0; e < 4; ++e) {
    EXPECT_GE(within_2mm[static_cast<std::size_t>(e)], 1) << "edge " << e;
    EXPECT_GE(beyond_area[static_cast<std::size_t>(e)], 10) << "side " << e;
  }
  // The 12 mm band is 37 % of the paper patch: uniform draws alone put 37 % there, the protocol's 30 % of
  // band draws 0.3 + 0.7 x 0.37 = 56 %.
  const double band_share = static_cast<double>(in_band) / static_cast<double>(presses.size());
  EXPECT_GT(band_share, 0.47);
  EXPECT_LT(band_share, 0.66);
  CoverageProtocol uniform = p;
  uniform.edge_fraction = 0.0;
  const auto uframes = Collect([&](const FrameSink& s) { return RunCoverage(twin, DefaultScene(), uniform, 5, s); }, nullptr);
  int u_band = 0;
  for (const auto& q : PressesOf(uframes, p.rest_frames)) u_band += patch::EdgeDistanceMm(spec, {q.y, q.r}) < p.edge_band_mm;
  EXPECT_GT(band_share, static_cast<double>(u_band) / p.indentations + 0.1) << "the edge draws add presses near the edges";

  // Forces: log-uniform peaks from 0.05 N up to the contact law's linear limit (beyond it every frame is
  // flagged saturated, over range for the decoder): none beyond, light and hard presses both present, the
  // median near the geometric mean of the range.
  const double f_lin = twin.contact_law(DefaultScene().probe)->linear_limit_force_n();
  std::vector<float> peaks;
  for (const auto& q : presses) peaks.push_back(q.peak);
  std::sort(peaks.begin(), peaks.end());
  EXPECT_LE(peaks.back(), f_lin + 1e-6);
  EXPECT_GT(peaks.back(), 0.9 * f_lin);
  EXPECT_LT(peaks.front(), 0.1f);
  const double median = peaks[peaks.size() / 2], geo_mean = std::sqrt(p.force_min_n * f_lin);
  EXPECT_GT(median, 0.7 * geo_mean);
  EXPECT_LT(median, 1.4 * geo_mean);
  std::size_t saturated = 0;
  for (const auto& f : frames) saturated += (f.flags & kFlagSaturated) ? 1 : 0;
  EXPECT_EQ(saturated, 0u) << "no press goes beyond the linear limit";
}

TEST(Protocols, CoverageIsSeedReproducible) {
  const SkinTwin& twin = DefaultTwin();
  CoverageProtocol p;
  p.indentations = 30;
  auto run = [&](std::uint64_t seed) {
    return Collect([&](const FrameSink& s) { return RunCoverage(twin, DefaultScene(), p, seed, s); }, nullptr);
  };
  const auto a = run(11), b = run(11), c = run(12);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t k = 0; k < a.size(); ++k) {
    ASSERT_EQ(a[k].wavelength_nm, b[k].wavelength_nm) << "frame " << k;
    ASSERT_EQ(a[k].force_n, b[k].force_n) << "frame " << k;
    ASSERT_EQ(a[k].true_force_n, b[k].true_force_n) << "frame " << k;
    ASSERT_TRUE(a[k].y_mm == b[k].y_mm || (std::isnan(a[k].y_mm) && std::isnan(b[k].y_mm))) << "frame " << k;
  }
  const auto pa = PressesOf(a, p.rest_frames), pc = PressesOf(c, p.rest_frames);
  int same = 0;
  for (std::size_t k = 0; k < std::min(pa.size(), pc.size()); ++k) same += pa[k].y == pc[k].y && pa[k].r == pc[k].r;
  EXPECT_EQ(same, 0) << "another seed presses elsewhere";
}

TEST(Protocols, CoverageRejectsBadParameters) {
  const SkinTwin& twin = DefaultTwin();
  auto run = [&](const CoverageProtocol& p) {
    (void)Collect([&](const FrameSink& s) { return RunCoverage(twin, DefaultScene(), p, 1, s); }, nullptr);
  };
  CoverageProtocol p;
  p.indentations = 0;
  EXPECT_THROW(run(p), InputError);
  p = {};
  p.edge_fraction = 1.5;
  EXPECT_THROW(run(p), InputError);
  p = {};
  p.force_min_n = 2.0;
  p.force_max_n = 1.0;
  EXPECT_THROW(run(p), InputError);
  p = {};
  p.force_min_n = 10.0;  // above the linear limit that force_max_n = 0 stands for
  EXPECT_THROW(run(p), InputError);
  p = {};
  p.edge_band_mm = 0.0;
  EXPECT_THROW(run(p), InputError);
}

// ---------------------------------------------------------------------------------------------------
// 13. Von Frey.

TEST(Protocols, VonFreyHoldsAtEachFilamentsForce) {
  const SkinTwin& twin = DefaultTwin();
  VonFreyProtocol p;
  p.subjects = 1;
  p.sites = 3;
  ProtocolRun run;
  const auto frames = Collect([&](const FrameSink& s) { return RunVonFrey(twin, p, 5, s); }, &run);
  const int stim = static_cast<int>(p.filaments_g.size()) * p.subjects * p.sites;
  ASSERT_EQ(p.filaments_g.size(), 8u);
  EXPECT_EQ(run.indentations, stim);
  EXPECT_EQ(frames.size(), static_cast<std::size_t>(stim * (p.rest_frames + p.ramp_frames + p.hold_frames + p.release_frames)));
  std::map<int, std::vector<const dataset::Frame*>> by;
  for (const auto& f : frames) {
    if (f.indentation >= 0) by[f.indentation].push_back(&f);
  }
  ASSERT_EQ(static_cast<int>(by.size()), stim);
  for (const auto& [index, fs] : by) {
    ASSERT_GE(index, 0);
    ASSERT_LT(index, stim);
    const double grams = p.filaments_g[static_cast<std::size_t>(index / p.sites)];  // subject 0: filament-major
    const auto nominal = static_cast<float>(GramsToNewtons(grams));
    int at_nominal = 0;
    float max_f = 0.0f;
    for (const auto* f : fs) {
      max_f = std::max(max_f, f->true_force_n);
      at_nominal += f->true_force_n == nominal ? 1 : 0;
      EXPECT_TRUE(twin.spec().indented_area.Contains({f->y_mm, f->r_deg}, 1e-4));
    }
    EXPECT_EQ(max_f, nominal) << "stimulation " << index;
    EXPECT_GE(at_nominal, p.hold_frames) << "stimulation " << index;
    EXPECT_EQ(fs.size(), static_cast<std::size_t>(p.ramp_frames + p.hold_frames + p.release_frames));
    EXPECT_EQ(fs.back()->true_force_n, 0.0f) << "released";
  }
  EXPECT_NEAR(GramsToNewtons(60.0), 0.588399, 1e-6);
  // The heaviest filament is felt; the response is on the wavelength channels.
  bool moved = false;
  for (const auto& f : frames) {
    if (f.true_force_n > 0.5f) {
      for (std::size_t i = 0; i < kN; ++i) {
        moved |= std::abs(f.wavelength_nm[i] - twin.reference_wavelength_nm()[i]) > 2e-3;
      }
    }
  }
  EXPECT_TRUE(moved);
}

// ---------------------------------------------------------------------------------------------------
// 14. Receptive field.

TEST(Protocols, ReceptiveFieldCoversTheGridAndRamps) {
  const SkinTwin& twin = DefaultTwin();
  ReceptiveFieldProtocol p;
  p.step_mm = 10.0;
  ProtocolRun run;
  const auto frames = Collect([&](const FrameSink& s) { return RunReceptiveField(twin, DefaultScene(), p, 9, s); }, &run);
  const patch::Region area = twin.spec().indented_area;
  const auto& geo = twin.geometry();
  const double arc0 = geo.ArcMm(area.r_min_deg), arc1 = geo.ArcMm(area.r_max_deg);
  const int ny = static_cast<int>(std::floor((area.y_max_mm - area.y_min_mm) / p.step_mm)) + 1;  // 13
  const int na = static_cast<int>(std::floor((arc1 - arc0) / p.step_mm)) + 1;                     // 6
  ASSERT_EQ(ny, 13);
  ASSERT_EQ(na, 6);
  EXPECT_EQ(run.indentations, ny * na);
  EXPECT_EQ(frames.size(), static_cast<std::size_t>(ny * na * (p.ramp_frames + 1)));

  std::map<int, std::vector<const dataset::Frame*>> by;
  for (const auto& f : frames) by[f.indentation].push_back(&f);
  ASSERT_EQ(static_cast<int>(by.size()), ny * na);
  std::set<std::pair<int, int>> cells;
  for (const auto& [index, fs] : by) {
    const float y = fs.front()->y_mm, r = fs.front()->r_deg;
    EXPECT_TRUE(area.Contains({y, r}, 1e-4)) << y << ", " << r;
    const double iy = (y - area.y_min_mm) / p.step_mm, ia = (geo.ArcMm(r) - arc0) / p.step_mm;
    EXPECT_NEAR(iy, std::round(iy), 1e-4);
    EXPECT_NEAR(ia, std::round(ia), 1e-4);
    cells.insert({static_cast<int>(std::lround(iy)), static_cast<int>(std::lround(ia))});
    EXPECT_EQ(fs.front()->true_force_n, 0.0f);
    EXPECT_FLOAT_EQ(fs.back()->true_force_n, 2.5f);
    for (std::size_t k = 1; k < fs.size(); ++k) {
      EXPECT_GT(fs[k]->true_force_n, fs[k - 1]->true_force_n);
      EXPECT_EQ(fs[k]->y_mm, y);
      EXPECT_EQ(fs[k]->r_deg, r);
    }
  }
  EXPECT_EQ(static_cast<int>(cells.size()), ny * na);
  for (const auto& [iy, ia] : cells) {
    EXPECT_GE(iy, 0);
    EXPECT_LT(iy, ny);
    EXPECT_GE(ia, 0);
    EXPECT_LT(ia, na);
  }
}

// ---------------------------------------------------------------------------------------------------
// 15. Scenes.

TEST(Scenes, DefaultSceneLoads) {
  const Scene& s = DefaultScene();
  EXPECT_EQ(s.name, "forearm-bench");
  ASSERT_EQ(s.patches.size(), 1u);
  EXPECT_EQ(s.Patch().name, "forearm");
  EXPECT_EQ(s.Patch().spec.name, "forearm");
  EXPECT_EQ(s.probe.shape, Probe::Shape::kSphere);
  EXPECT_EQ(s.probe.radius_mm, 5.5);
  const TwinEffects& e = s.effects;
  ASSERT_TRUE(e.noise.has_value());
  EXPECT_EQ(e.noise->sigma_pm, 0.3);
  ASSERT_TRUE(e.gain_spread.has_value());
  EXPECT_EQ(e.gain_spread->sigma, 0.10);
  ASSERT_TRUE(e.irregular.has_value());
  std::set<int> irregular;
  for (const auto& g : e.irregular->gratings) irregular.insert(g.grating);
  EXPECT_EQ(irregular, (std::set<int>{2, 6, 12, 13}));
  EXPECT_TRUE(e.stiffening.has_value());
  ASSERT_TRUE(e.skin_sample.has_value());
  EXPECT_EQ(e.skin_sample->seed, 0u);
  EXPECT_FALSE(e.temperature.has_value());
  EXPECT_TRUE(e.faults.empty());
  EXPECT_EQ(s.load_cell.resolution_n, 1.0 / 256.0);
}

class SceneFiles : public TempDirTest {
 protected:
  static std::string SpecPath() { return std::string(RUFFINI_SOURCE_DIR) + "/config/patches/forearm.yaml"; }
  std::string SceneText(const std::string& spec, const std::string& effects) const {
    return "name: test\n"
           "patches:\n"
           "  - name: forearm\n"
           "    spec: " + spec + "\n"
           "twin:\n"
           "  probe: {shape: sphere, radius_mm: 5.5}\n"
           "  effects:\n" + effects;
  }
};

TEST_F(SceneFiles, MinimalSceneLoadsOnlyWhatItNames) {
  const auto path = Write("min.yaml", SceneText(SpecPath(), "    noise: {sigma_pm: 0.5}\n"));
  const auto s = LoadScene(path);
  ASSERT_TRUE(s.effects.noise.has_value());
  EXPECT_EQ(s.effects.noise->sigma_pm, 0.5);
  EXPECT_FALSE(s.effects.gain_spread || s.effects.irregular || s.effects.stiffening || s.effects.temperature ||
               s.effects.skin_sample);
  EXPECT_EQ(s.effects.Summary(), "noise");
}

TEST_F(SceneFiles, UnknownEffectKeyIsNamedWithItsPlace) {
  const auto path = Write("colour.yaml", SceneText(SpecPath(), "    noise: {sigma_pm: 0.3}\n    colour: red\n"));
  try {
    (void)LoadScene(path);
    FAIL() << "an unknown key must be rejected";
  } catch (const InputError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("colour.yaml"), std::string::npos) << m;
    EXPECT_TRUE(std::regex_search(m, std::regex(R"(colour\.yaml:\d+:\d+)"))) << m;
    EXPECT_NE(m.find("'twin.effects.colour' is not a known key here"), std::string::npos) << m;
  }
}

// Casts (issue 16): each patch may name its own cast (skin sample) in the twin section, and its own model
// file (`model:`). A patch without one is the scene's cast; a twin built from EffectsOf is that cast.
TEST_F(SceneFiles, EachPatchMayNameItsOwnCastAndModel) {
  const std::string models = std::string(RUFFINI_SOURCE_DIR) + "/config/models/";
  const std::string text = "name: casts\n"
                           "patches:\n"
                           "  - {name: a, spec: " + SpecPath() + ", model: " + models + "forearm.rmodel}\n"
                           "  - {name: b, spec: " + SpecPath() + ", model: " + models + "forearm-field.rmodel}\n"
                           "  - {name: c, spec: " + SpecPath() + "}\n"
                           "twin:\n"
                           "  effects:\n"
                           "    gain_spread: {sigma: 0.1}\n"
                           "    skin_sample: {seed: 0, position_mm: 1.0}\n"
                           "  casts:\n"
                           "    - {patch: b, skin_sample: 7}\n";
  const auto s = LoadScene(Write("casts.yaml", text));
  ASSERT_EQ(s.patches.size(), 3u);
  EXPECT_FALSE(s.patches[0].cast_seed.has_value());
  EXPECT_EQ(s.patches[1].cast_seed, 7u);
  EXPECT_NE(s.patches[0].model_path, s.patches[1].model_path);
  EXPECT_EQ(s.EffectsOf(0).skin_sample->seed, 0u);
  EXPECT_EQ(s.EffectsOf(1).skin_sample->seed, 7u);
  EXPECT_EQ(s.EffectsOf(1).skin_sample->position_mm, 1.0);  // the scene's cast parameters, another draw
  const SkinTwin a(s.patches[0].spec, s.EffectsOf(0)), b(s.patches[1].spec, s.EffectsOf(1)), c(s.patches[2].spec, s.EffectsOf(2));
  EXPECT_NE(a.gain(), b.gain());
  EXPECT_NE(a.reference_wavelength_nm(), b.reference_wavelength_nm());
  EXPECT_EQ(a.gain(), c.gain());
  EXPECT_EQ(a.reference_wavelength_nm(), c.reference_wavelength_nm());
  // Validated: a cast for a patch the scene does not have, two casts for one patch, a negative seed.
  const std::string head = "name: casts\npatches:\n  - {name: a, spec: " + SpecPath() + "}\ntwin:\n  casts:\n";
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"    - {patch: z, skin_sample: 1}\n", "is not a patch of this scene"},
      {"    - {patch: a, skin_sample: 1}\n    - {patch: a, skin_sample: 2}\n", "has a cast already"},
      {"    - {patch: a, skin_sample: -1}\n", "skin_sample"},
      {"    - {patch: a, skin_sample: 1, colour: red}\n", "colour"},
  };
  for (const auto& [casts, what] : bad) {
    try {
      (void)LoadScene(Write("bad-casts.yaml", head + casts));
      ADD_FAILURE() << "accepted: " << casts;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("bad-casts.yaml"), std::string::npos) << e.what();
    }
  }
}

TEST_F(SceneFiles, MissingPatchSpecIsNamed) {
  const auto abs_path = Write("abs.yaml", SceneText("/no/such/dir/arm.yaml", ""));
  try {
    (void)LoadScene(abs_path);
    FAIL() << "a missing spec must be rejected";
  } catch (const InputError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("/no/such/dir/arm.yaml"), std::string::npos) << m;
    EXPECT_NE(m.find("abs.yaml"), std::string::npos) << m;
  }
  const auto rel_path = Write("rel.yaml", SceneText("missing-patch.yaml", ""));
  try {
    (void)LoadScene(rel_path);
    FAIL() << "a missing spec must be rejected";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("missing-patch.yaml"), std::string::npos) << e.what();
  }
}

TEST(Scenes, CobotSceneLoadsForTheTwin) {
  // The twin reads the patches and its own section; the robot, mounts and safety zones are other parts'.
  const auto cobot = LoadScene(std::string(RUFFINI_SOURCE_DIR) + "/config/scenes/cobot.yaml");
  ASSERT_EQ(cobot.patches.size(), 4u);
  EXPECT_EQ(cobot.patches[1].name, "forearm_b");
  EXPECT_EQ(cobot.Patch("upper_arm_b").spec.surface_radius_mm, 37.4);
  // Its twin section is the bench scene's (the same effects and probe) plus where its covers end (edges).
  const Scene& bench = DefaultScene();
  EXPECT_EQ(cobot.effects.Summary(), bench.effects.Summary() + ",edges");
  ASSERT_TRUE(cobot.effects.edges.has_value());
  EXPECT_FALSE(bench.effects.edges.has_value());
  EXPECT_EQ(cobot.probe.radius_mm, bench.probe.radius_mm);
  EXPECT_EQ(cobot.load_cell.noise_n, bench.load_cell.noise_n);
  // Every cobot patch names a copy of the bench scene's model (its map measured where it sits, the two-touch check on).
  EXPECT_EQ(fs::path(cobot.Patch("upper_arm_a").model_path).parent_path(), fs::path(bench.patches[0].model_path).parent_path());
  EXPECT_EQ(fs::path(cobot.Patch("upper_arm_a").model_path).filename(), "cobot-upper_arm.rmodel");
}

TEST(Scenes, OverrideSkinSampleSetsTheSeed) {
  Scene s = DefaultScene();
  OverrideSkinSample(s, 42);
  ASSERT_TRUE(s.effects.skin_sample.has_value());
  EXPECT_EQ(s.effects.skin_sample->seed, 42u);
  EXPECT_EQ(s.effects.skin_sample->position_mm, DefaultScene().effects.skin_sample->position_mm);
  EXPECT_EQ(s.effects.fabrication_seed(), 42u);
  Scene off = DefaultScene();
  off.effects.skin_sample.reset();
  OverrideSkinSample(off, 9);
  ASSERT_TRUE(off.effects.skin_sample.has_value());
  EXPECT_EQ(off.effects.skin_sample->seed, 9u);
  EXPECT_NE(off.effects.Summary().find("skin_sample=9"), std::string::npos);
}

}  // namespace
}  // namespace ruffini::twin
