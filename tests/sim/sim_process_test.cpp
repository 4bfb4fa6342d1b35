// The real ruffini-sim process on 127.0.0.1 (port 0, --ports-file), read by plain POSIX sockets and the
// ingest codec. Every wait is a condition with a deadline; the sim is started, always stopped by pid (SIGTERM,
// then SIGKILL after a timeout) and reaped by ruffini::testing::Process (tests/common/process.h).
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <regex>
#include <string>
#include <vector>

#include "../common/process.h"
#include "ruffini/dataset/dataset.h"
#include "ruffini/ingest/hyperion.h"

namespace {

using namespace ruffini;
using Clock = std::chrono::steady_clock;
namespace fs = std::filesystem;
namespace rt = ruffini::testing;

constexpr std::size_t kRows = 37;

double RowNm(std::size_t row, std::size_t g) { return 1530.0 + 2.5 * double(g) + 0.001 * double(row); }

// A tiny dataset made here: row r, grating g at 1530 + 2.5 g + 0.001 r nm (all distinct, in the window).
std::string MakeDataset(const std::string& dir) {
  dataset::Dataset d;
  d.info.patch_name = "forearm";
  d.info.source = "sim_process_test";
  for (std::size_t r = 0; r < kRows; ++r) {
    dataset::Frame f;
    for (std::size_t g = 0; g < kGratings; ++g) f.wavelength_nm[g] = RowNm(r, g);
    f.serial = r;
    f.t_s = double(r) * 0.01;
    d.Append(f);
  }
  const std::string path = dir + "/replay.h5";
  dataset::WriteDataset(path, d);
  return path;
}

struct Ports {
  std::uint16_t command = 0;
  std::uint16_t stream = 0;
};

// The sim's --ports-file ("command P" and "stream P" lines), or nullopt while it is missing or incomplete (the
// sim writes it under a temporary name and renames it, so a complete file is the whole story).
std::optional<Ports> ReadPortsFile(const std::string& path) {
  std::ifstream in(path);
  std::string k1, k2;
  unsigned c = 0, s = 0;
  if (!(in >> k1 >> c >> k2 >> s) || k1 != "command" || k2 != "stream" || c == 0 || s == 0 || c > 65535 ||
      s > 65535) {
    return std::nullopt;
  }
  return Ports{static_cast<std::uint16_t>(c), static_cast<std::uint16_t>(s)};
}

std::string SceneArg() { return std::string(RUFFINI_SOURCE_DIR) + "/config/scenes/forearm.yaml"; }

class Sim {
 public:
  // Starts ruffini-sim with the given extra arguments; waits (10 s at most) for its ports file.
  // source: {} replays a dataset written here; else the arguments that name the source (e.g. --scenario F).
  explicit Sim(const std::string& name, std::vector<std::string> extra = {}, std::vector<std::string> source = {}) {
    const std::string dir = (fs::current_path() / ("sim_" + name)).string();
    fs::remove_all(dir);
    fs::create_directories(dir);
    if (source.empty()) source = {"--replay", MakeDataset(dir)};
    const std::string ports_file = dir + "/ports";
    std::vector<std::string> args = {RUFFINI_SIM_EXE, "--scene", SceneArg(), source[0], source[1], "--rate-hz",
                                     "1000", "--host", "127.0.0.1", "--command-port", "0", "--stream-port", "0",
                                     "--ports-file", ports_file};
    args.insert(args.end(), extra.begin(), extra.end());
    process_ = rt::Process(std::move(args), dir);
    std::optional<Ports> ports;
    const bool up = rt::WaitFor(
        [&] {
          ports = ReadPortsFile(ports_file);
          return ports.has_value() || !process_.Running();
        },
        std::chrono::seconds(10));
    if (ports) {
      command_port_ = ports->command;
      stream_port_ = ports->stream;
    } else if (up) {
      ADD_FAILURE() << "ruffini-sim exited early: " << process_.stderr_text();
    } else {
      ADD_FAILURE() << "no ports file within 10 s";
    }
  }

  // SIGTERM, then SIGKILL after 5 s; returns the exit status (or -1).
  int Stop() {
    const int status = process_.Stop();
    if (process_.killed() && !kill_reported_) {
      kill_reported_ = true;
      ADD_FAILURE() << "ruffini-sim ignored SIGTERM for 5 s";
    }
    return status;
  }
  ~Sim() { Stop(); }
  Sim(const Sim&) = delete;
  Sim& operator=(const Sim&) = delete;

  [[nodiscard]] std::string stdout_text() const { return process_.stdout_text(); }
  [[nodiscard]] std::string stderr_text() const { return process_.stderr_text(); }
  [[nodiscard]] bool ok() { return process_.Running() && stream_port_ != 0; }
  std::uint16_t command_port_ = 0, stream_port_ = 0;

 private:
  rt::Process process_;
  bool kill_reported_ = false;
};

// A loopback TCP connection with a 5 s receive timeout.
class Conn {
 public:
  explicit Conn(std::uint16_t port) {
    fd_ = socket(AF_INET, SOCK_STREAM, 0);
    timeval tv{5, 0};
    setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    setsockopt(fd_, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    connected_ = connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  }
  ~Conn() {
    if (fd_ >= 0) close(fd_);
  }
  [[nodiscard]] bool connected() const { return connected_; }
  // Bytes read (0: the peer closed; -1: error or timeout).
  ssize_t Read(std::uint8_t* p, std::size_t n) { return recv(fd_, p, n, 0); }
  bool Send(const std::vector<std::uint8_t>& b) {
    return send(fd_, b.data(), b.size(), MSG_NOSIGNAL) == ssize_t(b.size());
  }

 private:
  int fd_ = -1;
  bool connected_ = false;
};

struct Received {
  std::vector<std::uint64_t> serials;
  std::vector<std::int64_t> timestamps_ns;
  std::vector<std::int64_t> arrival_unix_ns;  // system_clock right after the recv that completed the frame
  std::vector<std::uint8_t> buffer_available;
  std::vector<std::uint16_t> count0;          // channel 0's peak count
  std::vector<std::uint32_t> flags;
  std::vector<Wavelengths> channel0;
  std::vector<ingest::Reason> rejected;
  std::optional<ingest::Reason> framing_error;  // the decoder needs a resync
  bool closed = false;
  ingest::Counters counters;
};

std::int64_t UnixNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// Reads until at least `frames` frames and rejections in all (whole reads: it may return a few more), a
// framing error (a test failure unless framing_ok), the peer closes, or 10 s pass.
Received ReadFrames(Conn& c, std::size_t frames, ingest::StreamDecoder& decoder, bool framing_ok = false) {
  Received r;
  std::vector<std::uint8_t> buf(65536);
  const auto deadline = Clock::now() + std::chrono::seconds(10);
  while (r.serials.size() + r.rejected.size() < frames && Clock::now() < deadline) {
    const ssize_t n = c.Read(buf.data(), buf.size());
    const std::int64_t arrival_ns = UnixNowNs();
    if (n == 0) {
      r.closed = true;
      break;
    }
    if (n < 0) break;
    std::span<const std::uint8_t> rest(buf.data(), std::size_t(n));
    while (!rest.empty()) {
      const auto res = decoder.Feed(rest);
      rest = rest.subspan(res.consumed);
      if (res.status == ingest::StreamDecoder::Status::kFrame) {
        const auto& f = decoder.frame();
        r.serials.push_back(f.serial_number);
        r.timestamps_ns.push_back(f.timestamp_ns);
        r.arrival_unix_ns.push_back(arrival_ns);
        r.buffer_available.push_back(f.buffer_available);
        r.count0.push_back(f.count[0]);
        r.flags.push_back(decoder.flags());
        r.channel0.push_back(decoder.wavelength_nm());
      } else if (res.status == ingest::StreamDecoder::Status::kRejected) {
        r.rejected.push_back(res.reason);
      } else if (res.status == ingest::StreamDecoder::Status::kNeedsResync) {
        if (!framing_ok) ADD_FAILURE() << "framing error: " << ingest::ReasonName(res.reason);
        r.framing_error = res.reason;
        r.counters = decoder.counters();
        return r;
      }
    }
  }
  r.counters = decoder.counters();
  return r;
}

Received ReadFrames(Conn& c, std::size_t frames) {
  ingest::StreamDecoder decoder;
  return ReadFrames(c, frames, decoder);
}

// A count from the sim's last "fault totals: dropped 3, nan 2, ..." log line (written at shutdown).
std::optional<std::uint64_t> FaultTotal(const std::string& log, const std::string& name) {
  const auto line = log.rfind("fault totals:");
  if (line == std::string::npos) return std::nullopt;
  std::smatch m;
  const std::string rest = log.substr(line, log.find('\n', line) - line);
  if (!std::regex_search(rest, m, std::regex("[:,] " + name + " ([0-9]+)"))) return std::nullopt;
  return std::stoull(m[1].str());
}

// Sends a command and reads its reply. `reply` views the returned buffer: keep it while reading `reply`.
std::optional<std::vector<std::uint8_t>> Ask(Conn& c, const char* command, ingest::Reply& reply) {
  if (!c.Send(ingest::EncodeCommand(command))) return std::nullopt;
  std::vector<std::uint8_t> in;
  std::uint8_t buf[4096];
  const auto deadline = Clock::now() + std::chrono::seconds(5);
  while (Clock::now() < deadline) {
    const auto r = ingest::DecodeReply(in, reply);
    if (r.status == ingest::MessageResult::Status::kOk) {
      in.resize(r.consumed);
      ingest::DecodeReply(in, reply);  // views into the returned buffer's final storage below
      return in;
    }
    if (r.status == ingest::MessageResult::Status::kRejected) return std::nullopt;
    const ssize_t n = c.Read(buf, sizeof buf);
    if (n <= 0) return std::nullopt;
    in.insert(in.end(), buf, buf + n);
  }
  return std::nullopt;
}

TEST(SimProcess, StreamsTheReplayedDatasetWithConsecutiveSerialsToSeveralClients) {
  Sim sim("stream");
  ASSERT_TRUE(sim.ok());
  EXPECT_NE(sim.stdout_text().find("ports: command " + std::to_string(sim.command_port_) + " stream " +
                                   std::to_string(sim.stream_port_)),
            std::string::npos)
      << sim.stdout_text();
  Conn a(sim.stream_port_), b(sim.stream_port_);
  ASSERT_TRUE(a.connected());
  ASSERT_TRUE(b.connected());
  const auto ra = ReadFrames(a, 500);
  const auto rb = ReadFrames(b, 100);
  ASSERT_GE(ra.serials.size(), 500u);
  ASSERT_GE(rb.serials.size(), 100u);
  EXPECT_TRUE(ra.rejected.empty());
  for (const auto* r : {&ra, &rb}) {
    for (std::size_t i = 1; i < r->serials.size(); ++i) ASSERT_EQ(r->serials[i], r->serials[i - 1] + 1) << i;
    for (std::size_t i = 0; i < r->serials.size(); ++i) {
      const std::size_t row = std::size_t(r->serials[i] % kRows);
      for (std::size_t g = 0; g < kGratings; ++g) ASSERT_EQ(r->channel0[i][g], RowNm(row, g)) << i << " " << g;
    }
  }
  EXPECT_EQ(ra.counters.lost_samples, 0u);
  {
    // A client going away leaves the others served: a third one connects, leaves, and `a` reads on.
    Conn gone(sim.stream_port_);
    ASSERT_TRUE(gone.connected());
    ASSERT_GE(ReadFrames(gone, 5).serials.size(), 5u);
  }
  const auto more = ReadFrames(a, 200);
  ASSERT_GE(more.serials.size(), 200u);
  EXPECT_EQ(more.serials.front(), ra.serials.back() + 1);
  EXPECT_EQ(more.counters.lost_samples, 0u);
  // Unix-ns timestamps, now-ish.
  const auto now_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                          std::chrono::system_clock::now().time_since_epoch()).count();
  EXPECT_LT(std::llabs(now_ns - ra.timestamps_ns.back()), 10'000'000'000LL);
  // Each sample is stamped with its own time: exactly 1 ms apart at 1 kHz (1 ns of rounding).
  for (std::size_t i = 1; i < ra.timestamps_ns.size(); ++i) {
    ASSERT_NEAR(double(ra.timestamps_ns[i] - ra.timestamps_ns[i - 1]), 1e6, 1.0) << i;
  }
  // The timestamp is the scheduled send time, so no frame arrives before it (same host, same Unix clock; 1 ms
  // of slack for a clock adjustment during the test).
  for (std::size_t i = 0; i < ra.timestamps_ns.size(); ++i) {
    ASSERT_GE(ra.arrival_unix_ns[i] - ra.timestamps_ns[i], -1'000'000) << i;
  }
  EXPECT_EQ(sim.Stop(), 0);  // SIGTERM: a clean exit
}

TEST(SimProcess, AnswersCommands) {
  Sim sim("command");
  ASSERT_TRUE(sim.ok());
  Conn c(sim.command_port_);
  ASSERT_TRUE(c.connected());
  ingest::Reply r;
  auto bytes = Ask(c, "#GetDutChannelCount", r);
  ASSERT_TRUE(bytes);
  ASSERT_EQ(r.status, 0);
  ASSERT_EQ(r.content.size(), 4u);
  std::uint32_t n = 0;
  std::memcpy(&n, r.content.data(), 4);
  EXPECT_EQ(n, 1u);  // forearm.yaml: one patch
  bytes = Ask(c, "#NoSuchCommand", r);
  ASSERT_TRUE(bytes);
  EXPECT_NE(r.status, 0);
  EXPECT_TRUE(r.content.empty());
  EXPECT_FALSE(r.message.empty());
  bytes = Ask(c, "#isready", r);
  ASSERT_TRUE(bytes);
  ASSERT_EQ(r.content.size(), 1u);
  EXPECT_EQ(r.content[0], 1);
  bytes = Ask(c, "#GetSerialNumber", r);
  ASSERT_TRUE(bytes);
  EXPECT_EQ(r.status, 0);
  EXPECT_FALSE(r.content.empty());
  bytes = Ask(c, "#GetPeaks", r);
  ASSERT_TRUE(bytes);
  ASSERT_EQ(r.status, 0);
  std::vector<double> storage(64);
  ingest::PeakFrame f;
  ASSERT_EQ(ingest::ParsePeaks(r.content, storage, f), ingest::Reason::kOk);
  ASSERT_EQ(f.count[0], 16);
  const std::size_t row = std::size_t(f.serial_number % kRows);
  EXPECT_EQ(f.channel(0)[3], RowNm(row, 3));
  // Streaming off: a stream client gets nothing; on again: frames flow.
  // Streaming off: samples go on being taken (and numbered) but not sent, so a connected client sees a serial
  // gap once streaming is on again. Wait (bounded) until #GetPeaks shows 5 samples taken while off.
  Conn s(sim.stream_port_);
  ASSERT_TRUE(s.connected());
  const auto before = ReadFrames(s, 10);
  ASSERT_GE(before.serials.size(), 10u);
  bytes = Ask(c, "#DisablePeakDataStreaming", r);
  ASSERT_TRUE(bytes);
  EXPECT_EQ(r.status, 0);
  bytes = Ask(c, "#GetPeaks", r);
  ASSERT_TRUE(bytes);
  ASSERT_EQ(ingest::ParsePeaks(r.content, storage, f), ingest::Reason::kOk);
  const std::uint64_t off_at = f.serial_number;
  const auto deadline = Clock::now() + std::chrono::seconds(5);
  while (f.serial_number < off_at + 5 && Clock::now() < deadline) {
    bytes = Ask(c, "#GetPeaks", r);
    ASSERT_TRUE(bytes);
    ASSERT_EQ(ingest::ParsePeaks(r.content, storage, f), ingest::Reason::kOk);
  }
  ASSERT_GE(f.serial_number, off_at + 5);
  bytes = Ask(c, "#EnablePeakDataStreaming", r);
  ASSERT_TRUE(bytes);
  EXPECT_EQ(r.status, 0);
  const auto after = ReadFrames(s, 200);
  ASSERT_GE(after.serials.size(), 200u);
  bool gap = false;
  for (std::size_t i = 1; i < after.serials.size(); ++i) gap = gap || after.serials[i] > after.serials[i - 1] + 1;
  EXPECT_TRUE(gap || after.serials.front() > before.serials.back() + 1);
  EXPECT_EQ(sim.Stop(), 0);
}

TEST(SimProcess, FaultsDropNanAndDisconnect) {
  Sim sim("faults", {"--drop-every", "10", "--nan-every", "7", "--disconnect-after", "100"});
  ASSERT_TRUE(sim.ok());
  Conn c(sim.stream_port_);
  ASSERT_TRUE(c.connected());
  const auto r = ReadFrames(c, 1000);
  EXPECT_TRUE(r.closed);                                   // disconnected after 100 frames
  EXPECT_EQ(r.serials.size() + r.rejected.size(), 100u);
  EXPECT_GT(r.counters.lost_samples, 0u);                 // serial gaps
  ASSERT_FALSE(r.rejected.empty());
  for (auto reason : r.rejected) EXPECT_EQ(reason, ingest::Reason::kNonFinite);
  for (auto s : r.serials) {
    EXPECT_NE((s + 1) % 10, 0u) << s;  // dropped samples never arrive
    EXPECT_NE((s + 1) % 7, 0u) << s;   // NaN samples are rejected by the decoder
  }
  EXPECT_EQ(sim.Stop(), 0);
  // Counted and logged by the sim (totals at shutdown).
  const std::string log = sim.stderr_text();
  EXPECT_GT(FaultTotal(log, "dropped").value_or(0), 0u) << log;
  EXPECT_GT(FaultTotal(log, "nan").value_or(0), 0u) << log;
  EXPECT_EQ(FaultTotal(log, "disconnected"), 1u) << log;
  EXPECT_EQ(FaultTotal(log, "missing"), 0u) << log;
}

TEST(SimProcess, MissingEveryLeavesOneRotatingGratingOutOfChannel0) {
  Sim sim("missing", {"--missing-every", "5"});
  ASSERT_TRUE(sim.ok());
  // A client that allows missing peaks (bands around the dataset's gratings) sees which one went dark; a strict
  // client (the default) refuses those frames as wrong_peak_count.
  Wavelengths centre_nm{};
  for (std::size_t g = 0; g < kGratings; ++g) centre_nm[g] = RowNm(0, g);
  ingest::DecoderConfig tolerant_config;
  tolerant_config.pick = ingest::NearestGratingBands(0, centre_nm);
  tolerant_config.pick->allow_missing = true;
  ingest::StreamDecoder tolerant(tolerant_config);
  Conn a(sim.stream_port_), b(sim.stream_port_);
  ASSERT_TRUE(a.connected());
  ASSERT_TRUE(b.connected());
  const auto r = ReadFrames(a, 300, tolerant);
  const auto strict = ReadFrames(b, 100);
  ASSERT_GE(r.serials.size(), 300u);
  EXPECT_TRUE(r.rejected.empty());
  std::vector<bool> dark_seen(kGratings, false);
  for (std::size_t i = 0; i < r.serials.size(); ++i) {
    const std::uint64_t s = r.serials[i];
    if (i > 0) {
      ASSERT_EQ(s, r.serials[i - 1] + 1) << i;
    }
    const bool missing = (s + 1) % 5 == 0;
    const std::size_t dark = missing ? std::size_t(((s + 1) / 5 - 1) % kGratings) : kGratings;
    ASSERT_EQ(r.count0[i], missing ? 15 : 16) << s;
    ASSERT_EQ((r.flags[i] & kFlagPeakMissing) != 0, missing) << s;
    for (std::size_t g = 0; g < kGratings; ++g) {
      if (g == dark) {
        ASSERT_TRUE(std::isnan(r.channel0[i][g])) << s << " " << g;
      } else {
        ASSERT_EQ(r.channel0[i][g], RowNm(std::size_t(s % kRows), g)) << s << " " << g;
      }
    }
    if (missing) dark_seen[dark] = true;
  }
  EXPECT_EQ(std::count(dark_seen.begin(), dark_seen.end(), true), std::ptrdiff_t(kGratings));  // it rotates
  ASSERT_FALSE(strict.rejected.empty());
  for (auto reason : strict.rejected) EXPECT_EQ(reason, ingest::Reason::kWrongPeakCount);
  for (auto s : strict.serials) EXPECT_NE((s + 1) % 5, 0u) << s;
  EXPECT_EQ(sim.Stop(), 0);
  const std::string log = sim.stderr_text();
  EXPECT_GE(FaultTotal(log, "missing").value_or(0), 60u) << log;
}

TEST(SimProcess, GarbageEveryIsAFramingErrorAndAReconnectResyncs) {
  Sim sim("garbage", {"--garbage-every", "200"});
  ASSERT_TRUE(sim.ok());
  ingest::StreamDecoder decoder;
  Conn a(sim.stream_port_);
  ASSERT_TRUE(a.connected());
  const auto r = ReadFrames(a, 1000, decoder, /*framing_ok=*/true);
  // The 16 bytes before sample 199's frame (or 399's, ...) announce a 0xDEADBEEF-byte content.
  ASSERT_EQ(r.framing_error, ingest::Reason::kContentTooLong);
  EXPECT_TRUE(decoder.needs_resync());
  EXPECT_EQ(r.counters.resyncs, 1u);
  ASSERT_FALSE(r.serials.empty());
  for (std::size_t i = 1; i < r.serials.size(); ++i) ASSERT_EQ(r.serials[i], r.serials[i - 1] + 1) << i;
  EXPECT_EQ((r.serials.back() + 2) % 200, 0u) << r.serials.back();  // the frame before the garbage arrived
  // The sim keeps serving: a new connection starts on a frame boundary; Reset() keeps the last serial, so the
  // samples missed while reconnecting count as lost.
  decoder.Reset();
  Conn b(sim.stream_port_);
  ASSERT_TRUE(b.connected());
  const auto again = ReadFrames(b, 20, decoder, /*framing_ok=*/true);
  ASSERT_FALSE(again.serials.empty());
  EXPECT_GT(again.serials.front(), r.serials.back() + 1);
  EXPECT_GE(again.counters.lost_samples, again.serials.front() - r.serials.back() - 1);
  EXPECT_EQ(sim.Stop(), 0);
  const std::string log = sim.stderr_text();
  EXPECT_GE(FaultTotal(log, "garbage").value_or(0), 1u) << log;
}

TEST(SimProcess, StallHoldsSamplesThenSendsThemLateInOneBurst) {
  // Samples 0..299 go out on time; 300..549 (250 ms at 1 kHz) are held; at sample 550's deadline the held ones
  // go out in one burst, then 550 and on; the next stall starts at 850.
  Sim sim("stall", {"--stall-after", "300", "--stall-ms", "250"});
  ASSERT_TRUE(sim.ok());
  Conn c(sim.stream_port_);
  ASSERT_TRUE(c.connected());
  const auto r = ReadFrames(c, 600);
  ASSERT_GE(r.serials.size(), 600u);
  ASSERT_LT(r.serials.front(), 300u) << "connected after the stall began";
  EXPECT_EQ(r.counters.lost_samples, 0u);  // nothing lost: held, not dropped
  std::size_t first_held = r.serials.size();
  for (std::size_t i = 0; i < r.serials.size(); ++i) {
    const std::uint64_t s = r.serials[i];
    if (i > 0) {
      ASSERT_EQ(s, r.serials[i - 1] + 1) << i;
      ASSERT_NEAR(double(r.timestamps_ns[i] - r.timestamps_ns[i - 1]), 1e6, 1.0) << i;  // stamped on schedule
    }
    const bool held = s >= 300 && s < 550;
    // The simulated instrument buffers 2 s (2000 samples); each held sample fills it by 1/2000.
    const int expected = held ? 100 - int((100 * (s - 300 + 1) + 1999) / 2000) : 100;
    ASSERT_EQ(int(r.buffer_available[i]), expected) << s;
    if (s == 300) first_held = i;
  }
  ASSERT_LT(first_held, r.serials.size());
  ASSERT_GE(r.serials.back(), 550u);  // frames resume after the burst
  // TCP keeps order and nothing else is sent, so no byte after sample 299's frame arrives before the stall
  // ends: sample 300 arrives at least 250 ms after its timestamp (same host, same Unix clock; 1 ms of slack).
  EXPECT_GE(r.arrival_unix_ns[first_held] - r.timestamps_ns[first_held], 249'000'000);
  EXPECT_EQ(sim.Stop(), 0);
  const std::string log = sim.stderr_text();
  EXPECT_GE(FaultTotal(log, "stalls").value_or(0), 1u) << log;
  EXPECT_GE(FaultTotal(log, "sent_late").value_or(0), 250u) << log;
}

TEST(SimProcess, APortInUseIsAnInputError) {
  Sim first("port_owner");
  ASSERT_TRUE(first.ok());
  const std::string dir = (fs::current_path() / "sim_port_clash").string();
  fs::create_directories(dir);
  std::vector<std::string> args = {RUFFINI_SIM_EXE, "--scene", SceneArg(), "--replay", MakeDataset(dir),
                                   "--command-port", std::to_string(first.command_port_), "--stream-port", "0"};
  rt::Process second(std::move(args), dir);
  EXPECT_EQ(second.WaitExit(std::chrono::seconds(10)), 1) << "the second ruffini-sim did not exit with 1";
  EXPECT_NE(second.stderr_text().find("--command-port: cannot listen on 127.0.0.1:" +
                                      std::to_string(first.command_port_)),
            std::string::npos)
      << second.stderr_text();
  EXPECT_EQ(first.Stop(), 0);
}

TEST(SimProcess, StreamsTheLiveTwinUnderAScenario) {
  Sim sim("scenario", {}, {"--scenario", std::string(RUFFINI_SOURCE_DIR) + "/config/scenarios/forearm-presses.yaml"});
  ASSERT_TRUE(sim.ok());
  Conn c(sim.stream_port_);
  ASSERT_TRUE(c.connected());
  const auto r = ReadFrames(c, 300);
  ASSERT_GE(r.serials.size(), 300u);  // 16 ascending in-window peaks on channel 0, or the decoder refuses
  EXPECT_TRUE(r.rejected.empty());
  for (std::size_t i = 1; i < r.serials.size(); ++i) ASSERT_EQ(r.serials[i], r.serials[i - 1] + 1) << i;
  EXPECT_EQ(sim.Stop(), 0);
}

}  // namespace
