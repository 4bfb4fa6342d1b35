#include "ruffini/ingest/hyperion.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <string>

#include "ruffini/error.h"

namespace ruffini::ingest {
namespace {

static_assert(std::endian::native == std::endian::little || std::endian::native == std::endian::big);

constexpr std::int64_t kNsPerS = 1'000'000'000;
constexpr std::uint32_t kHardMaxContent = 16u << 20;  // the largest max_content_bytes a config may ask for

// Little-endian loads and stores by bytes: no alignment or aliasing assumptions, any host byte order.
std::uint16_t Load16(const std::uint8_t* p) noexcept {
  return static_cast<std::uint16_t>(p[0] | (p[1] << 8));
}
std::uint32_t Load32(const std::uint8_t* p) noexcept {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}
std::uint64_t Load64(const std::uint8_t* p) noexcept {
  return static_cast<std::uint64_t>(Load32(p)) | (static_cast<std::uint64_t>(Load32(p + 4)) << 32);
}
void Store16(std::uint8_t* p, std::uint16_t v) noexcept {
  p[0] = static_cast<std::uint8_t>(v);
  p[1] = static_cast<std::uint8_t>(v >> 8);
}
void Store32(std::uint8_t* p, std::uint32_t v) noexcept {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
void Store64(std::uint8_t* p, std::uint64_t v) noexcept {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

MessageHeader LoadHeader(const std::uint8_t* p) noexcept {
  return {p[0], p[1], Load16(p + 2), Load32(p + 4)};
}
void StoreHeader(std::uint8_t* p, const MessageHeader& h) noexcept {
  p[0] = h.status;
  p[1] = h.type;
  Store16(p + 2, h.message_length);
  Store32(p + 4, h.content_length);
}

bool InWindow(double nm) noexcept { return nm >= kWindowLoNm && nm <= kWindowHiNm; }

// Why the sample cannot be encoded, or empty.
std::string SampleProblem(const PeakSample& s) {
  if (s.timestamp_ns < 0 || s.timestamp_ns / kNsPerS > 0xffffffffLL) {
    return "'timestamp_ns' (" + std::to_string(s.timestamp_ns) + ") must lie in 0 .. 2^32 s";
  }
  for (std::size_t c = 0; c < kChannels; ++c) {
    if (s.channel_peaks_nm[c].size() > kMaxPeaksPerChannel) {
      return "'channel_peaks_nm[" + std::to_string(c) + "]' holds " + std::to_string(s.channel_peaks_nm[c].size()) +
             " peaks, at most 32767 fit an i16 count";
    }
  }
  return {};
}

bool Encodable(const PeakSample& s) noexcept {
  if (s.timestamp_ns < 0 || s.timestamp_ns / kNsPerS > 0xffffffffLL) return false;
  for (const auto& ch : s.channel_peaks_nm) {
    if (ch.size() > kMaxPeaksPerChannel) return false;
  }
  return true;
}

bool PrintableCommand(std::string_view c) noexcept {
  if (c.empty()) return false;
  for (const char ch : c) {
    const auto u = static_cast<unsigned char>(ch);
    if (u < 0x21 || u > 0x7e) return false;
  }
  return true;
}

}  // namespace

std::string_view ReasonName(Reason r) noexcept {
  switch (r) {
    case Reason::kOk: return "ok";
    case Reason::kContentTooLong: return "content_too_long";
    case Reason::kContentTooShort: return "content_too_short";
    case Reason::kBadPeaksLength: return "bad_peaks_length";
    case Reason::kNegativeCount: return "negative_count";
    case Reason::kCountMismatch: return "count_mismatch";
    case Reason::kNonFinite: return "non_finite";
    case Reason::kBadTimestamp: return "bad_timestamp";
    case Reason::kOutOfWindow: return "out_of_window";
    case Reason::kWrongPeakCount: return "wrong_peak_count";
    case Reason::kUnorderedPeaks: return "unordered_peaks";
    case Reason::kPeakOutsideBands: return "peak_outside_bands";
    case Reason::kDuplicatePeak: return "duplicate_peak";
    case Reason::kCommandTooLong: return "command_too_long";
    case Reason::kBadCommand: return "bad_command";
    case Reason::kReplyTooLong: return "reply_too_long";
    case Reason::kErrorWithContent: return "error_with_content";
  }
  return "unknown";
}

// --- Encoding ----------------------------------------------------------------------------------------------

std::size_t EncodedSize(const PeakSample& s) noexcept {
  std::size_t n = kHeaderBytes + kPeaksLength;
  for (const auto& ch : s.channel_peaks_nm) n += kPeakBytes * ch.size();
  return n;
}

std::size_t EncodePeaks(const PeakSample& s, std::span<std::uint8_t> out) noexcept {
  const std::size_t n = EncodedSize(s);
  if (!Encodable(s) || out.size() < n || n - kHeaderBytes > 0xffffffffu) return 0;
  std::uint8_t* p = out.data();
  StoreHeader(p, {0, 0, 0, static_cast<std::uint32_t>(n - kHeaderBytes)});
  p += kHeaderBytes;
  Store16(p, static_cast<std::uint16_t>(kPeaksLength));
  p[2] = s.buffer_available;
  p[3] = s.version;
  Store32(p + 4, 0);  // reserved
  Store64(p + 8, s.serial_number);
  Store32(p + 16, static_cast<std::uint32_t>(s.timestamp_ns / kNsPerS));
  Store32(p + 20, static_cast<std::uint32_t>(s.timestamp_ns % kNsPerS));
  p += kPeaksHeaderBytes;
  for (const auto& ch : s.channel_peaks_nm) {
    Store16(p, static_cast<std::uint16_t>(ch.size()));
    p += 2;
  }
  for (const auto& ch : s.channel_peaks_nm) {
    for (const double nm : ch) {
      Store64(p, std::bit_cast<std::uint64_t>(nm));
      p += kPeakBytes;
    }
  }
  return n;
}

std::vector<std::uint8_t> EncodePeaks(const PeakSample& s) {
  if (auto problem = SampleProblem(s); !problem.empty()) throw InputError("EncodePeaks: " + problem);
  std::vector<std::uint8_t> out(EncodedSize(s));
  if (EncodePeaks(s, out) != out.size()) throw InputError("EncodePeaks: content longer than 2^32 bytes");
  return out;
}

std::vector<std::uint8_t> EncodeWavelengths(std::uint64_t serial_number, std::int64_t timestamp_ns,
                                            std::size_t channel, const Wavelengths& wavelength_nm) {
  if (channel >= kChannels) {
    throw InputError("EncodeWavelengths: 'channel' (" + std::to_string(channel) + ") must lie in 0..15");
  }
  Wavelengths seen{};
  std::size_t n = 0;
  for (const double nm : wavelength_nm) {
    if (!std::isnan(nm)) seen[n++] = nm;
  }
  std::sort(seen.begin(), seen.begin() + static_cast<std::ptrdiff_t>(n));
  PeakSample s;
  s.serial_number = serial_number;
  s.timestamp_ns = timestamp_ns;
  s.channel_peaks_nm[channel] = std::span<const double>(seen.data(), n);
  return EncodePeaks(s);
}

// --- Peak decoding -----------------------------------------------------------------------------------------

Reason ParsePeaks(std::span<const std::uint8_t> content, std::span<double> storage, PeakFrame& out) noexcept {
  if (content.size() < kPeaksLength) return Reason::kContentTooShort;
  const std::uint8_t* p = content.data();
  if (Load16(p) != kPeaksLength) return Reason::kBadPeaksLength;
  std::uint64_t total = 0;
  std::array<std::uint16_t, kChannels> count{};
  for (std::size_t c = 0; c < kChannels; ++c) {
    const auto v = static_cast<std::int16_t>(Load16(p + kPeaksHeaderBytes + 2 * c));
    if (v < 0) return Reason::kNegativeCount;
    count[c] = static_cast<std::uint16_t>(v);
    total += count[c];
  }
  if (total * kPeakBytes != content.size() - kPeaksLength) return Reason::kCountMismatch;
  if (total > storage.size()) return Reason::kContentTooLong;

  // Structurally sound from here: fill the frame (the serial number counts even if the values are refused).
  const std::uint32_t ts_s = Load32(p + 16), ts_ns = Load32(p + 20);
  out.buffer_available = p[2];
  out.version = p[3];
  out.reserved = Load32(p + 4);
  out.serial_number = Load64(p + 8);
  out.timestamp_ns = static_cast<std::int64_t>(ts_s) * kNsPerS + static_cast<std::int64_t>(ts_ns);
  out.count = count;
  std::uint32_t first = 0;
  for (std::size_t c = 0; c < kChannels; ++c) {
    out.first[c] = first;
    first += count[c];
  }
  const std::uint8_t* q = p + kPeaksLength;
  bool finite = true;
  for (std::size_t i = 0; i < total; ++i, q += kPeakBytes) {
    storage[i] = std::bit_cast<double>(Load64(q));
    finite = finite && std::isfinite(storage[i]);
  }
  out.peaks_nm = storage.first(total);
  if (ts_ns >= kNsPerS) return Reason::kBadTimestamp;
  if (!finite) return Reason::kNonFinite;
  return Reason::kOk;
}

// --- Picking one channel -----------------------------------------------------------------------------------

void Validate(const PickConfig& c) {
  if (c.channel >= kChannels) {
    throw InputError("pick: 'channel' (" + std::to_string(c.channel) + ") must lie in 0..15");
  }
  if (!c.allow_missing) return;
  for (std::size_t i = 0; i < kGratings; ++i) {
    const double lo = c.band_lo_nm[i], hi = c.band_hi_nm[i];
    // Built with append: GCC 12 warns falsely (-Wrestrict) on a long chain of std::string operator+.
    std::string msg = "pick: ";
    if (!(lo >= kWindowLoNm && hi <= kWindowHiNm && lo < hi)) {
      msg.append("band ").append(std::to_string(i)).append(" ('band_lo_nm' ").append(std::to_string(lo));
      msg.append(" .. 'band_hi_nm' ").append(std::to_string(hi)).append(") must be non-empty inside 1510..1590 nm");
      throw InputError(msg);
    }
    if (i > 0 && lo <= c.band_hi_nm[i - 1]) {
      msg.append("'band_lo_nm[").append(std::to_string(i)).append("]' (").append(std::to_string(lo));
      msg.append(") must lie above 'band_hi_nm[").append(std::to_string(i - 1)).append("]' (");
      msg.append(std::to_string(c.band_hi_nm[i - 1])).append(")");
      throw InputError(msg);
    }
  }
}

PickConfig NearestGratingBands(std::size_t channel, const Wavelengths& centre_nm) {
  PickConfig c;
  c.channel = channel;
  c.allow_missing = true;
  for (std::size_t i = 0; i < kGratings; ++i) {
    const double x = centre_nm[i];
    if (!(x > kWindowLoNm && x < kWindowHiNm) || (i > 0 && !(x > centre_nm[i - 1]))) {
      throw InputError("pick: 'centre_nm[" + std::to_string(i) + "]' (" + std::to_string(x) +
                       ") must lie inside 1510..1590 nm, above the previous centre");
    }
  }
  for (std::size_t i = 0; i < kGratings; ++i) {
    c.band_lo_nm[i] = i == 0 ? kWindowLoNm : std::nextafter((centre_nm[i - 1] + centre_nm[i]) / 2, kWindowHiNm);
    c.band_hi_nm[i] = i + 1 == kGratings ? kWindowHiNm : (centre_nm[i] + centre_nm[i + 1]) / 2;
  }
  Validate(c);
  return c;
}

Reason PickChannel(const PeakFrame& frame, const PickConfig& config, Wavelengths& wavelength_nm,
                   std::uint32_t& flags) noexcept {
  const auto peaks = frame.channel(config.channel);
  for (const double nm : peaks) {
    if (!std::isfinite(nm)) return Reason::kNonFinite;  // ParsePeaks refuses these; a hand-made frame may not
    if (!InWindow(nm)) return Reason::kOutOfWindow;
  }
  flags = kFlagNone;
  if (!config.allow_missing) {
    if (peaks.size() != kGratings) return Reason::kWrongPeakCount;
    for (std::size_t i = 1; i < kGratings; ++i) {
      if (!(peaks[i] > peaks[i - 1])) return Reason::kUnorderedPeaks;
    }
    for (std::size_t i = 0; i < kGratings; ++i) wavelength_nm[i] = peaks[i];
    return Reason::kOk;
  }
  if (peaks.size() > kGratings) return Reason::kWrongPeakCount;
  Wavelengths w;
  w.fill(std::nan(""));
  for (const double nm : peaks) {
    std::size_t g = 0;
    while (g < kGratings && !(nm >= config.band_lo_nm[g] && nm <= config.band_hi_nm[g])) ++g;
    if (g == kGratings) return Reason::kPeakOutsideBands;
    if (!std::isnan(w[g])) return Reason::kDuplicatePeak;
    w[g] = nm;
  }
  if (peaks.size() < kGratings) flags |= kFlagPeakMissing;
  wavelength_nm = w;
  return Reason::kOk;
}

// --- Stream decoder ----------------------------------------------------------------------------------------

StreamDecoder::StreamDecoder(DecoderConfig config) : config_(config) {
  if (config_.max_content_bytes < kPeaksLength || config_.max_content_bytes > kHardMaxContent) {
    throw InputError("stream decoder: 'max_content_bytes' (" + std::to_string(config_.max_content_bytes) +
                     ") must lie in 56.." + std::to_string(kHardMaxContent));
  }
  if (config_.pick) Validate(*config_.pick);
  content_.assign(config_.max_content_bytes, 0);
  peaks_.assign((config_.max_content_bytes - kPeaksLength) / kPeakBytes, 0.0);
  wavelength_nm_.fill(std::nan(""));
}

void StreamDecoder::Reset() noexcept {
  header_got_ = 0;
  content_got_ = 0;
  resync_ = false;
}

StreamDecoder::Result StreamDecoder::Framing(Reason r, std::size_t consumed, std::size_t fed) noexcept {
  resync_ = true;
  ++counters_.rejected[static_cast<std::size_t>(r)];
  ++counters_.resyncs;
  // The partial frame and the rest of this input are dropped.
  counters_.bytes_discarded += header_got_ + content_got_ + (fed - consumed);
  header_got_ = 0;
  content_got_ = 0;
  return {fed, Status::kNeedsResync, r};
}

StreamDecoder::Result StreamDecoder::Feed(std::span<const std::uint8_t> bytes) noexcept {
  const Result r = Step(bytes);
  counters_.bytes += r.consumed;  // the caller feeds the rest again: count each byte once
  return r;
}

StreamDecoder::Result StreamDecoder::Step(std::span<const std::uint8_t> bytes) noexcept {
  if (resync_) {
    counters_.bytes_discarded += bytes.size();
    return {bytes.size(), Status::kNeedsResync, Reason::kOk};
  }
  std::size_t used = 0;
  while (used < bytes.size()) {
    if (header_got_ < kHeaderBytes) {
      const std::size_t n = std::min(kHeaderBytes - header_got_, bytes.size() - used);
      std::copy_n(bytes.data() + used, n, header_bytes_.data() + header_got_);
      header_got_ += n;
      used += n;
      if (header_got_ < kHeaderBytes) break;
      header_ = LoadHeader(header_bytes_.data());
      // Stream frames carry message_length 0; like the vendor's clients we ignore it and read content_length.
      if (header_.content_length > config_.max_content_bytes) {
        return Framing(Reason::kContentTooLong, used, bytes.size());
      }
      if (header_.content_length < kPeaksLength) return Framing(Reason::kContentTooShort, used, bytes.size());
      continue;
    }
    const std::size_t n = std::min<std::size_t>(header_.content_length - content_got_, bytes.size() - used);
    std::copy_n(bytes.data() + used, n, content_.data() + content_got_);
    content_got_ += n;
    used += n;
    if (content_got_ == header_.content_length) return Complete(used, bytes.size());
  }
  return {used, Status::kNeedMore, Reason::kOk};
}

StreamDecoder::Result StreamDecoder::Complete(std::size_t consumed, std::size_t fed) noexcept {
  const std::size_t frame_bytes = kHeaderBytes + content_got_;
  const auto content = std::span<const std::uint8_t>(content_.data(), content_got_);
  header_got_ = 0;
  content_got_ = 0;
  Reason r = ParsePeaks(content, peaks_, frame_);
  if (IsFramingError(r)) {
    resync_ = true;
    ++counters_.rejected[static_cast<std::size_t>(r)];
    ++counters_.resyncs;
    counters_.bytes_discarded += frame_bytes + (fed - consumed);  // the frame and the rest of this input
    return {fed, Status::kNeedsResync, r};
  }
  // A structurally sound sample arrived: account for the serial numbers between it and the last one.
  frame_.header = header_;
  if (have_serial_) {
    if (frame_.serial_number > last_serial_) {
      counters_.lost_samples += frame_.serial_number - last_serial_ - 1;
    } else {
      ++counters_.serial_restarts;
    }
  }
  have_serial_ = true;
  last_serial_ = frame_.serial_number;
  flags_ = kFlagNone;
  if (r == Reason::kOk && config_.pick) r = PickChannel(frame_, *config_.pick, wavelength_nm_, flags_);
  if (r != Reason::kOk) {
    ++counters_.rejected[static_cast<std::size_t>(r)];
    counters_.bytes_discarded += frame_bytes;
    return {consumed, Status::kRejected, r};
  }
  ++counters_.frames;
  return {consumed, Status::kFrame, Reason::kOk};
}

// --- Command port ------------------------------------------------------------------------------------------

std::vector<std::uint8_t> EncodeCommand(std::string_view command, std::string_view argument,
                                        std::uint8_t options) {
  if (!PrintableCommand(command) || command.size() > 0xffff) {
    throw InputError("EncodeCommand: 'command' (\"" + std::string(command) +
                     "\") must be 1..65535 printable ASCII characters without spaces");
  }
  if (argument.size() > 0xffffffffu) throw InputError("EncodeCommand: 'argument' longer than 2^32 bytes");
  std::vector<std::uint8_t> out(kHeaderBytes + command.size() + argument.size());
  StoreHeader(out.data(), {options, 0, static_cast<std::uint16_t>(command.size()),
                           static_cast<std::uint32_t>(argument.size())});
  std::copy(command.begin(), command.end(), out.begin() + kHeaderBytes);
  std::copy(argument.begin(), argument.end(), out.begin() + static_cast<std::ptrdiff_t>(kHeaderBytes + command.size()));
  return out;
}

std::vector<std::uint8_t> EncodeReply(const Reply& reply) {
  if (reply.message.size() > 0xffff) {
    throw InputError("EncodeReply: 'message' (" + std::to_string(reply.message.size()) +
                     " bytes) must be at most 65535 bytes");
  }
  if (reply.status != 0 && !reply.content.empty()) {
    throw InputError("EncodeReply: an error reply (status " + std::to_string(reply.status) +
                     ") carries no content, got " + std::to_string(reply.content.size()) + " bytes");
  }
  if (reply.content.size() > 0xffffffffu) throw InputError("EncodeReply: 'content' longer than 2^32 bytes");
  std::vector<std::uint8_t> out(kHeaderBytes + reply.message.size() + reply.content.size());
  StoreHeader(out.data(), {reply.status, reply.type, static_cast<std::uint16_t>(reply.message.size()),
                           static_cast<std::uint32_t>(reply.content.size())});
  std::copy(reply.message.begin(), reply.message.end(), out.begin() + kHeaderBytes);
  std::copy(reply.content.begin(), reply.content.end(),
            out.begin() + static_cast<std::ptrdiff_t>(kHeaderBytes + reply.message.size()));
  return out;
}

MessageResult DecodeCommand(std::span<const std::uint8_t> bytes, Command& out,
                            std::uint32_t max_argument_bytes) noexcept {
  using S = MessageResult::Status;
  if (bytes.size() < kHeaderBytes) return {S::kNeedMore, Reason::kOk, 0, kHeaderBytes};
  const MessageHeader h = LoadHeader(bytes.data());
  if (h.content_length > max_argument_bytes) return {S::kRejected, Reason::kCommandTooLong, 0, 0};
  const std::size_t total = kHeaderBytes + h.message_length + std::size_t{h.content_length};
  if (bytes.size() < total) return {S::kNeedMore, Reason::kOk, 0, total};
  const auto* p = reinterpret_cast<const char*>(bytes.data()) + kHeaderBytes;
  const std::string_view command(p, h.message_length);
  if (!PrintableCommand(command)) return {S::kRejected, Reason::kBadCommand, 0, 0};
  out.options = h.status;
  out.command = command;
  out.argument = std::string_view(p + h.message_length, h.content_length);
  return {S::kOk, Reason::kOk, total, 0};
}

MessageResult DecodeReply(std::span<const std::uint8_t> bytes, Reply& out, std::uint32_t max_content_bytes) noexcept {
  using S = MessageResult::Status;
  if (bytes.size() < kHeaderBytes) return {S::kNeedMore, Reason::kOk, 0, kHeaderBytes};
  const MessageHeader h = LoadHeader(bytes.data());
  if (h.status != 0 && h.content_length != 0) return {S::kRejected, Reason::kErrorWithContent, 0, 0};
  if (h.content_length > max_content_bytes) return {S::kRejected, Reason::kReplyTooLong, 0, 0};
  const std::size_t total = kHeaderBytes + h.message_length + std::size_t{h.content_length};
  if (bytes.size() < total) return {S::kNeedMore, Reason::kOk, 0, total};
  out.status = h.status;
  out.type = h.type;
  out.message = std::string_view(reinterpret_cast<const char*>(bytes.data()) + kHeaderBytes, h.message_length);
  out.content = bytes.subspan(kHeaderBytes + h.message_length, h.content_length);
  return {S::kOk, Reason::kOk, total, 0};
}

}  // namespace ruffini::ingest
