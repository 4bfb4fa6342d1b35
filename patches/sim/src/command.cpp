#include "ruffini/sim/command.h"

#include <span>
#include <string_view>

namespace ruffini::sim {

// --- Commands ----------------------------------------------------------------------------------------------

namespace {

std::vector<std::uint8_t> Ok(std::span<const std::uint8_t> content, std::string_view message = {}) {
  ingest::Reply r;
  r.message = message;
  r.content = content;
  return ingest::EncodeReply(r);
}
std::vector<std::uint8_t> OkText(std::string_view text) {
  return Ok(std::span(reinterpret_cast<const std::uint8_t*>(text.data()), text.size()));
}
std::vector<std::uint8_t> Error(std::string_view message) {
  ingest::Reply r;
  r.status = 1;
  r.message = message;
  return ingest::EncodeReply(r);
}

}  // namespace

std::vector<std::uint8_t> AnswerCommand(const ingest::Command& command, CommandState& state) {
  const std::string_view c = command.command;
  if (c == "#GetSerialNumber") return OkText(state.serial_number);
  if (c == "#GetFirmwareVersion") return OkText(state.firmware_version);
  if (c == "#isready") {
    const std::array<std::uint8_t, 1> ready{1};
    return Ok(ready);
  }
  if (c == "#GetDutChannelCount") {
    const auto n = static_cast<std::uint32_t>(state.channels);
    const std::array<std::uint8_t, 4> le{static_cast<std::uint8_t>(n), static_cast<std::uint8_t>(n >> 8),
                                         static_cast<std::uint8_t>(n >> 16), static_cast<std::uint8_t>(n >> 24)};
    return Ok(le);
  }
  if (c == "#GetPeaks") {
    if (state.last_frame.size() <= ingest::kHeaderBytes) return Error("no peaks acquired yet");
    return Ok(std::span(state.last_frame).subspan(ingest::kHeaderBytes));
  }
  if (c == "#EnablePeakDataStreaming") {
    state.streaming = true;
    return Ok({}, "Peak data streaming enabled");
  }
  if (c == "#DisablePeakDataStreaming") {
    state.streaming = false;
    return Ok({}, "Peak data streaming disabled");
  }
  std::string msg = "Unknown command: ";
  msg.append(c.substr(0, 200));
  return Error(msg);
}


}  // namespace ruffini::sim
