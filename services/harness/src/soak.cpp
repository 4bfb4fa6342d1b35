#include "ruffini/harness/soak.h"

#include <dirent.h>
#include <grpcpp/grpcpp.h>
#include <signal.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <set>
#include <sstream>
#include <thread>
#include <vector>

#include "ruffini/error.h"
#include "ruffini/plot/svg.h"
#include "ruffini/safety/scene.h"
#include "ruffini/scene_file.h"
#include "ruffini/service/child.h"
#include "ruffini/service/common.h"
#include "ruffini/service/tcp_proxy.h"
#include "ruffini/v1/aggregator.grpc.pb.h"
#include "run_common.h"

namespace ruffini::harness {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using service::Child;
using Clock = std::chrono::steady_clock;

// --- What was scripted -------------------------------------------------------------------------------------

struct ScriptedPress {
  double t_s = 0;  // the sim's time of the ramp's start
  std::size_t patch = 0;
  double y_mm = 0, r_deg = 0, force_n = 0, ramp_s = 0, hold_s = 0, release_s = 0;
  double threshold_n = 0;
  [[nodiscard]] bool above() const { return force_n > threshold_n; }
  [[nodiscard]] double end_s() const { return t_s + ramp_s + hold_s + release_s; }
  // When the applied force (a linear ramp) crosses the threshold.
  [[nodiscard]] double crossing_s() const { return t_s + ramp_s * threshold_n / force_n; }
};

// One press at a time over the whole scene: above the threshold (2 to 3 times it) or at most half of it, at
// sites well inside the patches' indented area (the soak tests the system, not the skin's edges: issue 16), each
// followed by a quiet gap in which the operator resets.
std::vector<ScriptedPress> MakePresses(const SoakOptions& o, const std::vector<double>& thresholds, double start_s,
                                       std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  auto between = [&](double a, double b) { return a + (b - a) * u(rng); };
  std::vector<ScriptedPress> out;
  double t = start_s;
  while (t < start_s + o.duration_s) {
    ScriptedPress p;
    p.t_s = t;
    p.patch = static_cast<std::size_t>(u(rng) * static_cast<double>(thresholds.size())) % thresholds.size();
    p.threshold_n = thresholds[p.patch];
    p.y_mm = between(40, 110);
    p.r_deg = between(40, 105);
    if (u(rng) < o.above_share) {
      p.force_n = p.threshold_n * between(2.0, 3.0);
      p.ramp_s = between(0.05, 0.3);
      p.hold_s = between(0.3, 0.8);
    } else {
      p.force_n = p.threshold_n * between(0.1, 0.5);
      p.ramp_s = between(0.1, 0.4);
      p.hold_s = between(0.3, 1.0);
    }
    p.release_s = 0.2;
    out.push_back(p);
    t = p.end_s() + std::max(1.2, o.press_every_s * between(0.6, 1.4) - (p.end_s() - p.t_s));
  }
  return out;
}

void WriteScenario(const std::string& path, const std::vector<ScriptedPress>& presses,
                   const std::vector<std::string>& patches, double duration_s, std::uint64_t seed) {
  std::ofstream f(path);
  f << "# Written by ruffini soak: one press at a time, above (2-3x) or below (<= 0.5x) the threshold.\n"
    << "loop: false\nduration_s: " << duration_s << "\nseed: " << seed << "\npresses:\n";
  for (const auto& p : presses) {
    f << "  - {t_s: " << p.t_s << ", patch: " << patches[p.patch] << ", y_mm: " << p.y_mm << ", r_deg: " << p.r_deg
      << ", force_n: " << p.force_n << ", ramp_s: " << p.ramp_s << ", hold_s: " << p.hold_s
      << ", release_s: " << p.release_s << "}\n";
  }
  if (!f) throw InputError(path + ": cannot write the soak's scenario");
}

// --- What was observed -------------------------------------------------------------------------------------

struct StateRecord {
  std::int64_t arrival_ns = 0;
  std::uint64_t run = 0, epoch = 0;
  v1::SafetyState::State state = v1::SafetyState::STATE_UNSPECIFIED;
  v1::SafetyCause::Kind kind = v1::SafetyCause::KIND_UNSPECIFIED;
  std::string patch, message;
};

// The soak's own WatchSafety subscriber, re-opened whenever the stream ends (the aggregator restarts).
class SafetyWatch {
 public:
  explicit SafetyWatch(const std::string& address) {
    grpc::ChannelArguments args;
    args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, 50);
    args.SetInt(GRPC_ARG_MIN_RECONNECT_BACKOFF_MS, 50);
    args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, 250);
    stub_ = v1::Aggregator::NewStub(grpc::CreateCustomChannel(address, grpc::InsecureChannelCredentials(), args));
    thread_ = std::thread([this] { Run(); });
  }
  ~SafetyWatch() { Stop(); }
  void Stop() {
    stop_ = true;
    {
      std::lock_guard lock(ctx_mu_);
      if (ctx_) ctx_->TryCancel();
    }
    if (thread_.joinable()) thread_.join();
  }
  std::vector<StateRecord> States() {
    std::lock_guard lock(mu_);
    return log_;
  }
  std::optional<StateRecord> Latest() {
    std::lock_guard lock(mu_);
    if (log_.empty()) return std::nullopt;
    return log_.back();
  }
  std::int64_t last_arrival_ns() const { return last_arrival_ns_.load(); }
  // A reset of `epoch` of run `run`; true when accepted.
  bool Reset(std::uint64_t run, std::uint64_t epoch, std::string& message) {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + 500ms);
    v1::ResetStopRequest r;
    r.set_stop_epoch(epoch);
    r.set_aggregator_run_id(run);
    r.set_operator_name("ruffini soak");
    r.set_operator_note("the scripted press and any injected fault are over");
    v1::ResetStopResponse resp;
    const grpc::Status s = stub_->ResetStop(&ctx, r, &resp);
    message = s.ok() ? resp.message() : "rpc " + std::to_string(s.error_code()) + ": " + s.error_message();
    return s.ok() && resp.accepted();
  }

 private:
  void Run() {
    while (!stop_) {
      auto ctx = std::make_unique<grpc::ClientContext>();
      {
        std::lock_guard lock(ctx_mu_);
        if (stop_) break;
        ctx_ = ctx.get();
      }
      v1::WatchSafetyRequest req;
      req.set_subscriber("ruffini soak");
      ctx->set_wait_for_ready(true);
      auto reader = stub_->WatchSafety(ctx.get(), req);
      v1::SafetyState s;
      while (reader->Read(&s)) {
        StateRecord r;
        r.arrival_ns = service::UnixNowNs();
        r.run = s.aggregator_run_id();
        r.epoch = s.stop_epoch();
        r.state = s.state();
        if (s.has_cause()) {
          r.kind = s.cause().kind();
          r.patch = s.cause().patch_id();
          r.message = s.cause().message();
        }
        last_arrival_ns_ = r.arrival_ns;
        std::lock_guard lock(mu_);
        log_.push_back(std::move(r));
      }
      reader->Finish();
      {
        std::lock_guard lock(ctx_mu_);
        ctx_ = nullptr;
      }
      if (!stop_) std::this_thread::sleep_for(20ms);
    }
  }
  std::unique_ptr<v1::Aggregator::Stub> stub_;
  std::mutex mu_, ctx_mu_;
  grpc::ClientContext* ctx_ = nullptr;
  std::vector<StateRecord> log_;
  std::atomic<bool> stop_{false};
  std::atomic<std::int64_t> last_arrival_ns_{0};
  std::thread thread_;
};

// Threads that open WatchSafety and WatchContacts streams and abandon them after a random while: cancelled, or
// the channel simply dropped (a client that vanished).
class WatchChurn {
 public:
  WatchChurn(const std::string& address, int threads, std::uint64_t seed) {
    for (int i = 0; i < threads; ++i) {
      threads_.emplace_back([this, address, seed, i] { Run(address, seed + static_cast<std::uint64_t>(i)); });
    }
  }
  ~WatchChurn() { Stop(); }
  void Stop() {
    stop_ = true;
    for (auto& t : threads_) {
      if (t.joinable()) t.join();
    }
  }
  [[nodiscard]] std::uint64_t calls() const { return calls_.load(); }

 private:
  void Run(const std::string& address, std::uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::shared_ptr<grpc::Channel> channel;
    while (!stop_) {
      if (!channel || u(rng) < 0.3) channel = grpc::CreateChannel(address, grpc::InsecureChannelCredentials());
      auto stub = v1::Aggregator::NewStub(channel);
      grpc::ClientContext ctx;
      const auto deadline = Clock::now() + std::chrono::milliseconds(5 + static_cast<int>(u(rng) * 300));
      ctx.set_deadline(std::chrono::system_clock::now() + 2s);
      if (u(rng) < 0.5) {
        v1::WatchSafetyRequest req;
        req.set_subscriber("soak churn");
        auto r = stub->WatchSafety(&ctx, req);
        v1::SafetyState s;
        while (!stop_ && Clock::now() < deadline && r->Read(&s)) {}
        ctx.TryCancel();
        r->Finish();
      } else {
        v1::WatchContactsRequest req;
        req.set_subscriber("soak churn");
        auto r = stub->WatchContacts(&ctx, req);
        v1::ContactSet s;
        while (!stop_ && Clock::now() < deadline && r->Read(&s)) {}
        ctx.TryCancel();
        r->Finish();
      }
      calls_.fetch_add(1);
      std::this_thread::sleep_for(std::chrono::milliseconds(10 + static_cast<int>(u(rng) * 90)));
    }
  }
  std::atomic<bool> stop_{false};
  std::atomic<std::uint64_t> calls_{0};
  std::vector<std::thread> threads_;
};

// --- Faults the soak injects -------------------------------------------------------------------------------

struct Injection {
  std::string what;     // "kill", "term", "freeze", "throttle", "freeze controller_b", "aggregator restart"
  std::string target;   // a patch, "controller_b" or "aggregator"
  std::int64_t from_ns = 0, to_ns = 0;  // the fault's span (to: when it was undone, or the process restarted)
};

// How long after an injection's end its consequences may still show: a restarted decoder's baseline (1 s) and
// hello, a frozen link's keepalive (3 s) and reconnect back-off.
constexpr std::int64_t kAftermathNs = 12'000'000'000;

struct ProcSample {
  double t_s = 0;
  long rss_kb = -1;
  int fds = -1;
};

long RssKb(pid_t pid) {
  std::ifstream f("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(f, line)) {
    if (line.rfind("VmRSS:", 0) == 0) return std::strtol(line.c_str() + 6, nullptr, 10);
  }
  return -1;
}

int OpenFds(pid_t pid) {
  DIR* d = opendir(("/proc/" + std::to_string(pid) + "/fd").c_str());
  if (d == nullptr) return -1;
  int n = 0;
  while (const dirent* e = readdir(d)) n += e->d_name[0] != '.';
  closedir(d);
  return n;
}

// Halt intervals of one ruffini-controller, from its --unix-time stdout lines.
struct ControllerTimeline {
  std::string name;
  std::vector<std::pair<std::int64_t, std::int64_t>> halted;  // [from, to); to = INT64_MAX while halted
  std::vector<std::pair<std::int64_t, std::uint64_t>> clears;  // (t, epoch)
  std::map<std::string, int> halt_reasons;
  [[nodiscard]] bool HaltedAt(std::int64_t t) const {
    for (const auto& [a, b] : halted) {
      if (a <= t && t < b) return true;
    }
    return false;
  }
  // Seconds halted within [from, to).
  [[nodiscard]] double HaltedSeconds(std::int64_t from, std::int64_t to) const {
    double sum = 0;
    for (const auto& [a, b] : halted) sum += static_cast<double>(std::max<std::int64_t>(0, std::min(b, to) - std::max(a, from)));
    return sum / 1e9;
  }
  // When the robot was halted at or after t (t itself when already halted), or nullopt.
  [[nodiscard]] std::optional<std::int64_t> HaltFrom(std::int64_t t) const {
    for (const auto& [a, b] : halted) {
      if (a <= t && t < b) return t;
      if (a > t) return a;
    }
    return std::nullopt;
  }
};

ControllerTimeline ParseController(const std::string& name, const std::string& out, std::int64_t started_ns) {
  ControllerTimeline c;
  c.name = name;
  std::int64_t halted_since = started_ns;  // a controller starts halted (NOT_STARTED)
  std::istringstream in(out);
  std::string line;
  while (std::getline(in, line)) {
    long long t = 0;
    char kind[16] = {0};
    if (std::sscanf(line.c_str(), "t_unix_ns=%lld %15s", &t, kind) != 2) continue;
    const std::string k = kind;
    if (k == "HALT") {
      const auto colon = line.find(':', line.find("HALT"));
      ++c.halt_reasons[line.substr(line.find("HALT") + 5, colon == std::string::npos ? 0 : colon - line.find("HALT") - 5)];
      if (halted_since < 0) halted_since = t;
    } else if (k == "CLEAR") {
      unsigned long long epoch = 0;
      const auto at = line.find("epoch ");
      if (at != std::string::npos) epoch = std::strtoull(line.c_str() + at + 6, nullptr, 10);
      c.clears.emplace_back(t, epoch);
      if (halted_since >= 0) c.halted.emplace_back(halted_since, t);
      halted_since = -1;
    }
  }
  if (halted_since >= 0) c.halted.emplace_back(halted_since, INT64_MAX);
  return c;
}

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1))];
}

// The scene at `path` with only its first `n` patches, written to `to` (relative paths made absolute, so the
// copy reads the same robot, specs and models); returns `to`. A soak at 8 patches then needs no second scene.
std::string ScenePrefix(const std::string& path, int n, const std::string& to) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::Exception& e) {
    throw InputError(path + ": " + e.what());
  }
  const YAML::Node patches = root["patches"];
  if (!patches || !patches.IsSequence() || n < 1 || static_cast<std::size_t>(n) > patches.size()) {
    throw InputError("--patches " + std::to_string(n) + ": " + path + " has " +
                     std::to_string(patches && patches.IsSequence() ? patches.size() : 0) + " patches");
  }
  const fs::path dir = fs::absolute(path).parent_path();
  auto absolute = [&](YAML::Node node, const char* key) {
    if (node[key] && node[key].IsScalar()) node[key] = (dir / node[key].as<std::string>()).lexically_normal().string();
  };
  YAML::Node kept(YAML::NodeType::Sequence);
  for (int i = 0; i < n; ++i) {
    YAML::Node p = YAML::Clone(patches[static_cast<std::size_t>(i)]);
    absolute(p, "spec");
    absolute(p, "model");
    kept.push_back(p);
  }
  root["patches"] = kept;
  if (root["robot"]) absolute(root["robot"], "urdf");
  std::ofstream f(to);
  f << "# " << path << " with its first " << n << " patches (ruffini soak --patches " << n << ")\n" << root << "\n";
  if (!f) throw InputError("cannot write " + to);
  return to;
}

}  // namespace

SoakResult RunSoak(const SoakOptions& o, const std::function<void(const std::string&)>& log) {
  RequireServiceExecutables(o.bin_dir);
  if (!(o.duration_s > 0)) throw InputError("--duration-s must be above 0");
  const fs::path out = o.out_dir;
  fs::create_directories(out);
  // --patches N: the scene's first N patches, written as OUT/scene.yaml (what every service is given).
  const std::string scene_path = o.patches > 0 ? ScenePrefix(o.scene_path, o.patches, (out / "scene.yaml").string())
                                               : o.scene_path;
  const SceneFile scene = LoadSceneFile(scene_path);
  if (!scene.robot || !scene.safety) {
    throw InputError(o.scene_path + ": the soak needs a scene with a robot and a safety section (e.g. "
                     "config/scenes/soak-16.yaml)");
  }
  if (scene.patches.size() > 16) throw InputError(o.scene_path + ": one interrogator streams at most 16 patches");
  const safety::Config safety_config = safety::ConfigFromScene(scene);
  std::vector<std::string> patches;
  std::vector<double> thresholds;
  for (const auto& p : safety_config.patches) {
    patches.push_back(p.id);
    double th = 0;
    for (const auto& r : safety_config.regions) {
      if (r.name == p.region) th = r.threshold_n;
    }
    thresholds.push_back(th);
  }
  const int proxied = std::clamp(o.proxied_decoders, 0, static_cast<int>(patches.size()));

  const fs::path run = out / "logs";
  fs::remove_all(run);
  fs::create_directories(run);
  auto exe = [&](const char* name) { return (fs::path(o.bin_dir) / name).string(); };
  const std::string rate = std::to_string(static_cast<int>(o.rate_hz));
  std::mt19937_64 rng(o.seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);

  // The scenario: presses from start_s of the sim's time, for duration_s.
  constexpr double kStartS = 10.0;  // decoders up, baselines captured, the start-up FAULT reset
  const auto presses = MakePresses(o, thresholds, kStartS, rng);
  const std::string scenario = (run / "scenario.yaml").string();
  WriteScenario(scenario, presses, patches, kStartS + o.duration_s + 60.0, o.seed);

  // --- Start-up -----------------------------------------------------------------------------------------
  // --realtime-priority, --stand-in-priority: a process started under chrt (the same pid after its exec, so
  // signals, RSS and fds still reach the service).
  if (o.realtime_priority < 0 || o.realtime_priority > 89) throw InputError("--realtime-priority: expected 0..89");
  if (o.stand_in_priority < 0 || o.stand_in_priority > 99) throw InputError("--stand-in-priority: expected 0..99");
  const int services_priority = o.realtime_priority;
  const int stand_in = o.stand_in_priority > 0 ? o.stand_in_priority
                                               : (o.realtime_priority > 0 ? o.realtime_priority + 10 : 0);
  const std::string chrt = "/usr/bin/chrt";
  if ((services_priority > 0 || stand_in > 0) && !fs::exists(chrt)) {
    throw InputError("--realtime-priority and --stand-in-priority need " + chrt + " (util-linux)");
  }
  auto fifo = [&](std::vector<std::string> args, int priority) {
    if (priority > 0) args.insert(args.begin(), {chrt, "--fifo", std::to_string(priority)});
    return args;
  };
  auto start_aggregator = [&](const std::string& listen, int generation) {
    const fs::path dir = run / ("aggregator-" + std::to_string(generation));
    std::vector<std::string> args{exe("ruffini-aggregator"), "--insecure", "--scene", scene_path, "--listen", listen,
                                  "--metrics", "127.0.0.1:0", "--ports-file", (dir / "ports").string()};
    if (o.freshness_budget_ms > 0) {
      args.insert(args.end(), {"--patch-freshness-ms", std::to_string(o.freshness_budget_ms)});
    }
    auto child = std::make_unique<Child>(fifo(args, services_priority), dir.string());
    const int port = child->WaitPort((dir / "ports").string(), "grpc", 20s);
    if (port == 0) throw InputError("ruffini-aggregator did not start: " + child->stderr_text());
    return std::make_pair(std::move(child), port);
  };
  log("starting ruffini-aggregator (" + scene_path + ", " + std::to_string(patches.size()) + " patches)");
  auto [aggregator, grpc_port] = start_aggregator("127.0.0.1:0", 1);
  const std::string address = "127.0.0.1:" + std::to_string(grpc_port);
  SafetyWatch watch(address);

  service::TcpProxy controller_b_proxy(grpc_port);
  std::vector<std::unique_ptr<service::TcpProxy>> decoder_proxies;
  for (int i = 0; i < proxied; ++i) decoder_proxies.push_back(std::make_unique<service::TcpProxy>(grpc_port));
  if (stand_in > 0) {
    bool ok = controller_b_proxy.SetRealtimePriority(stand_in);
    for (auto& p : decoder_proxies) ok = p->SetRealtimePriority(stand_in) && ok;
    if (!ok) throw InputError("SCHED_FIFO " + std::to_string(stand_in) + " refused for the proxies' threads (needs CAP_SYS_NICE)");
  }

  auto start_controller = [&](const std::string& name, const std::string& addr, bool watch_only) {
    std::vector<std::string> args{exe("ruffini-controller"), "--insecure", "--robot", scene.name, "--aggregator", addr,
                                  "--rate-hz", std::to_string(static_cast<int>(o.joint_rate_hz)), "--unix-time",
                                  "--subscriber", name, "--connect-timeout-s", "20"};
    if (watch_only) args.push_back("--watch-only");
    if (o.freshness_budget_ms > 0) args.insert(args.end(), {"--freshness-budget-ms", std::to_string(o.freshness_budget_ms)});
    return std::make_unique<Child>(fifo(args, services_priority), (run / name).string());
  };
  const std::int64_t controllers_started_ns = service::UnixNowNs();
  auto controller_a = start_controller("controller_a", address, false);
  auto controller_b = start_controller("controller_b", controller_b_proxy.address(), true);

  log("starting ruffini-sim (" + rate + " Hz, " + std::to_string(presses.size()) + " scripted presses)");
  Child sim(fifo({exe("ruffini-sim"), "--scene", scene_path, "--scenario", scenario, "--rate-hz", rate,
                  "--command-port", "0", "--stream-port", "0", "--ports-file", (run / "sim" / "ports").string()},
                 stand_in),
            (run / "sim").string());
  const int stream_port = sim.WaitPort((run / "sim" / "ports").string(), "stream", 30s);
  if (stream_port == 0) throw InputError("ruffini-sim did not start: " + sim.stderr_text());
  // The sim's sample 0 on the Unix clock (it logs it): the scenario's time 0.
  const std::int64_t sim_t0 = SimSampleZeroNs([&] { return sim.stderr_text(); }, 10s);
  auto unix_of = [&](double sim_s) { return sim_t0 + static_cast<std::int64_t>(sim_s * 1e9); };
  auto now_s = [&] { return static_cast<double>(service::UnixNowNs() - sim_t0) / 1e9; };

  std::vector<std::unique_ptr<Child>> decoders(patches.size());
  std::vector<std::int64_t> decoder_started_ns(patches.size(), 0);
  int decoder_generation = 0;
  auto start_decoder = [&](std::size_t i) {
    const std::string agg = static_cast<int>(i) < proxied ? decoder_proxies[i]->address() : address;
    std::vector<std::string> args{exe("ruffini-decoder"), "--insecure", "--scene", scene_path, "--patch", patches[i],
                                  "--interrogator", "127.0.0.1:" + std::to_string(stream_port), "--aggregator", agg,
                                  "--metrics", "127.0.0.1:0", "--rate-hz", rate};
    if (o.freshness_budget_ms > 0) {
      args.insert(args.end(), {"--freshness-budget-ms", std::to_string(o.freshness_budget_ms)});
    }
    decoders[i] = std::make_unique<Child>(
        fifo(args, services_priority), (run / ("decoder-" + patches[i] + "-" + std::to_string(++decoder_generation))).string());
    decoder_started_ns[i] = service::UnixNowNs();
  };
  for (std::size_t i = 0; i < patches.size(); ++i) start_decoder(i);
  log(std::to_string(patches.size()) + " decoders started (" + std::to_string(proxied) +
      " behind a proxy); two controllers (controller_b behind a proxy, watch only)");
  WatchChurn churn(address, o.churn_threads, o.seed * 7919 + 1);

  // --- The soak -----------------------------------------------------------------------------------------
  std::vector<Injection> injections;
  struct AcceptedReset {
    std::uint64_t run = 0, epoch = 0;
    std::int64_t requested_ns = 0;
  };
  std::vector<AcceptedReset> resets;
  int crashes = 0;
  std::vector<std::string> crash_notes;
  std::map<std::string, std::vector<ProcSample>> samples;
  std::vector<std::int64_t> aggregator_restarts;

  // A press under way (or about to start, or just released) on any patch: the operator waits.
  auto press_near = [&](double t_s, double before_s, double after_s) {
    for (const auto& p : presses) {
      if (t_s >= p.t_s - before_s && t_s <= p.end_s() + after_s) return true;
    }
    return false;
  };
  // Patch i is pressed in [from_s, to_s]?
  auto patch_pressed = [&](std::size_t i, double from_s, double to_s) {
    for (const auto& p : presses) {
      if (p.patch == i && p.end_s() >= from_s && p.t_s <= to_s) return true;
    }
    return false;
  };
  auto exp_interval = [&](double mean_s) { return mean_s <= 0 ? 1e300 : -mean_s * std::log(1.0 - 0.999 * u(rng)); };

  double next_kill_s = kStartS + exp_interval(o.kill_every_s);
  double next_link_s = kStartS + exp_interval(o.link_fault_every_s);
  const double restart_at_s = kStartS + o.duration_s / 2;
  bool restarted = !o.restart_aggregator;
  struct Pending {
    double at_s;
    std::function<void()> action;
  };
  std::vector<Pending> pending;
  double next_sample_s = 0, next_reset_s = 0, next_progress_s = kStartS, next_ack_s = 0;
  int acknowledgements = 0;
  std::vector<std::pair<std::int64_t, double>> stalls;  // (when, ms late) of the soak's own loop
  const double end_s = kStartS + o.duration_s + 3.0;

  // A process that ends without being told to is a crash (reported once; keyed by its log folder, one per process).
  std::set<std::string> stopped_by_us, reported_exits;
  auto check_children_once = [&] {
    auto check = [&](Child& c, const std::string& name) {
      if (c.Running() || stopped_by_us.count(c.dir()) || !reported_exits.insert(c.dir()).second) return;
      ++crashes;
      const std::string err = c.stderr_text();
      crash_notes.push_back(name + " exited by itself at " + Fmt("%.1f", now_s()) + " s; stderr ends: " +
                            err.substr(err.size() > 400 ? err.size() - 400 : 0));
      log("CRASH: " + crash_notes.back());
    };
    check(*aggregator, "ruffini-aggregator");
    check(sim, "ruffini-sim");
    check(*controller_a, "controller_a");
    check(*controller_b, "controller_b");
    for (std::size_t i = 0; i < decoders.size(); ++i) {
      if (decoders[i]) check(*decoders[i], "decoder " + patches[i]);
    }
  };

  while (now_s() < end_s) {
    const double t = now_s();
    // Scheduled undo actions (restart a killed decoder, lift a throttle, close frozen connections).
    for (std::size_t k = 0; k < pending.size();) {
      if (pending[k].at_s <= t) {
        auto action = std::move(pending[k].action);
        pending.erase(pending.begin() + static_cast<std::ptrdiff_t>(k));
        action();
      } else {
        ++k;
      }
    }
    // A decoder killed (SIGKILL, or SIGTERM a third of the time) and restarted 0.5-2 s later; never one whose
    // patch is pressed around then (a baseline captured under a press is another issue's subject).
    if (t >= next_kill_s && t < kStartS + o.duration_s - 5) {
      next_kill_s = t + exp_interval(o.kill_every_s);
      const double down_s = 0.5 + 1.5 * u(rng);
      std::vector<std::size_t> candidates;
      for (std::size_t i = 0; i < patches.size(); ++i) {
        // Started: it has logged its first line, after it blocked the stop signals (decoder/main.cpp). A SIGTERM
        // before that ends it by the signal's default action, no crash of the decoder (a loaded CI machine
        // restarted one and killed it again before it ran).
        const bool settled = decoders[i] && !decoders[i]->stderr_text().empty();
        if (!patch_pressed(i, t - 0.5, t + down_s + 4.0) && decoders[i] && decoders[i]->Running() && settled) {
          candidates.push_back(i);
        }
      }
      if (!candidates.empty()) {
        const std::size_t i = candidates[static_cast<std::size_t>(u(rng) * static_cast<double>(candidates.size())) % candidates.size()];
        const bool term = u(rng) < 1.0 / 3.0;
        Injection inj{term ? "SIGTERM decoder" : "SIGKILL decoder", patches[i], service::UnixNowNs(), 0};
        stopped_by_us.insert(decoders[i]->dir());
        if (term) {
          const int status = decoders[i]->Stop(2000ms);
          if (status != 0) {
            ++crashes;
            crash_notes.push_back("decoder " + patches[i] + ": SIGTERM gave exit status " + std::to_string(status));
          }
        } else {
          decoders[i]->Signal(SIGKILL);
          decoders[i]->Stop(1000ms);  // reap it
        }
        const std::size_t index = injections.size();
        injections.push_back(inj);
        pending.push_back({t + down_s, [&, i, index] {
                             start_decoder(i);
                             injections[index].to_ns = service::UnixNowNs();
                           }});
        log(Fmt("%7.1f s  ", t) + inj.what + " " + patches[i] + ", back in " + Fmt("%.1f", down_s) + " s");
      }
    }
    // A proxied link frozen (its connections never forward again; the peers' keepalive gives up on them) or
    // throttled to 2 kB/s for 3 s: a decoder's, or controller_b's.
    if (t >= next_link_s && t < kStartS + o.duration_s - 5) {
      next_link_s = t + exp_interval(o.link_fault_every_s);
      const int targets = proxied + 1;
      const int k = static_cast<int>(u(rng) * targets) % targets;
      service::TcpProxy* proxy = k < proxied ? decoder_proxies[static_cast<std::size_t>(k)].get() : &controller_b_proxy;
      const std::string target = k < proxied ? patches[static_cast<std::size_t>(k)] : "controller_b";
      const bool freeze = k == proxied || u(rng) < 0.5;
      const std::size_t index = injections.size();
      injections.push_back({freeze ? "freeze link" : "throttle link to 2 kB/s", target, service::UnixNowNs(), 0});
      if (freeze) {
        proxy->Freeze();
        pending.push_back({t + 10.0, [&, proxy, index] {
                             proxy->CloseFrozen();
                             injections[index].to_ns = service::UnixNowNs();
                           }});
      } else {
        proxy->Throttle(2000);
        pending.push_back({t + 3.0, [&, proxy, index] {
                             proxy->Throttle(0);
                             injections[index].to_ns = service::UnixNowNs();
                           }});
      }
      log(Fmt("%7.1f s  ", t) + injections[index].what + " of " + target);
    }
    // The aggregator restarted once, on the same port (SIGTERM must end it within 2 s).
    if (!restarted && t >= restart_at_s) {
      restarted = true;
      Injection inj{"aggregator restart", "aggregator", service::UnixNowNs(), 0};
      const auto t0 = Clock::now();
      stopped_by_us.insert(aggregator->dir());
      const int status = aggregator->Stop(2000ms);
      const double stop_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
      if (status != 0) {
        ++crashes;
        crash_notes.push_back("ruffini-aggregator: SIGTERM gave exit status " + std::to_string(status) + " after " +
                              Fmt("%.0f", stop_ms) + " ms");
      }
      auto [next, port] = start_aggregator(address, 2);
      aggregator = std::move(next);
      inj.to_ns = service::UnixNowNs();
      aggregator_restarts.push_back(inj.from_ns);
      injections.push_back(inj);
      log(Fmt("%7.1f s  ", t) + "aggregator restarted on " + address + " (the old one exited in " +
          Fmt("%.0f", stop_ms) + " ms)");
    }
    // The operator: once nothing is pressed, a stop or fault is reset (its run and epoch, as last seen).
    if (t >= next_reset_s && !press_near(t, 0.3, 0.4)) {
      next_reset_s = t + 0.2;
      const auto latest = watch.Latest();
      if (latest && latest->state != v1::SafetyState::STATE_CLEAR && latest->run != 0) {
        std::string message;
        const std::int64_t requested = service::UnixNowNs();
        if (watch.Reset(latest->run, latest->epoch, message)) {
          resets.push_back({latest->run, latest->epoch, requested});
        }
      }
    }
    // The operator also acknowledges a controller's latched link-error halt (ruffini-controller: SIGUSR1), as
    // the operator of a real cell would once the link is back; how often it was needed is in the report.
    if (t >= next_ack_s && !press_near(t, 0.3, 0.4)) {
      next_ack_s = t + 0.5;
      for (auto* c : {controller_a.get(), controller_b.get()}) {
        const std::string text = c->stdout_text();
        const auto latched = text.rfind("[latched"), acked = text.rfind("ACK LINK_ERRORS");
        if (latched != std::string::npos && (acked == std::string::npos || acked < latched)) {
          c->Signal(SIGUSR1);
          ++acknowledgements;
        }
      }
    }
    // RSS and fds.
    if (t >= next_sample_s) {
      next_sample_s = t + o.sample_every_s;
      // Per process: keyed by its log folder (a restarted decoder or aggregator is a new series).
      auto sample = [&](Child* c) {
        if (c == nullptr || !c->Running()) return;
        samples[fs::path(c->dir()).filename().string()].push_back({t, RssKb(c->pid()), OpenFds(c->pid())});
      };
      sample(aggregator.get());
      sample(&sim);
      sample(controller_a.get());
      sample(controller_b.get());
      for (auto& d : decoders) sample(d.get());
      samples["ruffini soak"].push_back({t, RssKb(getpid()), OpenFds(getpid())});
    }
    if (t >= next_progress_s) {
      next_progress_s = t + 60.0;
      const auto latest = watch.Latest();
      log(Fmt("%7.1f s  ", t) + "state " + (latest ? std::string(StateName(latest->state)) + " epoch " +
                                                  std::to_string(latest->epoch)
                                            : std::string("none")) +
          "; " + std::to_string(resets.size()) + " resets accepted, " + std::to_string(injections.size()) +
          " faults injected, " + std::to_string(churn.calls()) + " watch calls churned");
    }
    check_children_once();
    // The host's own hiccups, measured: how late this loop's 10 ms sleep woke (a stalled host starves the
    // services too; the report puts each unexplained fault beside the stalls around it).
    const auto slept_from = Clock::now();
    std::this_thread::sleep_for(10ms);
    const double late_ms = std::chrono::duration<double, std::milli>(Clock::now() - slept_from).count() - 10.0;
    if (late_ms > 20.0) stalls.push_back({service::UnixNowNs(), late_ms});
  }
  const std::int64_t shutdown_ns = service::UnixNowNs();  // what fails from here on is the shutdown's doing
  for (auto& p : pending) p.action();  // restart what is still down, so that every process ends by SIGTERM
  pending.clear();
  churn.Stop();

  // --- Shut down: by pid, every exit status checked ------------------------------------------------------
  log("stopping: controllers, decoders, sim, aggregator");
  check_children_once();
  auto stop = [&](Child& c, const std::string& name) {
    if (reported_exits.count(c.dir())) return;  // already counted
    stopped_by_us.insert(c.dir());
    const int status = c.Stop(3000ms);
    if (status != 0) {
      ++crashes;
      crash_notes.push_back(name + ": exit status " + std::to_string(status) + " at shutdown");
    }
  };
  stop(*controller_a, "controller_a");
  stop(*controller_b, "controller_b");
  for (std::size_t i = 0; i < decoders.size(); ++i) stop(*decoders[i], "decoder " + patches[i]);
  stop(sim, "ruffini-sim");
  stop(*aggregator, "ruffini-aggregator");
  watch.Stop();

  // --- Judgement ----------------------------------------------------------------------------------------
  const auto states = watch.States();
  std::vector<ControllerTimeline> controllers{
      ParseController("controller_a", controller_a->stdout_text(), controllers_started_ns),
      ParseController("controller_b", controller_b->stdout_text(), controllers_started_ns)};
  SoakResult result;
  std::ostringstream findings;

  // 1. Every press above the threshold: every controller halted within the bound of the true crossing.
  const auto bound_ns = static_cast<std::int64_t>(o.stop_bound_ms * 1e6);
  std::map<std::string, std::vector<double>> halt_ms;  // per controller: crossing to halt (0: already halted)
  std::map<std::string, std::vector<double>> moving_ms;  // the same, for presses that met the robot moving
  for (const auto& p : presses) {
    if (!p.above()) {
      ++result.presses_below;
      continue;
    }
    // A press whose crossing plus the bound falls after the soak's end is not judged.
    if (unix_of(p.crossing_s()) + bound_ns > unix_of(end_s) - 500'000'000) continue;
    ++result.presses_above;
    const std::int64_t crossing = unix_of(p.crossing_s());
    bool lost = false;
    std::string why;
    for (const auto& c : controllers) {
      const auto h = c.HaltFrom(crossing);
      const double ms = h ? static_cast<double>(*h - crossing) / 1e6 : INFINITY;
      halt_ms[c.name].push_back(ms);
      if (!c.HaltedAt(crossing)) moving_ms[c.name].push_back(ms);
      if (!(ms <= o.stop_bound_ms) || !c.HaltedAt(crossing + bound_ns)) {
        lost = true;
        why += " " + c.name + (h ? " halted after " + Fmt("%.1f", ms) + " ms" : " never halted");
      }
    }
    if (lost) {
      ++result.lost_stops;
      findings << "- LOST STOP: press at " << Fmt("%.2f", p.t_s) << " s on " << patches[p.patch] << " (Y "
               << Fmt("%.0f", p.y_mm) << " mm, R " << Fmt("%.0f", p.r_deg) << " deg, " << Fmt("%.2f", p.force_n)
               << " N, crossing at " << Fmt("%.3f", p.crossing_s()) << " s):" << why << "\n";
    }
  }

  // 2. Every CLEAR (published, or acted on by a controller) of an epoch an accepted reset cleared, requested before.
  auto reset_before = [&](std::uint64_t run_id, std::uint64_t epoch, std::int64_t t) {
    for (const auto& r : resets) {
      if ((run_id == 0 || r.run == run_id) && r.epoch == epoch && r.requested_ns <= t) return true;
    }
    return false;
  };
  auto run_at = [&](std::int64_t t) -> std::uint64_t {  // the run whose states arrived last before t
    std::uint64_t run_id = 0;
    for (const auto& s : states) {
      if (s.arrival_ns > t) break;
      run_id = s.run;
    }
    return run_id;
  };
  {
    std::set<std::pair<std::uint64_t, std::uint64_t>> seen;
    for (const auto& s : states) {
      if (s.state != v1::SafetyState::STATE_CLEAR || !seen.insert({s.run, s.epoch}).second) continue;
      if (!reset_before(s.run, s.epoch, s.arrival_ns)) {
        ++result.false_clears;
        findings << "- FALSE CLEAR at the aggregator: run " << s.run << " epoch " << s.epoch << " CLEAR at "
                 << Fmt("%.3f", static_cast<double>(s.arrival_ns - sim_t0) / 1e9) << " s with no accepted reset\n";
      }
    }
    for (const auto& c : controllers) {
      for (const auto& [t, epoch] : c.clears) {
        if (!reset_before(run_at(t), epoch, t)) {
          ++result.false_clears;
          findings << "- FALSE CLEAR at " << c.name << ": epoch " << epoch << " at "
                   << Fmt("%.3f", static_cast<double>(t - sim_t0) / 1e9) << " s with no accepted reset\n";
        }
      }
    }
  }

  // 3. Every FAULT explained by an injected fault: the start of each run, or a fault injected on its patch (or,
  // for controller_b's link, nothing the aggregator sees), up to kAftermathNs after it was undone.
  // A run is in service from its first accepted reset: before it, it is starting (decoders capturing their
  // baselines, connecting: every fault then is the start-up's).
  std::map<std::uint64_t, std::int64_t> in_service_ns;
  for (const auto& r : resets) {
    if (!in_service_ns.count(r.run)) in_service_ns[r.run] = r.requested_ns;
  }
  // The sim's late wake-ups (ruffini-sim logs each one more than 10 ms after its deadline, with its thread's
  // CPU time over the gap): an unexplained silence that follows one started at the interrogator's stand-in.
  struct SimLate {
    std::int64_t unix_ns = 0;  // the deadline it missed, on the Unix clock
    double late_ms = 0, gap_ms = 0, cpu_ms = 0;
  };
  std::vector<SimLate> sim_late;
  {
    const std::string err = sim.stderr_text();
    const std::string key = "late wake-up: sample ";
    for (std::size_t at = err.find(key); at != std::string::npos; at = err.find(key, at + key.size())) {
      unsigned long long k = 0;
      SimLate l;
      if (std::sscanf(err.c_str() + at + key.size(),
                      "%llu %lf ms after its deadline; since the previous wake-up %lf ms of wall time, %lf ms", &k,
                      &l.late_ms, &l.gap_ms, &l.cpu_ms) == 4) {
        l.unix_ns = sim_t0 + static_cast<std::int64_t>(static_cast<double>(k) * 1e9 / o.rate_hz);
        sim_late.push_back(l);
      }
    }
  }
  std::map<std::string, int> fault_kinds;
  {
    std::set<std::tuple<std::uint64_t, std::uint64_t, int, std::string>> seen;
    for (const auto& s : states) {
      // A contact is judged as a stop (below), whatever the state it came in (FAULT while a fault is present).
      if (s.state != v1::SafetyState::STATE_FAULT || s.kind == v1::SafetyCause::KIND_CONTACT) continue;
      if (!seen.insert({s.run, s.epoch, static_cast<int>(s.kind), s.patch}).second) continue;
      const std::string kind = v1::SafetyCause::Kind_Name(s.kind);
      ++fault_kinds[kind];
      const auto service = in_service_ns.find(s.run);
      bool explained = service == in_service_ns.end() || s.arrival_ns < service->second || s.arrival_ns >= shutdown_ns;
      if (s.kind == v1::SafetyCause::KIND_SHUTTING_DOWN) {
        for (const auto r : aggregator_restarts) explained |= s.arrival_ns >= r - 1'000'000'000 && s.arrival_ns <= r + 5'000'000'000;
      }
      for (const auto& inj : injections) {
        const std::int64_t until = (inj.to_ns > 0 ? inj.to_ns : INT64_MAX - kAftermathNs) + kAftermathNs;
        if (s.arrival_ns < inj.from_ns - 100'000'000 || s.arrival_ns > until) continue;
        if (inj.target == "aggregator" || (!s.patch.empty() && inj.target == s.patch)) explained = true;
      }
      if (!explained) {
        ++result.unexplained_faults;
        double stall_ms = 0;
        for (const auto& [when, ms] : stalls) {
          if (std::abs(when - s.arrival_ns) < 200'000'000) stall_ms = std::max(stall_ms, ms);
        }
        findings << "- UNEXPLAINED FAULT: run " << s.run << " epoch " << s.epoch << " at "
                 << Fmt("%.3f", static_cast<double>(s.arrival_ns - sim_t0) / 1e9) << " s: " << kind << " "
                 << s.patch << " (" << s.message << ")"
                 << (stall_ms > 0 ? "; the host stalled then (the soak's own 10 ms sleep woke " + Fmt("%.0f", stall_ms) +
                                        " ms late within 0.2 s)"
                                  : std::string());
        for (const auto& l : sim_late) {
          if (l.unix_ns < s.arrival_ns - 200'000'000 || l.unix_ns > s.arrival_ns) continue;
          findings << "; the sim woke " << Fmt("%.1f", l.late_ms) << " ms late "
                   << Fmt("%.0f", static_cast<double>(s.arrival_ns - l.unix_ns) / 1e6) << " ms before ("
                   << Fmt("%.1f", l.cpu_ms) << " ms of CPU in a " << Fmt("%.1f", l.gap_ms) << " ms gap)";
        }
        findings << "\n";
      }
    }
  }

  // 4. STOPs with no press above the threshold under way (false stops; reported).
  {
    std::set<std::pair<std::uint64_t, std::uint64_t>> seen;
    for (const auto& s : states) {
      if (s.kind != v1::SafetyCause::KIND_CONTACT || !seen.insert({s.run, s.epoch}).second) continue;
      const double t = static_cast<double>(s.arrival_ns - sim_t0) / 1e9;
      bool pressed = false;
      for (const auto& p : presses) pressed |= p.above() && t >= p.crossing_s() - 0.05 && t <= p.end_s() + 0.5;
      if (!pressed) {
        ++result.stops_without_press;
        findings << "- contact cause (STOP) without a press above the threshold: run " << s.run << " epoch " << s.epoch << " at "
                 << Fmt("%.3f", t) << " s: " << s.patch << " (" << s.message << ")\n";
      }
    }
  }
  result.crashes = crashes;
  for (const auto& n : crash_notes) findings << "- CRASH or unclean exit: " << n << "\n";
  result.pass = result.lost_stops == 0 && result.false_clears == 0 && crashes == 0 &&
                (result.unexplained_faults == 0 || !o.unexplained_faults_fail);

  // --- Report ---------------------------------------------------------------------------------------------
  // RSS and fds: the first and last quarter of each long-lived process's samples.
  std::ostringstream resources;
  resources << "| process | samples | RSS first quarter (MB) | RSS last quarter (MB) | fds first | fds last |\n"
            << "| --- | --- | --- | --- | --- | --- |\n";
  for (const auto& [name, v] : samples) {
    if (v.size() < 4) continue;
    const std::size_t q = v.size() / 4;
    auto mean_rss = [&](std::size_t a, std::size_t b) {
      double s = 0;
      for (std::size_t k = a; k < b; ++k) s += static_cast<double>(v[k].rss_kb);
      return s / static_cast<double>(b - a) / 1024.0;
    };
    resources << "| " << name << " | " << v.size() << " | " << Fmt("%.1f", mean_rss(0, q)) << " | "
              << Fmt("%.1f", mean_rss(v.size() - q, v.size())) << " | " << v[q / 2].fds << " | " << v.back().fds
              << " |\n";
  }
  {
    plot::Figure f("Resident memory per process", "time since the sim started (s)", "RSS (MB)", 760, 420);
    for (const auto& [name, v] : samples) {
      if (name.rfind("decoder-", 0) == 0 && name != "decoder-" + patches.back() + "-" + std::to_string(patches.size())) {
        continue;  // one decoder (the last one started at start-up) stands for all
      }
      plot::Series s;
      s.label = name;
      s.style = plot::Series::Style::kLine;
      for (const auto& x : v) {
        s.x.push_back(x.t_s);
        s.y.push_back(static_cast<double>(x.rss_kb) / 1024.0);
      }
      if (!s.x.empty()) f.Add(s);
    }
    for (const auto r : aggregator_restarts) f.AddVLine(static_cast<double>(r - sim_t0) / 1e9, "aggregator restart");
    f.Save((out / "rss.svg").string());
  }
  {
    plot::Figure f("Crossing to halt at each controller", "press (in order)", "ms (0: already halted)", 760, 360);
    for (const auto& [name, v] : halt_ms) {
      plot::Series s;
      s.label = name;
      s.style = plot::Series::Style::kPoints;
      for (std::size_t k = 0; k < v.size(); ++k) {
        s.x.push_back(static_cast<double>(k));
        s.y.push_back(std::isfinite(v[k]) ? v[k] : o.stop_bound_ms * 2);
      }
      f.Add(s);
    }
    f.AddHLine(o.stop_bound_ms, "bound");
    f.Save((out / "halts.svg").string());
  }

  std::map<std::string, int> injected;
  for (const auto& inj : injections) ++injected[inj.what];
  std::ostringstream md;
  md << "# `ruffini soak`\n\n"
     << "Written by `ruffini soak --scene " << o.scene_path
     << (o.patches > 0 ? " --patches " + std::to_string(o.patches) : std::string())
     << (o.realtime_priority > 0 ? " --realtime-priority " + std::to_string(o.realtime_priority) : std::string())
     << (o.stand_in_priority > 0 ? " --stand-in-priority " + std::to_string(o.stand_in_priority) : std::string())
     << " --duration-s " << o.duration_s
     << " --rate-hz "
     << o.rate_hz << " --seed " << o.seed << "` (docs/soak.md). " << patches.size() << " decoders at " << rate
     << " Hz into one aggregator, two controllers (controller_a publishes joint states at "
     << Fmt("%.0f", o.joint_rate_hz) << " Hz; controller_b only obeys, behind a TCP proxy), " << proxied
     << " decoder links behind TCP proxies, " << o.churn_threads << " threads churning watch streams, all on "
     << "127.0.0.1. Machine: " << std::thread::hardware_concurrency() << " hardware threads. Scheduling: "
     << (o.realtime_priority > 0 ? "SCHED_FIFO " + std::to_string(o.realtime_priority) +
                                       " for the decoders, the aggregator and the controllers; "
                                 : std::string("the decoders, the aggregator and the controllers at normal priority; "))
     << (stand_in > 0 ? "SCHED_FIFO " + std::to_string(stand_in) + " for the sim and the proxies (the stand-ins)"
                      : std::string("the sim and the proxies at normal priority"))
     << "; the soak's judge and watch churn at normal priority.\n\n"
     << "**" << (result.pass ? "PASS" : "FAIL") << "**: lost stops " << result.lost_stops << ", false clears "
     << result.false_clears << ", unexplained faults " << result.unexplained_faults << ", crashes " << crashes
     << ".\n\n"
     << "| check | result | must be |\n| --- | --- | --- |\n"
     << "| presses above the threshold (2-3x) with some controller not halted within " << Fmt("%.0f", o.stop_bound_ms)
     << " ms of the true crossing | " << result.lost_stops << " of " << result.presses_above << " | 0 |\n"
     << "| CLEARs (aggregator or controller) with no accepted reset of that epoch | " << result.false_clears
     << " | 0 |\n"
     << "| FAULT causes not explained by an injected fault | " << result.unexplained_faults << " | "
     << (o.unexplained_faults_fail ? "0" : "0 (counted, not failed: --unexplained-faults-fail false)") << " |\n"
     << "| crashes and unclean exits | " << crashes << " | 0 |\n"
     << "| STOPs with no press above the threshold under way (presses below: " << result.presses_below
     << ", at most half the threshold) | " << result.stops_without_press << " | (reported) |\n\n"
     << "## Crossing to halt\n\n| controller | presses | p50 (ms) | p99 (ms) | max (ms) | of which met the robot moving | "
        "their p50 / p99 / max (ms) |\n| --- | --- | --- | --- | --- | --- | --- |\n";
  for (const auto& [name, v] : halt_ms) {
    const auto& m = moving_ms[name];
    md << "| " << name << " | " << v.size() << " | " << Fmt("%.1f", Quantile(v, 0.5)) << " | "
       << Fmt("%.1f", Quantile(v, 0.99)) << " | " << Fmt("%.1f", Quantile(v, 1.0)) << " | " << m.size() << " | "
       << Fmt("%.1f", Quantile(m, 0.5)) << " / " << Fmt("%.1f", Quantile(m, 0.99)) << " / " << Fmt("%.1f", Quantile(m, 1.0))
       << " |\n";
  }
  md << "\nFrom the twin's true threshold crossing (the applied force's linear ramp) to the controller's halt (0 when "
        "it was already halted, e.g. during an injected fault; the last columns leave those out).\n\n## Injected\n\n";
  for (const auto& [what, n] : injected) md << "- " << what << ": " << n << "\n";
  md << "- watch streams opened and abandoned: " << churn.calls() << "\n- operator resets accepted: " << resets.size()
     << "\n- controller link-error latches acknowledged (SIGUSR1): " << acknowledgements
     << "\n\nSim late wake-ups (more than 10 ms after a sample's deadline): " << sim_late.size();
  if (!sim_late.empty()) {
    int idle = 0;
    double worst = 0;
    for (const auto& l : sim_late) {
      idle += l.cpu_ms < 0.5 * l.gap_ms;
      worst = std::max(worst, l.late_ms);
    }
    md << ", the worst " << Fmt("%.1f", worst) << " ms late; in " << idle
       << " of them the sim's thread had less than half the gap on a CPU (it was not running, not busy)";
  }
  md << "\n\nHost stalls (the soak's own 10 ms sleep woke more than 20 ms late): " << stalls.size();
  if (!stalls.empty()) {
    double worst = 0;
    for (const auto& st : stalls) worst = std::max(worst, st.second);
    md << ", the worst " << Fmt("%.0f", worst) << " ms late";
  }
  md << "\n\nFAULT causes seen (each run, epoch, kind and patch once):";
  for (const auto& [k, n] : fault_kinds) md << " " << k << " " << n << ";";
  md << "\n\n## Controllers\n\n";
  for (const auto& c : controllers) {
    md << "- " << c.name << ": halted " << Fmt("%.1f", c.HaltedSeconds(unix_of(kStartS), unix_of(kStartS + o.duration_s)))
       << " s of the soak's " << Fmt("%.0f", o.duration_s) << " s; " << c.clears.size() << " clears; halts by reason:";
    for (const auto& [r, n] : c.halt_reasons) md << " " << r << " " << n << ";";
    md << "\n";
  }
  md << "\n## Resources\n\n" << resources.str() << "\n![rss](rss.svg)\n\n![halts](halts.svg)\n\n## Findings\n\n"
     << (findings.str().empty() ? std::string("None.\n") : findings.str())
     << "\nLogs of every process and the generated scenario are in `logs/`.\n";
  result.report_path = (out / "report.md").string();
  std::ofstream(result.report_path) << md.str();
  return result;
}

}  // namespace ruffini::harness
