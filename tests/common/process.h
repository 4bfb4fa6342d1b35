#pragma once
// Test helper for multi-process tests: start a real executable (fork + execv) with its stdout and stderr in
// files, wait on conditions with a deadline (never a bare sleep), and always stop it by pid (SIGTERM, then
// SIGKILL after a timeout) and reap it. Header-only; POSIX.
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <map>
#include <string>
#include <thread>
#include <vector>

namespace ruffini::testing {

inline std::string Slurp(const std::string& path) {
  std::ifstream in(path);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// "key P" lines of a ports file (the services write it atomically).
inline std::map<std::string, int> ReadPorts(const std::string& path) {
  std::map<std::string, int> ports;
  std::ifstream in(path);
  std::string key;
  int port = 0;
  while (in >> key >> port) ports[key] = port;
  return ports;
}

// Polls cond every `poll` until it holds (true) or the timeout passes (false).
inline bool WaitFor(const std::function<bool()>& cond, std::chrono::milliseconds timeout,
                    std::chrono::milliseconds poll = std::chrono::milliseconds(2)) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    if (cond()) return true;
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(poll);
  }
}

class Process {
 public:
  Process() = default;
  // Starts args[0] with args; stdout and stderr go to `dir`/stdout and `dir`/stderr (dir is created).
  Process(std::vector<std::string> args, const std::string& dir) : dir_(dir) {
    std::filesystem::create_directories(dir_);
    const std::string out = dir_ + "/stdout", err = dir_ + "/stderr";
    pid_ = fork();
    if (pid_ == 0) {
      // If the test dies (a crash, a kill), its children die with it instead of running on.
      prctl(PR_SET_PDEATHSIG, SIGKILL);
      if (!freopen(out.c_str(), "w", stdout) || !freopen(err.c_str(), "w", stderr)) _exit(126);
      std::vector<char*> argv;
      for (auto& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      execv(argv[0], argv.data());
      _exit(127);
    }
  }
  Process(const Process&) = delete;
  Process& operator=(const Process&) = delete;
  Process(Process&& o) noexcept { *this = std::move(o); }
  Process& operator=(Process&& o) noexcept {
    if (this != &o) {
      Stop();
      pid_ = o.pid_;
      dir_ = std::move(o.dir_);
      exit_status_ = o.exit_status_;
      o.pid_ = -1;
    }
    return *this;
  }
  ~Process() { Stop(); }

  [[nodiscard]] pid_t pid() const noexcept { return pid_; }
  [[nodiscard]] std::string stdout_text() const { return Slurp(dir_ + "/stdout"); }
  [[nodiscard]] std::string stderr_text() const { return Slurp(dir_ + "/stderr"); }
  [[nodiscard]] const std::string& dir() const noexcept { return dir_; }

  // True while the process runs; reaps it (and records its exit status) once it has exited.
  bool Running() {
    if (pid_ <= 0) return false;
    int status = 0;
    if (waitpid(pid_, &status, WNOHANG) == pid_) {
      Record(status);
      return false;
    }
    return true;
  }

  // Waits (up to timeout) for the process to exit by itself; returns its exit status or -1 (still running,
  // or killed by a signal).
  int WaitExit(std::chrono::milliseconds timeout) {
    WaitFor([&] { return !Running(); }, timeout);
    return pid_ > 0 ? -1 : exit_status_;
  }

  // Sends sig without waiting.
  void Signal(int sig) const {
    if (pid_ > 0) kill(pid_, sig);
  }

  // SIGTERM, then SIGKILL after `grace`; returns the exit status (-1: killed, or never started). Sets
  // killed() when SIGKILL was needed.
  int Stop(std::chrono::milliseconds grace = std::chrono::seconds(5)) {
    if (pid_ <= 0) return exit_status_;
    kill(pid_, SIGTERM);
    if (!WaitFor([&] { return !Running(); }, grace)) {
      kill(pid_, SIGKILL);
      int status = 0;
      waitpid(pid_, &status, 0);
      killed_ = true;
      Record(status);
    }
    return exit_status_;
  }
  [[nodiscard]] bool killed() const noexcept { return killed_; }
  [[nodiscard]] int exit_status() const noexcept { return exit_status_; }

 private:
  void Record(int status) {
    exit_status_ = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    pid_ = -1;
  }
  pid_t pid_ = -1;
  std::string dir_;
  int exit_status_ = -1;
  bool killed_ = false;
};

}  // namespace ruffini::testing
