// ruffini::sim without sockets: the replay source and the command replies.
#include <gtest/gtest.h>

#include <cstring>
#include <vector>

#include "ruffini/error.h"
#include "ruffini/ingest/hyperion.h"
#include "ruffini/sim/server.h"
#include "ruffini/sim/source.h"

namespace {

using namespace ruffini;

dataset::Dataset Rows(std::size_t n) {
  dataset::Dataset d;
  for (std::size_t r = 0; r < n; ++r) {
    dataset::Frame f;
    for (std::size_t g = 0; g < kGratings; ++g) f.wavelength_nm[g] = 1530.0 + 2.5 * double(g) + 0.001 * double(r);
    f.serial = r;
    d.Append(f);
  }
  return d;
}

TEST(ReplaySource, LoopsOverTheRowsOnEveryChannel) {
  sim::ReplaySource src(Rows(3), 2);
  ASSERT_EQ(src.channels(), 2u);
  std::vector<Wavelengths> out(2);
  src.Sample(7, out);  // row 7 mod 3 = 1
  EXPECT_DOUBLE_EQ(out[0][0], 1530.001);
  EXPECT_DOUBLE_EQ(out[1][15], 1530.0 + 37.5 + 0.001);
}

TEST(ReplaySource, RefusesAnEmptyDatasetAndTooManyChannels) {
  EXPECT_THROW(sim::ReplaySource(dataset::Dataset{}, 1), InputError);
  EXPECT_THROW(sim::ReplaySource(Rows(1), 17), InputError);
  EXPECT_THROW(sim::ReplaySource(Rows(1), 0), InputError);
}

ingest::Reply Ask(sim::CommandState& state, const char* command, std::vector<std::uint8_t>& bytes) {
  const auto req = ingest::EncodeCommand(command);
  ingest::Command cmd;
  EXPECT_EQ(ingest::DecodeCommand(req, cmd).status, ingest::MessageResult::Status::kOk);
  bytes = sim::AnswerCommand(cmd, state);
  ingest::Reply reply;
  const auto r = ingest::DecodeReply(bytes, reply);
  EXPECT_EQ(r.status, ingest::MessageResult::Status::kOk);
  EXPECT_EQ(r.consumed, bytes.size());
  return reply;
}

TEST(AnswerCommand, AnswersTheVendorCommands) {
  sim::CommandState state;
  state.channels = 3;
  state.serial_number = "SN-0000000000000001";
  state.firmware_version = "firmware version 1.2.3";
  std::vector<std::uint8_t> b;
  auto r = Ask(state, "#GetDutChannelCount", b);
  ASSERT_EQ(r.status, 0);
  ASSERT_EQ(r.content.size(), 4u);
  std::uint32_t n = 0;
  std::memcpy(&n, r.content.data(), 4);
  EXPECT_EQ(n, 3u);
  r = Ask(state, "#GetSerialNumber", b);
  EXPECT_EQ(std::string(r.content.begin(), r.content.end()), "SN-0000000000000001");
  r = Ask(state, "#isready", b);
  ASSERT_EQ(r.content.size(), 1u);
  EXPECT_EQ(r.content[0], 1);
  r = Ask(state, "#GetPeaks", b);  // nothing acquired yet
  EXPECT_NE(r.status, 0);
  state.last_frame = ingest::EncodeWavelengths(5, 1'700'000'000'000'000'000, 0, Wavelengths{});
  r = Ask(state, "#GetPeaks", b);
  ASSERT_EQ(r.status, 0);
  std::vector<double> storage(64);
  ingest::PeakFrame frame;
  ASSERT_EQ(ingest::ParsePeaks(r.content, storage, frame), ingest::Reason::kOk);
  EXPECT_EQ(frame.serial_number, 5u);
  Ask(state, "#DisablePeakDataStreaming", b);
  EXPECT_FALSE(state.streaming);
  Ask(state, "#EnablePeakDataStreaming", b);
  EXPECT_TRUE(state.streaming);
}

TEST(AnswerCommand, UnknownCommandGetsTheVendorErrorReply) {
  sim::CommandState state;
  std::vector<std::uint8_t> b;
  const auto r = Ask(state, "#Frobnicate", b);
  EXPECT_NE(r.status, 0);
  EXPECT_TRUE(r.content.empty());
  EXPECT_NE(r.message.find("#Frobnicate"), std::string_view::npos);
}

}  // namespace
