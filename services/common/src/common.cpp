#include "ruffini/service/common.h"

#include <openssl/evp.h>
#include <spdlog/spdlog.h>
#include <pthread.h>
#include <signal.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <system_error>

#include "ruffini/error.h"

namespace ruffini::service {

HostPort ParseHostPort(const std::string& text, const std::string& flag, bool allow_zero) {
  const auto bad = [&](const std::string& why) {
    return InputError(flag + " '" + text + "': " + why + " (expected HOST:PORT, e.g. 127.0.0.1:51972)");
  };
  HostPort hp;
  std::string port;
  if (!text.empty() && text.front() == '[') {
    const auto close = text.find(']');
    if (close == std::string::npos || close + 1 >= text.size() || text[close + 1] != ':') throw bad("unclosed [ or no :PORT");
    hp.host = text.substr(1, close - 1);
    port = text.substr(close + 2);
  } else {
    const auto colon = text.rfind(':');
    if (colon == std::string::npos) throw bad("no port");
    hp.host = text.substr(0, colon);
    port = text.substr(colon + 1);
    if (hp.host.find(':') != std::string::npos) throw bad("an IPv6 host must be in brackets");
  }
  if (hp.host.empty()) throw bad("empty host");
  if (port.empty() || port.size() > 5 || port.find_first_not_of("0123456789") != std::string::npos) {
    throw bad("the port is not a number");
  }
  const unsigned long p = std::stoul(port);
  if (p > 65535) throw bad("the port is above 65535");
  if (p == 0 && !allow_zero) throw bad("port 0 is not allowed here");
  hp.port = static_cast<std::uint16_t>(p);
  return hp;
}

namespace {
std::string Hex(const unsigned char* d, unsigned n) {
  static const char* k = "0123456789abcdef";
  std::string s(2 * n, '0');
  for (unsigned i = 0; i < n; ++i) {
    s[2 * i] = k[d[i] >> 4];
    s[2 * i + 1] = k[d[i] & 15];
  }
  return s;
}
struct CtxFree {
  void operator()(EVP_MD_CTX* c) const { EVP_MD_CTX_free(c); }
};
}  // namespace

std::string Sha256Hex(const std::string& bytes) {
  std::unique_ptr<EVP_MD_CTX, CtxFree> ctx(EVP_MD_CTX_new());
  unsigned char md[EVP_MAX_MD_SIZE];
  unsigned n = 0;
  if (!ctx || EVP_DigestInit_ex(ctx.get(), EVP_sha256(), nullptr) != 1 ||
      EVP_DigestUpdate(ctx.get(), bytes.data(), bytes.size()) != 1 || EVP_DigestFinal_ex(ctx.get(), md, &n) != 1) {
    throw InputError("SHA-256: OpenSSL failed");
  }
  return Hex(md, n);
}

std::string Sha256OfFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path + ": cannot read (" + std::strerror(errno) + ")");
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  return Sha256Hex(bytes);
}

void WriteFileAtomically(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp." + std::to_string(getpid());
  {
    std::ofstream out(tmp, std::ios::trunc);
    if (!out) throw InputError(path + ": cannot write (" + std::strerror(errno) + ")");
    out << text;
    if (!out.flush()) throw InputError(path + ": cannot write (" + std::strerror(errno) + ")");
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) throw InputError(path + ": cannot write (" + ec.message() + ")");
}

std::string InstanceName() {
  std::array<char, 256> host{};
  if (gethostname(host.data(), host.size() - 1) != 0) std::snprintf(host.data(), host.size(), "unknown");
  return std::string(host.data()) + ":" + std::to_string(getpid());
}

namespace {
sigset_t StopSet() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  return set;
}
}  // namespace

void BlockStopSignals() {
  const sigset_t set = StopSet();
  pthread_sigmask(SIG_BLOCK, &set, nullptr);
  signal(SIGPIPE, SIG_IGN);
}

int WaitForStopSignal() {
  const sigset_t set = StopSet();
  int sig = 0;
  sigwait(&set, &sig);
  return sig;
}

void AnnouncePorts(const std::string& path, const std::vector<std::pair<std::string, int>>& ports) {
  std::string line = "ports:", file;
  for (const auto& [key, port] : ports) {
    line += " " + key + " " + std::to_string(port);
    file += key + " " + std::to_string(port) + "\n";
  }
  std::printf("%s\n", line.c_str());
  std::fflush(stdout);
  if (!path.empty()) WriteFileAtomically(path, file);
}

void ExitAfterCleanStop() {
  spdlog::shutdown();
  std::fflush(nullptr);
  std::_Exit(0);
}

std::string ExecutableDir() {
  std::error_code ec;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (ec) throw InputError("cannot read /proc/self/exe: " + ec.message());
  return self.parent_path().string();
}

std::int64_t UnixNowNs() noexcept {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count();
}
std::int64_t MonoNowNs() noexcept {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

}  // namespace ruffini::service
