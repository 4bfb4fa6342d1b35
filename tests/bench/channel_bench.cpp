// The safety layer's cost per message (docs/safety-channel.md): sealing a message at the sender, and a
// receiver's whole check (CRC, identity, sequence, freshness). Run: build/release/bin/channel_bench.
#include <benchmark/benchmark.h>

#include "ruffini/channel/checkers.h"
#include "ruffini/channel/crc.h"

namespace {

namespace v1 = ruffini::v1;
namespace channel = ruffini::channel;

v1::PatchMessage Contact() {
  v1::PatchMessage m;
  m.set_patch_id("forearm_a");
  m.set_seq(2);
  m.set_interrogator_serial(1234);
  m.set_t_ns(1700000000000000000);
  m.set_decoder_t_ns(1700000000000100000);
  m.set_sender_run_id(0x0123456789abcdefULL);
  m.set_aggregator_run_id(0xfedcba9876543210ULL);
  v1::PatchContact& c = *m.mutable_contact();
  c.set_force_n(2.5f);
  c.set_located(true);
  c.set_y_mm(75.5f);
  c.set_r_deg(42.25f);
  c.set_cov_yy_mm2(4.0f);
  c.set_cov_rr_mm2(9.0f);
  return m;
}

void BM_SealContact(benchmark::State& state) {
  v1::PatchMessage m = Contact();
  std::int64_t t = 0;
  for (auto _ : state) {
    m.set_sender_steady_ns(++t);
    channel::Seal(m);
    benchmark::DoNotOptimize(m.safety_crc32());
  }
}
BENCHMARK(BM_SealContact);

void BM_ReceiveContact(benchmark::State& state) {
  channel::PatchLinkCheck check(channel::LinkConfig{}, 0xfedcba9876543210ULL, "forearm_a");
  v1::PatchMessage m = Contact();
  std::uint64_t seq = 1;
  std::int64_t t = 0;
  for (auto _ : state) {
    state.PauseTiming();
    m.set_seq(++seq);
    t += 1'000'000;
    m.set_sender_steady_ns(t);
    channel::Seal(m);
    state.ResumeTiming();
    const channel::Verdict v = check.Receive(m, t + 50'000);
    benchmark::DoNotOptimize(v.use);
  }
}
BENCHMARK(BM_ReceiveContact);

void BM_SealState(benchmark::State& state) {
  v1::SafetyState s;
  s.set_state(v1::SafetyState::STATE_CLEAR);
  s.set_stop_epoch(3);
  s.set_aggregator_run_id(1);
  s.set_robot_name("cobot");
  std::uint64_t seq = 0;
  for (auto _ : state) {
    s.set_seq(++seq);
    channel::Seal(s);
    benchmark::DoNotOptimize(s.safety_crc32());
  }
}
BENCHMARK(BM_SealState);

}  // namespace

BENCHMARK_MAIN();
