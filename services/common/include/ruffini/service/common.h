#pragma once
// Small pieces every Ruffini service shares: HOST:PORT parsing, SHA-256 of a file, the ports file a service
// writes when it was asked for port 0, the process instance name.
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace ruffini::service {

struct HostPort {
  std::string host;
  std::uint16_t port = 0;
  [[nodiscard]] std::string str() const { return host + ":" + std::to_string(port); }
};
// "HOST:PORT" (an IPv6 host in brackets: "[::1]:50051"); port 0..65535 (0 only when allow_zero). Throws
// InputError naming the flag and the value.
HostPort ParseHostPort(const std::string& text, const std::string& flag, bool allow_zero = false);

// SHA-256 of a file's bytes, lower-case hex (OpenSSL's EVP). Throws InputError when the file cannot be read.
std::string Sha256OfFile(const std::string& path);
// SHA-256 of bytes, lower-case hex.
std::string Sha256Hex(const std::string& bytes);

// Writes text to path atomically (a temporary file in the same folder, then rename), so a reader polling for
// the file never sees half of it. Throws InputError naming the path.
void WriteFileAtomically(const std::string& path, const std::string& text);

// "host:pid", to tell two processes apart in logs and hellos.
std::string InstanceName();

// Blocks SIGINT and SIGTERM in the calling thread and every thread it starts later (call it first in main),
// and ignores SIGPIPE (a peer closing a socket is an error code, not a death).
void BlockStopSignals();
// Waits for SIGINT or SIGTERM (blocked by BlockStopSignals); returns the signal.
int WaitForStopSignal();

// Writes a ports file ("key P" lines) when path is not empty, and prints "ports: key P key P" on stdout.
void AnnouncePorts(const std::string& path, const std::vector<std::pair<std::string, int>>& ports);

// A service's last step after it stopped cleanly (links closed, threads joined): flush the logs and exit 0
// without the remaining destructors. The metrics exposer's web server (civetweb) waits out its one-second poll
// timeout when destroyed, which would hold up every restart by a second.
[[noreturn]] void ExitAfterCleanStop();

// The folder of the running executable (/proc/self/exe), where the other Ruffini executables are installed.
// Throws InputError when it cannot be read.
std::string ExecutableDir();

// Unix time now, ns.
std::int64_t UnixNowNs() noexcept;
// The steady clock now, ns.
std::int64_t MonoNowNs() noexcept;

}  // namespace ruffini::service
