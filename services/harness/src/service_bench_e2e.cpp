// `ruffini bench-service`, parts 2 and 3: the real ruffini-sim and ruffini-decoder on 127.0.0.1 (port 0, ports
// files), the decoder publishing to a recording Aggregator in this process; latency per contact message and
// the CPU time of both processes over the window. Every wait has a deadline; every process is stopped by pid
// (SIGTERM, then SIGKILL after a grace period) and reaped.
#include <fcntl.h>
#include <grpcpp/grpcpp.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cctype>
#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <map>
#include <mutex>
#include <optional>
#include <sstream>
#include <thread>

#include "ruffini/error.h"
#include "ruffini/v1/aggregator.grpc.pb.h"
#include "ruffini/scene_file.h"
#include "ruffini/service/child.h"
#include "ruffini/harness/service_bench.h"

extern char** environ;

namespace ruffini::harness {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;

std::int64_t UnixNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

using service::Child;
using service::ReadPorts;
using service::Slurp;

// utime + stime of a process, in clock ticks (fields 14 and 15 of /proc/<pid>/stat); nullopt when gone.
std::optional<std::uint64_t> CpuTicks(pid_t pid) {
  const std::string text = Slurp("/proc/" + std::to_string(pid) + "/stat");
  const auto close = text.rfind(')');
  if (close == std::string::npos) return std::nullopt;
  std::istringstream in(text.substr(close + 1));
  std::string field;
  std::uint64_t utime = 0, stime = 0;
  for (int i = 3; i <= 15 && in >> field; ++i) {  // field 3 (state) is the first after ')'
    if (i == 14) utime = std::stoull(field);
    if (i == 15) stime = std::stoull(field);
  }
  return utime + stime;
}

// utime + stime summed by thread name (comm) over /proc/<pid>/task: where a process's CPU goes.
std::map<std::string, std::uint64_t> ThreadTicks(pid_t pid) {
  std::map<std::string, std::uint64_t> by_name;
  std::error_code ec;
  for (const auto& task : fs::directory_iterator("/proc/" + std::to_string(pid) + "/task", ec)) {
    const std::string text = Slurp((task.path() / "stat").string());
    const auto open = text.find('('), close = text.rfind(')');
    if (open == std::string::npos || close == std::string::npos || close < open) continue;
    std::istringstream in(text.substr(close + 1));
    std::string field;
    std::uint64_t ticks = 0;
    for (int i = 3; i <= 15 && in >> field; ++i) {
      if (i == 14 || i == 15) ticks += std::stoull(field);
    }
    by_name[text.substr(open + 1, close - open - 1)] += ticks;
  }
  return by_name;
}

struct Record {
  enum class Kind : std::uint8_t { kHello, kContact, kHeartbeat, kFault, kOther };
  Kind kind = Kind::kOther;
  std::int64_t t_ns = 0, decoder_t_ns = 0, arrival_ns = 0;
  std::uint64_t serial = 0;
  int fault_code = 0;  // v1::PatchFaultCode
  bool healthy = false;
  std::uint64_t messages_dropped = 0, serial_gaps = 0;
};

// The recording Aggregator: Connect only; accepts every hello and records each message with its arrival time
// (system_clock, Unix ns, taken as soon as Read returns).
class RecordingAggregator final : public v1::Aggregator::Service {
 public:
  // robot_name: the scene's name, as a real aggregator names it in HelloAccepted (the decoder refuses another).
  explicit RecordingAggregator(std::string robot_name) : robot_name_(std::move(robot_name)) {
    records_.reserve(200000);
    grpc::ServerBuilder builder;
    builder.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port_);
    builder.RegisterService(this);
    server_ = builder.BuildAndStart();
    if (!server_ || port_ == 0) throw InputError("bench-service: cannot start the recording aggregator on 127.0.0.1");
  }
  ~RecordingAggregator() override { Shutdown(); }
  RecordingAggregator(const RecordingAggregator&) = delete;
  RecordingAggregator& operator=(const RecordingAggregator&) = delete;

  [[nodiscard]] std::string address() const { return "127.0.0.1:" + std::to_string(port_); }
  void Shutdown() {
    if (!server_) return;
    server_->Shutdown(std::chrono::system_clock::now() + milliseconds(500));
    server_->Wait();
    server_.reset();
  }
  // Waits until a healthy heartbeat has arrived, or `timeout` passes, or `alive` says a process died.
  bool WaitHealthy(milliseconds timeout, const std::function<bool()>& alive) {
    const auto deadline = Clock::now() + timeout;
    std::unique_lock lock(mutex_);
    while (!healthy_seen_) {
      if (Clock::now() >= deadline || !alive()) return false;
      cv_.wait_for(lock, milliseconds(100));
    }
    return true;
  }
  std::vector<Record> Take() {
    std::lock_guard lock(mutex_);
    return std::move(records_);
  }

  grpc::Status Connect(grpc::ServerContext* /*ctx*/,
                       grpc::ServerReaderWriter<v1::AggregatorCommand, v1::PatchMessage>* stream) override {
    v1::PatchMessage m;
    std::uint64_t seq = 0;
    while (stream->Read(&m)) {
      const std::int64_t arrival = UnixNs();
      Record r;
      r.t_ns = m.t_ns();
      r.decoder_t_ns = m.decoder_t_ns();
      r.arrival_ns = arrival;
      r.serial = m.interrogator_serial();
      if (m.has_hello()) r.kind = Record::Kind::kHello;
      if (m.has_contact()) r.kind = Record::Kind::kContact;
      if (m.has_fault()) {
        r.kind = Record::Kind::kFault;
        r.fault_code = static_cast<int>(m.fault().code());
      }
      if (m.has_heartbeat()) {
        r.kind = Record::Kind::kHeartbeat;
        r.healthy = m.heartbeat().healthy();
        r.messages_dropped = m.heartbeat().messages_dropped();
        r.serial_gaps = m.heartbeat().serial_gaps();
      }
      bool notify = false;
      {
        std::lock_guard lock(mutex_);
        records_.push_back(r);
        if (r.healthy && !healthy_seen_) healthy_seen_ = notify = true;
      }
      if (notify) cv_.notify_all();
      if (m.has_hello()) {
        v1::AggregatorCommand c;
        c.set_seq(++seq);
        c.set_t_ns(arrival);
        c.mutable_hello_accepted()->set_patch_id(m.patch_id());
        c.mutable_hello_accepted()->set_watchdog_ns(30'000'000);
        c.mutable_hello_accepted()->set_aggregator_instance("ruffini-bench-service");
        c.mutable_hello_accepted()->set_robot_name(robot_name_);
        stream->Write(c);
      }
    }
    return grpc::Status::OK;
  }

 private:
  std::string robot_name_;
  int port_ = 0;
  std::unique_ptr<grpc::Server> server_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::vector<Record> records_;
  bool healthy_seen_ = false;
};

std::string Rate(double hz) { return std::to_string(static_cast<long long>(hz)); }

// The sim's "write lag (...)" log line at shutdown, without spdlog's prefix.
std::string WriteLagLine(const std::string& log) {
  const auto at = log.rfind("write lag (");
  if (at == std::string::npos) return {};
  const auto end = log.find('\n', at);
  return log.substr(at, end == std::string::npos ? std::string::npos : end - at);
}

}  // namespace

void CheckServiceExecutables(const std::string& bin_dir) {
  for (const char* name : {"ruffini-sim", "ruffini-decoder"}) {
    const std::string exe = (fs::path(bin_dir) / name).string();
    if (access(exe.c_str(), X_OK) != 0) {
      throw InputError("bench-service: " + exe + " not found (or not executable): build it next to `ruffini` "
                       "(cmake --build build/release --target ruffini-sim ruffini-decoder)");
    }
  }
}

EndToEndRun RunEndToEnd(const ServiceBenchOptions& o, double rate_hz, const std::function<void(const std::string&)>& log) {
  CheckServiceExecutables(o.bin_dir);
  const std::string sim_exe = (fs::path(o.bin_dir) / "ruffini-sim").string();
  const std::string decoder_exe = (fs::path(o.bin_dir) / "ruffini-decoder").string();
  const std::string dir = (fs::path(o.work_dir) / ("e2e-" + Rate(rate_hz) + "hz")).string();
  fs::remove_all(dir);
  fs::create_directories(dir);

  EndToEndRun run;
  run.rate_hz = rate_hz;
  RecordingAggregator aggregator(LoadSceneFile(o.scene_path).name);

  const std::string sim_ports = dir + "/sim.ports", decoder_ports = dir + "/decoder.ports";
  Child sim({sim_exe, "--scene", o.scene_path, "--scenario", o.scenario_path, "--rate-hz", Rate(rate_hz),
             "--command-port", "0", "--stream-port", "0", "--ports-file", sim_ports},
            dir + "/sim");
  auto wait_for = [](const std::function<bool()>& cond, milliseconds timeout) {
    const auto deadline = Clock::now() + timeout;
    while (!cond()) {
      if (Clock::now() >= deadline) return false;
      std::this_thread::sleep_for(milliseconds(5));
    }
    return true;
  };
  if (!wait_for([&] { return ReadPorts(sim_ports).count("stream") > 0 || !sim.Running(); }, milliseconds(15000)) ||
      ReadPorts(sim_ports).count("stream") == 0) {
    throw InputError("bench-service: ruffini-sim wrote no ports file within 15 s: " + sim.stderr_text());
  }
  const int stream_port = ReadPorts(sim_ports)["stream"];
  log("e2e " + Rate(rate_hz) + " Hz: sim pid " + std::to_string(sim.pid()) + " streaming on port " +
      std::to_string(stream_port));

  const auto decoder_start = Clock::now();
  Child decoder({decoder_exe, "--insecure", "--scene", o.scene_path, "--patch", o.patch, "--interrogator",
                 "127.0.0.1:" + std::to_string(stream_port), "--aggregator", aggregator.address(), "--metrics",
                 "127.0.0.1:0", "--ports-file", decoder_ports, "--rate-hz", Rate(rate_hz)},
                dir + "/decoder");
  if (!aggregator.WaitHealthy(milliseconds(30000), [&] { return decoder.Running() && sim.Running(); })) {
    const std::string why = decoder.Running() ? "no healthy heartbeat within 30 s" : "ruffini-decoder exited";
    throw InputError("bench-service: " + why + " at " + Rate(rate_hz) + " Hz; decoder log: " + decoder.stderr_text());
  }
  run.capture_wait_s = std::chrono::duration<double>(Clock::now() - decoder_start).count();
  log("e2e " + Rate(rate_hz) + " Hz: decoder pid " + std::to_string(decoder.pid()) + " healthy after " +
      std::to_string(run.capture_wait_s) + " s; warm-up, then a " + std::to_string(o.seconds) + " s window");

  std::this_thread::sleep_for(std::chrono::duration<double>(o.warmup_s));
  const auto dec_threads0 = ThreadTicks(decoder.pid());
  const auto dec0 = CpuTicks(decoder.pid()), sim0 = CpuTicks(sim.pid());
  const auto t0 = Clock::now();
  const std::int64_t open_ns = UnixNs();
  std::this_thread::sleep_until(t0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.seconds)));
  const auto dec1 = CpuTicks(decoder.pid()), sim1 = CpuTicks(sim.pid());
  const auto dec_threads1 = ThreadTicks(decoder.pid());
  const auto t1 = Clock::now();
  const std::int64_t close_ns = UnixNs();
  run.window_s = std::chrono::duration<double>(t1 - t0).count();
  if (!dec0 || !dec1 || !sim0 || !sim1) {
    throw InputError("bench-service: a process exited during the window at " + Rate(rate_hz) +
                     " Hz; decoder log: " + decoder.stderr_text() + "\nsim log: " + sim.stderr_text());
  }
  const double tick_s = 1.0 / static_cast<double>(sysconf(_SC_CLK_TCK));
  run.decoder_cpu_pct = 100.0 * static_cast<double>(*dec1 - *dec0) * tick_s / run.window_s;
  run.sim_cpu_pct = 100.0 * static_cast<double>(*sim1 - *sim0) * tick_s / run.window_s;
  for (const auto& [name, ticks] : dec_threads1) {
    const auto before = dec_threads0.find(name);
    const std::uint64_t start = before == dec_threads0.end() ? 0 : std::min(before->second, ticks);
    run.decoder_threads_cpu_pct[name] = 100.0 * static_cast<double>(ticks - start) * tick_s / run.window_s;
  }

  // Decoder first (it sends its shutting_down fault to the aggregator), then the sim (it logs its write lag).
  run.decoder_exit = decoder.Stop(milliseconds(5000));
  run.decoder_killed = decoder.killed();
  run.sim_exit = sim.Stop(milliseconds(5000));
  run.sim_killed = sim.killed();
  run.sim_write_lag = WriteLagLine(sim.stderr_text());
  aggregator.Shutdown();

  std::vector<double> latency, to_decoder, to_aggregator;
  std::uint64_t first_serial = 0, last_serial = 0;
  for (const Record& r : aggregator.Take()) {
    if (r.arrival_ns < open_ns || r.arrival_ns > close_ns) continue;
    ++run.messages;
    if (r.kind == Record::Kind::kHeartbeat) {
      ++run.heartbeats;
      run.messages_dropped = r.messages_dropped;
      run.serial_gaps = r.serial_gaps;
    }
    if (r.kind == Record::Kind::kFault) {
      ++run.faults;
      std::string name = v1::PatchFaultCode_Name(static_cast<v1::PatchFaultCode>(r.fault_code));
      if (name.rfind("PATCH_FAULT_CODE_", 0) == 0) name = name.substr(17);
      for (auto& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
      ++run.fault_counts[name];
    }
    if (r.kind != Record::Kind::kContact) continue;
    if (latency.empty()) first_serial = r.serial;
    last_serial = r.serial;
    latency.push_back(static_cast<double>(r.arrival_ns - r.t_ns) / 1e3);
    to_decoder.push_back(static_cast<double>(r.decoder_t_ns - r.t_ns) / 1e3);
    to_aggregator.push_back(static_cast<double>(r.arrival_ns - r.decoder_t_ns) / 1e3);
  }
  run.serial_span = latency.empty() ? 0 : last_serial - first_serial;
  run.latency = QuantilesOf(latency);
  run.to_decoder = QuantilesOf(to_decoder);
  run.to_aggregator = QuantilesOf(to_aggregator);
  run.latency_us = std::move(latency);
  log("e2e " + Rate(rate_hz) + " Hz: " + std::to_string(run.latency.count) + " contact messages, p50 " +
      std::to_string(run.latency.p50_us) + " us, p99 " + std::to_string(run.latency.p99_us) + " us; decoder CPU " +
      std::to_string(run.decoder_cpu_pct) + " %");
  return run;
}

}  // namespace ruffini::harness
