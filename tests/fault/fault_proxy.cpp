// ruffini-fault-proxy: a message-level man in the middle for the safety layer's error table
// (docs/safety-channel.md). It serves the Aggregator contract on 127.0.0.1, forwards every call to the real
// aggregator, and alters the messages of one link in one of the eight ways IEC 61784-3 lists:
//
//   --link patch   Connect: decoder -> aggregator PatchMessages (commands go back untouched)
//   --link state   WatchSafety: aggregator -> controller SafetyStates
//
//   --error corruption          message N has a field flipped after its CRC was computed (not resealed)
//   --error repetition          message N is sent twice
//   --error incorrect_sequence  messages N and N+1 are swapped
//   --error loss                message N is dropped
//   --error delay               from message N on, every message is held --delay-ms before it is forwarded
//   --error insertion           after message N, a copy from another sender run (resealed) is inserted
//   --error masquerade          after message N, a copy claiming another sender identity (resealed): another
//                               patch id on the patch link, another aggregator run on the state link
//   --error addressing          after message N, a copy addressed elsewhere (resealed): another aggregator
//                               run on the patch link, another robot on the state link
//   --error none                forward only
//
// N counts the link's messages of each stream from 1 (the hello is 1 on the patch link) and is --at; with
// --every K the alteration repeats every K messages after N (for the error-rate rule), --times M times in all
// (0: without end). Only the first stream
// of the link (--streams 0: every stream) is altered. Other calls (GetStatus, ResetStop, PublishJointStates,
// WatchContacts) are forwarded unchanged. The chosen port goes to --ports-file ("grpc P"); each alteration
// made is printed on stdout ("altered <error> at <n> t_ns <Unix ns>"), so a test can wait for it.
//
// A test tool (tests/fault), never deployed. Synchronous gRPC: a thread per call is fine at test scale.
#include <grpcpp/grpcpp.h>
#include <signal.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <mutex>
#include <string>
#include <thread>

#include <CLI/CLI.hpp>

#include "ruffini/channel/crc.h"
#include "ruffini/v1/aggregator.grpc.pb.h"

namespace v1 = ruffini::v1;
using namespace std::chrono_literals;

namespace {

struct Options {
  std::string upstream;
  std::string link = "patch";
  std::string error = "none";
  int at = 20;
  int every = 0;
  int times = 0;  // with every: alter this many messages in all (0: no limit)
  int delay_ms = 100;
  int streams = 1;
};

bool Hits(const Options& o, int n) {
  if (n == o.at) return true;
  return o.every > 0 && n > o.at && (n - o.at) % o.every == 0 && (o.times == 0 || (n - o.at) / o.every < o.times);
}

void Say(const std::string& what, int n) {
  const auto unix_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                           std::chrono::system_clock::now().time_since_epoch())
                           .count();
  std::printf("altered %s at %d t_ns %lld\n", what.c_str(), n, static_cast<long long>(unix_ns));
  std::fflush(stdout);
}

// Corrupts a message's safety field without resealing.
void Corrupt(v1::PatchMessage& m) {
  if (m.has_contact()) {
    m.mutable_contact()->set_force_n(m.contact().force_n() * 0.5f);
  } else if (m.has_heartbeat()) {
    m.mutable_heartbeat()->set_frames(m.heartbeat().frames() ^ 0x10);
  } else {
    m.set_t_ns(m.t_ns() ^ 0x10);
  }
}
void Corrupt(v1::SafetyState& s) {
  s.set_state(s.state() == v1::SafetyState::STATE_CLEAR ? v1::SafetyState::STATE_STOP : v1::SafetyState::STATE_CLEAR);
}

// Builds the forged copy for insertion, masquerade and addressing; false when the error is not of that kind.
bool Forge(const std::string& error, v1::PatchMessage& m) {
  if (error == "insertion") {
    m.set_sender_run_id(m.sender_run_id() ^ 0x5A5A5A5A5A5A5A5AULL);
  } else if (error == "masquerade") {
    m.set_patch_id(m.patch_id() + "_forged");
  } else if (error == "addressing") {
    m.set_aggregator_run_id(m.aggregator_run_id() ^ 0x00FF00FF00FF00FFULL);
  } else {
    return false;
  }
  m.set_seq(m.seq() + 1);  // what the next genuine message will carry: the forgery takes its place first
  ruffini::channel::Seal(m);
  return true;
}
bool Forge(const std::string& error, v1::SafetyState& s) {
  if (error == "insertion" || error == "masquerade") {
    s.set_aggregator_run_id(s.aggregator_run_id() ^ 0x5A5A5A5A5A5A5A5AULL);
  } else if (error == "addressing") {
    s.set_robot_name(s.robot_name() + "-other-cell");
  } else {
    return false;
  }
  s.set_seq(s.seq() + 1);
  ruffini::channel::Seal(s);
  return true;
}

// Applies the error to one message stream. `send` forwards one message and returns false when the far side
// is gone.
template <typename Msg, typename Send>
class Alterer {
 public:
  Alterer(const Options& o, bool active, Send send) : o_(o), active_(active), send_(std::move(send)) {}

  bool Offer(const Msg& in) {
    ++n_;
    if (!active_) return send_(in);
    const std::string& e = o_.error;
    if (have_swap_) {  // incorrect_sequence: the message after the held one goes first
      have_swap_ = false;
      Say(e, n_ - 1);
      return send_(in) && send_(swap_);
    }
    if (e == "delay" && n_ >= o_.at) {
      // Every message from N on is held delay_ms before it goes on, in order: a link that got slow.
      if (n_ == o_.at) Say(e, n_);
      std::this_thread::sleep_for(std::chrono::milliseconds(o_.delay_ms));
      return send_(in);
    }
    if (!Hits(o_, n_)) return send_(in);
    Msg m = in;
    if (e == "corruption") {
      Corrupt(m);
      Say(e, n_);
      return send_(m);
    }
    if (e == "repetition") {
      Say(e, n_);
      return send_(m) && send_(m);
    }
    if (e == "incorrect_sequence") {
      swap_ = m;
      have_swap_ = true;
      return true;
    }
    if (e == "loss") {
      Say(e, n_);
      return true;
    }
    Msg forged = m;
    if (Forge(e, forged)) {
      Say(e, n_);
      return send_(m) && send_(forged);
    }
    return send_(m);
  }

 private:
  const Options& o_;
  bool active_;
  Send send_;
  int n_ = 0;
  Msg swap_;
  bool have_swap_ = false;
};

class Proxy final : public v1::Aggregator::Service {
 public:
  explicit Proxy(Options o)
      : o_(std::move(o)),
        channel_(grpc::CreateChannel(o_.upstream, grpc::InsecureChannelCredentials())),
        stub_(v1::Aggregator::NewStub(channel_)) {}

  grpc::Status Connect(grpc::ServerContext* ctx,
                       grpc::ServerReaderWriter<v1::AggregatorCommand, v1::PatchMessage>* down) override {
    const bool active = o_.link == "patch" && Claim(patch_streams_);
    grpc::ClientContext up_ctx;
    Forward(*ctx, up_ctx);
    auto up = stub_->Connect(&up_ctx);
    std::thread back([&] {
      v1::AggregatorCommand c;
      while (up->Read(&c)) {
        if (!down->Write(c)) break;
      }
      ctx->TryCancel();
    });
    auto send = [&](const v1::PatchMessage& m) { return up->Write(m); };
    Alterer<v1::PatchMessage, decltype(send)> alter(o_, active, send);
    v1::PatchMessage m;
    while (down->Read(&m)) {
      if (!alter.Offer(m)) break;
    }
    up->WritesDone();
    up_ctx.TryCancel();
    back.join();
    return up->Finish();
  }

  grpc::Status WatchSafety(grpc::ServerContext* ctx, const v1::WatchSafetyRequest* request,
                           grpc::ServerWriter<v1::SafetyState>* down) override {
    const bool active = o_.link == "state" && Claim(state_streams_);
    grpc::ClientContext up_ctx;
    Forward(*ctx, up_ctx);
    auto up = stub_->WatchSafety(&up_ctx, *request);
    std::atomic<bool> done{false};
    std::thread watch([&] {
      while (!done.load()) {
        if (ctx->IsCancelled()) {
          up_ctx.TryCancel();
          return;
        }
        std::this_thread::sleep_for(5ms);
      }
    });
    auto send = [&](const v1::SafetyState& s) { return down->Write(s); };
    Alterer<v1::SafetyState, decltype(send)> alter(o_, active, send);
    v1::SafetyState s;
    while (up->Read(&s)) {
      if (!alter.Offer(s)) break;
    }
    done = true;
    up_ctx.TryCancel();
    watch.join();
    return up->Finish();
  }

  grpc::Status WatchContacts(grpc::ServerContext* ctx, const v1::WatchContactsRequest* request,
                             grpc::ServerWriter<v1::ContactSet>* down) override {
    grpc::ClientContext up_ctx;
    Forward(*ctx, up_ctx);
    auto up = stub_->WatchContacts(&up_ctx, *request);
    v1::ContactSet c;
    while (up->Read(&c)) {
      if (ctx->IsCancelled() || !down->Write(c)) break;
    }
    up_ctx.TryCancel();
    return up->Finish();
  }

  grpc::Status PublishJointStates(grpc::ServerContext* ctx, grpc::ServerReader<v1::JointState>* down,
                                  v1::PublishJointStatesResponse* response) override {
    grpc::ClientContext up_ctx;
    Forward(*ctx, up_ctx);
    auto up = stub_->PublishJointStates(&up_ctx, response);
    v1::JointState j;
    while (down->Read(&j)) {
      if (!up->Write(j)) break;
    }
    up->WritesDone();
    return up->Finish();
  }

  grpc::Status ResetStop(grpc::ServerContext* ctx, const v1::ResetStopRequest* request,
                         v1::ResetStopResponse* response) override {
    grpc::ClientContext up_ctx;
    Forward(*ctx, up_ctx);
    return stub_->ResetStop(&up_ctx, *request, response);
  }

  grpc::Status GetStatus(grpc::ServerContext* ctx, const v1::GetStatusRequest* request,
                         v1::AggregatorStatus* response) override {
    grpc::ClientContext up_ctx;
    Forward(*ctx, up_ctx);
    return stub_->GetStatus(&up_ctx, *request, response);
  }

 private:
  // Whether this stream is one of the first --streams of its link (0: all).
  bool Claim(std::atomic<int>& counter) const {
    const int k = ++counter;
    return o_.streams == 0 || k <= o_.streams;
  }
  static void Forward(const grpc::ServerContext& down, grpc::ClientContext& up) {
    if (down.deadline() != std::chrono::system_clock::time_point::max()) up.set_deadline(down.deadline());
  }

  Options o_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::Aggregator::Stub> stub_;
  std::atomic<int> patch_streams_{0}, state_streams_{0};
};

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"ruffini-fault-proxy: alter one safety link's messages between real services (tests only)"};
  Options o;
  std::string listen = "127.0.0.1:0", ports_file;
  app.add_option("--upstream", o.upstream, "The real aggregator, HOST:PORT")->required();
  app.add_option("--listen", listen, "Where to serve, HOST:PORT (port 0: pick one)")->capture_default_str();
  app.add_option("--link", o.link, "Which link to alter")->check(CLI::IsMember({"patch", "state"}))->capture_default_str();
  app.add_option("--error", o.error, "What to do to it")
      ->check(CLI::IsMember({"none", "corruption", "repetition", "incorrect_sequence", "loss", "delay", "insertion",
                             "masquerade", "addressing"}))
      ->capture_default_str();
  app.add_option("--at", o.at, "The message (of a stream, from 1) to alter")->check(CLI::Range(1, 1 << 30))->capture_default_str();
  app.add_option("--every", o.every, "Repeat every K messages after --at (0: once)")->check(CLI::Range(0, 1 << 30));
  app.add_option("--times", o.times, "With --every: alter this many messages in all (0: no limit)")->check(CLI::Range(0, 1 << 30));
  app.add_option("--delay-ms", o.delay_ms, "For delay: how long each message is held")->check(CLI::Range(1, 60000))
      ->capture_default_str();
  app.add_option("--streams", o.streams, "Alter the first K streams of the link (0: every stream)")->capture_default_str();
  app.add_option("--ports-file", ports_file, "Write 'grpc P' here once serving");
  CLI11_PARSE(app, argc, argv);

  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGTERM);
  sigaddset(&set, SIGINT);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);

  Proxy proxy(o);
  int port = 0;
  grpc::ServerBuilder builder;
  builder.AddListeningPort(listen, grpc::InsecureServerCredentials(), &port);
  builder.RegisterService(&proxy);
  auto server = builder.BuildAndStart();
  if (!server || port == 0) {
    std::fprintf(stderr, "ruffini-fault-proxy: cannot listen on %s\n", listen.c_str());
    return 1;
  }
  if (!ports_file.empty()) {
    const std::string tmp = ports_file + ".tmp";
    std::ofstream(tmp) << "grpc " << port << "\n";
    std::rename(tmp.c_str(), ports_file.c_str());
  }
  std::fprintf(stderr, "ruffini-fault-proxy: serving on port %d, upstream %s, link %s, error %s at %d\n", port,
               o.upstream.c_str(), o.link.c_str(), o.error.c_str(), o.at);
  int sig = 0;
  sigwait(&set, &sig);
  server->Shutdown(std::chrono::system_clock::now() + 500ms);
  return 0;
}
