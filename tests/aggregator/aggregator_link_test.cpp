// The decoder -> aggregator link over a bad network: real ruffini-sim, ruffini-decoder and ruffini-aggregator
// on 127.0.0.1 (port 0, ports files, stopped by pid), the decoder talking to the aggregator through a TCP
// proxy (ruffini/service/tcp_proxy.h) that can freeze the link without closing it.
//
// Finding 5 of the review: nothing had keepalive. A decoder whose host vanished without closing its socket
// held its patch for hours (the aggregator saw a silent but open stream, and refused the restarted decoder as
// a DUPLICATE_PATCH); a decoder behind a dead link never noticed it. Now the server and the decoder's channel
// ping every second and close a transport whose ping is not answered within a second
// (services/common/include/ruffini/service/keepalive.h).
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <mutex>
#include <thread>
#include <string>
#include <vector>

#include "process.h"
#include "ruffini/v1/aggregator.grpc.pb.h"
#include "service_process.h"
#include "ruffini/service/tcp_proxy.h"

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
  ruffini::service::TcpProxy proxy(grpc_port_);
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
  ruffini::service::TcpProxy proxy(grpc_port_);
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

// A WatchContacts subscriber in a thread of its own: every ContactSet it receives. It subscribes again when
// its stream ends (on a loaded machine the aggregator drops a subscriber whose write is stuck for 50 ms).
class ContactWatcher {
 public:
  ContactWatcher(v1::Aggregator::Stub& stub, v1::WatchContactsRequest request)
      : thread_([this, &stub, request] {
          while (!stop_) {
            grpc::ClientContext ctx;
            {
              std::lock_guard lock(mu_);
              if (stop_) break;
              ctx_ = &ctx;
            }
            auto reader = stub.WatchContacts(&ctx, request);
            v1::ContactSet c;
            while (reader->Read(&c)) {
              std::lock_guard lock(mu_);
              sets_.push_back(c);
            }
            reader->Finish();
            std::lock_guard lock(mu_);
            ctx_ = nullptr;
          }
        }) {}
  ~ContactWatcher() {
    {
      std::lock_guard lock(mu_);
      stop_ = true;
      if (ctx_) ctx_->TryCancel();
    }
    thread_.join();
  }
  std::vector<v1::ContactSet> Sets() {
    std::lock_guard lock(mu_);
    return sets_;
  }
  std::vector<v1::BodyContact> Contacts() {
    std::vector<v1::BodyContact> out;
    for (const auto& s : Sets()) out.insert(out.end(), s.contacts().begin(), s.contacts().end());
    return out;
  }

 private:
  std::mutex mu_;
  bool stop_ = false;
  grpc::ClientContext* ctx_ = nullptr;
  std::vector<v1::ContactSet> sets_;
  std::thread thread_;
};

// Finding 11 of the review (server side): WatchContacts ignored its request (asked for links
// ['no_such_link'] and min_force_n 100, a subscriber got a 2 N forearm contact). Real decoders on forearm_a and
// forearm_b, the scenario's touches (0.7 N on forearm_a at 4 s, 3.5 N across the seam at 7 s): subscribers
// with filters get only what they asked for; an unfiltered one sees both touches (so the filters had
// something to remove). ContactSet.t_ns is the newest contact's frame time, 0 when the set is empty.
TEST_F(LinkTest, WatchContactsHonoursItsFilters) {
  const std::string address = "127.0.0.1:" + std::to_string(grpc_port_);
  rt::Process a = StartDecoder(address, "decoder_a");
  int metrics = 0;
  rt::Process b = rt::StartWithPorts({RUFFINI_DECODER_EXE, "--insecure", "--scene", kScene, "--patch", "forearm_b",
                                      "--interrogator", "127.0.0.1:" + std::to_string(sim_port_), "--aggregator",
                                      address, "--metrics", "127.0.0.1:0", "--rate-hz", "1000", "--silence-ms", "100"},
                                     base_ + "/decoder_b", "metrics", metrics);
  // Joint states at 100 Hz, so contacts are placed on their links (an unplaced contact names no link).
  std::atomic<bool> stop_joints{false};
  std::thread joints([&] {
    grpc::ClientContext names_ctx;
    names_ctx.set_deadline(std::chrono::system_clock::now() + 5s);
    v1::AggregatorStatus st;
    if (!stub_->GetStatus(&names_ctx, v1::GetStatusRequest{}, &st).ok()) return;
    grpc::ClientContext ctx;
    v1::PublishJointStatesResponse resp;
    auto w = stub_->PublishJointStates(&ctx, &resp);
    for (std::uint64_t seq = 1; !stop_joints; ++seq) {
      v1::JointState js;
      for (const auto& n : st.joint_names()) {
        js.add_names(n);
        js.add_positions_rad(0.1);
      }
      js.set_t_ns(std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count());
      js.set_seq(seq);
      if (!w->Write(js)) break;
      std::this_thread::sleep_for(10ms);  // a 100 Hz controller's period, not a wait
    }
    w->WritesDone();
    w->Finish();
  });
  struct Join {
    std::atomic<bool>& stop;
    std::thread& t;
    ~Join() {
      stop = true;
      t.join();
    }
  } join_joints{stop_joints, joints};
  v1::WatchContactsRequest all, other_link, huge_force, forearm_hard;
  other_link.add_links("no_such_link");
  huge_force.set_min_force_n(100.0F);
  forearm_hard.add_links("forearm_link");
  forearm_hard.set_min_force_n(1.0F);
  ContactWatcher w_all(*stub_, all), w_other(*stub_, other_link), w_huge(*stub_, huge_force),
      w_hard(*stub_, forearm_hard);
  // Both touches seen by the unfiltered subscriber (one below 1 N, one above), and the hard one by the
  // subscriber that asked for forearm contacts of 1 N or more.
  auto seen = [&](auto pred) {
    const auto c = w_all.Contacts();
    return std::any_of(c.begin(), c.end(), pred);
  };
  ASSERT_TRUE(rt::WaitFor([&] {
    return seen([](const v1::BodyContact& c) { return c.force_n() > 0.2F && c.force_n() < 1.0F; }) &&
           seen([](const v1::BodyContact& c) { return c.force_n() >= 1.5F; }) && !w_hard.Contacts().empty();
  }, 30s, 50ms)) << w_all.Sets().size() << " sets, " << w_all.Contacts().size() << " contacts; of 1 N or more: " << [&] {
    std::string out;
    for (const auto& c : w_all.Contacts()) {
      if (c.force_n() >= 1.0F) out += "'" + c.link() + "' " + std::to_string(c.force_n()) + " N; ";
    }
    return out.substr(0, 2000);
  }() << "\n" << agg_.stderr_text();
  std::this_thread::sleep_for(50ms);  // one more publication period for the filtered subscribers' slots
  EXPECT_GT(w_other.Sets().size(), 10u);  // heartbeats keep coming, empty
  EXPECT_TRUE(w_other.Contacts().empty()) << w_other.Contacts().front().DebugString();
  EXPECT_GT(w_huge.Sets().size(), 10u);
  EXPECT_TRUE(w_huge.Contacts().empty()) << w_huge.Contacts().front().DebugString();
  const auto hard = w_hard.Contacts();
  for (const auto& c : hard) {
    EXPECT_EQ(c.link(), "forearm_link");
    EXPECT_GE(c.force_n(), 1.0F);
  }
  for (auto* w : {&w_all, &w_other, &w_hard}) {
    for (const auto& set : w->Sets()) {
      std::int64_t newest = 0;
      for (const auto& c : set.contacts()) newest = std::max(newest, c.t_ns());
      EXPECT_EQ(set.t_ns(), newest) << set.DebugString();
    }
  }
}

}  // namespace
