// The decode thread's per-frame work allocates nothing: link::Monitor over the shipped model's pipeline
// (float and double), frames with contacts, rejections, heartbeats and faults included.
#include "../common/alloc_counter.h"

#include <gtest/gtest.h>

#include <cmath>

#include "ruffini/decode/model_io.h"
#include "ruffini/link/monitor.h"
#include "ruffini/twin/scene.h"

namespace {

using namespace ruffini;

struct CountingSink final : link::MessageSink {
  std::size_t n = 0;
  void Push(const link::Message&) noexcept override { ++n; }
};

void RunMonitor(const char* choice_name) {
  const auto model = decode::LoadModel(std::string(RUFFINI_SOURCE_DIR) + "/config/models/forearm.rmodel");
  const auto scene = twin::LoadScene(std::string(RUFFINI_SOURCE_DIR) + "/config/scenes/forearm.yaml");
  const auto& spec = scene.Patch().spec;
  decode::PipelineConfig pc;
  pc.baseline = decode::BaselineFor(model, 1000.0);
  auto pipe = link::MakePipeline(model, spec, pc, link::ParseDecoderChoice(choice_name, model));
  link::MonitorConfig mc;
  mc.sample_rate_hz = 1000.0;
  link::Monitor monitor(*pipe, mc, {0, 0});
  CountingSink sink;
  monitor.OnConnected({0, 0}, sink);
  Wavelengths rest{};
  for (std::size_t i = 0; i < kGratings; ++i) rest[i] = spec.gratings[i].wavelength_nm;
  std::int64_t t = 0;
  std::uint64_t serial = 0;
  auto frame = [&](const Wavelengths& w) {
    link::FrameIn f;
    f.serial = ++serial;
    f.t_ns = t;
    f.wavelength_nm = w;
    monitor.OnFrame(f, {t, t}, sink);
    t += 1'000'000;
  };
  for (int i = 0; i < 1500; ++i) frame(rest);  // baseline capture
  ASSERT_TRUE(monitor.health().healthy);
  const long allocations = ruffini::testing::CountAllocations([&] {
    for (int k = 0; k < 3000; ++k) {
      Wavelengths w = rest;
      // A press on gratings 5..7 for frames 500..1500, a NaN frame now and then, a silence, a stream rejection.
      if (k >= 500 && k < 1500) {
        for (std::size_t g = 5; g < 8; ++g) w[g] += 0.05;
      }
      if (k % 97 == 0) w[3] = std::nan("");
      if (k == 2000) t += 50'000'000;
      frame(w);
      if (k % 500 == 0) monitor.OnStreamRejected(ingest::Reason::kNonFinite, {t, t}, sink);
      monitor.Tick({t, t}, sink);
    }
  });
  EXPECT_EQ(allocations, 0);
  EXPECT_GT(sink.n, 300u);
  EXPECT_GT(monitor.health().onsets, 0u);
}

TEST(LinkRealTime, MonitorStepDoesNotAllocateFloat) { RunMonitor("paper-float"); }
TEST(LinkRealTime, MonitorStepDoesNotAllocateDouble) { RunMonitor("paper-double"); }

}  // namespace
