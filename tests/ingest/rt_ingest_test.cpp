// The per-frame decode path allocates nothing once the decoder is constructed: a counting global operator new,
// armed around Feed (every chunking, good, rejected and framing-error frames, Reset), ParsePeaks, PickChannel,
// the span EncodePeaks and the command/reply decoders.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "../common/alloc_counter.h"
#include "ruffini/ingest/hyperion.h"

namespace ruffini::ingest {
namespace {

std::vector<std::uint8_t> Stream(int frames) {
  std::vector<std::uint8_t> s;
  for (int k = 0; k < frames; ++k) {
    Wavelengths w;
    for (std::size_t i = 0; i < kGratings; ++i) w[i] = 1520.0 + 4.0 * static_cast<double>(i) + 0.001 * k;
    if (k % 5 == 0) w[3] = std::nan("");   // a missing peak: accepted (missing allowed), NaN-filled
    if (k % 11 == 0) w[0] = 1500.0;         // out of the window: rejected
    const auto b = EncodeWavelengths(static_cast<std::uint64_t>(k), 1'700'000'000'000'000'000LL + k, 2, w);
    s.insert(s.end(), b.begin(), b.end());
  }
  return s;
}

TEST(IngestRealTime, FeedDoesNotAllocate) {
  Wavelengths centre;
  for (std::size_t i = 0; i < kGratings; ++i) centre[i] = 1520.0 + 4.0 * static_cast<double>(i);
  StreamDecoder d({.pick = NearestGratingBands(2, centre)});
  const auto stream = Stream(300);
  std::vector<std::uint8_t> garbage(64, 0xff);  // content_length 0xffffffff: a framing error
  long frames = 0, rejected = 0;
  const long n = ruffini::testing::CountAllocations([&] {
    for (const std::size_t chunk : {std::size_t{1}, std::size_t{7}, std::size_t{4096}}) {
      for (std::size_t at = 0; at < stream.size(); at += chunk) {
        std::span<const std::uint8_t> rest(stream.data() + at, std::min(chunk, stream.size() - at));
        while (!rest.empty()) {
          const auto r = d.Feed(rest);
          rest = rest.subspan(r.consumed);
          frames += r.status == StreamDecoder::Status::kFrame;
          rejected += r.status == StreamDecoder::Status::kRejected;
        }
      }
      (void)d.Feed(garbage);
      (void)d.Feed(garbage);
      d.Reset();
    }
  });
  EXPECT_EQ(n, 0);
  EXPECT_EQ(frames + rejected, 900);
  EXPECT_EQ(rejected, 3 * 28);
  EXPECT_EQ(d.counters().resyncs, 3u);
}

TEST(IngestRealTime, ParsePickEncodeAndCommandsDoNotAllocate) {
  const auto one = EncodeWavelengths(1, 0, 0, Wavelengths{1520, 1524, 1528, 1532, 1536, 1540, 1544, 1548,
                                                          1552, 1556, 1560, 1564, 1568, 1572, 1576, 1580});
  const auto cmd = EncodeCommand("#SetPeakDataStreamingDivider", "10");
  const auto rep = EncodeReply({.message = "ok", .content = std::span(one).subspan(8)});
  std::array<double, 64> storage{};
  std::vector<std::uint8_t> out(one.size());
  const PickConfig pick{};
  long ok = 0;
  const long n = ruffini::testing::CountAllocations([&] {
    for (int k = 0; k < 1000; ++k) {
      PeakFrame f;
      Wavelengths w;
      std::uint32_t flags = 0;
      ok += ParsePeaks(std::span(one).subspan(8), storage, f) == Reason::kOk;
      ok += PickChannel(f, pick, w, flags) == Reason::kOk;
      PeakSample s;
      s.serial_number = static_cast<std::uint64_t>(k);
      s.channel_peaks_nm[0] = std::span<const double>(w.data(), w.size());
      ok += EncodePeaks(s, out) == one.size();
      Command c;
      Reply r;
      ok += DecodeCommand(cmd, c).status == MessageResult::Status::kOk;
      ok += DecodeReply(rep, r).status == MessageResult::Status::kOk;
    }
  });
  EXPECT_EQ(n, 0);
  EXPECT_EQ(ok, 5000);
  int* seen = nullptr;  // the counter counts
  EXPECT_EQ(ruffini::testing::CountAllocations([&] { seen = new int(1); }), 1);
  delete seen;
}

}  // namespace
}  // namespace ruffini::ingest
