#pragma once
// A child process of a tool that runs the services (the demo, the service bench): started with posix_spawn
// (nothing runs between fork and exec in a process that has gRPC threads), stdout and stderr in files of a
// folder, stopped by pid (SIGTERM, then SIGKILL after a grace period) and reaped.
#include <sys/types.h>

#include <chrono>
#include <map>
#include <string>
#include <vector>

namespace ruffini::service {

class Child {
 public:
  // Throws InputError when args[0] cannot be started.
  Child(const std::vector<std::string>& args, const std::string& dir);
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;
  ~Child();

  [[nodiscard]] pid_t pid() const noexcept { return pid_; }
  [[nodiscard]] const std::string& dir() const noexcept { return dir_; }
  [[nodiscard]] std::string stdout_text() const;
  [[nodiscard]] std::string stderr_text() const;
  [[nodiscard]] bool killed() const noexcept { return killed_; }
  // True while it runs (reaps it once it has exited).
  bool Running();
  void Signal(int sig) const;
  // SIGTERM, then SIGKILL after `grace`; the exit status (-1: killed by a signal or never started).
  int Stop(std::chrono::milliseconds grace = std::chrono::milliseconds(2000));
  // Waits until `path` (a ports file: "key P" lines) names `key`; its port, or 0 after the timeout or when the
  // child exited.
  int WaitPort(const std::string& path, const std::string& key, std::chrono::milliseconds timeout);

 private:
  void Record(int status);
  std::string dir_;
  pid_t pid_ = -1;
  int exit_ = -1;
  bool killed_ = false;
};

// "key P" lines of a ports file (written atomically by the services).
std::map<std::string, int> ReadPorts(const std::string& path);
// A whole file ("" when it cannot be read).
std::string Slurp(const std::string& path);

}  // namespace ruffini::service
