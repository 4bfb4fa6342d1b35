// Mutual TLS and roles (docs/security.md), as real processes on 127.0.0.1 (port 0, ports files): certificates
// made at test time by deploy/tls/make-dev-ca.sh into the build folder; ruffini-sim (no presses), one
// ruffini-decoder per patch and ruffini-controller over mutual TLS; this test is the operator. Once an
// operator's reset has cleared the aggregator, every refusal (no certificate, another CA, an expired
// certificate, a decoder publishing as another patch, a controller calling ResetStop, a role calling an RPC it
// may not) is refused with a clear status, counted, and leaves the safety state as it was.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "process.h"
#include "service_process.h"
#include "seal.h"
#include "ruffini/v1/aggregator.grpc.pb.h"
#include "scrape.h"

namespace {

using namespace std::chrono_literals;
namespace v1 = ruffini::v1;
namespace rt = ruffini::testing;
namespace fs = std::filesystem;

const std::string kSrc = RUFFINI_SOURCE_DIR;
const std::string kScene = kSrc + "/config/scenes/cobot.yaml";
const std::vector<std::string> kPatches = {"forearm_a", "forearm_b", "upper_arm_a", "upper_arm_b"};

std::string Slurp(const std::string& path) {
  std::ifstream in(path);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// The certificates: `good` (the deployment's CA, with an expired controller) and `rogue` (another CA with
// the same names). Made once per test program.
struct Certs {
  std::string good, rogue;
  bool made = false;
  std::string why_not;
};
const Certs& MakeCerts() {
  static const Certs certs = [] {
    Certs c;
    if (std::system("command -v openssl >/dev/null 2>&1") != 0) {
      c.why_not = "openssl not installed";
      return c;
    }
    const std::string base = (fs::current_path() / "tls_certs").string();
    fs::remove_all(base);
    c.good = base + "/good";
    c.rogue = base + "/rogue";
    const std::string script = kSrc + "/deploy/tls/make-dev-ca.sh";
    const std::string cmd = script + " " + c.good + " --scene " + kScene + " --expired >/dev/null && " + script + " " +
                            c.rogue + " --scene " + kScene + " >/dev/null";
    if (std::system(cmd.c_str()) != 0) {
      c.why_not = "make-dev-ca.sh failed: " + cmd;
      return c;
    }
    c.made = true;
    return c;
  }();
  return certs;
}

// A client channel presenting dir/name.crt (no name: no client certificate), trusting ca_dir/ca.crt.
std::unique_ptr<v1::Aggregator::Stub> Client(const std::string& address, const std::string& ca_dir,
                                             const std::string& dir, const std::string& name) {
  grpc::SslCredentialsOptions o;
  o.pem_root_certs = Slurp(ca_dir + "/ca.crt");
  if (!name.empty()) {
    o.pem_cert_chain = Slurp(dir + "/" + name + ".crt");
    o.pem_private_key = Slurp(dir + "/" + name + ".key");
  }
  return v1::Aggregator::NewStub(grpc::CreateChannel(address, grpc::SslCredentials(o)));
}

grpc::Status Status(v1::Aggregator::Stub& stub, v1::AggregatorStatus* out) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + 3s);
  return stub.GetStatus(&ctx, v1::GetStatusRequest{}, out);
}

v1::ResetStopResponse Reset(v1::Aggregator::Stub& stub, std::uint64_t epoch, grpc::Status* status) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + 3s);
  v1::ResetStopRequest r;
  r.set_stop_epoch(epoch);
  v1::AggregatorStatus st;
  if (Status(stub, &st).ok()) r.set_aggregator_run_id(st.aggregator_run_id());  // the run whose epoch this is
  r.set_operator_name("tls_process_test");
  v1::ResetStopResponse resp;
  *status = stub.ResetStop(&ctx, r, &resp);
  return resp;
}

// ruffini_aggregator_auth_refusals_total{reason="R"} from a scrape (-1 when absent).
double Refusals(const std::string& metrics, const std::string& reason) {
  std::smatch m;
  const std::regex re("ruffini_aggregator_auth_refusals_total\\{reason=\"" + reason + "\"\\} ([0-9.e+]+)");
  return std::regex_search(metrics, m, re) ? std::stod(m[1]) : -1;
}

class TlsProcess : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!MakeCerts().made) GTEST_SKIP() << MakeCerts().why_not;
  }
};

TEST_F(TlsProcess, OperatorResetsOverMutualTlsAndEveryRefusalIsCountedAndChangesNothing) {
  const Certs& certs = MakeCerts();
  const std::string base = (fs::current_path() / "tls_chain").string();
  int grpc_port = 0, metrics_port = 0, sim_port = 0;
  rt::Process agg = rt::StartWithPorts({RUFFINI_AGGREGATOR_EXE, "--tls-dir", certs.good, "--scene", kScene, "--listen",
                                    "127.0.0.1:0", "--metrics", "127.0.0.1:0", "--patch-silence-ms", "200",
                                    "--joint-max-age-ms", "200"},
                                   base + "/aggregator", "grpc", grpc_port);
  metrics_port = rt::ReadPorts(base + "/aggregator/ports")["metrics"];
  const std::string address = "127.0.0.1:" + std::to_string(grpc_port);
  auto op = Client(address, certs.good, certs.good, "operator");
  {
    v1::AggregatorStatus s;
    const grpc::Status st = Status(*op, &s);
    ASSERT_TRUE(st.ok()) << st.error_message() << "\n" << agg.stderr_text();
    EXPECT_EQ(s.safety().state(), v1::SafetyState::STATE_FAULT);
  }

  // The happy path: the sim, four decoders and ruffini-controller, all over mutual TLS.
  fs::create_directories(base);
  const std::string quiet = base + "/quiet.yaml";  // nothing touches the skin
  std::ofstream(quiet) << "loop: true\nduration_s: 60.0\nseed: 7\npresses: []\n";
  rt::Process sim = rt::StartWithPorts({RUFFINI_SIM_EXE, "--scene", kScene, "--scenario", quiet, "--rate-hz", "1000",
                                    "--command-port", "0", "--stream-port", "0"},
                                   base + "/sim", "stream", sim_port);
  std::vector<rt::Process> decoders;
  for (const auto& p : kPatches) {
    int metrics = 0;
    decoders.push_back(rt::StartWithPorts({RUFFINI_DECODER_EXE, "--tls-dir", certs.good, "--scene", kScene, "--patch", p,
                                       "--interrogator", "127.0.0.1:" + std::to_string(sim_port), "--aggregator",
                                       address, "--metrics", "127.0.0.1:0", "--rate-hz", "1000", "--silence-ms", "100"},
                                      base + "/decoder_" + p, "metrics", metrics));
  }
  fs::create_directories(base + "/controller");
  rt::Process ctl({RUFFINI_CONTROLLER_EXE, "--tls-dir", certs.good, "--robot", "cobot", "--aggregator", address, "--rate-hz", "200"},
                  base + "/controller");
  v1::ResetStopResponse cleared;
  ASSERT_TRUE(rt::WaitFor([&] {
    v1::AggregatorStatus s;
    if (!Status(*op, &s).ok()) return false;
    grpc::Status st;
    cleared = Reset(*op, s.safety().stop_epoch(), &st);
    return st.ok() && cleared.accepted();
  }, 20s, 100ms)) << agg.stderr_text() << ctl.stderr_text() << decoders[0].stderr_text();
  ASSERT_EQ(cleared.state().state(), v1::SafetyState::STATE_CLEAR);
  const std::uint64_t epoch = cleared.state().stop_epoch();
  {
    v1::AggregatorStatus s;
    ASSERT_TRUE(Status(*op, &s).ok());
    for (const auto& p : s.patches()) EXPECT_EQ(p.link_state(), v1::LINK_STATE_HEALTHY) << p.patch_id();
    EXPECT_GE(s.joint_state_age_ns(), 0);  // ruffini-controller's joint states arrive
  }
  const std::string before = rt::Scrape(metrics_port);
  std::printf("[ metric ] CLEAR over mutual TLS at epoch %llu; refusals before: no_certificate %g bad_certificate %g\n",
              static_cast<unsigned long long>(epoch), Refusals(before, "no_certificate"),
              Refusals(before, "bad_certificate"));

  // 1. No client certificate, 2. a certificate from another CA, 3. an expired certificate: the handshake is
  // refused (the RPC fails UNAVAILABLE before any handler runs).
  {
    v1::AggregatorStatus s;
    const grpc::Status none = Status(*Client(address, certs.good, "", ""), &s);
    EXPECT_EQ(none.error_code(), grpc::StatusCode::UNAVAILABLE) << none.error_message();
    const grpc::Status rogue = Status(*Client(address, certs.good, certs.rogue, "controller"), &s);
    EXPECT_EQ(rogue.error_code(), grpc::StatusCode::UNAVAILABLE) << rogue.error_message();
    const grpc::Status expired = Status(*Client(address, certs.good, certs.good, "expired-controller"), &s);
    EXPECT_EQ(expired.error_code(), grpc::StatusCode::UNAVAILABLE) << expired.error_message();
    std::printf("[ metric ] no certificate: %s | other CA: %s | expired: %s\n", none.error_message().c_str(),
                rogue.error_message().c_str(), expired.error_message().c_str());
  }
  // 4. A decoder publishing as another patch (forearm_a's certificate, a hello for forearm_b, which is live).
  {
    auto dec = Client(address, certs.good, certs.good, "decoder-forearm_a");
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 3s);
    auto stream = dec->Connect(&ctx);
    v1::PatchMessage hello;
    hello.set_patch_id("forearm_b");
    hello.set_seq(1);
    hello.mutable_hello()->set_decoder_instance("impostor");
    ruffini::testing::SealAsDecoder(hello, 0, 1);  // a well-formed message: refused for who sends it, not how
    ASSERT_TRUE(stream->Write(hello));
    v1::AggregatorCommand cmd;
    ASSERT_TRUE(stream->Read(&cmd));
    ASSERT_TRUE(cmd.has_hello_refused()) << cmd.DebugString();
    EXPECT_EQ(cmd.hello_refused().reason(), v1::HELLO_REFUSAL_UNAUTHORIZED);
    std::printf("[ metric ] hello for another patch: %s\n", cmd.hello_refused().message().c_str());
    stream->WritesDone();
    const grpc::Status st = stream->Finish();
    EXPECT_EQ(st.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  }
  // 5. A controller calling ResetStop (the current epoch, and while CLEAR: refused for who it is, first).
  auto controller = Client(address, certs.good, certs.good, "controller");
  {
    grpc::Status st;
    const auto r = Reset(*controller, epoch, &st);
    ASSERT_TRUE(st.ok()) << st.error_message();
    EXPECT_FALSE(r.accepted());
    EXPECT_EQ(r.reason(), v1::RESET_REFUSAL_UNAUTHORIZED) << r.message();
    EXPECT_EQ(r.state().state(), v1::SafetyState::STATE_CLEAR);
  }
  // 6. Roles: a decoder may not read the status, a controller may not Connect.
  {
    v1::AggregatorStatus s;
    const grpc::Status st = Status(*Client(address, certs.good, certs.good, "decoder-upper_arm_a"), &s);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::PERMISSION_DENIED) << st.error_message();
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 3s);
    auto stream = controller->Connect(&ctx);
    v1::AggregatorCommand cmd;
    EXPECT_FALSE(stream->Read(&cmd));
    EXPECT_EQ(stream->Finish().error_code(), grpc::StatusCode::PERMISSION_DENIED);
  }

  // Counted; and the safety state is what it was: CLEAR, same epoch, every patch healthy.
  ASSERT_TRUE(rt::WaitFor([&] {
    const std::string m = rt::Scrape(metrics_port);
    return Refusals(m, "hello_other_patch") >= 1;  // copied from the core every 5 ms
  }, 2s));
  const std::string after = rt::Scrape(metrics_port);
  EXPECT_GE(Refusals(after, "no_certificate") - Refusals(before, "no_certificate"), 1) << after;
  EXPECT_GE(Refusals(after, "bad_certificate") - Refusals(before, "bad_certificate"), 2) << after;
  EXPECT_EQ(Refusals(after, "hello_other_patch"), 1);
  EXPECT_EQ(Refusals(after, "reset_not_operator"), 1);
  EXPECT_EQ(Refusals(after, "wrong_role"), 2);
  v1::AggregatorStatus s;
  ASSERT_TRUE(Status(*op, &s).ok());
  EXPECT_EQ(s.safety().state(), v1::SafetyState::STATE_CLEAR) << s.safety().DebugString();
  EXPECT_EQ(s.safety().stop_epoch(), epoch);
  for (const auto& p : s.patches()) EXPECT_EQ(p.link_state(), v1::LINK_STATE_HEALTHY) << p.patch_id();
  EXPECT_NE(agg.stderr_text().find("mutual TLS"), std::string::npos);
  EXPECT_EQ(ctl.Stop(), 0) << ctl.stderr_text();
}

// Neither --tls-dir nor --insecure: the service will not start, and says which flags it needs.
TEST_F(TlsProcess, AServiceWithoutTlsDirOrInsecureRefusesToStart) {
  const std::string dir = (fs::current_path() / "tls_noflag").string();
  fs::remove_all(dir);
  fs::create_directories(dir);
  rt::Process agg({RUFFINI_AGGREGATOR_EXE, "--scene", kScene, "--listen", "127.0.0.1:0", "--metrics", "127.0.0.1:0"},
                  dir);
  EXPECT_EQ(agg.WaitExit(10s), 1);
  EXPECT_NE(agg.stderr_text().find("--tls-dir DIR (mutual TLS) and --insecure"), std::string::npos) << agg.stderr_text();
}

// The other way round: a client refuses an aggregator whose certificate comes from another CA;
// ruffini-controller says it could not reach the aggregator and exits 1.
TEST_F(TlsProcess, AClientRefusesAnAggregatorFromAnotherCa) {
  const Certs& certs = MakeCerts();
  const std::string base = (fs::current_path() / "tls_rogue_server").string();
  int port = 0;
  rt::Process agg = rt::StartWithPorts({RUFFINI_AGGREGATOR_EXE, "--tls-dir", certs.rogue, "--scene", kScene, "--listen",
                                    "127.0.0.1:0", "--metrics", "127.0.0.1:0"},
                                   base + "/aggregator", "grpc", port);
  const std::string address = "127.0.0.1:" + std::to_string(port);
  fs::create_directories(base + "/controller");
  rt::Process ctl({RUFFINI_CONTROLLER_EXE, "--tls-dir", certs.good, "--robot", "cobot", "--aggregator", address, "--connect-timeout-s", "1"},
                  base + "/controller");
  EXPECT_EQ(ctl.WaitExit(10s), 1);
  EXPECT_NE(ctl.stderr_text().find("no aggregator answered GetStatus"), std::string::npos) << ctl.stderr_text();
  // The rogue aggregator's own clients (its CA) do get in.
  v1::AggregatorStatus s;
  EXPECT_TRUE(Status(*Client(address, certs.rogue, certs.rogue, "operator"), &s).ok());
  EXPECT_EQ(agg.Stop(), 0);
}

// --insecure: plaintext, said loudly.
TEST_F(TlsProcess, InsecureIsLoggedAsAWarning) {
  const std::string dir = (fs::current_path() / "tls_insecure").string();
  int port = 0;
  rt::Process agg = rt::StartWithPorts({RUFFINI_AGGREGATOR_EXE, "--insecure", "--scene", kScene, "--listen", "127.0.0.1:0",
                                    "--metrics", "127.0.0.1:0"},
                                   dir, "grpc", port);
  EXPECT_NE(agg.stderr_text().find("PLAINTEXT"), std::string::npos) << agg.stderr_text();
  EXPECT_EQ(agg.Stop(), 0);
}

}  // namespace
