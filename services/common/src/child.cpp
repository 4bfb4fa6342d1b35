#include "ruffini/service/child.h"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <thread>

#include "ruffini/error.h"

extern char** environ;

namespace ruffini::service {

std::string Slurp(const std::string& path) {
  std::ifstream in(path);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

std::map<std::string, int> ReadPorts(const std::string& path) {
  std::map<std::string, int> ports;
  std::ifstream in(path);
  std::string key;
  int port = 0;
  while (in >> key >> port) ports[key] = port;
  return ports;
}

Child::Child(const std::vector<std::string>& args, const std::string& dir) : dir_(dir) {
  std::filesystem::create_directories(dir_);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  const std::string out = dir_ + "/stdout", err = dir_ + "/stderr";
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  std::vector<std::string> copy = args;
  std::vector<char*> argv;
  for (auto& a : copy) argv.push_back(a.data());
  argv.push_back(nullptr);
  const int rc = posix_spawn(&pid_, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0) {
    pid_ = -1;
    throw InputError(args[0] + ": cannot start (" + std::strerror(rc) + ")");
  }
}

Child::~Child() { Stop(); }

std::string Child::stdout_text() const { return Slurp(dir_ + "/stdout"); }
std::string Child::stderr_text() const { return Slurp(dir_ + "/stderr"); }

bool Child::Running() {
  if (pid_ <= 0) return false;
  int status = 0;
  if (waitpid(pid_, &status, WNOHANG) == pid_) {
    Record(status);
    return false;
  }
  return true;
}

void Child::Signal(int sig) const {
  if (pid_ > 0) kill(pid_, sig);
}

int Child::Stop(std::chrono::milliseconds grace) {
  if (pid_ <= 0) return exit_;
  kill(pid_, SIGCONT);  // a stopped child cannot act on SIGTERM
  kill(pid_, SIGTERM);
  const auto deadline = std::chrono::steady_clock::now() + grace;
  while (Running() && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  if (pid_ > 0) {
    kill(pid_, SIGKILL);
    int status = 0;
    waitpid(pid_, &status, 0);
    killed_ = true;
    Record(status);
  }
  return exit_;
}

int Child::WaitPort(const std::string& path, const std::string& key, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    const auto ports = ReadPorts(path);
    if (auto it = ports.find(key); it != ports.end() && it->second > 0) return it->second;
    if (!Running() || std::chrono::steady_clock::now() >= deadline) return 0;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
}

void Child::Record(int status) {
  exit_ = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  pid_ = -1;
}

}  // namespace ruffini::service
