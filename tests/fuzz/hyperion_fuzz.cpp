// libFuzzer driver for the Hyperion codec. The first byte picks the target:
//   0: StreamDecoder (byte 1 picks the channel config, byte 2 seeds a chunking; the rest is the stream)
//   1: DecodeCommand over a buffer of back-to-back commands
//   2: DecodeReply over a buffer of back-to-back replies
//   3: ParsePeaks + PickChannel on one peaks content
// Beyond "no crash, no sanitizer report", it checks properties: a chunked feed gives the same events and
// counters as one whole feed, a delivered frame re-encodes to the bytes it came from, a delivered picked channel
// lies in the window, and a decoded command or reply re-encodes to its bytes.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <span>
#include <vector>

#include "ruffini/ingest/hyperion.h"

using namespace ruffini;
using namespace ruffini::ingest;

namespace {

void Check(bool ok, const char* what) {
  if (!ok) {
    __builtin_printf("property violated: %s\n", what);
    std::abort();
  }
}

struct Event {
  StreamDecoder::Status status;
  Reason reason;
  std::uint64_t serial;
  std::size_t end;  // offset in the stream just after the event's last byte
};

DecoderConfig ConfigFor(std::uint8_t selector) {
  DecoderConfig c;
  c.max_content_bytes = 56 + 8 * 64;  // small, so lengths just above it are reachable
  const std::size_t channel = selector % kChannels;
  if (selector & 0x40) {
    c.pick = std::nullopt;
  } else if (selector & 0x80) {
    Wavelengths centre;
    for (std::size_t i = 0; i < kGratings; ++i) centre[i] = 1520.0 + 4.0 * static_cast<double>(i);
    c.pick = NearestGratingBands(channel, centre);
  } else {
    c.pick = PickConfig{.channel = channel};
  }
  return c;
}

std::vector<Event> Run(StreamDecoder& d, std::span<const std::uint8_t> stream, std::uint32_t chunk_seed) {
  std::vector<Event> events;
  std::size_t at = 0;
  std::uint32_t lcg = chunk_seed;
  while (at < stream.size()) {
    std::size_t n = stream.size() - at;
    if (chunk_seed != 0) {
      lcg = lcg * 1664525u + 1013904223u;
      n = std::min<std::size_t>(n, 1 + (lcg >> 24) % 97);
    }
    std::span<const std::uint8_t> rest = stream.subspan(at, n);
    while (!rest.empty()) {
      const auto r = d.Feed(rest);
      Check(r.consumed > 0 && r.consumed <= rest.size(), "Feed consumes 1..size bytes");
      rest = rest.subspan(r.consumed);
      const std::size_t end = at + n - rest.size();
      if (r.status == StreamDecoder::Status::kFrame) {
        events.push_back({r.status, r.reason, d.frame().serial_number, end});
        if (d.config().pick) {
          for (const double nm : d.wavelength_nm()) {
            Check(std::isnan(nm) || (nm >= kWindowLoNm && nm <= kWindowHiNm), "picked peaks lie in the window");
          }
        }
      } else if (r.status != StreamDecoder::Status::kNeedMore) {
        // After a resync only the first event names a reason; later ones are all the same.
        if (!events.empty() && events.back().status == StreamDecoder::Status::kNeedsResync) continue;
        events.push_back({r.status, r.reason, 0, 0});
      }
    }
    at += n;
  }
  return events;
}

void FuzzStream(std::span<const std::uint8_t> data) {
  if (data.size() < 2) return;
  const DecoderConfig config = ConfigFor(data[0]);
  const std::uint32_t seed = 1u + data[1];
  const auto stream = data.subspan(2);

  StreamDecoder whole(config);
  const auto a = Run(whole, stream, 0);
  StreamDecoder chunked(config);
  const auto b = Run(chunked, stream, seed);
  Check(a.size() == b.size(), "chunking changes the number of events");
  for (std::size_t i = 0; i < a.size(); ++i) {
    Check(a[i].status == b[i].status && a[i].reason == b[i].reason && a[i].serial == b[i].serial,
          "chunking changes an event");
  }
  const Counters& ca = whole.counters();
  const Counters& cb = chunked.counters();
  Check(ca.bytes == stream.size() && cb.bytes == stream.size(), "every byte counted once");
  Check(ca.frames == cb.frames && ca.rejected == cb.rejected && ca.bytes_discarded == cb.bytes_discarded &&
            ca.lost_samples == cb.lost_samples && ca.resyncs == cb.resyncs,
        "chunking changes the counters");
  Check(ca.bytes_discarded <= ca.bytes, "discarded at most what was fed");

  // Each delivered frame re-encodes to its own bytes (reserved, status, type, message_length aside).
  StreamDecoder again(config);
  std::size_t at = 0;
  std::vector<std::uint8_t> out;
  while (at < stream.size()) {
    const auto r = again.Feed(stream.subspan(at));
    at += r.consumed;
    if (r.status != StreamDecoder::Status::kFrame) continue;
    const PeakFrame& f = again.frame();
    PeakSample s;
    s.serial_number = f.serial_number;
    s.timestamp_ns = f.timestamp_ns;
    s.buffer_available = f.buffer_available;
    s.version = f.version;
    for (std::size_t c = 0; c < kChannels; ++c) s.channel_peaks_nm[c] = f.channel(c);
    out.assign(EncodedSize(s), 0);
    Check(EncodePeaks(s, out) == out.size(), "a decoded frame encodes");
    const std::size_t size = 8 + f.header.content_length;
    Check(size == out.size() && at >= size, "frame sizes agree");
    const std::uint8_t* orig = stream.data() + (at - size);
    Check(std::memcmp(orig + 4, out.data() + 4, 8) == 0, "content_length, length and the next bytes agree");
    Check(std::memcmp(orig + 16, out.data() + 16, size - 16) == 0, "serial, time, counts and peaks agree");
  }
}

void FuzzCommands(std::span<const std::uint8_t> data) {
  Command c;
  while (!data.empty()) {
    const auto r = DecodeCommand(data, c, 1024);
    if (r.status != MessageResult::Status::kOk) {
      Check(r.consumed == 0, "no bytes consumed unless ok");
      Check(r.status != MessageResult::Status::kNeedMore || r.needed > data.size(), "needs more than it has");
      return;
    }
    Check(r.consumed >= 9 && r.consumed <= data.size(), "a command is 9..size bytes");
    const auto b = EncodeCommand(c.command, c.argument, c.options);
    // Byte 1 of a request is 0 when we write it; the decoder ignores it.
    Check(b.size() == r.consumed && b[0] == data[0] && std::memcmp(b.data() + 2, data.data() + 2, b.size() - 2) == 0,
          "a decoded command re-encodes to its bytes");
    data = data.subspan(r.consumed);
  }
}

void FuzzReplies(std::span<const std::uint8_t> data) {
  Reply rep;
  while (!data.empty()) {
    const auto r = DecodeReply(data, rep, 4096);
    if (r.status != MessageResult::Status::kOk) {
      Check(r.consumed == 0, "no bytes consumed unless ok");
      return;
    }
    Check(rep.status == 0 || rep.content.empty(), "an error reply has no content");
    const auto b = EncodeReply(rep);
    Check(b.size() == r.consumed && std::memcmp(b.data(), data.data(), b.size()) == 0,
          "a decoded reply re-encodes to its bytes");
    data = data.subspan(r.consumed);
  }
}

void FuzzParse(std::span<const std::uint8_t> data) {
  if (data.empty()) return;
  std::array<double, 32> storage{};
  PeakFrame f;
  if (ParsePeaks(data.subspan(1), storage, f) != Reason::kOk) return;
  std::size_t total = 0;
  for (std::size_t c = 0; c < kChannels; ++c) {
    Check(f.first[c] == total, "channels follow each other");
    total += f.count[c];
  }
  Check(total == f.peaks_nm.size() && 56 + 8 * total == data.size() - 1, "counts add up to the content");
  Wavelengths w;
  std::uint32_t flags = 0;
  const DecoderConfig config = ConfigFor(data[0]);
  if (config.pick) (void)PickChannel(f, *config.pick, w, flags);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const std::span<const std::uint8_t> rest(data + 1, size - 1);
  switch (data[0] % 4) {
    case 0: FuzzStream(rest); break;
    case 1: FuzzCommands(rest); break;
    case 2: FuzzReplies(rest); break;
    default: FuzzParse(rest); break;
  }
  return 0;
}
