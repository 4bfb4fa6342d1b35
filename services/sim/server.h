#pragma once
// The networking of ruffini-sim (a service, so it lives in services/, not patches/).
// A simulated Hyperion interrogator on TCP (Boost.Asio, one thread): the peak stream pushes a frame to every
// connected stream client at the sample rate, paced on absolute deadlines of a steady clock (no drift), with
// consecutive serial numbers and Unix-ns timestamps; the command port answers the vendor's commands. All bytes
// are made and parsed by ruffini::ingest.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "ruffini/ingest/hyperion.h"
#include "ruffini/sim/command.h"
#include "ruffini/sim/source.h"

namespace ruffini::sim {

// Faults to inject on purpose (0 = off).
struct Faults {
  std::uint64_t drop_every = 0;        // every N-th sample is not sent (its serial number is skipped)
  std::uint64_t nan_every = 0;         // every N-th sample has a NaN as channel 0's first peak
  std::uint64_t disconnect_after = 0;  // each stream client is disconnected after N frames
};

struct ServerConfig {
  std::string host = "127.0.0.1";
  std::uint16_t command_port = ingest::kCommandPort;  // 0: pick a free port
  std::uint16_t stream_port = ingest::kPeakStreamPort;
  double rate_hz = 1000.0;                             // 100 .. 5000
  Faults faults;
  std::string serial_number = "RUFFINI-SIM-0001";
  std::string firmware_version = "ruffini-sim 0.1.0";
};

class SimServer {
 public:
  // Binds both ports. Throws InputError naming the host and port when it cannot, or when the config is bad.
  SimServer(ServerConfig config, std::unique_ptr<FrameSource> source);
  ~SimServer();
  SimServer(const SimServer&) = delete;
  SimServer& operator=(const SimServer&) = delete;

  [[nodiscard]] std::uint16_t command_port() const noexcept;
  [[nodiscard]] std::uint16_t stream_port() const noexcept;

  // Serves until Stop() or SIGINT / SIGTERM (handled while Run runs), then closes every connection.
  void Run();
  // Thread-safe; Run returns soon after.
  void Stop();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ruffini::sim
