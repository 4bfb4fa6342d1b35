#pragma once
// The simulated interrogator's command port as a pure function: a decoded command and the server's state in,
// the reply bytes out (no sockets; the Asio server in services/sim calls it). All bytes via ruffini::ingest.
#include <cstdint>
#include <string>
#include <vector>

#include "ruffini/ingest/hyperion.h"

namespace ruffini::sim {

// The reply to one command (a pure function of the command and the server's state; no sockets).
struct CommandState {
  std::size_t channels = 1;
  bool streaming = true;
  std::string serial_number;
  std::string firmware_version;
  std::vector<std::uint8_t> last_frame;  // the last encoded stream frame (header + content), may be empty
};
// Answers #GetSerialNumber, #GetFirmwareVersion, #isready, #GetDutChannelCount, #GetPeaks,
// #EnablePeakDataStreaming, #DisablePeakDataStreaming (these two change state.streaming); anything else gets
// an error reply (status 1, a message, no content).
std::vector<std::uint8_t> AnswerCommand(const ingest::Command& command, CommandState& state);

}  // namespace ruffini::sim
