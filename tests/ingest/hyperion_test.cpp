// The Hyperion codec: golden bytes written out by hand from the struct formats (header `<BBHI`, peaks header
// `<HBBIQII`, `<h` counts, `<d` peaks), round trips, any chunking, and one test per rejection reason.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <cstdint>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "ruffini/error.h"
#include "ruffini/ingest/hyperion.h"

namespace ruffini::ingest {
namespace {

using Bytes = std::vector<std::uint8_t>;
using Status = StreamDecoder::Status;

Bytes FromHex(std::string_view hex) {
  Bytes out;
  int nibbles = 0, acc = 0;
  for (const char c : hex) {
    int v;
    if (c >= '0' && c <= '9') v = c - '0';
    else if (c >= 'a' && c <= 'f') v = c - 'a' + 10;
    else continue;  // spaces, '|' separators
    acc = acc * 16 + v;
    if (++nibbles == 2) {
      out.push_back(static_cast<std::uint8_t>(acc));
      nibbles = acc = 0;
    }
  }
  return out;
}

// The worked example of docs/hyperion.md, derived by hand:
//   serial 42, 1700000000 s + 500000000 ns, buffer 100 %, version 0;
//   channel 0: one peak at 1550.0 nm (0x4098380000000000), channel 2: one at 1531.5 nm (0x4097ee0000000000).
constexpr std::string_view kGoldenFrame =
    "00 00 0000 48000000 |"                     // status 0, type 0, message_length 0, content_length 72
    "3800 64 00 00000000 |"                     // length 56, buffer_available 100, version 0, reserved
    "2a00000000000000 | 00f15365 | 0065cd1d |"  // serial 42, timestamp_s 0x6553f100, timestamp_ns 0x1dcd6500
    "0100 0000 0100 0000 0000 0000 0000 0000 0000 0000 0000 0000 0000 0000 0000 0000 |"  // 16 i16 counts
    "0000000000389840 | 0000000000ee9740";   // 1550.0, 1531.5 (f64, little-endian)

// Writes a frame by hand (not with EncodePeaks): every field explicit, so malformed frames can be made.
struct RawFrame {
  std::uint8_t status = 0, type = 0;
  std::uint16_t message_length = 0;
  std::int64_t content_length = -1;  // -1: the true length
  std::uint16_t length = 56;
  std::uint64_t serial = 7;
  std::uint32_t ts_s = 1'700'000'000, ts_ns = 0;
  std::array<std::int16_t, 16> counts{};
  std::vector<double> peaks;

  Bytes Bytes_() const {
    Bytes b;
    auto put = [&b](std::uint64_t v, int n) {
      for (int i = 0; i < n; ++i) b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
    };
    const std::size_t content = 56 + 8 * peaks.size();
    put(status, 1);
    put(type, 1);
    put(message_length, 2);
    put(content_length < 0 ? content : static_cast<std::uint64_t>(content_length), 4);
    put(length, 2);
    put(100, 1);
    put(0, 1);
    put(0, 4);
    put(serial, 8);
    put(ts_s, 4);
    put(ts_ns, 4);
    for (const auto c : counts) put(static_cast<std::uint16_t>(c), 2);
    for (const double p : peaks) {
      std::uint64_t u;
      std::memcpy(&u, &p, 8);
      put(u, 8);
    }
    return b;
  }
};

Wavelengths Ramp(double start = 1520.0) {
  Wavelengths w;
  for (std::size_t i = 0; i < 16; ++i) w[i] = start + 4.0 * static_cast<double>(i);
  return w;
}

// A 16-peak patch on `channel`.
RawFrame PatchFrame(std::uint64_t serial, std::size_t channel = 0, const Wavelengths& w = Ramp()) {
  RawFrame f;
  f.serial = serial;
  f.counts[channel] = 16;
  f.peaks.assign(w.begin(), w.end());
  return f;
}

struct Event {
  Status status;
  Reason reason;
  std::uint64_t serial;
  bool operator==(const Event&) const = default;
};

// Feeds `stream` in chunks of the given sizes (cycled) and records what came out.
std::vector<Event> FeedAll(StreamDecoder& d, const Bytes& stream, const std::vector<std::size_t>& chunks) {
  std::vector<Event> events;
  std::size_t at = 0, k = 0;
  while (at < stream.size()) {
    const std::size_t n = std::min(chunks[k++ % chunks.size()], stream.size() - at);
    std::span<const std::uint8_t> rest(stream.data() + at, n);
    at += n;
    while (!rest.empty()) {
      const auto r = d.Feed(rest);
      EXPECT_LE(r.consumed, rest.size());
      EXPECT_GT(r.consumed, 0u);
      rest = rest.subspan(r.consumed);
      if (r.status == Status::kFrame) events.push_back({r.status, r.reason, d.frame().serial_number});
      if (r.status == Status::kRejected || r.status == Status::kNeedsResync) events.push_back({r.status, r.reason, 0});
    }
  }
  return events;
}

// One complete message fed at once: its outcome.
StreamDecoder::Result FeedOne(StreamDecoder& d, const Bytes& b) {
  const auto r = d.Feed(b);
  EXPECT_EQ(r.consumed, b.size());
  return r;
}

// --- Golden bytes ------------------------------------------------------------------------------------------

TEST(HyperionGolden, DecodesTheWorkedExample) {
  const Bytes golden = FromHex(kGoldenFrame);
  ASSERT_EQ(golden.size(), 8u + 72u);
  StreamDecoder d({.pick = std::nullopt});
  const auto r = FeedOne(d, golden);
  ASSERT_EQ(r.status, Status::kFrame) << ReasonName(r.reason);
  const PeakFrame& f = d.frame();
  EXPECT_EQ(f.header.content_length, 72u);
  EXPECT_EQ(f.buffer_available, 100);
  EXPECT_EQ(f.version, 0);
  EXPECT_EQ(f.serial_number, 42u);
  EXPECT_EQ(f.timestamp_ns, 1'700'000'000'500'000'000LL);
  EXPECT_EQ(f.count[0], 1);
  EXPECT_EQ(f.count[1], 0);
  EXPECT_EQ(f.count[2], 1);
  ASSERT_EQ(f.channel(0).size(), 1u);
  EXPECT_EQ(f.channel(0)[0], 1550.0);
  ASSERT_EQ(f.channel(2).size(), 1u);
  EXPECT_EQ(f.channel(2)[0], 1531.5);
  EXPECT_TRUE(f.channel(15).empty());
  EXPECT_EQ(d.counters().frames, 1u);
  EXPECT_EQ(d.counters().bytes, 80u);
}

TEST(HyperionGolden, EncodesTheWorkedExample) {
  const std::array<double, 1> ch0{1550.0}, ch2{1531.5};
  PeakSample s;
  s.serial_number = 42;
  s.timestamp_ns = 1'700'000'000'500'000'000LL;
  s.buffer_available = 100;
  s.channel_peaks_nm[0] = ch0;
  s.channel_peaks_nm[2] = ch2;
  EXPECT_EQ(EncodePeaks(s), FromHex(kGoldenFrame));
  EXPECT_EQ(EncodedSize(s), 80u);
  Bytes exact(80), small(79);
  EXPECT_EQ(EncodePeaks(s, exact), 80u);
  EXPECT_EQ(exact, FromHex(kGoldenFrame));
  EXPECT_EQ(EncodePeaks(s, small), 0u);  // too small: nothing written, no overrun
}

TEST(HyperionGolden, EmptySampleHasSixteenZeroCounts) {
  PeakSample s;
  s.serial_number = 1;
  EXPECT_EQ(EncodePeaks(s), FromHex("00 00 0000 38000000 | 3800 64 00 00000000 | 0100000000000000 | 00000000 |"
                                    "00000000 | 0000000000000000 0000000000000000 0000000000000000 0000000000000000"));
}

TEST(HyperionGolden, CommandAndReplyBytes) {
  // `<BBHI` (options 0, 0, len 16, len 0) + "#GetSerialNumber"
  EXPECT_EQ(EncodeCommand("#GetSerialNumber"),
            FromHex("00 00 1000 00000000 | 23 47 65 74 53 65 72 69 61 6c 4e 75 6d 62 65 72"));
  // options 0, 0, len 28, len 2 + "#SetPeakDataStreamingDivider" + "10"
  const Bytes set = FromHex(
      "00 00 1c00 02000000 | 23 53 65 74 50 65 61 6b 44 61 74 61 53 74 72 65 61 6d 69 6e 67 44 69 76 69 64 65 72 |"
      "31 30");
  EXPECT_EQ(EncodeCommand("#SetPeakDataStreamingDivider", "10"), set);
  Command c;
  const auto r = DecodeCommand(set, c);
  ASSERT_EQ(r.status, MessageResult::Status::kOk);
  EXPECT_EQ(r.consumed, set.size());
  EXPECT_EQ(c.options, 0);
  EXPECT_EQ(c.command, "#SetPeakDataStreamingDivider");
  EXPECT_EQ(c.argument, "10");

  // #isready answers a u8: status 0, type 0, no message, 1 byte of content.
  const std::array<std::uint8_t, 1> one{1};
  EXPECT_EQ(EncodeReply({.content = one}), FromHex("00 00 0000 01000000 | 01"));
  // An error reply: status 1, message "bad", no content.
  const Bytes error = FromHex("01 00 0300 00000000 | 62 61 64");
  EXPECT_EQ(EncodeReply({.status = 1, .message = "bad"}), error);
  Reply rep;
  const auto e = DecodeReply(error, rep);
  ASSERT_EQ(e.status, MessageResult::Status::kOk);
  EXPECT_EQ(rep.status, 1);
  EXPECT_EQ(rep.message, "bad");
  EXPECT_TRUE(rep.content.empty());
}

// --- Round trips and chunking ------------------------------------------------------------------------------

TEST(HyperionStream, RoundTripPicksTheChannel) {
  const Wavelengths w = Ramp(1525.25);
  const Bytes b = EncodeWavelengths(9, 1'234'567'890'123'456'789LL, 3, w);
  StreamDecoder d({.pick = PickConfig{.channel = 3}});
  ASSERT_EQ(FeedOne(d, b).status, Status::kFrame);
  EXPECT_EQ(d.wavelength_nm(), w);
  EXPECT_EQ(d.flags(), kFlagNone);
  EXPECT_EQ(d.frame().serial_number, 9u);
  EXPECT_EQ(d.frame().timestamp_ns, 1'234'567'890'123'456'789LL);
  EXPECT_EQ(d.frame().header.message_length, 0);
  for (std::size_t c = 0; c < 16; ++c) EXPECT_EQ(d.frame().count[c], c == 3 ? 16 : 0);
}

TEST(HyperionStream, AnyChunkingGivesTheSameFrames) {
  Bytes stream;
  std::vector<Event> expected;
  std::mt19937 rng(5);
  for (std::uint64_t k = 1; k <= 40; ++k) {
    RawFrame f = PatchFrame(k, 1);
    // Other channels carry other sensors' peaks (any wavelength): they must not disturb channel 1.
    for (int extra = 0; extra < static_cast<int>(k % 4); ++extra) f.peaks.push_back(1600.0 + extra);
    f.counts[5] = static_cast<std::int16_t>(k % 4);
    if (k % 7 == 0) f.peaks[4] = 1700.0;  // out of the window on channel 1: rejected, stream still aligned
    const Bytes b = f.Bytes_();
    stream.insert(stream.end(), b.begin(), b.end());
    expected.push_back(k % 7 == 0 ? Event{Status::kRejected, Reason::kOutOfWindow, 0}
                                  : Event{Status::kFrame, Reason::kOk, k});
  }
  std::vector<std::vector<std::size_t>> chunkings = {{1}, {2}, {3}, {7}, {8}, {55}, {64}, {1, 200, 3}, {stream.size()}};
  std::vector<std::size_t> random;
  for (int i = 0; i < 200; ++i) random.push_back(1 + rng() % 300);
  chunkings.push_back(random);
  for (const auto& chunks : chunkings) {
    StreamDecoder d({.pick = PickConfig{.channel = 1}});
    EXPECT_EQ(FeedAll(d, stream, chunks), expected) << "first chunk " << chunks[0];
    EXPECT_EQ(d.counters().bytes, stream.size());
    EXPECT_EQ(d.counters().frames, 35u);
    EXPECT_EQ(d.counters().rejected[static_cast<std::size_t>(Reason::kOutOfWindow)], 5u);
    EXPECT_EQ(d.counters().lost_samples, 0u);
  }
}

TEST(HyperionStream, TwoFramesInOneChunk) {
  Bytes b = PatchFrame(1).Bytes_();
  const Bytes second = PatchFrame(2, 0, Ramp(1521.0)).Bytes_();
  const std::size_t first_size = b.size();
  b.insert(b.end(), second.begin(), second.end());
  b.insert(b.end(), second.begin(), second.begin() + 5);  // and the start of a third
  StreamDecoder d;
  std::span<const std::uint8_t> rest = b;
  auto r = d.Feed(rest);
  ASSERT_EQ(r.status, Status::kFrame);
  EXPECT_EQ(r.consumed, first_size);
  EXPECT_EQ(d.wavelength_nm(), Ramp());
  rest = rest.subspan(r.consumed);
  r = d.Feed(rest);
  ASSERT_EQ(r.status, Status::kFrame);
  EXPECT_EQ(d.frame().serial_number, 2u);
  EXPECT_EQ(d.wavelength_nm(), Ramp(1521.0));
  rest = rest.subspan(r.consumed);
  r = d.Feed(rest);
  EXPECT_EQ(r.status, Status::kNeedMore);
  EXPECT_EQ(r.consumed, 5u);
}

TEST(HyperionStream, MessageLengthStatusAndTypeArePassedThrough) {
  RawFrame f = PatchFrame(3);
  f.status = 2;
  f.type = 4;
  f.message_length = 9;  // stream clients ignore it and read content_length bytes
  StreamDecoder d;
  ASSERT_EQ(FeedOne(d, f.Bytes_()).status, Status::kFrame);
  EXPECT_EQ(d.frame().header.status, 2);
  EXPECT_EQ(d.frame().header.type, 4);
  EXPECT_EQ(d.frame().header.message_length, 9);
}

TEST(HyperionStream, SerialGapsAndRestartsAreCounted) {
  StreamDecoder d;
  for (const std::uint64_t s : {10, 11, 14, 15, 3, 4}) FeedOne(d, PatchFrame(s).Bytes_());
  EXPECT_EQ(d.counters().frames, 6u);
  EXPECT_EQ(d.counters().lost_samples, 2u);     // 12 and 13
  EXPECT_EQ(d.counters().serial_restarts, 1u);  // 15 -> 3
}

// --- Rejections --------------------------------------------------------------------------------------------

void ExpectFraming(const Bytes& bad, Reason reason, DecoderConfig config = {}) {
  StreamDecoder d(config);
  const Bytes good = PatchFrame(100).Bytes_();
  Bytes stream = bad;
  stream.insert(stream.end(), good.begin(), good.end());
  // Fed one byte at a time: the error is seen as soon as the bytes that prove it arrive.
  std::vector<Event> events = FeedAll(d, stream, {1});
  ASSERT_FALSE(events.empty()) << ReasonName(reason);
  EXPECT_EQ(events.front(), (Event{Status::kNeedsResync, reason, 0})) << ReasonName(events.front().reason);
  for (std::size_t i = 1; i < events.size(); ++i) EXPECT_EQ(events[i].status, Status::kNeedsResync);
  EXPECT_TRUE(d.needs_resync());
  EXPECT_EQ(d.counters().frames, 0u);  // the good frame after it is not trusted
  EXPECT_EQ(d.counters().rejected[static_cast<std::size_t>(reason)], 1u);
  EXPECT_EQ(d.counters().resyncs, 1u);
  EXPECT_EQ(d.counters().bytes_discarded, stream.size());
  // A new connection: Reset, and the stream decodes again.
  d.Reset();
  EXPECT_FALSE(d.needs_resync());
  EXPECT_EQ(FeedOne(d, good).status, Status::kFrame);
}

TEST(HyperionReject, ContentTooLong) {
  RawFrame f = PatchFrame(1);
  f.content_length = 4097;
  Bytes b = f.Bytes_();
  ExpectFraming(Bytes(b.begin(), b.begin() + 8), Reason::kContentTooLong,
                {.max_content_bytes = 4096});
  f.content_length = 0xffffffff;  // never allocated, never waited for
  ExpectFraming(f.Bytes_(), Reason::kContentTooLong);
}

TEST(HyperionReject, ContentTooShort) {
  RawFrame f;
  f.content_length = 24;  // a peaks header without the counts
  Bytes b = f.Bytes_();
  ExpectFraming(Bytes(b.begin(), b.begin() + 32), Reason::kContentTooShort);
  f.content_length = 0;
  b = f.Bytes_();
  ExpectFraming(Bytes(b.begin(), b.begin() + 8), Reason::kContentTooShort);
}

TEST(HyperionReject, BadPeaksLength) {
  RawFrame f = PatchFrame(1);
  f.length = 24 + 2 * 8;  // eight channels: parses differently in the vendor's C++ and Python clients
  ExpectFraming(f.Bytes_(), Reason::kBadPeaksLength);
}

TEST(HyperionReject, NegativeCount) {
  RawFrame f = PatchFrame(1);
  f.counts[4] = -1;
  ExpectFraming(f.Bytes_(), Reason::kNegativeCount);
}

TEST(HyperionReject, CountMismatch) {
  RawFrame f = PatchFrame(1);
  f.counts[0] = 15;  // 15 peaks declared, 16 sent
  ExpectFraming(f.Bytes_(), Reason::kCountMismatch);
  f.counts[0] = 17;
  ExpectFraming(f.Bytes_(), Reason::kCountMismatch);
}

// A per-frame rejection: the frame is dropped, the next one decodes.
void ExpectRejected(const RawFrame& bad, Reason reason, DecoderConfig config = {}) {
  StreamDecoder d(config);
  const Bytes b = bad.Bytes_();
  const auto r = FeedOne(d, b);
  EXPECT_EQ(r.status, Status::kRejected);
  EXPECT_EQ(r.reason, reason) << ReasonName(r.reason) << " instead of " << ReasonName(reason);
  EXPECT_FALSE(d.needs_resync());
  EXPECT_EQ(d.counters().rejected[static_cast<std::size_t>(reason)], 1u);
  EXPECT_EQ(d.counters().bytes_discarded, b.size());
  const std::size_t channel = config.pick ? config.pick->channel : 0;
  EXPECT_EQ(FeedOne(d, PatchFrame(bad.serial + 1, channel).Bytes_()).status, Status::kFrame);
  EXPECT_EQ(d.counters().frames, 1u);
  EXPECT_EQ(d.counters().lost_samples, 0u);  // the rejected sample still arrived
}

TEST(HyperionReject, NonFinite) {
  RawFrame f = PatchFrame(1);
  f.peaks[3] = std::nan("");
  ExpectRejected(f, Reason::kNonFinite);
  f = PatchFrame(1);
  f.peaks[15] = INFINITY;
  ExpectRejected(f, Reason::kNonFinite);
  f = PatchFrame(1);  // on any channel, picked or not
  f.counts[9] = 1;
  f.peaks.push_back(-INFINITY);
  ExpectRejected(f, Reason::kNonFinite);
}

TEST(HyperionReject, BadTimestamp) {
  RawFrame f = PatchFrame(1);
  f.ts_ns = 1'000'000'000;
  ExpectRejected(f, Reason::kBadTimestamp);
}

TEST(HyperionReject, OutOfWindow) {
  for (const double nm : {1509.999, 1590.001, 0.0, -1550.0}) {
    Wavelengths w = Ramp();
    w[0] = nm;
    std::sort(w.begin(), w.end());
    ExpectRejected(PatchFrame(1, 0, w), Reason::kOutOfWindow);
  }
  Wavelengths edges = Ramp();
  edges[0] = 1510.0;
  edges[15] = 1590.0;
  StreamDecoder d;
  EXPECT_EQ(FeedOne(d, PatchFrame(1, 0, edges).Bytes_()).status, Status::kFrame);  // the window is closed
}

TEST(HyperionReject, WrongPeakCount) {
  RawFrame f = PatchFrame(1);
  f.counts[0] = 15;
  f.peaks.pop_back();
  ExpectRejected(f, Reason::kWrongPeakCount);
  ExpectRejected(PatchFrame(1, 2), Reason::kWrongPeakCount);  // the patch is on channel 2, channel 0 is empty
}

TEST(HyperionReject, UnorderedPeaks) {
  Wavelengths w = Ramp();
  std::swap(w[4], w[5]);
  ExpectRejected(PatchFrame(1, 0, w), Reason::kUnorderedPeaks);
  w = Ramp();
  w[5] = w[4];
  ExpectRejected(PatchFrame(1, 0, w), Reason::kUnorderedPeaks);
}

PickConfig MissingAllowed(std::size_t channel = 0) { return NearestGratingBands(channel, Ramp()); }

TEST(HyperionPick, MissingPeaksAreNaNWhenAllowed) {
  Wavelengths w = Ramp();
  RawFrame f = PatchFrame(1);
  f.peaks.erase(f.peaks.begin() + 6);  // grating 6 went dark
  f.peaks[0] += 1.5;                   // a shifted peak still belongs to its nearest grating
  f.counts[0] = 15;
  StreamDecoder d({.pick = MissingAllowed()});
  ASSERT_EQ(FeedOne(d, f.Bytes_()).status, Status::kFrame);
  EXPECT_TRUE(std::isnan(d.wavelength_nm()[6]));
  EXPECT_EQ(d.wavelength_nm()[0], w[0] + 1.5);
  EXPECT_EQ(d.wavelength_nm()[7], w[7]);
  EXPECT_EQ(d.flags(), kFlagPeakMissing);
  // A whole frame still decodes without the flag; an empty channel is all NaN.
  ASSERT_EQ(FeedOne(d, PatchFrame(2).Bytes_()).status, Status::kFrame);
  EXPECT_EQ(d.wavelength_nm(), w);
  EXPECT_EQ(d.flags(), kFlagNone);
  ASSERT_EQ(FeedOne(d, PatchFrame(3, 4).Bytes_()).status, Status::kFrame);
  for (const double nm : d.wavelength_nm()) EXPECT_TRUE(std::isnan(nm));
  EXPECT_EQ(d.flags(), kFlagPeakMissing);
}

TEST(HyperionReject, PeakOutsideBandsAndDuplicatePeak) {
  PickConfig narrow = MissingAllowed();
  for (std::size_t i = 0; i < 16; ++i) {
    narrow.band_lo_nm[i] = Ramp()[i] - 1.0;
    narrow.band_hi_nm[i] = Ramp()[i] + 1.0;
  }
  Wavelengths w = Ramp();
  w[3] += 1.5;  // between the bands of gratings 3 and 4
  ExpectRejected(PatchFrame(1, 0, w), Reason::kPeakOutsideBands, {.pick = narrow});

  RawFrame f = PatchFrame(1);
  f.peaks[4] = f.peaks[3] + 0.5;  // two peaks nearest grating 3, none for grating 4
  ExpectRejected(f, Reason::kDuplicatePeak, {.pick = MissingAllowed()});

  f = PatchFrame(1);
  f.counts[0] = 17;
  f.peaks.push_back(1589.0);
  ExpectRejected(f, Reason::kWrongPeakCount, {.pick = MissingAllowed()});
}

TEST(HyperionReject, CountersAddUp) {
  StreamDecoder d;
  RawFrame nan = PatchFrame(2);
  nan.peaks[0] = std::nan("");
  RawFrame short_ch = PatchFrame(3);
  short_ch.counts[0] = 15;
  short_ch.peaks.pop_back();
  Bytes stream;
  for (const auto& f : {PatchFrame(1), nan, short_ch, PatchFrame(4)}) {
    const Bytes b = f.Bytes_();
    stream.insert(stream.end(), b.begin(), b.end());
  }
  FeedAll(d, stream, {13});
  const Counters& c = d.counters();
  EXPECT_EQ(c.bytes, stream.size());
  EXPECT_EQ(c.frames, 2u);
  EXPECT_EQ(c.rejected[static_cast<std::size_t>(Reason::kNonFinite)], 1u);
  EXPECT_EQ(c.rejected[static_cast<std::size_t>(Reason::kWrongPeakCount)], 1u);
  EXPECT_EQ(c.bytes_discarded, nan.Bytes_().size() + short_ch.Bytes_().size());
  EXPECT_EQ(c.resyncs, 0u);
  EXPECT_EQ(c.rejected[0], 0u);
}

TEST(HyperionReject, ReasonNamesAreDistinct) {
  std::set<std::string_view> names;
  for (std::size_t i = 0; i < kReasonCount; ++i) names.insert(ReasonName(static_cast<Reason>(i)));
  EXPECT_EQ(names.size(), kReasonCount);
  EXPECT_EQ(names.count("unknown"), 0u);
  EXPECT_EQ(ReasonName(Reason::kCountMismatch), "count_mismatch");
}

// --- Configuration and encoding errors ---------------------------------------------------------------------

TEST(HyperionConfig, BadConfigsNameTheField) {
  EXPECT_THROW(StreamDecoder({.max_content_bytes = 55}), InputError);
  EXPECT_THROW(StreamDecoder({.max_content_bytes = 0xffffffff}), InputError);
  try {
    StreamDecoder d({.pick = PickConfig{.channel = 16}});
    FAIL();
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "pick: 'channel' (16) must lie in 0..15");
  }
  PickConfig overlap = MissingAllowed();
  overlap.band_lo_nm[5] = overlap.band_hi_nm[4];
  EXPECT_THROW(Validate(overlap), InputError);
  Wavelengths down = Ramp();
  std::swap(down[0], down[1]);
  EXPECT_THROW(NearestGratingBands(0, down), InputError);
}

TEST(HyperionConfig, EncodingErrors) {
  std::vector<double> many(32768, 1550.0);
  PeakSample s;
  s.channel_peaks_nm[1] = many;
  EXPECT_THROW(EncodePeaks(s), InputError);
  Bytes big(EncodedSize(s));
  EXPECT_EQ(EncodePeaks(s, big), 0u);
  PeakSample t;
  t.timestamp_ns = -1;
  EXPECT_THROW(EncodePeaks(t), InputError);
  EXPECT_THROW(EncodeWavelengths(1, 0, 16, Ramp()), InputError);
  EXPECT_THROW(EncodeCommand(""), InputError);
  EXPECT_THROW(EncodeCommand("#Get Peaks"), InputError);
  const std::array<std::uint8_t, 1> one{1};
  EXPECT_THROW(EncodeReply({.status = 3, .message = "no", .content = one}), InputError);
}

TEST(HyperionStream, TwinFrameLeavesMissingPeaksOut) {
  Wavelengths w = Ramp();
  w[2] = std::nan("");
  const Bytes b = EncodeWavelengths(5, 0, 0, w);
  EXPECT_EQ(b.size(), 8u + 56u + 15u * 8u);
  StreamDecoder d({.pick = MissingAllowed()});
  ASSERT_EQ(FeedOne(d, b).status, Status::kFrame);
  EXPECT_TRUE(std::isnan(d.wavelength_nm()[2]));
  EXPECT_EQ(d.wavelength_nm()[3], w[3]);
}

// A hard press can push a peak past its neighbour's: the frame lists the channel's peaks by wavelength, as
// the instrument does (a stream in another order is refused as unordered peaks).
TEST(HyperionStream, TwinFrameListsPeaksByWavelength) {
  Wavelengths w = Ramp();
  std::swap(w[4], w[5]);
  w[9] = std::nan("");
  const Bytes b = EncodeWavelengths(5, 0, 0, w);
  ASSERT_EQ(b.size(), 8u + 56u + 15u * 8u);
  for (std::size_t k = 0; k + 1 < 15; ++k) {
    double a = 0, c = 0;
    std::memcpy(&a, b.data() + 64 + 8 * k, 8);
    std::memcpy(&c, b.data() + 64 + 8 * (k + 1), 8);
    EXPECT_LT(a, c) << k;
  }
}

// --- Command port ------------------------------------------------------------------------------------------

TEST(HyperionCommand, PartialAndBackToBack) {
  Bytes b = EncodeCommand("#isready");
  const Bytes second = EncodeCommand("#GetPeaks", "", 1);
  b.insert(b.end(), second.begin(), second.end());
  Command c;
  for (std::size_t n = 0; n < 8; ++n) {
    const auto r = DecodeCommand(std::span(b).first(n), c);
    EXPECT_EQ(r.status, MessageResult::Status::kNeedMore);
    EXPECT_EQ(r.needed, 8u);
  }
  const auto part = DecodeCommand(std::span(b).first(10), c);
  EXPECT_EQ(part.status, MessageResult::Status::kNeedMore);
  EXPECT_EQ(part.needed, 16u);
  auto r = DecodeCommand(b, c);
  ASSERT_EQ(r.status, MessageResult::Status::kOk);
  EXPECT_EQ(c.command, "#isready");
  EXPECT_EQ(r.consumed, 16u);
  r = DecodeCommand(std::span(b).subspan(r.consumed), c);
  ASSERT_EQ(r.status, MessageResult::Status::kOk);
  EXPECT_EQ(c.command, "#GetPeaks");
  EXPECT_EQ(c.options, 1);
  EXPECT_TRUE(c.argument.empty());
}

TEST(HyperionCommand, Rejections) {
  Command c;
  const auto bad = [&](std::string_view hex, Reason reason, std::uint32_t max_arg = 65536) {
    const auto r = DecodeCommand(FromHex(hex), c, max_arg);
    EXPECT_EQ(r.status, MessageResult::Status::kRejected) << hex;
    EXPECT_EQ(r.reason, reason) << hex << ": " << ReasonName(r.reason);
    EXPECT_EQ(r.consumed, 0u);
  };
  bad("00 00 0000 00000000", Reason::kBadCommand);             // empty command
  bad("00 00 0200 00000000 23 20", Reason::kBadCommand);       // "# "
  bad("00 00 0200 00000000 23 80", Reason::kBadCommand);       // not ASCII
  bad("00 00 0100 ffffffff", Reason::kCommandTooLong);         // a 4 GiB argument is never waited for
  bad("00 00 0100 05000000", Reason::kCommandTooLong, 4);
}

TEST(HyperionReply, ContentAndRejections) {
  // #GetPeaks answers the peaks content without the stream header: ParsePeaks reads it.
  const Bytes frame = FromHex(kGoldenFrame);
  const Bytes content(frame.begin() + 8, frame.end());
  const Bytes reply = EncodeReply({.message = "ok", .content = content});
  Reply r;
  const auto res = DecodeReply(reply, r);
  ASSERT_EQ(res.status, MessageResult::Status::kOk);
  EXPECT_EQ(r.message, "ok");
  std::array<double, 4> storage{};
  PeakFrame f;
  ASSERT_EQ(ParsePeaks(r.content, storage, f), Reason::kOk);
  EXPECT_EQ(f.serial_number, 42u);
  EXPECT_EQ(f.channel(2)[0], 1531.5);
  std::array<double, 1> small{};
  EXPECT_EQ(ParsePeaks(r.content, small, f), Reason::kContentTooLong);

  EXPECT_EQ(DecodeReply(FromHex("02 00 0300 01000000 626164 00"), r).reason, Reason::kErrorWithContent);
  EXPECT_EQ(DecodeReply(FromHex("00 00 0000 00001000"), r, 4096).reason, Reason::kReplyTooLong);
  const auto more = DecodeReply(FromHex("00 00 0300 02000000 6f6b"), r);
  EXPECT_EQ(more.status, MessageResult::Status::kNeedMore);
  EXPECT_EQ(more.needed, 13u);
}

}  // namespace
}  // namespace ruffini::ingest
