// The aggregator's per-update costs: robot::ForwardKinematics on srs7, fusion::Fuser::Update for 1, 2 (a seam)
// and 8 contacts, and aggregate::Core::OnPatchMessage for one contact message (placement and policy).
// Run: build/release/bin/aggregate_bench (ruffini bench-aggregator runs it and pastes the table into
// docs/bench/aggregator.md).
#include <benchmark/benchmark.h>

#include "sealed.h"

#include <cmath>
#include <numbers>

#include "ruffini/aggregate/core.h"
#include "ruffini/fusion/fuser.h"
#include "ruffini/robot/kinematics.h"
#include "ruffini/robot/scene.h"
#include "ruffini/safety/scene.h"
#include "ruffini/scene_file.h"
#include "ruffini/twin/scene.h"

namespace {

using namespace ruffini;

const std::string kScene = std::string(RUFFINI_SOURCE_DIR) + "/config/scenes/cobot.yaml";
constexpr std::int64_t kT0 = 1'700'000'000'000'000'000;
constexpr std::int64_t kMs = 1'000'000;

const robot::RobotScene& Cobot() {
  static const robot::RobotScene s = robot::LoadRobotScene(LoadSceneFile(kScene));
  return s;
}

std::array<double, 7> Q(double phase) {
  std::array<double, 7> q{};
  for (std::size_t i = 0; i < q.size(); ++i) q[i] = 0.3 * std::sin(phase + static_cast<double>(i));
  return q;
}

void BM_ForwardKinematics_srs7(benchmark::State& state) {
  const robot::Model& model = Cobot().model;
  robot::Data data;
  double phase = 0.0;
  for (auto _ : state) {
    phase += 1e-3;
    const auto q = Q(phase);
    benchmark::DoNotOptimize(robot::ForwardKinematics(model, q, data));
    benchmark::DoNotOptimize(data.X_BL[model.num_links() - 1]);
  }
}
BENCHMARK(BM_ForwardKinematics_srs7);

// The cobot's 4 patches plus 4 more (the forearm design turned 90 deg and moved along each arm link): 8.
fusion::FusionConfig EightPatches() {
  fusion::FusionConfig c;
  for (const auto& p : Cobot().patches) {
    c.patches.push_back({p.name, p.mount, p.extent_y_mm, p.extent_r_deg});
  }
  for (std::size_t i = 0; i < 4; ++i) {
    fusion::FusionPatch p = c.patches[i];
    p.id += "_far";
    p.mount.X_LP = Eigen::Translation3d(0, 0, 0.12) * p.mount.X_LP * Eigen::AngleAxisd(std::numbers::pi / 2, Eigen::Vector3d::UnitY());
    c.patches.push_back(p);
  }
  return c;
}

fusion::SurfaceContact Located(double y_mm, double r_deg, double force_n, double var_mm2 = 4.0) {
  fusion::SurfaceContact s;
  s.force_n = force_n;
  s.force_sd_n = 0.03;
  s.located = true;
  s.y_mm = y_mm;
  s.r_deg = r_deg;
  s.cov_yy_mm2 = var_mm2;
  s.cov_ss_mm2 = var_mm2;
  s.uncertainty_calibrated = true;
  return s;
}

// state.range(0): 1 (one patch), 2 (the forearm seam: forearm_a at R 142 and forearm_b at R 3, 4 mm apart
// across the seam, 3 mm sd each: one press, fused into one contact), 8 (one contact on each of 8 patches, spread apart).
void BM_FuserUpdate(benchmark::State& state) {
  const fusion::Fuser fuser(Cobot().model, EightPatches());
  auto data = std::make_unique<fusion::FusionData>();
  robot::Data fk;
  (void)robot::ForwardKinematics(Cobot().model, Q(0.2), fk);
  std::vector<fusion::PatchInput> in;
  const int n = static_cast<int>(state.range(0));
  if (n == 1) in.push_back({0, Located(75, 70, 2.0)});
  if (n == 2) {
    in.push_back({0, Located(75, 142, 1.2, 9.0)});
    in.push_back({1, Located(75, 3, 1.3, 9.0)});
  }
  if (n == 8) {
    for (std::size_t i = 0; i < 8; ++i) in.push_back({i, Located(30.0 + 12.0 * static_cast<double>(i), 20.0 + 14.0 * static_cast<double>(i), 1.0)});
  }
  std::size_t out = 0;
  for (auto _ : state) {
    out = fuser.Update(in, std::span<const Eigen::Isometry3d>(fk.X_BL.data(), fk.X_BL.size()), *data);
    benchmark::DoNotOptimize(out);
  }
  state.counters["body_contacts"] = static_cast<double>(out);
  state.counters["merges"] = static_cast<double>(data->counters.merges) / static_cast<double>(state.iterations());
}
BENCHMARK(BM_FuserUpdate)->Arg(1)->Arg(2)->Arg(8);

// One contact message through the Core: seq check, the joint state interpolated at the frame's time (1 s of
// 100 Hz history; the contact is newer than all but the newest), placement (FK + lift), the safety policy.
void BM_CoreOnPatchMessage_Contact(benchmark::State& state) {
  const SceneFile file = LoadSceneFile(kScene);
  aggregate::Setup setup;
  setup.safety = safety::ConfigFromScene(file);
  setup.robot = Cobot().model;
  for (const auto& p : twin::LoadScene(kScene).patches) {
    aggregate::PatchExpectation e;
    e.id = p.name;
    e.spec_name = p.spec.name;
    e.spec_fingerprint = p.spec.Fingerprint();
    e.mount = Cobot().FindPatch(p.name)->mount;
    setup.patches.push_back(e);
  }
  aggregate::Core core(setup, kT0);
  for (int j = 0; j <= 100; ++j) {
    v1::JointState js;
    const auto q = Q(0.01 * j);
    for (std::size_t i = 0; i < 7; ++i) {
      js.add_names(setup.robot->dof_joint(i).name);
      js.add_positions_rad(q[i]);
    }
    js.set_t_ns(kT0 + j * 10 * kMs);
    (void)core.OnJointState(js, kT0 + j * 10 * kMs);
  }
  const int stream = core.OpenStream(kT0);
  v1::PatchMessage hello;
  hello.set_patch_id(setup.patches[0].id);
  hello.set_seq(1);
  hello.mutable_hello()->set_patch_name(setup.patches[0].spec_name);
  hello.mutable_hello()->set_patch_fingerprint(setup.patches[0].spec_fingerprint);
  hello.mutable_hello()->set_model_patch_fingerprint(setup.patches[0].spec_fingerprint);
  hello.mutable_hello()->set_heartbeat_period_ns(10 * kMs);
  ruffini::testing::SealAsDecoder(hello, core.run_id(), kT0 + 1000 * kMs);
  if (!core.OnPatchMessage(stream, hello, kT0 + 1000 * kMs).command->has_hello_accepted()) {
    state.SkipWithError("hello refused");
    return;
  }
  v1::PatchMessage m;
  m.set_patch_id(setup.patches[0].id);
  auto* c = m.mutable_contact();
  c->set_force_n(0.5f);
  c->set_force_sd_n(0.03f);
  c->set_located(true);
  c->set_y_mm(75.0f);
  c->set_r_deg(70.0f);
  c->set_cov_yy_mm2(4.0f);
  c->set_cov_rr_mm2(4.0f);
  c->set_uncertainty_calibrated(true);
  std::uint64_t seq = 1;
  std::int64_t k = 0;
  for (auto _ : state) {
    ++k;
    m.set_seq(++seq);
    m.set_t_ns(kT0 + 995 * kMs + (k % 5) * kMs);
    m.set_decoder_t_ns(m.t_ns());
    // Sealing is the decoder's cost, not the aggregator's: outside the timing.
    state.PauseTiming();
    ruffini::testing::SealAsDecoder(m, core.run_id(), kT0 + 1000 * kMs + k * 1000);
    state.ResumeTiming();
    const auto r = core.OnPatchMessage(stream, m, kT0 + 1000 * kMs + k * 1000);
    benchmark::DoNotOptimize(r.close);
  }
  state.counters["placed_share"] = static_cast<double>(core.counters().contacts_placed) /
                                   static_cast<double>(std::max<std::uint64_t>(1, core.counters().contacts));
}
BENCHMARK(BM_CoreOnPatchMessage_Contact);

}  // namespace

BENCHMARK_MAIN();
