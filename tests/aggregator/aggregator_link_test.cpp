// The decoder -> aggregator link over a bad network: real ruffini-sim, ruffini-decoder and ruffini-aggregator
// on 127.0.0.1 (port 0, ports files, stopped by pid), the decoder talking to the aggregator through a TCP
// proxy (tests/common/tcp_proxy.h) that can freeze the link without closing it.
//
// Finding 5 of the review: nothing had keepalive. A decoder whose host vanished without closing its socket
// held its patch for hours (the aggregator saw a silent but open stream, and refused the restarted decoder as
// a DUPLICATE_PATCH); a decoder behind a dead link never noticed it. Now the server and the decoder's channel
// ping every second and close a transport whose ping is not answered within a second
// (services/common/include/ruffini/service/keepalive.h).
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "process.h"
#include "ruffini/v1/aggregator.grpc.pb.h"
#include "service_process.h"
#include "tcp_proxy.h"

namespace {

using namespace std::chrono_literals;
namespace v1 = ruffini::v1;
namespace rt = ruffini::testing;
namespace fs = std::filesystem;

const std::string kSrc = RUFFINI_SOURCE_DIR;
const std::string kScene = kSrc + "/config/scenes/cobot.yaml";
const std::string kScenario = kSrc + "/config/scenarios/cobot-demo.yaml";
const std::string kPatch = "forearm_a";

double Since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

class LinkTest : public ::testing::Test {
 protected:
  void SetUp() override {
    base_ = (fs::current_path() / ("link_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name())))
                .string();
    agg_ = rt::StartWithPorts({RUFFINI_AGGREGATOR_EXE, "--insecure", "--scene", kScene, "--listen", "127.0.0.1:0",
                               "--metrics", "127.0.0.1:0"},
                              base_ + "/aggregator", "grpc", grpc_port_);
    sim_ = rt::StartWithPorts({RUFFINI_SIM_EXE, "--scene", kScene, "--scenario", kScenario, "--rate-hz", "1000",
                               "--command-port", "0", "--stream-port", "0"},
                              base_ + "/sim", "stream", sim_port_);
    stub_ = v1::Aggregator::NewStub(
        grpc::CreateChannel("127.0.0.1:" + std::to_string(grpc_port_), grpc::InsecureChannelCredentials()));
  }

  rt::Process StartDecoder(const std::string& aggregator, const std::string& name) {
    int metrics = 0;
    return rt::StartWithPorts({RUFFINI_DECODER_EXE, "--insecure", "--scene", kScene, "--patch", kPatch,
                               "--interrogator", "127.0.0.1:" + std::to_string(sim_port_), "--aggregator", aggregator,
                               "--metrics", "127.0.0.1:0", "--rate-hz", "1000", "--silence-ms", "100"},
                              base_ + "/" + name, "metrics", metrics);
  }

  // The patch's link state as GetStatus reports it (UNSPECIFIED when the call fails).
  v1::LinkState Link() {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 1s);
    v1::AggregatorStatus st;
    if (!stub_->GetStatus(&ctx, v1::GetStatusRequest{}, &st).ok()) return v1::LINK_STATE_UNSPECIFIED;
    for (const auto& p : st.patches()) {
      if (p.patch_id() == kPatch) return p.link_state();
    }
    return v1::LINK_STATE_UNSPECIFIED;
  }

  std::string base_;
  int grpc_port_ = 0, sim_port_ = 0;
  rt::Process agg_, sim_;
  std::unique_ptr<v1::Aggregator::Stub> stub_;
};

// The aggregator side: the link is frozen (nothing passes, nothing is closed) and the decoder behind it is
// killed, so its FIN never arrives. The aggregator's keepalive must drop the half-open stream within 3 s
// (nominally 1 s to the next ping + 1 s without its ack; the rest is margin for a loaded machine), after which
// a restarted decoder takes the patch (before, it was refused DUPLICATE_PATCH for hours).
TEST_F(LinkTest, TheAggregatorDropsAHalfOpenDecoderStreamWithinThreeSeconds) {
  rt::TcpProxy proxy(grpc_port_);
  ASSERT_GT(proxy.port(), 0);
  rt::Process decoder = StartDecoder(proxy.address(), "decoder");
  ASSERT_TRUE(rt::WaitFor([&] { return Link() == v1::LINK_STATE_HEALTHY; }, 20s, 20ms)) << decoder.stderr_text();
  proxy.Freeze();
  decoder.Signal(SIGKILL);
  const auto frozen = std::chrono::steady_clock::now();
  ASSERT_TRUE(rt::WaitFor([&] { return Link() == v1::LINK_STATE_DISCONNECTED; }, 10s, 20ms)) << agg_.stderr_text();
  const double dropped_s = Since(frozen);
  std::printf("[ metric ] frozen link + SIGKILLed decoder -> stream dropped by the aggregator: %.2f s\n", dropped_s);
  EXPECT_LT(dropped_s, 3.0);
  // The restarted decoder (straight to the aggregator) takes the patch.
  rt::Process restarted = StartDecoder("127.0.0.1:" + std::to_string(grpc_port_), "decoder_restarted");
  EXPECT_TRUE(rt::WaitFor([&] { return Link() == v1::LINK_STATE_HEALTHY; }, 20s, 20ms)) << restarted.stderr_text();
}

// The decoder side: behind a frozen link the decoder's own keepalive closes its dead transport and it
// reconnects (through the proxy: a new connection is forwarded); the patch is healthy again once the
// aggregator has dropped the old stream too.
TEST_F(LinkTest, ADecoderBehindAFrozenLinkReconnects) {
  rt::TcpProxy proxy(grpc_port_);
  ASSERT_GT(proxy.port(), 0);
  rt::Process decoder = StartDecoder(proxy.address(), "decoder");
  ASSERT_TRUE(rt::WaitFor([&] { return Link() == v1::LINK_STATE_HEALTHY; }, 20s, 20ms)) << decoder.stderr_text();
  ASSERT_EQ(proxy.accepted(), 1);
  proxy.Freeze();
  const auto frozen = std::chrono::steady_clock::now();
  ASSERT_TRUE(rt::WaitFor([&] { return proxy.accepted() >= 2; }, 10s, 20ms)) << decoder.stderr_text();
  const double reconnect_s = Since(frozen);
  ASSERT_TRUE(rt::WaitFor([&] { return Link() == v1::LINK_STATE_HEALTHY; }, 10s, 20ms)) << decoder.stderr_text();
  const double healthy_s = Since(frozen);
  std::printf("[ metric ] frozen link -> decoder reconnected after %.2f s, patch healthy again after %.2f s\n",
              reconnect_s, healthy_s);
  EXPECT_LT(reconnect_s, 4.0);  // nominally 2 s (ping period + timeout), plus the 100 ms reconnect backoff
  EXPECT_TRUE(decoder.Running());
}

}  // namespace
