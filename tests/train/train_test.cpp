// Training (libtorch) and the Eigen runtime agree: golden vectors, a libtorch eager forward, save/load.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>

#include "ruffini/decode/grids.h"
#include "ruffini/decode/model_io.h"
#include "ruffini/decode/network_decoder.h"
#include "ruffini/error.h"
#include "ruffini/eval/prepared.h"
#include "ruffini/train/torch_decoder.h"
#include "ruffini/train/trainer.h"
#include "ruffini/twin/protocols.h"
#include "ruffini/twin/scene.h"
#include "../common/golden.h"

namespace ruffini::train {
namespace {

struct Fixture {
  twin::Scene scene = twin::LoadScene(RUFFINI_SOURCE_DIR "/config/scenes/forearm.yaml");
  eval::Prepared prepared;
  // W = 1; W = 8; W = 8 with the L1 force loss, unit-pattern input, soft labels and cosine decay (the variants).
  std::array<v1::DecoderModel, 3> models;
  Fixture() {
    const twin::SkinTwin t(scene.Patch().spec, scene.effects, {scene.probe.radius_mm});
    dataset::Dataset d;
    d.info = twin::TwinDatasetInfo(t, scene, "paper", 3, 100.0);
    twin::PaperProtocol p;
    p.indentations = 40;
    twin::RunPaper(t, scene, p, 3, [&](std::span<const dataset::Frame> f) {
      for (const auto& x : f) d.Append(x);
    });
    prepared = eval::PrepareFrames(d);
    for (int k = 0; k < 3; ++k) {
      TrainOptions o;
      o.window = k == 0 ? 1 : 8;
      if (k == 2) {
        o.force_loss = "l1";
        o.location_input = "unit";
        o.label_sigma_mm = 5.0;
        o.lr_schedule = "cosine";
      }
      o.mlp_widths = {16, 16, 16};
      o.epochs_force = o.epochs_location = 2;
      o.frames_per_epoch = 4096;
      o.folds = 2;
      o.threads = 1;
      models[static_cast<std::size_t>(k)] = Train(prepared, scene.Patch().spec, o, "in-memory");
    }
  }
};

const Fixture& F() {
  static const Fixture f;
  return f;
}

TEST(TrainTest, ModelIsCompleteAndValid) {
  for (const auto& m : F().models) {
    EXPECT_NO_THROW(decode::ValidateModel(m, "trained"));
    EXPECT_NO_THROW(decode::CheckModelMatchesPatch(m, F().scene.Patch().spec, "trained"));
    EXPECT_EQ(m.location_size(), 4);
    EXPECT_EQ(m.location(0).grid().name(), "SG");
    EXPECT_EQ(m.location(3).grid().ny() * m.location(3).grid().nr(), 42u);
    EXPECT_EQ(m.training().folds_size(), 2 * 6);  // 2 folds x (force, SG, VSG, HSG, DSG, union)
    EXPECT_EQ(m.test_indentations_size(), 6);     // 15 % of 40
    EXPECT_GE(m.golden_size(), 1);
  }
}

// The Eigen runtime reproduces libtorch's outputs on the golden vectors to 1e-5 (float and double).
TEST(TrainTest, RuntimeMatchesLibtorchOnGoldenVectors) {
  for (const auto& m : F().models) {
    decode::NetworkDecoder<float> df(m);
    decode::NetworkDecoder<double> dd(m);
    decode::NetworkDecoder<float>::Data af(df);
    decode::NetworkDecoder<double>::Data ad(dd);
    for (const auto& g : m.golden()) {
      ASSERT_EQ(g.window_shift_pm_size(), static_cast<int>(m.force().window()) * 16);
      const float ff = df.ForceOnWindow(g.window_shift_pm().data(), af);
      const float fd = dd.ForceOnWindow(g.window_shift_pm().data(), ad);
      EXPECT_NEAR(ff, g.force_n(), 1e-5 * std::max(1.0f, std::abs(g.force_n())));
      EXPECT_NEAR(fd, g.force_n(), 1e-5 * std::max(1.0f, std::abs(g.force_n())));
      const decode::ShiftsPm last = testing::LastFrame(g, m);
      std::vector<float> p;
      df.Probabilities(last, af, p);
      ASSERT_EQ(static_cast<int>(p.size()), g.probabilities_size());
      for (std::size_t k = 0; k < p.size(); ++k) EXPECT_NEAR(p[k], g.probabilities(static_cast<int>(k)), 1e-5);
      double y = 0, r = 0;
      df.nip().Locate(p, y, r);
      EXPECT_NEAR(y, g.y_mm(), 1e-3);
      EXPECT_NEAR(r, g.r_deg(), 1e-3);
    }
  }
}

TEST(TrainTest, TorchEagerForwardEqualsRuntime) {
  const auto& m = F().models[1];
  TorchNets torch_net(m);
  decode::NetworkDecoder<float> d(m);
  decode::NetworkDecoder<float>::Data a(d);
  for (const auto& g : m.golden()) {
    EXPECT_NEAR(torch_net.Forward(g.window_shift_pm().data()), d.ForceOnWindow(g.window_shift_pm().data(), a), 1e-5);
  }
}

// The frozen TorchScript nets compute what the eager nets compute: on every golden vector of every model, the
// force and every grid's probabilities agree to 1e-5 (and both match the golden values libtorch exported).
TEST(TorchDecoderTest, FrozenTorchScriptEqualsEagerOnGoldenVectors) {
  UseOneTorchThread();
  for (const auto& m : F().models) {
    TorchNets eager(m, TorchVariant::kEager), frozen(m, TorchVariant::kFrozen);
    ASSERT_EQ(frozen.variant(), TorchVariant::kFrozen);
    ASSERT_GE(m.golden_size(), 1);
    for (const auto& g : m.golden()) {
      const float fe = eager.Forward(g.window_shift_pm().data());
      const float ff = frozen.Forward(g.window_shift_pm().data());
      EXPECT_NEAR(ff, fe, 1e-5 * std::max(1.0f, std::abs(fe)));
      EXPECT_NEAR(ff, g.force_n(), 1e-5 * std::max(1.0f, std::abs(g.force_n())));
      const decode::ShiftsPm last = testing::LastFrame(g, m);
      std::vector<float> pe, pf;
      eager.Locate(last.data(), pe);
      frozen.Locate(last.data(), pf);
      ASSERT_EQ(pf.size(), pe.size());
      ASSERT_EQ(static_cast<int>(pf.size()), g.probabilities_size());
      for (std::size_t k = 0; k < pf.size(); ++k) {
        EXPECT_NEAR(pf[k], pe[k], 1e-5);
        EXPECT_NEAR(pf[k], g.probabilities(static_cast<int>(k)), 1e-5);
      }
    }
  }
}

// The libtorch frame decoders (window, gate, NIP around the nets) decode a stream as the Eigen runtime does.
TEST(TorchDecoderTest, FrameDecodersFollowTheRuntimeOnAStream) {
  UseOneTorchThread();
  const auto& p = F().prepared;
  // W = 8 (the window matters), with the gate moved to the median force of the stream, so that it opens
  // and closes (these briefly trained nets rarely predict forces below the trained gate).
  v1::DecoderModel m = F().models[1];
  {
    eval::NetworkFrameDecoder<float> probe(m);
    std::vector<float> forces;
    for (std::size_t i = 0; i < 3; ++i) {
      probe.Reset(&p.shift_pm[p.ranges[i].first]);
      for (std::size_t k = p.ranges[i].first; k < p.ranges[i].second; ++k) forces.push_back(probe.Decode(p.shift_pm[k]).force_n);
    }
    std::nth_element(forces.begin(), forces.begin() + static_cast<std::ptrdiff_t>(forces.size() / 2), forces.end());
    m.mutable_gating()->set_on_n(forces[forces.size() / 2]);
    m.mutable_gating()->set_off_n(forces[forces.size() / 2] - 1e-3f);
  }
  eval::NetworkFrameDecoder<float> runtime(m);
  for (TorchVariant v : {TorchVariant::kEager, TorchVariant::kFrozen}) {
    TorchFrameDecoder torch_dec(m, v);
    std::size_t located = 0, frames = 0;
    for (std::size_t i = 0; i < 3; ++i) {
      const auto [first, last] = p.ranges[i];
      runtime.Reset(&p.shift_pm[first]);
      torch_dec.Reset(&p.shift_pm[first]);
      for (std::size_t k = first; k < last; k += 1, ++frames) {
        const auto a = runtime.Decode(p.shift_pm[k]);
        const auto b = torch_dec.Decode(p.shift_pm[k]);
        ASSERT_EQ(a.valid, b.valid) << VariantName(v) << " frame " << k;
        EXPECT_NEAR(a.force_n, b.force_n, 1e-4) << VariantName(v) << " frame " << k;
        ASSERT_EQ(a.located, b.located) << VariantName(v) << " frame " << k;
        if (a.located) {
          ++located;
          EXPECT_NEAR(a.y_mm, b.y_mm, 1e-3);
          EXPECT_NEAR(a.r_deg, b.r_deg, 1e-3);
        }
      }
    }
    EXPECT_GT(located, 0u) << "no frame of the stream opened the gate: the location path went untested";
    EXPECT_GT(frames, located);
  }
}

TEST(TorchDecoderTest, BenchDecodersAreEagerAndFrozen) {
  const auto decoders = TorchBenchDecoders(F().models[0]);
  ASSERT_EQ(decoders.size(), 2u);
  EXPECT_EQ(decoders[0].configuration, "libtorch eager, same weights");
  EXPECT_EQ(decoders[1].configuration, "libtorch TorchScript frozen, same weights");
  for (const auto& d : decoders) {
    EXPECT_EQ(d.runtime, eval::Runtime::kLibtorch);
    EXPECT_NE(d.decoder, nullptr);
  }
}

TEST(TrainTest, VariantKnobsAreRecorded) {
  EXPECT_EQ(F().models[0].training().force_loss(), "mse");
  EXPECT_EQ(F().models[2].training().force_loss(), "l1");
  EXPECT_FLOAT_EQ(F().models[0].training().location_label_sigma_mm(), 0.0f);
  EXPECT_FLOAT_EQ(F().models[2].training().location_label_sigma_mm(), 5.0f);
  EXPECT_EQ(F().models[0].training().lr_schedule(), "constant");
  EXPECT_EQ(F().models[2].training().lr_schedule(), "cosine");
  for (const auto& l : F().models[0].location()) EXPECT_EQ(l.input_kind(), v1::LocationNet::RAW);
  for (const auto& l : F().models[2].location()) {
    EXPECT_EQ(l.input_kind(), v1::LocationNet::UNIT);
    EXPECT_FLOAT_EQ(l.unit_floor_pm(), 1.0f);
  }
}

// libtorch eager location (with its own unit scaling) and the runtime agree, for both input kinds.
TEST(TrainTest, TorchEagerLocateEqualsRuntime) {
  for (const auto& m : F().models) {
    TorchNets torch_net(m);
    decode::NetworkDecoder<float> d(m);
    decode::NetworkDecoder<float>::Data a(d);
    for (const auto& g : m.golden()) {
      const decode::ShiftsPm last = testing::LastFrame(g, m);
      std::vector<float> pt, pr;
      torch_net.Locate(last.data(), pt);
      d.Probabilities(last, a, pr);
      ASSERT_EQ(pt.size(), pr.size());
      for (std::size_t k = 0; k < pt.size(); ++k) EXPECT_NEAR(pt[k], pr[k], 1e-5);
    }
  }
}

// Unit input sees only the pattern: scaling every shift by 3 leaves the location probabilities unchanged
// (the raw-input nets change); a missing grating still gives finite probabilities.
TEST(TrainTest, UnitInputIsScaleInvariant) {
  for (std::size_t k : {0u, 2u}) {
    const auto& m = F().models[k];
    decode::NetworkDecoder<float> d(m);
    decode::NetworkDecoder<float>::Data a(d);
    const auto& g = m.golden(0);
    decode::ShiftsPm s = testing::LastFrame(g, m), s3 = s;
    for (float& v : s3) v *= 3.0f;
    std::vector<float> p1, p3;
    d.Probabilities(s, a, p1);
    d.Probabilities(s3, a, p3);
    double diff = 0;
    for (std::size_t j = 0; j < p1.size(); ++j) diff = std::max(diff, static_cast<double>(std::abs(p1[j] - p3[j])));
    if (k == 2) {
      EXPECT_LT(diff, 1e-5);
    } else {
      EXPECT_GT(diff, 1e-4);
    }
    s[5] = std::numeric_limits<float>::quiet_NaN();
    d.Probabilities(s, a, p1);
    for (float v : p1) EXPECT_TRUE(std::isfinite(v));
  }
}

TEST(TrainTest, SaveLoadRoundTrip) {
  const auto path = std::filesystem::temp_directory_path() / "ruffini_train_test.rmodel";
  decode::SaveModel(path.string(), F().models[0]);
  const auto back = decode::LoadModel(path.string());
  EXPECT_EQ(back.SerializeAsString(), F().models[0].SerializeAsString());
  std::filesystem::remove(path);
}

TEST(TrainTest, SameSeedSameModel) {
  TrainOptions o;
  o.mlp_widths = {8, 8, 8};
  o.epochs_force = o.epochs_location = 1;
  o.frames_per_epoch = 1024;
  o.folds = 0;
  o.threads = 1;
  const auto a = Train(F().prepared, F().scene.Patch().spec, o, "x");
  const auto b = Train(F().prepared, F().scene.Patch().spec, o, "x");
  EXPECT_EQ(a.force().dense(1).weight().SerializeAsString(), b.force().dense(1).weight().SerializeAsString());
  EXPECT_EQ(a.location(2).dense(3).weight().SerializeAsString(), b.location(2).dense(3).weight().SerializeAsString());
}

// CV folds and the final fit run in parallel; the model must not depend on how many at once.
TEST(TrainTest, ParallelFitsGiveTheSerialModel) {
  TrainOptions o;
  o.window = 4;
  o.mlp_widths = {8, 8, 8};
  o.epochs_force = 1;
  o.epochs_location = 2;
  o.frames_per_epoch = 1024;
  o.folds = 3;
  o.label_sigma_mm = 4.0;
  o.threads = 1;
  std::vector<int> seen;
  const auto serial = Train(F().prepared, F().scene.Patch().spec, o, "x", [&](const std::string&, int done, int total, double) {
    EXPECT_EQ(total, 4 * 3);  // 4 fits x (1 + 2) epochs
    seen.push_back(done);
  });
  EXPECT_EQ(seen.size(), 12u);
  EXPECT_EQ(seen.back(), 12);
  o.threads = 3;
  const auto parallel = Train(F().prepared, F().scene.Patch().spec, o, "x");
  EXPECT_EQ(parallel.training().parallel_fits(), 3u);
  EXPECT_EQ(serial.training().parallel_fits(), 1u);
  EXPECT_EQ(serial.force().SerializeAsString(), parallel.force().SerializeAsString());
  for (int k = 0; k < 4; ++k) EXPECT_EQ(serial.location(k).SerializeAsString(), parallel.location(k).SerializeAsString());
  ASSERT_EQ(serial.training().folds_size(), parallel.training().folds_size());
  for (int k = 0; k < serial.training().folds_size(); ++k) {
    EXPECT_EQ(serial.training().folds(k).SerializeAsString(), parallel.training().folds(k).SerializeAsString());
  }
}

// --area whole (issue 16): trained on presses over the whole patch (the coverage protocol), the model records
// the whole-surface grids, the runtime decodes with them (libtorch's golden outputs, locations outside the
// indented area included) and the default stays the paper's grids.
TEST(TrainTest, WholeAreaModelRecordsTheWholeSurfaceGrids) {
  const twin::Scene& scene = F().scene;
  const twin::SkinTwin t(scene.Patch().spec, scene.effects, {scene.probe.radius_mm});
  dataset::Dataset d;
  d.info = twin::TwinDatasetInfo(t, scene, "coverage", 4, 100.0);
  twin::CoverageProtocol cp;
  cp.indentations = 40;
  twin::RunCoverage(t, scene, cp, 4, [&](std::span<const dataset::Frame> f) {
    for (const auto& x : f) d.Append(x);
  });
  const eval::Prepared prepared = eval::PrepareFrames(d);
  TrainOptions o;
  o.window = 4;
  o.mlp_widths = {16, 16, 16};
  o.epochs_force = o.epochs_location = 1;
  o.frames_per_epoch = 2048;
  o.label_sigma_mm = 3.0;
  o.folds = 0;
  o.threads = 1;
  o.golden_vectors = 8;
  o.area = "whole";
  const patch::PatchSpec& spec = scene.Patch().spec;
  const auto m = Train(prepared, spec, o, "in-memory");
  EXPECT_NO_THROW(decode::ValidateModel(m, "whole"));
  const auto want = decode::WholeSurfaceGrids(spec);
  ASSERT_EQ(m.location_size(), 4);
  for (int k = 0; k < 4; ++k) {
    const auto& g = m.location(k).grid();
    const auto& w = want[static_cast<std::size_t>(k)];
    EXPECT_EQ(g.name(), w.name);
    EXPECT_DOUBLE_EQ(g.y0_mm(), w.y0_mm);
    EXPECT_DOUBLE_EQ(g.r0_deg(), w.r0_deg);
    EXPECT_DOUBLE_EQ(g.cell_y_mm(), w.cell_y_mm);
    EXPECT_DOUBLE_EQ(g.cell_r_deg(), w.cell_r_deg);
    EXPECT_EQ(static_cast<int>(g.ny()), w.ny);
    EXPECT_EQ(static_cast<int>(g.nr()), w.nr);
  }
  decode::NetworkDecoder<float> df(m);
  decode::NetworkDecoder<float>::Data af(df);
  ASSERT_EQ(df.nip().inputs(), static_cast<std::size_t>(want[0].classes() + want[1].classes() + want[2].classes() + want[3].classes()));
  ASSERT_GE(m.golden_size(), 1);
  for (const auto& g : m.golden()) {
    std::vector<float> p;
    df.Probabilities(testing::LastFrame(g, m), af, p);
    ASSERT_EQ(static_cast<int>(p.size()), g.probabilities_size());
    for (std::size_t k = 0; k < p.size(); ++k) EXPECT_NEAR(p[k], g.probabilities(static_cast<int>(k)), 1e-5);
    double y = 0, r = 0;
    df.nip().Locate(p, y, r);
    EXPECT_NEAR(y, g.y_mm(), 1e-3);
    EXPECT_NEAR(r, g.r_deg(), 1e-3);
  }
  // The decoder's fused grid reaches beyond the indented area to the patch's edges.
  const patch::Region& a = spec.indented_area;
  std::vector<float> corner(df.nip().inputs(), 0.0f);
  std::size_t off = 0;
  for (const auto& w : want) {
    corner[off + static_cast<std::size_t>(w.ClassOf(1.0, 1.0))] = 1.0f;
    off += static_cast<std::size_t>(w.classes());
  }
  double y = 0, r = 0;
  df.nip().Locate(corner, y, r);
  EXPECT_LT(y, a.y_min_mm - 5.0);
  EXPECT_LT(r, a.r_min_deg - 10.0);
  // The default is the paper's grids.
  EXPECT_EQ(F().models[0].location(0).grid().ny() * F().models[0].location(0).grid().nr(), 30u);
}

TEST(TrainTest, RejectsBadOptions) {
  TrainOptions o;
  o.mlp_widths = {8, 8};
  EXPECT_THROW(Train(F().prepared, F().scene.Patch().spec, o, "x"), InputError);
  o.mlp_widths = {8, 8, 8};
  o.force_loss = "l2";
  EXPECT_THROW(Train(F().prepared, F().scene.Patch().spec, o, "x"), InputError);
  o.force_loss = "mse";
  o.location_input = "normalised";
  EXPECT_THROW(Train(F().prepared, F().scene.Patch().spec, o, "x"), InputError);
  o.location_input = "unit";
  o.unit_floor_pm = 0.0;
  EXPECT_THROW(Train(F().prepared, F().scene.Patch().spec, o, "x"), InputError);
  o.unit_floor_pm = 1.0;
  o.label_sigma_mm = -1.0;
  EXPECT_THROW(Train(F().prepared, F().scene.Patch().spec, o, "x"), InputError);
  o.label_sigma_mm = 0.0;
  o.lr_schedule = "step";
  EXPECT_THROW(Train(F().prepared, F().scene.Patch().spec, o, "x"), InputError);
  o.lr_schedule = "constant";
  o.area = "elbow";
  EXPECT_THROW(Train(F().prepared, F().scene.Patch().spec, o, "x"), InputError);
}

}  // namespace
}  // namespace ruffini::train
