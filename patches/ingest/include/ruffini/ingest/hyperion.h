#pragma once
// The Hyperion (Luna / Micron Optics x55 family) wire format: the peak stream (TCP 51972) and the command
// port (TCP 51971). A pure codec: bytes in, frames out, no sockets. docs/hyperion.md has the byte layout with
// a worked frame, every rejection reason and the resync policy.
//
// Every message: an 8-byte little-endian header `u8 status, u8 type, u16 message_length, u32 content_length`,
// then message_length bytes of message text, then content_length bytes of content.
// Peak-stream content: a 24-byte peaks header `u16 length, u8 buffer_available, u8 version, u32 reserved,
// u64 serial_number, u32 timestamp_s, u32 timestamp_ns`, then 16 `i16` peak counts (one per channel; length
// is 24 + 2 x 16 = 56, the only value we accept or write), then every peak as `f64` nm, channel after channel.
//
// Malformed input never throws, aborts or allocates on the per-frame path: it is a rejection with a Reason,
// counted in plain Counters. A TCP stream has no sync marker, so a framing error (a length that cannot be
// right) puts the StreamDecoder into "needs resync": it discards every further byte until Reset(); the
// service drops the connection, reconnects and calls Reset().
#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>
#include <vector>

#include "ruffini/frame.h"

namespace ruffini::ingest {

inline constexpr std::uint16_t kCommandPort = 51971;
inline constexpr std::uint16_t kPeakStreamPort = 51972;

inline constexpr std::size_t kChannels = 16;           // channel counts per peaks content, always 16
inline constexpr std::size_t kHeaderBytes = 8;         // message header
inline constexpr std::size_t kPeaksHeaderBytes = 24;   // peaks header, without the counts
inline constexpr std::size_t kPeaksLength = kPeaksHeaderBytes + 2 * kChannels;  // 56: `length` field
inline constexpr std::size_t kPeakBytes = 8;           // one f64 peak
inline constexpr std::size_t kMaxPeaksPerChannel = 32767;  // i16 count

// The one window every reported peak of the picked channel must lie in (the C-band gratings we use).
inline constexpr double kWindowLoNm = 1510.0;
inline constexpr double kWindowHiNm = 1590.0;

// Why input was refused. Framing reasons (IsFramingError) lose the stream's alignment; the rest drop one
// frame (or one command/reply) and keep going.
enum class Reason : std::uint8_t {
  kOk = 0,
  // Framing: the stream decoder needs a resync after these.
  kContentTooLong,     // content_length above the configured maximum
  kContentTooShort,    // content_length below the 56 bytes of peaks header + counts
  kBadPeaksLength,     // peaks header `length` is not 56 (24 + 2 x 16 channels)
  kNegativeCount,      // a channel's i16 peak count is negative
  kCountMismatch,      // 8 x (sum of counts) differs from the bytes after the counts
  // One frame dropped, stream still aligned.
  kNonFinite,          // some peak (any channel) is NaN or +-Inf
  kBadTimestamp,       // timestamp_ns is 1e9 or more (it is the nanoseconds within timestamp_s)
  kOutOfWindow,        // a peak of the picked channel lies outside 1510..1590 nm
  kWrongPeakCount,     // the picked channel has not exactly 16 peaks (or more than 16 with missing allowed)
  kUnorderedPeaks,     // the picked channel's peaks are not strictly ascending (missing not allowed)
  kPeakOutsideBands,   // missing allowed: a peak of the picked channel lies in no grating's band
  kDuplicatePeak,      // missing allowed: two peaks in one grating's band
  // Command port (returned by DecodeCommand / DecodeReply; the stream decoder never counts them).
  kCommandTooLong,     // argument length above the configured maximum
  kBadCommand,         // the command is empty or not printable ASCII (0x21..0x7e)
  kReplyTooLong,       // reply content_length above the configured maximum
  kErrorWithContent,   // an error reply (status != 0) with content_length != 0
};
inline constexpr std::size_t kReasonCount = 17;
// snake_case, stable: metric label values.
std::string_view ReasonName(Reason r) noexcept;
constexpr bool IsFramingError(Reason r) noexcept {
  return r == Reason::kContentTooLong || r == Reason::kContentTooShort || r == Reason::kBadPeaksLength ||
         r == Reason::kNegativeCount || r == Reason::kCountMismatch;
}

struct MessageHeader {
  std::uint8_t status = 0;
  std::uint8_t type = 0;
  std::uint16_t message_length = 0;
  std::uint32_t content_length = 0;
};

// --- Peak stream: encoding ---------------------------------------------------------------------------------

// One sample as the instrument would send it. channel_peaks_nm[c] lists channel c's peaks (any count up to
// 32767, usually ascending); the spans must outlive the call.
struct PeakSample {
  std::uint64_t serial_number = 0;
  std::int64_t timestamp_ns = 0;    // Unix time, ns; must be >= 0 and below 2^32 s
  std::uint8_t buffer_available = 100;  // percent
  std::uint8_t version = 0;
  std::array<std::span<const double>, kChannels> channel_peaks_nm{};
};

// Bytes EncodePeaks writes for this sample: 8 + 56 + 8 x (all peaks).
std::size_t EncodedSize(const PeakSample& s) noexcept;
// Writes header + content (status 0, type 0, message_length 0, 16 counts) into out. Returns the bytes
// written, or 0 when out is too small or the sample cannot be encoded (a count above 32767, a timestamp out of
// range). Real-time safe: no allocation, no lock, no throw.
std::size_t EncodePeaks(const PeakSample& s, std::span<std::uint8_t> out) noexcept;
// The same into a new buffer. Throws InputError naming the field when the sample cannot be encoded.
std::vector<std::uint8_t> EncodePeaks(const PeakSample& s);
// One patch's frame on one channel (the twin's interrogator): missing peaks (NaN) are left out, as the
// instrument leaves out a grating it cannot see, and the rest are listed by wavelength, as the instrument
// lists a channel's peaks (a hard press can push a peak past its neighbour's); the other channels report 0.
std::vector<std::uint8_t> EncodeWavelengths(std::uint64_t serial_number, std::int64_t timestamp_ns,
                                            std::size_t channel, const Wavelengths& wavelength_nm);

// --- Peak stream: decoding ---------------------------------------------------------------------------------

// A decoded peaks content. peaks_nm views storage owned by whoever decoded it (the StreamDecoder: valid until
// its next Feed or Reset).
struct PeakFrame {
  MessageHeader header{};          // the stream frame's header (status, type, message_length: passed through)
  std::uint8_t buffer_available = 0;  // percent
  std::uint8_t version = 0;
  std::uint32_t reserved = 0;
  std::uint64_t serial_number = 0;
  std::int64_t timestamp_ns = 0;   // Unix time: timestamp_s x 1e9 + timestamp_ns
  std::array<std::uint16_t, kChannels> count{};   // peaks per channel
  std::array<std::uint32_t, kChannels> first{};   // index of each channel's first peak in peaks_nm
  std::span<const double> peaks_nm{};             // every peak, channel after channel

  [[nodiscard]] std::span<const double> channel(std::size_t c) const noexcept {
    return peaks_nm.subspan(first[c], count[c]);
  }
};

// Parses a peaks content (the stream frame's content, or a #GetPeaks reply's content). Peaks are copied into
// storage, which must hold (content.size() - 56) / 8 doubles (else kContentTooLong). Checks lengths, counts,
// timestamp and finiteness; not the window (that is the picker's, per channel). Leaves out.header alone.
// Real-time safe: no allocation, no lock, no throw.
Reason ParsePeaks(std::span<const std::uint8_t> content, std::span<double> storage, PeakFrame& out) noexcept;

// Which channel holds the patch, and what to do when a grating reports no peak.
struct PickConfig {
  std::size_t channel = 0;   // 0..15
  // false: the channel must report exactly 16 strictly ascending peaks, grating i = the i-th peak.
  // true: each peak is assigned to the grating whose band [band_lo_nm, band_hi_nm] holds it; a grating with
  // no peak is NaN (and the frame is flagged kFlagPeakMissing). A list of fewer peaks cannot say which
  // grating went dark any other way. The bands must be ascending, non-overlapping, inside the window.
  bool allow_missing = false;
  std::array<double, kGratings> band_lo_nm{};
  std::array<double, kGratings> band_hi_nm{};
};
// Throws InputError naming the field and value when the config is unusable.
void Validate(const PickConfig& c);
// Bands halfway between neighbouring nominal centres (the outer edges at the window): every in-window peak
// then belongs to its nearest grating. Throws InputError unless the centres ascend inside the window.
PickConfig NearestGratingBands(std::size_t channel, const Wavelengths& centre_nm);

// The picked channel's peaks as one patch frame; flags gets kFlagPeakMissing when a peak is NaN.
// The config must have passed Validate. Real-time safe: no allocation, no lock, no throw.
Reason PickChannel(const PeakFrame& frame, const PickConfig& config, Wavelengths& wavelength_nm,
                   std::uint32_t& flags) noexcept;

struct DecoderConfig {
  // Largest content accepted; the decoder's buffers are sized to it at construction. The default holds 16
  // channels x 64 peaks with room to spare.
  std::uint32_t max_content_bytes = 16384;
  // The channel handed out as Wavelengths with each frame; nullopt: no picking (all channels, no window).
  std::optional<PickConfig> pick = PickConfig{};
};

// Plain counters a service copies into its metrics off the real-time thread.
struct Counters {
  std::uint64_t bytes = 0;            // every byte consumed by Feed
  std::uint64_t bytes_discarded = 0;  // bytes of rejected frames and bytes dropped while resync was needed
  std::uint64_t frames = 0;           // frames delivered (Status::kFrame)
  std::array<std::uint64_t, kReasonCount> rejected{};  // indexed by Reason (kOk stays 0)
  std::uint64_t lost_samples = 0;     // serial numbers skipped (the serial rises by 1 a sample)
  std::uint64_t serial_restarts = 0;  // serial numbers that did not rise (instrument restarted)
  std::uint64_t resyncs = 0;          // framing errors (each put the decoder into needs-resync)
};

// Incremental peak-stream decoder: feed the bytes exactly as the socket returns them (any chunking, one byte
// at a time included). Construction allocates its buffers; Feed and Reset never allocate.
//
//   std::span<const std::uint8_t> rest = received;
//   while (!rest.empty()) {
//     const auto r = decoder.Feed(rest);
//     rest = rest.subspan(r.consumed);
//     if (r.status == StreamDecoder::Status::kFrame) Use(decoder.frame(), decoder.wavelength_nm());
//     if (r.status == StreamDecoder::Status::kNeedsResync) { Reconnect(); decoder.Reset(); break; }
//   }
class StreamDecoder {
 public:
  enum class Status : std::uint8_t {
    kNeedMore,     // every byte consumed, no frame complete yet
    kFrame,        // a frame is complete and valid: frame(), wavelength_nm(), flags() until the next Feed
    kRejected,     // a frame was complete but refused (reason); the stream is still aligned
    kNeedsResync,  // a framing error now or earlier: every byte is discarded until Reset()
  };
  struct Result {
    // Bytes of the input used: Feed stops after at most one complete frame; on kNeedsResync it is all of them.
    std::size_t consumed = 0;
    Status status = Status::kNeedMore;
    Reason reason = Reason::kOk;  // kRejected: why; kNeedsResync: the framing error (on the call that hit it)
  };

  // Throws InputError when the config is unusable (max_content_bytes below 56 or above 16 MiB, a bad pick).
  explicit StreamDecoder(DecoderConfig config = {});

  // Real-time safe: no allocation, no lock, no throw.
  Result Feed(std::span<const std::uint8_t> bytes) noexcept;
  // Forget any partial frame and the resync state (a new connection). Counters and the last serial number
  // are kept, so samples lost while reconnecting count as lost. Real-time safe.
  void Reset() noexcept;

  [[nodiscard]] bool needs_resync() const noexcept { return resync_; }
  [[nodiscard]] const PeakFrame& frame() const noexcept { return frame_; }
  [[nodiscard]] const Wavelengths& wavelength_nm() const noexcept { return wavelength_nm_; }  // when picking
  [[nodiscard]] std::uint32_t flags() const noexcept { return flags_; }  // ruffini::FrameFlags
  [[nodiscard]] const Counters& counters() const noexcept { return counters_; }
  [[nodiscard]] const DecoderConfig& config() const noexcept { return config_; }

 private:
  Result Step(std::span<const std::uint8_t> bytes) noexcept;
  Result Complete(std::size_t consumed, std::size_t fed) noexcept;
  Result Framing(Reason r, std::size_t consumed, std::size_t fed) noexcept;

  DecoderConfig config_;
  std::array<std::uint8_t, kHeaderBytes> header_bytes_{};
  std::size_t header_got_ = 0;
  MessageHeader header_{};
  std::vector<std::uint8_t> content_;  // max_content_bytes, sized once
  std::size_t content_got_ = 0;
  std::vector<double> peaks_;          // (max_content_bytes - 56) / 8, sized once
  bool resync_ = false;
  bool have_serial_ = false;
  std::uint64_t last_serial_ = 0;
  PeakFrame frame_;
  Wavelengths wavelength_nm_{};
  std::uint32_t flags_ = 0;
  Counters counters_;
};

// --- Command port ------------------------------------------------------------------------------------------

// A request: header (options, 0, len(command), len(argument)), the ASCII command, the argument.
struct Command {
  std::uint8_t options = 0;
  std::string_view command{};  // e.g. "#GetSerialNumber"; views the decoded buffer
  std::string_view argument{};  // e.g. "1" (may be empty); views the decoded buffer
};
// A reply: header (status, type, len(message), len(content)), the message text, the content.
struct Reply {
  std::uint8_t status = 0;  // 0 = success; an error reply has status != 0, a message and no content
  std::uint8_t type = 0;
  std::string_view message{};
  std::span<const std::uint8_t> content{};
};

// Throws InputError when the command is empty, not printable ASCII or longer than 65535 bytes.
std::vector<std::uint8_t> EncodeCommand(std::string_view command, std::string_view argument = {},
                                        std::uint8_t options = 0);
// Throws InputError when message is longer than 65535 bytes, or status != 0 with content (an error reply
// carries none).
std::vector<std::uint8_t> EncodeReply(const Reply& reply);

// Result of decoding a message from the front of a buffer that may hold a part of it, one or several.
struct MessageResult {
  enum class Status : std::uint8_t { kNeedMore, kOk, kRejected };
  Status status = Status::kNeedMore;
  Reason reason = Reason::kOk;
  std::size_t consumed = 0;  // kOk: the message's bytes; otherwise 0
  std::size_t needed = 0;    // kNeedMore: total bytes the message needs, as far as known (>= 8)
};
// A rejected command or reply cannot be skipped safely either: drop the connection.
// Real-time safe: no allocation, no lock, no throw.
MessageResult DecodeCommand(std::span<const std::uint8_t> bytes, Command& out,
                            std::uint32_t max_argument_bytes = 65536) noexcept;
MessageResult DecodeReply(std::span<const std::uint8_t> bytes, Reply& out,
                          std::uint32_t max_content_bytes = 1u << 20) noexcept;

}  // namespace ruffini::ingest
