#include "ruffini/channel/checkers.h"

#include <algorithm>
#include <limits>
#include <random>
#include <stdexcept>
#include <utility>

#include "ruffini/channel/crc.h"

namespace ruffini::channel {
namespace {

constexpr std::int64_t kMax = std::numeric_limits<std::int64_t>::max();
constexpr std::int64_t kMin = std::numeric_limits<std::int64_t>::min();

std::int64_t SaturatingSub(std::int64_t a, std::int64_t b) noexcept {
  std::int64_t out = 0;
  if (__builtin_sub_overflow(a, b, &out)) return b < 0 ? kMax : kMin;
  return out;
}
std::int64_t SaturatingAdd(std::int64_t a, std::int64_t b) noexcept {
  std::int64_t out = 0;
  if (__builtin_add_overflow(a, b, &out)) return b > 0 ? kMax : kMin;
  return out;
}

// A discarded message: counted, and the error-rate rule asked whether the link must latch now.
Verdict Discarded(ErrorCounts& counts, ErrorRate& rate, Error e, std::int64_t arrival_steady_ns) noexcept {
  counts.Count(e);
  Verdict v;
  v.use = false;
  v.error = true;
  v.kind = e;
  v.rate_latch = rate.Record(arrival_steady_ns);
  v.latch = v.rate_latch;
  return v;
}

}  // namespace

std::string_view Name(Error e) noexcept {
  switch (e) {
    case Error::kCorruption: return "corruption";
    case Error::kRepetition: return "repetition";
    case Error::kIncorrectSequence: return "incorrect_sequence";
    case Error::kLoss: return "loss";
    case Error::kDelay: return "delay";
    case Error::kInsertion: return "insertion";
    case Error::kMasquerade: return "masquerade";
    case Error::kAddressing: return "addressing";
  }
  return "unknown";
}

std::uint64_t DrawRunId() {
  std::random_device rd;
  std::uint64_t id = 0;
  while (id == 0) id = (static_cast<std::uint64_t>(rd()) << 32) ^ static_cast<std::uint64_t>(rd());
  return id;
}

SeqVerdict SequenceCheck::Check(std::uint64_t seq) noexcept {
  if (seq == 0 || seq < last_) return SeqVerdict::kOld;
  if (seq == last_) return SeqVerdict::kRepeat;
  skipped_ = seq - last_ - 1;
  last_ = seq;
  return skipped_ == 0 ? SeqVerdict::kNext : SeqVerdict::kGap;
}

SeqVerdict SequenceCheck::CheckJoining(std::uint64_t seq) noexcept {
  if (last_ == 0 && seq != 0) {
    last_ = seq;
    skipped_ = 0;
    return SeqVerdict::kNext;
  }
  return Check(seq);
}

FreshnessCheck::FreshnessCheck(FreshnessConfig config) : config_(config) {
  if (!(config_.budget_ns > 0)) throw std::invalid_argument("freshness budget_ns must be > 0");
  if (!(config_.max_drift_ppm >= 0 && config_.max_drift_ppm <= 10'000))
    throw std::invalid_argument("freshness max_drift_ppm must lie in 0..10000");
}

std::int64_t FreshnessCheck::Age(std::int64_t sent_steady_ns, std::int64_t arrival_steady_ns) noexcept {
  const std::int64_t offset = SaturatingSub(arrival_steady_ns, sent_steady_ns);
  if (!learned_) {
    learned_ = true;
    offset_ns_ = offset;
    last_arrival_ns_ = arrival_steady_ns;
    return 0;
  }
  // The learned offset may creep up by the allowed drift since the previous message (never down: a
  // faster message lowers it directly below).
  const std::int64_t elapsed = std::max<std::int64_t>(0, SaturatingSub(arrival_steady_ns, last_arrival_ns_));
  const auto creep = static_cast<std::int64_t>(static_cast<double>(elapsed) * config_.max_drift_ppm * 1e-6);
  last_arrival_ns_ = std::max(last_arrival_ns_, arrival_steady_ns);
  offset_ns_ = std::min(SaturatingAdd(offset_ns_, creep), offset);
  return SaturatingSub(offset, offset_ns_);
}

ErrorRate::ErrorRate(ErrorRateConfig config) : config_(config) {
  if (!(config_.window_ns > 0)) throw std::invalid_argument("error-rate window_ns must be > 0");
  if (config_.limit < 1 || config_.limit > static_cast<int>(std::tuple_size_v<decltype(times_)>))
    throw std::invalid_argument("error-rate limit must lie in 1..8");
}

bool ErrorRate::Record(std::int64_t now_ns) noexcept {
  times_[count_ % times_.size()] = now_ns;
  ++count_;
  const auto limit = static_cast<std::size_t>(config_.limit);
  if (count_ < limit) return false;
  // The oldest of the newest `limit` errors.
  const std::int64_t oldest = times_[(count_ - limit) % times_.size()];
  return SaturatingSub(now_ns, oldest) <= config_.window_ns;
}

std::uint64_t ErrorCounts::total() const noexcept {
  std::uint64_t n = 0;
  for (std::uint64_t c : by_error) n += c;
  return n;
}

PatchLinkCheck::PatchLinkCheck(LinkConfig config, std::uint64_t aggregator_run_id, std::string patch_id)
    : aggregator_run_id_(aggregator_run_id),
      patch_id_(std::move(patch_id)),
      freshness_(config.freshness),
      rate_(config.error_rate) {}

Verdict PatchLinkCheck::Discard(Error e, std::int64_t arrival_steady_ns) noexcept {
  return Discarded(counts_, rate_, e, arrival_steady_ns);
}

Verdict PatchLinkCheck::Receive(const v1::PatchMessage& m, std::int64_t arrival_steady_ns) noexcept {
  // Integrity first: nothing else in a corrupted message can be trusted.
  if (!CrcMatches(m)) return Discard(Error::kCorruption, arrival_steady_ns);
  if (m.patch_id() != patch_id_) return Discard(Error::kMasquerade, arrival_steady_ns);
  if (m.sender_run_id() == 0) return Discard(Error::kInsertion, arrival_steady_ns);
  if (sender_run_id_ == 0) {
    sender_run_id_ = m.sender_run_id();
    if (remembered_.sender_run_id == sender_run_id_ && !freshness_.learned()) {
      freshness_.Seed(remembered_.offset_ns, remembered_.last_arrival_ns);
    }
  } else if (m.sender_run_id() != sender_run_id_) {
    return Discard(Error::kInsertion, arrival_steady_ns);
  }
  // The hello goes to whichever aggregator answers (0); every later message names this run.
  const bool addressed = m.has_hello() ? (m.aggregator_run_id() == 0 || m.aggregator_run_id() == aggregator_run_id_)
                                       : m.aggregator_run_id() == aggregator_run_id_;
  if (!addressed) return Discard(Error::kAddressing, arrival_steady_ns);
  switch (seq_.Check(m.seq())) {
    case SeqVerdict::kRepeat: return Discard(Error::kRepetition, arrival_steady_ns);
    case SeqVerdict::kOld: return Discard(Error::kIncorrectSequence, arrival_steady_ns);
    case SeqVerdict::kGap: {
      counts_.Count(Error::kLoss);
      Verdict v;
      v.error = true;
      v.kind = Error::kLoss;
      v.latch = true;
      v.rate_latch = rate_.Record(arrival_steady_ns);
      v.age_ns = freshness_.Age(m.sender_steady_ns(), arrival_steady_ns);
      return v;
    }
    case SeqVerdict::kNext: break;
  }
  Verdict v;
  v.age_ns = freshness_.Age(m.sender_steady_ns(), arrival_steady_ns);
  if (freshness_.Late(v.age_ns)) {
    counts_.Count(Error::kDelay);
    v.error = true;
    v.kind = Error::kDelay;
    v.latch = true;
  }
  return v;
}

StateLinkCheck::StateLinkCheck(LinkConfig config, std::string robot_name)
    : robot_name_(std::move(robot_name)), freshness_(config.freshness), rate_(config.error_rate) {}

Verdict StateLinkCheck::Discard(Error e, std::int64_t arrival_steady_ns) noexcept {
  return Discarded(counts_, rate_, e, arrival_steady_ns);
}

Verdict StateLinkCheck::Receive(const v1::SafetyState& s, std::int64_t arrival_steady_ns) noexcept {
  if (!CrcMatches(s)) return Discard(Error::kCorruption, arrival_steady_ns);
  if (s.robot_name() != robot_name_) return Discard(Error::kAddressing, arrival_steady_ns);
  if (s.aggregator_run_id() == 0) return Discard(Error::kInsertion, arrival_steady_ns);
  if (run_id_ == 0) {
    run_id_ = s.aggregator_run_id();
    if (remembered_.run_id == run_id_ && !freshness_.learned()) {
      freshness_.Seed(remembered_.offset_ns, remembered_.last_arrival_ns);
    }
  } else if (s.aggregator_run_id() != run_id_) {
    return Discard(Error::kInsertion, arrival_steady_ns);
  }
  Verdict v;
  switch (seq_.CheckJoining(s.seq())) {
    case SeqVerdict::kRepeat: return Discard(Error::kRepetition, arrival_steady_ns);
    case SeqVerdict::kOld: return Discard(Error::kIncorrectSequence, arrival_steady_ns);
    case SeqVerdict::kGap:
      counts_.Count(Error::kLoss);  // tolerable: the watchdog bounds how long nothing arrives
      v.error = true;
      v.kind = Error::kLoss;
      break;
    case SeqVerdict::kNext: break;
  }
  v.age_ns = freshness_.Age(s.sender_steady_ns(), arrival_steady_ns);
  if (freshness_.Late(v.age_ns)) {
    counts_.Count(Error::kDelay);
    v.use = false;
    v.error = true;
    v.kind = Error::kDelay;
    v.latch = true;
  }
  return v;
}

}  // namespace ruffini::channel
