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

// Faults to inject on purpose (0 = off). "Every N-th sample" means the samples (serials) k with (k + 1) mod N = 0.
// docs/sim.md says exactly what each one puts on the wire. Each is counted and logged (the first of a kind at
// once, then a summary at most once a second, and the totals at shutdown).
struct Faults {
  std::uint64_t drop_every = 0;        // every N-th sample is not sent (its serial number is skipped)
  std::uint64_t nan_every = 0;         // every N-th sample has a NaN as channel 0's first peak
  std::uint64_t missing_every = 0;     // every N-th sample leaves one grating out of channel 0 (15 peaks); the
                                       // m-th such sample (m = (k + 1) / N) drops grating (m - 1) mod 16
  std::uint64_t garbage_every = 0;     // every N-th sample's frame is preceded by kGarbage (a framing error)
  std::uint64_t disconnect_after = 0;  // each stream client is disconnected after N frames
  std::uint64_t stall_after = 0;       // after N samples sent, the stream stalls for stall_ms: the samples of
  std::uint32_t stall_ms = 0;          // the stall are held and sent late in one burst, then N more, and so on
};
inline constexpr std::uint32_t kMaxStallMs = 2000;  // the simulated instrument buffers 2 s of samples

// The --garbage-every burst, 16 bytes: a message header whose content_length is 0xDEADBEEF (3735928559, above
// any decoder's limit: content_too_long as soon as its 8 bytes are in), then the ASCII text "GARBAGE!".
inline constexpr std::uint8_t kGarbage[16] = {0x00, 0x00, 0x00, 0x00, 0xEF, 0xBE, 0xAD, 0xDE,
                                              'G',  'A',  'R',  'B',  'A',  'G',  'E',  '!'};

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
