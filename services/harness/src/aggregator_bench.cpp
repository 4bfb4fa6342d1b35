// `ruffini bench-aggregator`: the runs (aggregator_bench.h). The report is aggregator_bench_report.cpp.
// Every wait has a deadline; every process is stopped by pid (SIGTERM, then SIGKILL after a grace period).
#include "ruffini/harness/aggregator_bench.h"

#include "ruffini/channel/checkers.h"
#include "ruffini/channel/crc.h"
#include "ruffini/service/common.h"

#include <arpa/inet.h>
#include <grpcpp/grpcpp.h>
#include <netinet/in.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <numbers>
#include <optional>
#include <sstream>
#include <thread>

#include "ruffini/error.h"
#include "ruffini/robot/scene.h"
#include "ruffini/scene_file.h"
#include "ruffini/service/child.h"
#include "ruffini/twin/scene.h"
#include "ruffini/v1/aggregator.grpc.pb.h"
#include "scene_setup.h"

namespace ruffini::harness {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;
using service::Child;
using service::ReadPorts;
using service::Slurp;

std::int64_t UnixNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}
double SecondsSince(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

bool WaitFor(const std::function<bool()>& cond, milliseconds timeout, milliseconds poll = milliseconds(5)) {
  const auto deadline = Clock::now() + timeout;
  while (!cond()) {
    if (Clock::now() >= deadline) return false;
    std::this_thread::sleep_for(poll);
  }
  return true;
}

// utime + stime of a process in clock ticks (fields 14 and 15 of /proc/<pid>/stat); nullopt when gone.
std::optional<std::uint64_t> CpuTicks(pid_t pid) {
  const std::string text = Slurp("/proc/" + std::to_string(pid) + "/stat");
  const auto close = text.rfind(')');
  if (close == std::string::npos) return std::nullopt;
  std::istringstream in(text.substr(close + 1));
  std::string field;
  std::uint64_t utime = 0, stime = 0;
  for (int i = 3; i <= 15 && in >> field; ++i) {
    if (i == 14) utime = std::stoull(field);
    if (i == 15) stime = std::stoull(field);
  }
  return utime + stime;
}
double TickSeconds() { return 1.0 / static_cast<double>(sysconf(_SC_CLK_TCK)); }
double SelfCpuSeconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return static_cast<double>(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         static_cast<double>(u.ru_utime.tv_usec + u.ru_stime.tv_usec) * 1e-6;
}

// One value of a Prometheus text exposition (HTTP/1.0 GET /metrics on 127.0.0.1); nullopt when unreadable.
std::optional<double> ScrapeMetric(int port, const std::string& name) {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return std::nullopt;
  timeval tv{2, 0};
  setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<std::uint16_t>(port));
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  std::string text;
  if (connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) == 0) {
    const std::string req = "GET /metrics HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n";
    if (write(fd, req.data(), req.size()) == static_cast<ssize_t>(req.size())) {
      char buf[8192];
      ssize_t n = 0;
      while ((n = read(fd, buf, sizeof buf)) > 0) text.append(buf, static_cast<std::size_t>(n));
    }
  }
  close(fd);
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind(name + " ", 0) == 0) return std::stod(line.substr(name.size() + 1));
  }
  return std::nullopt;
}

std::string KindName(v1::SafetyCause::Kind k) {
  std::string s = v1::SafetyCause::Kind_Name(k);
  if (s.rfind("KIND_", 0) == 0) s = s.substr(5);
  for (auto& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// Starts an executable that writes a ports file; waits for `key`. Throws InputError with its log otherwise.
std::unique_ptr<Child> StartWithPorts(std::vector<std::string> args, const std::string& dir, const std::string& key,
                                      int& port) {
  fs::create_directories(dir);
  const std::string ports = dir + "/ports";
  args.push_back("--ports-file");
  args.push_back(ports);
  auto child = std::make_unique<Child>(args, dir);
  if (!WaitFor([&] { return ReadPorts(ports).count(key) > 0 || !child->Running(); }, milliseconds(20000)) ||
      ReadPorts(ports).count(key) == 0) {
    throw InputError("bench-aggregator: " + args[0] + " wrote no '" + key + "' port within 20 s: " +
                     child->stderr_text());
  }
  port = ReadPorts(ports)[key];
  return child;
}

struct Seen {
  v1::SafetyState state;
  std::int64_t arrival_ns = 0;
};

// The bench's controller: one WatchSafety subscriber (its own thread and channel), joint states at 100 Hz
// (another thread), ResetStop and GetStatus.
class Controller {
 public:
  explicit Controller(const std::string& address) {
    stub_ = v1::Aggregator::NewStub(grpc::CreateChannel(address, grpc::InsecureChannelCredentials()));
    watcher_ = std::thread([this] { Watch(); });
  }
  ~Controller() {
    StopJoints();
    watch_ctx_.TryCancel();
    watcher_.join();
  }
  Controller(const Controller&) = delete;
  Controller& operator=(const Controller&) = delete;

  std::optional<v1::AggregatorStatus> Status() {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(2));
    v1::AggregatorStatus s;
    if (!stub_->GetStatus(&ctx, v1::GetStatusRequest{}, &s).ok()) return std::nullopt;
    return s;
  }
  // The reset of the state the bench saw: its epoch and its run (not a fresh GetStatus run id, which is 0 when
  // that call fails and would pair the epoch with another run after a restart; review 14 finding 6).
  bool Reset(const v1::SafetyState& seen) {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(2));
    v1::ResetStopRequest r;
    r.set_stop_epoch(seen.stop_epoch());
    r.set_aggregator_run_id(seen.aggregator_run_id());  // the run whose epoch this is
    r.set_operator_name("ruffini bench-aggregator");
    v1::ResetStopResponse resp;
    const bool ok = stub_->ResetStop(&ctx, r, &resp).ok() && resp.accepted();
    (ok ? resets_accepted_ : resets_refused_)++;
    return ok;
  }
  void StartJoints(const std::vector<std::string>& names) {
    joints_ = std::thread([this, names] {
      grpc::ClientContext ctx;
      v1::PublishJointStatesResponse resp;
      auto w = stub_->PublishJointStates(&ctx, &resp);
      std::uint64_t seq = 0;
      auto next = Clock::now();
      while (!stop_joints_) {
        v1::JointState js;
        const std::int64_t now = UnixNs();
        for (std::size_t i = 0; i < names.size(); ++i) {
          js.add_names(names[i]);
          js.add_positions_rad(0.3 * std::sin(1e-9 * static_cast<double>(now) + static_cast<double>(i)));
        }
        js.set_t_ns(now);
        js.set_seq(++seq);
        if (!w->Write(js)) break;
        next += milliseconds(10);  // a 100 Hz controller's publishing period
        std::this_thread::sleep_until(next);
      }
      w->WritesDone();
      w->Finish();
    });
  }
  void StopJoints() {
    stop_joints_ = true;
    if (joints_.joinable()) joints_.join();
  }
  std::optional<Seen> Last() {
    std::lock_guard lock(mu_);
    if (seen_.empty()) return std::nullopt;
    return seen_.back();
  }
  std::vector<Seen> Snapshot() {
    std::lock_guard lock(mu_);
    return seen_;
  }
  int resets_accepted() const { return resets_accepted_; }
  int resets_refused() const { return resets_refused_; }

 private:
  void Watch() {
    v1::WatchSafetyRequest req;
    req.set_subscriber("ruffini bench-aggregator");
    auto r = stub_->WatchSafety(&watch_ctx_, req);
    v1::SafetyState s;
    while (r->Read(&s)) {
      const std::int64_t arrival = UnixNs();
      std::lock_guard lock(mu_);
      seen_.push_back({s, arrival});
    }
    r->Finish();
  }
  std::unique_ptr<v1::Aggregator::Stub> stub_;
  grpc::ClientContext watch_ctx_;
  std::thread watcher_, joints_;
  std::atomic<bool> stop_joints_{false};
  std::atomic<int> resets_accepted_{0}, resets_refused_{0};
  std::mutex mu_;
  std::vector<Seen> seen_;
};

// Waits until every patch is healthy and a reset naming the current epoch clears (the start-up FAULT).
bool ClearStartup(Controller& c, milliseconds timeout, const std::function<bool()>& alive) {
  return WaitFor([&] {
    if (!alive()) return false;
    const auto last = c.Last();
    if (!last) return false;
    if (last->state.state() == v1::SafetyState::STATE_CLEAR) return true;
    c.Reset(last->state);
    return false;
  }, timeout, milliseconds(100));
}

// A synthetic decoder: one Connect stream on its own channel; a valid hello, then what Tick queues. One write
// in flight; at most kQueue messages waiting (more are counted as overflows, never sent: seq stays gapless).
class SyntheticDecoder final : public grpc::ClientBidiReactor<v1::PatchMessage, v1::AggregatorCommand> {
 public:
  static constexpr std::size_t kQueue = 64;
  SyntheticDecoder(const std::string& address, const aggregate::PatchExpectation& e, int index)
      : id_(e.id), index_(index) {
    grpc::ChannelArguments args;
    args.SetInt("ruffini.bench.decoder", index);   // a distinct channel (own TCP connection), as real decoders
    args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
    stub_ = v1::Aggregator::NewStub(grpc::CreateCustomChannel(address, grpc::InsecureChannelCredentials(), args));
    v1::PatchMessage m;
    m.set_patch_id(e.id);
    m.set_t_ns(UnixNs());
    auto* h = m.mutable_hello();
    h->set_patch_name(e.spec_name);
    h->set_patch_fingerprint(e.spec_fingerprint);
    h->set_model_patch_fingerprint(e.spec_fingerprint);
    h->set_model_sha256(e.model_sha256);
    h->set_model_name("forearm.rmodel");
    h->set_sample_rate_hz(1000.0);
    h->set_heartbeat_period_ns(10'000'000);
    h->set_grating_count(16);
    h->set_decoder_version("bench-synthetic");
    h->set_decoder_instance("bench-synthetic-" + std::to_string(index));
    stub_->async()->Connect(&ctx_, this);
    {
      std::lock_guard lock(mu_);
      Enqueue(std::move(m));
    }
    StartRead(&in_);
    StartCall();
  }
  ~SyntheticDecoder() override {
    ctx_.TryCancel();
    std::unique_lock lock(done_mu_);
    done_cv_.wait_for(lock, std::chrono::seconds(5), [&] { return done_; });
  }
  SyntheticDecoder(const SyntheticDecoder&) = delete;
  SyntheticDecoder& operator=(const SyntheticDecoder&) = delete;

  // The pacing thread, every 1 ms: a contact below the threshold; every 10th tick (offset by the index) a
  // healthy heartbeat too.
  void Tick(std::uint64_t k, std::int64_t t_ns) {
    std::lock_guard lock(mu_);
    if (!accepted_ || broken_) return;
    v1::PatchMessage m;
    m.set_patch_id(id_);
    m.set_interrogator_serial(k);
    m.set_t_ns(t_ns);
    m.set_decoder_t_ns(t_ns);
    auto* c = m.mutable_contact();
    c->set_force_n(0.5f);
    c->set_force_sd_n(0.03f);
    c->set_located(true);
    c->set_y_mm(75.0f);
    c->set_r_deg(70.0f);
    c->set_cov_yy_mm2(4.0f);
    c->set_cov_rr_mm2(4.0f);
    c->set_confidence(0.9f);
    c->set_uncertainty_calibrated(true);
    c->set_onset(!onset_sent_);
    onset_sent_ = true;
    if (Enqueue(std::move(m))) ++contacts_;
    if ((k + static_cast<std::uint64_t>(index_)) % 10 == 0) {
      v1::PatchMessage h;
      h.set_patch_id(id_);
      h.set_interrogator_serial(k);
      h.set_t_ns(t_ns);
      h.set_decoder_t_ns(t_ns);
      auto* hb = h.mutable_heartbeat();
      hb->set_healthy(true);
      hb->set_in_contact(true);
      hb->set_frames(k);
      hb->set_valid_frames(k);
      hb->set_baseline_state(v1::BASELINE_STATE_FROZEN);
      if (Enqueue(std::move(h))) ++heartbeats_;
    }
  }
  bool accepted() {
    std::lock_guard lock(mu_);
    return accepted_;
  }
  std::string refusal() {
    std::lock_guard lock(mu_);
    return refusal_;
  }
  struct Counts {
    std::uint64_t contacts = 0, heartbeats = 0, overflows = 0, sent = 0;
  };
  Counts counts() {
    std::lock_guard lock(mu_);
    return {contacts_, heartbeats_, overflows_, seq_};
  }

  void OnWriteDone(bool ok) override {
    std::lock_guard lock(mu_);
    queue_.pop_front();
    if (!ok) {
      broken_ = true;
      writing_ = false;
      return;
    }
    if (!queue_.empty()) StartWrite(&queue_.front());
    else writing_ = false;
  }
  void OnReadDone(bool ok) override {
    if (!ok) return;
    {
      std::lock_guard lock(mu_);
      if (in_.has_hello_accepted()) {
        accepted_ = true;
        aggregator_run_ = in_.hello_accepted().aggregator_run_id();
      }
      if (in_.has_hello_refused()) refusal_ = in_.hello_refused().message();
    }
    StartRead(&in_);
  }
  void OnDone(const grpc::Status& /*s*/) override {
    std::lock_guard lock(done_mu_);
    done_ = true;
    done_cv_.notify_all();
  }

 private:
  // mu_ held.
  bool Enqueue(v1::PatchMessage m) {
    if (queue_.size() >= kQueue) {
      ++overflows_;
      return false;
    }
    m.set_seq(++seq_);
    // The decoder's part of the safety layer (docs/safety-channel.md), stamped when the message is queued.
    m.set_sender_run_id(run_id_);
    m.set_sender_steady_ns(service::MonoNowNs());
    m.set_aggregator_run_id(m.has_hello() ? 0 : aggregator_run_);
    channel::Seal(m);
    queue_.push_back(std::move(m));
    if (!writing_) {
      writing_ = true;
      StartWrite(&queue_.front());
    }
    return true;
  }
  std::string id_;
  int index_;
  std::unique_ptr<v1::Aggregator::Stub> stub_;
  grpc::ClientContext ctx_;
  std::recursive_mutex mu_;
  std::deque<v1::PatchMessage> queue_;
  v1::AggregatorCommand in_;
  bool writing_ = false, accepted_ = false, broken_ = false, onset_sent_ = false;
  std::string refusal_;
  std::uint64_t seq_ = 0, contacts_ = 0, heartbeats_ = 0, overflows_ = 0;
  const std::uint64_t run_id_ = channel::DrawRunId();
  std::uint64_t aggregator_run_ = 0;
  std::mutex done_mu_;
  std::condition_variable done_cv_;
  bool done_ = false;
};

std::string Exe(const AggregatorBenchOptions& o, const char* name) { return (fs::path(o.bin_dir) / name).string(); }

// The scenario: after 4 s untouched (the decoders' 1 s baseline capture, the start-up FAULT cleared), one hard
// press (2.5 N, above the 1.5 N threshold) every touch_period_s, patch after patch, at varying places.
int WriteScenario(const std::vector<std::string>& patches, double period_s, double total_s, const std::string& path) {
  std::ostringstream y;
  y << "# Written by ruffini bench-aggregator: one hard press every " << period_s << " s, patch after patch.\n"
    << "loop: false\nseed: 11\npresses:\n";
  int n = 0;
  for (double t = 4.0; t < total_s; t += period_s, ++n) {
    const std::size_t p = static_cast<std::size_t>(n) % patches.size();
    const int round = n / static_cast<int>(patches.size());
    const double y_mm = 45.0 + 60.0 * (round % 2), r_deg = 40.0 + 65.0 * ((round / 2) % 2);
    y << "  - {t_s: " << t << ", patch: " << patches[p] << ", y_mm: " << y_mm << ", r_deg: " << r_deg
      << ", force_n: 2.5, ramp_s: 0.1, hold_s: 0.3, release_s: 0.1}\n";
  }
  std::ofstream out(path);
  out << y.str();
  if (!out) throw InputError(path + ": cannot write the scenario");
  return n;
}

}  // namespace

void CheckAggregatorExecutables(const std::string& bin_dir) {
  for (const char* name : {"ruffini-sim", "ruffini-decoder", "ruffini-aggregator"}) {
    const std::string exe = (fs::path(bin_dir) / name).string();
    if (access(exe.c_str(), X_OK) != 0) {
      throw InputError("bench-aggregator: " + exe + " not found (or not executable): build it next to `ruffini` "
                       "(cmake --build build/release --target ruffini-sim ruffini-decoder ruffini-aggregator)");
    }
  }
}

void WriteGeneratedScene(const std::string& cobot_scene, int n, const std::string& path) {
  const std::string text = Slurp(cobot_scene);
  const auto safety = text.find("\nsafety:");
  if (text.empty() || safety == std::string::npos) {
    throw InputError(cobot_scene + ": cannot read its `safety:` section (the generated scenes copy it)");
  }
  const fs::path dir = fs::path(cobot_scene).parent_path();
  const auto abs = [&](const char* rel) { return fs::weakly_canonical(dir / rel).string(); };
  std::ostringstream y;
  y << "# Written by ruffini bench-aggregator: " << n << " patches of the forearm design around srs7's forearm and\n"
    << "# upper arm (rings along the limb, several yaws per ring; neighbours may overlap: a load layout, not a\n"
    << "# buildable skin). Safety and twin sections: " << cobot_scene << ".\n"
    << "name: bench" << n << "\nrobot: {urdf: " << abs("../robots/srs7.urdf") << "}\npatches:\n";
  const int forearm = (n + 1) / 2;
  for (int link = 0; link < 2; ++link) {
    const int m = link == 0 ? forearm : n - forearm;
    if (m == 0) continue;
    const int yaws = m <= 2 ? m : (m <= 8 ? 4 : 8);
    const int rings = (m + yaws - 1) / yaws;
    for (int i = 0; i < m; ++i) {
      const int ring = i / yaws, k = i % yaws;
      const double z = rings == 1 ? 0.125 : 0.02 + 0.23 * ring / (rings - 1);
      const double yaw = 2.0 * std::numbers::pi * k / yaws;
      char name[32];
      std::snprintf(name, sizeof name, "%s_%02d", link == 0 ? "forearm" : "upper_arm", i);
      y << "  - name: " << name << "\n    spec: " << abs("../patches/forearm.yaml") << "\n    model: "
        << abs("../models/forearm.rmodel") << "\n    mount: {link: " << (link == 0 ? "forearm_link" : "upper_arm_link")
        << ", xyz_m: [0, 0, " << z << "], rpy_rad: [1.5707963267948966, 0, " << yaw << "]}\n    region: "
        << (link == 0 ? "forearm" : "upper_arm") << "\n";
    }
  }
  y << text.substr(safety + 1);
  std::ofstream out(path);
  out << y.str();
  if (!out) throw InputError(path + ": cannot write the generated scene");
}

LatencyRun RunLatency(const AggregatorBenchOptions& o, int patches, const std::function<void(const std::string&)>& log) {
  CheckAggregatorExecutables(o.bin_dir);
  const std::string dir = (fs::path(o.work_dir) / ("latency-" + std::to_string(patches))).string();
  fs::remove_all(dir);
  fs::create_directories(dir);
  LatencyRun run;
  run.patches = patches;
  if (patches == 4) {
    run.scene = o.cobot_scene;
  } else {
    run.scene = dir + "/scene.yaml";
    WriteGeneratedScene(o.cobot_scene, patches, run.scene);
  }
  const twin::Scene scene = twin::LoadScene(run.scene);
  if (static_cast<int>(scene.patches.size()) != patches) {
    throw InputError(run.scene + ": " + std::to_string(scene.patches.size()) + " patches, expected " +
                     std::to_string(patches));
  }
  std::vector<std::string> names;
  for (const auto& p : scene.patches) names.push_back(p.name);
  const std::string scenario = dir + "/scenario.yaml";
  WriteScenario(names, o.touch_period_s, 4.0 + 60.0 + o.seconds + 10.0, scenario);
  const std::string tag = "latency " + std::to_string(patches) + " patches: ";

  int grpc_port = 0, sim_port = 0;
  const auto t_start = Clock::now();
  auto agg = StartWithPorts({Exe(o, "ruffini-aggregator"), "--insecure", "--scene", run.scene, "--listen", "127.0.0.1:0",
                             "--metrics", "127.0.0.1:0"},
                            dir + "/aggregator", "grpc", grpc_port);
  const std::string address = "127.0.0.1:" + std::to_string(grpc_port);
  Controller controller(address);
  const auto status = controller.Status();
  if (!status) throw InputError("bench-aggregator: GetStatus failed: " + agg->stderr_text());
  controller.StartJoints({status->joint_names().begin(), status->joint_names().end()});
  auto sim = StartWithPorts({Exe(o, "ruffini-sim"), "--scene", run.scene, "--scenario", scenario, "--rate-hz", "1000",
                             "--command-port", "0", "--stream-port", "0"},
                            dir + "/sim", "stream", sim_port);
  const auto sim_start = Clock::now();
  std::vector<std::unique_ptr<Child>> decoders;
  for (const auto& p : names) {
    int metrics = 0;
    // --silence-ms 100: the decoder's interrogator watchdog, widened for a loaded 2-core machine; the
    // aggregator keeps the scene's own deadlines.
    decoders.push_back(StartWithPorts({Exe(o, "ruffini-decoder"), "--insecure", "--scene", run.scene, "--patch", p, "--interrogator",
                                       "127.0.0.1:" + std::to_string(sim_port), "--aggregator", address, "--metrics",
                                       "127.0.0.1:0", "--rate-hz", "1000", "--silence-ms", "100"},
                                      dir + "/decoder_" + p, "metrics", metrics));
  }
  log(tag + "aggregator pid " + std::to_string(agg->pid()) + ", sim pid " + std::to_string(sim->pid()) + ", " +
      std::to_string(decoders.size()) + " decoders started; clearing the start-up FAULT");
  const auto alive = [&] { return agg->Running() && sim->Running(); };
  if (!ClearStartup(controller, milliseconds(60000), alive)) {
    throw InputError("bench-aggregator: " + tag + "no CLEAR within 60 s of the start; aggregator log: " +
                     agg->stderr_text().substr(0, 4000));
  }
  run.setup_s = SecondsSince(t_start);
  const std::int64_t open_ns = UnixNs();
  const auto w0 = Clock::now();
  std::uint64_t agg0 = CpuTicks(agg->pid()).value_or(0), sim0 = CpuTicks(sim->pid()).value_or(0), dec0 = 0;
  for (auto& d : decoders) dec0 += CpuTicks(d->pid()).value_or(0);
  log(tag + "CLEAR after " + std::to_string(run.setup_s) + " s; measuring for " + std::to_string(o.seconds) + " s");

  // The operator: after each STOP (or FAULT), a reset naming the current epoch every 50 ms until accepted (it
  // is refused while the press is held or the patch not healthy long enough).
  const auto w_end = w0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.seconds));
  std::size_t reported = 0;
  while (Clock::now() < w_end) {
    if (!alive()) throw InputError("bench-aggregator: " + tag + "a process exited: " + agg->stderr_text().substr(0, 4000));
    const auto last = controller.Last();
    if (last && last->state.state() != v1::SafetyState::STATE_CLEAR) controller.Reset(last->state);
    std::this_thread::sleep_for(milliseconds(50));
    if (static_cast<std::size_t>(SecondsSince(w0) / 15.0) > reported) {
      reported = static_cast<std::size_t>(SecondsSince(w0) / 15.0);
      log(tag + std::to_string(static_cast<int>(SecondsSince(w0))) + " s of " + std::to_string(static_cast<int>(o.seconds)));
    }
  }
  const double window = SecondsSince(w0);
  const std::int64_t close_ns = UnixNs();
  std::uint64_t dec1 = 0;
  for (auto& d : decoders) dec1 += CpuTicks(d->pid()).value_or(0);
  const std::uint64_t agg1 = CpuTicks(agg->pid()).value_or(0), sim1 = CpuTicks(sim->pid()).value_or(0);
  run.window_s = window;
  run.aggregator_cpu_pct = 100.0 * static_cast<double>(agg1 - agg0) * TickSeconds() / window;
  run.sim_cpu_pct = 100.0 * static_cast<double>(sim1 - sim0) * TickSeconds() / window;
  run.decoders_cpu_pct = 100.0 * static_cast<double>(dec1 - dec0) * TickSeconds() / window;
  run.resets_accepted = controller.resets_accepted();
  run.resets_refused = controller.resets_refused();
  // Presses scheduled in the window (the sim's clock starts about when its process did).
  const double ws = std::chrono::duration<double>(w0 - sim_start).count();
  for (double t = 4.0; t < ws + window; t += o.touch_period_s) run.presses_in_window += t >= ws ? 1 : 0;

  controller.StopJoints();
  for (auto& d : decoders) d->Stop(milliseconds(3000));
  sim->Stop(milliseconds(3000));
  run.aggregator_exit = agg->Stop(milliseconds(3000));

  std::vector<double> lat, latch, out;
  v1::SafetyState::State prev = v1::SafetyState::STATE_CLEAR;
  for (const Seen& s : controller.Snapshot()) {
    if (s.arrival_ns < open_ns || s.arrival_ns > close_ns) {
      prev = s.state.state();
      continue;
    }
    const auto st = s.state.state();
    if (st == v1::SafetyState::STATE_FAULT && prev != v1::SafetyState::STATE_FAULT) {
      ++run.faults;
      ++run.fault_causes[KindName(s.state.cause().kind())];
    }
    // One sample per press: the first STOP after CLEAR. (A further cause while stopped, e.g. a second patch,
    // opens a new epoch with the STOP already in force: not a new stop.)
    if (st == v1::SafetyState::STATE_STOP && prev == v1::SafetyState::STATE_CLEAR) {
      ++run.stops;
      if (s.state.cause().kind() == v1::SafetyCause::KIND_CONTACT && s.state.cause().t_ns() > 0) {
        lat.push_back(static_cast<double>(s.arrival_ns - s.state.cause().t_ns()) / 1e3);
        latch.push_back(static_cast<double>(s.state.changed_t_ns() - s.state.cause().t_ns()) / 1e3);
        out.push_back(static_cast<double>(s.arrival_ns - s.state.changed_t_ns()) / 1e3);
      }
    }
    prev = st;
  }
  run.latency = QuantilesOf(lat);
  run.to_latch = QuantilesOf(latch);
  run.latch_to_arrival = QuantilesOf(out);
  run.latency_us = std::move(lat);
  log(tag + std::to_string(run.latency.count) + " STOPs, p50 " + std::to_string(run.latency.p50_us) + " us, p99 " +
      std::to_string(run.latency.p99_us) + " us; " + std::to_string(run.faults) + " FAULTs");
  return run;
}

FanInRun RunFanIn(const AggregatorBenchOptions& o, int patches, const std::function<void(const std::string&)>& log) {
  CheckAggregatorExecutables(o.bin_dir);
  const std::string dir = (fs::path(o.work_dir) / ("fanin-" + std::to_string(patches))).string();
  fs::remove_all(dir);
  fs::create_directories(dir);
  FanInRun run;
  run.patches = patches;
  const std::string scene = dir + "/scene.yaml";
  WriteGeneratedScene(o.cobot_scene, patches, scene);
  const aggregate::Setup setup = aggregator::SetupFromScene(scene);  // what the aggregator will expect
  const std::string tag = "fan-in " + std::to_string(patches) + " patches: ";

  int grpc_port = 0;
  auto agg = StartWithPorts({Exe(o, "ruffini-aggregator"), "--insecure", "--scene", scene, "--listen", "127.0.0.1:0", "--metrics",
                             "127.0.0.1:0"},
                            dir + "/aggregator", "grpc", grpc_port);
  const int metrics_port = ReadPorts(dir + "/aggregator/ports")["metrics"];
  const std::string address = "127.0.0.1:" + std::to_string(grpc_port);
  Controller controller(address);
  const auto status = controller.Status();
  if (!status) throw InputError("bench-aggregator: GetStatus failed: " + agg->stderr_text());
  controller.StartJoints({status->joint_names().begin(), status->joint_names().end()});

  std::vector<std::unique_ptr<SyntheticDecoder>> decoders;
  for (std::size_t i = 0; i < setup.patches.size(); ++i) {
    decoders.push_back(std::make_unique<SyntheticDecoder>(address, setup.patches[i], static_cast<int>(i)));
  }
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> ticks{0}, late{0};
  std::thread pacer([&] {
    auto next = Clock::now();
    std::uint64_t k = 0;
    while (!stop) {
      next += milliseconds(1);
      std::this_thread::sleep_until(next);
      const auto lag = Clock::now() - next;
      if (lag > milliseconds(1)) late.fetch_add(1);
      if (lag > milliseconds(50)) next = Clock::now();  // give up on a long stall rather than burst
      ++k;
      const std::int64_t t = UnixNs();
      for (auto& d : decoders) d->Tick(k, t);
      ticks.fetch_add(1);
    }
  });
  const auto stop_pacer = [&] {
    stop = true;
    if (pacer.joinable()) pacer.join();
  };
  const bool hellos = WaitFor([&] {
    return std::all_of(decoders.begin(), decoders.end(), [](auto& d) { return d->accepted(); });
  }, milliseconds(10000), milliseconds(20));
  if (!hellos || !ClearStartup(controller, milliseconds(15000), [&] { return agg->Running(); })) {
    std::string why = hellos ? "no CLEAR within 15 s" : "not every hello accepted within 10 s";
    for (auto& d : decoders) {
      if (!d->refusal().empty()) {
        why += " (refused: " + d->refusal() + ")";
        break;
      }
    }
    stop_pacer();
    decoders.clear();
    controller.StopJoints();
    agg->Stop(milliseconds(3000));
    run.error = why;
    log(tag + why);
    return run;
  }
  // A short settle, then the window.
  std::this_thread::sleep_for(milliseconds(300));
  auto sent = [&] {
    SyntheticDecoder::Counts c;
    for (auto& d : decoders) {
      const auto x = d->counts();
      c.contacts += x.contacts;
      c.heartbeats += x.heartbeats;
      c.overflows += x.overflows;
      c.sent += x.sent;
    }
    return c;
  };
  const auto s0 = sent();
  const std::uint64_t ticks0 = ticks, late0 = late;
  const std::uint64_t agg0 = CpuTicks(agg->pid()).value_or(0);
  const double self0 = SelfCpuSeconds();
  const std::int64_t open_ns = UnixNs();
  const auto w0 = Clock::now();
  log(tag + "CLEAR; " + std::to_string(patches) + " synthetic decoders at 1 kHz for " + std::to_string(o.fanin_seconds) +
      " s");
  std::this_thread::sleep_for(std::chrono::duration<double>(o.fanin_seconds));
  const auto s1 = sent();
  const auto received = ScrapeMetric(metrics_port, "ruffini_aggregator_patch_messages_total");
  const double window = SecondsSince(w0);
  const std::int64_t close_ns = UnixNs();
  const std::uint64_t agg1 = CpuTicks(agg->pid()).value_or(agg0);
  const double self1 = SelfCpuSeconds();
  run.ticks = ticks - ticks0;
  run.pacer_late_ticks = late - late0;
  stop_pacer();
  run.ran = true;
  run.window_s = window;
  run.contacts_sent = s1.contacts - s0.contacts;
  run.heartbeats_sent = s1.heartbeats - s0.heartbeats;
  run.sender_overflows = s1.overflows - s0.overflows;
  run.aggregator_cpu_pct = 100.0 * static_cast<double>(agg1 - agg0) * TickSeconds() / window;
  run.bench_cpu_pct = 100.0 * (self1 - self0) / window;
  const double per_ms = static_cast<double>(run.contacts_sent + run.heartbeats_sent) / (window * 1e3);
  // The aggregator copies its counters every 5 ms: up to 5 ms of apparent backlog is only that.
  if (received && per_ms > 0) run.backlog_ms = std::max(0.0, (static_cast<double>(s1.sent) - *received) / per_ms);

  decoders.clear();
  controller.StopJoints();
  agg->Stop(milliseconds(3000));

  std::int64_t prev_arrival = 0;
  for (const Seen& s : controller.Snapshot()) {
    if (s.arrival_ns < open_ns || s.arrival_ns > close_ns) continue;
    ++run.heartbeats_seen;
    if (prev_arrival) run.max_heartbeat_gap_ms = std::max(run.max_heartbeat_gap_ms, static_cast<double>(s.arrival_ns - prev_arrival) / 1e6);
    prev_arrival = s.arrival_ns;
    if (s.state.state() == v1::SafetyState::STATE_FAULT) {
      if (run.faults++ == 0) run.fault_cause = KindName(s.state.cause().kind()) + " " + s.state.cause().patch_id();
    }
    if (s.state.state() == v1::SafetyState::STATE_STOP) ++run.stops;
  }
  std::string why;
  if (run.faults > 0) why += "FAULT (" + run.fault_cause + "); ";
  if (run.stops > 0) why += "STOP; ";
  if (run.max_heartbeat_gap_ms > 30.0) why += "heartbeat gap " + std::to_string(run.max_heartbeat_gap_ms) + " ms; ";
  if (!received) why += "metrics unreadable; ";
  else if (run.backlog_ms > 30.0) why += "aggregator behind by " + std::to_string(run.backlog_ms) + " ms of traffic; ";
  run.miss = !why.empty();
  run.miss_reason = run.miss ? why.substr(0, why.size() - 2) : "";
  log(tag + (run.miss ? "MISS: " + run.miss_reason : "no miss") + "; aggregator CPU " +
      std::to_string(run.aggregator_cpu_pct) + " %, max heartbeat gap " + std::to_string(run.max_heartbeat_gap_ms) +
      " ms, backlog " + std::to_string(run.backlog_ms) + " ms");
  return run;
}

}  // namespace ruffini::harness
