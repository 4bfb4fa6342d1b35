#pragma once
// The decoder service's shared statistics: plain atomics each thread writes with relaxed stores (no lock on
// the real-time path), and a prometheus-cpp Collectable that turns them into metric families at scrape time
// (histograms: service::AtomicHistogram).
#include <array>
#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

#include <prometheus/collectable.h>
#include <prometheus/metric_family.h>

#include "ruffini/decode/pipeline.h"
#include "ruffini/ingest/hyperion.h"
#include "ruffini/link/messages.h"
#include "ruffini/service/atomic_histogram.h"

namespace ruffini::decoder {

using AtomicHistogram = service::AtomicHistogram;

struct Stats {
  // Written by the decode thread (a copy of link::Monitor's health after each step).
  std::atomic<std::uint64_t> frames{0}, valid_frames{0}, serial_gaps{0}, frames_lost{0}, onsets{0}, faint_frames{0},
      release_refused_frames{0}, captures_refused{0}, rest_file_errors{0};
  std::array<std::atomic<std::uint64_t>, decode::kReasonCount> decode_rejected{};
  std::array<std::atomic<std::uint64_t>, ingest::kReasonCount> stream_rejected{};
  std::array<std::atomic<std::uint64_t>, link::kFaultCodeCount> faults{};
  std::atomic<int> baseline_state{0};
  std::atomic<int> active_fault{0};
  std::atomic<bool> healthy{false}, in_contact{false};
  std::atomic<double> drift_pm{0.0}, common_mode_pm{0.0};
  std::atomic<std::uint64_t> messages_dropped{0};   // heartbeats / mid-contact frames dropped on a full ring
  std::atomic<std::uint64_t> critical_dropped{0};   // onsets, releases or faults lost (overflow of the overflow)
  AtomicHistogram decode_seconds;     // monitor step per frame (pipeline + health + message)
  AtomicHistogram frame_age_seconds;  // socket read -> message handed to the publisher
  // Ingest thread.
  std::atomic<bool> interrogator_connected{false};
  std::atomic<std::uint64_t> interrogator_connects{0}, interrogator_bytes{0}, ingest_dropped{0}, resyncs{0};
  // Publisher thread.
  std::atomic<bool> aggregator_connected{false};
  std::atomic<std::uint64_t> aggregator_connects{0}, hello_refused{0}, stale_discarded{0};
  std::atomic<std::uint64_t> late_frames{0};    // frames that waited past the freshness budget in ring A
  std::atomic<std::uint64_t> late_messages{0};  // messages that waited past the freshness budget in ring B
  std::atomic<std::uint64_t> hello_timeouts{0}; // streams ended because the hello got no answer in time
  std::atomic<std::uint64_t> hello_wrong_robot{0}; // hellos accepted by an aggregator of another robot
  std::array<std::atomic<std::uint64_t>, 4> messages_sent{};  // by link::Message::Kind
  // Re-tares (docs/safety.md "Re-tare"): requests taken by the decode thread, repeated ones ignored
  // (publisher), and outcomes (decode thread, a copy of link::Monitor's).
  std::atomic<std::uint64_t> retare_requests{0}, retare_repeated{0};
  std::array<std::atomic<std::uint64_t>, decode::kRetareOutcomeCount> retares{};
};

// Every decoder metric, named by FACTS.md's rules (ruffini_ prefix, base units, _total on counters, bounded
// labels). Constant labels: patch; ruffini_decoder_info carries the configuration.
class StatsCollectable final : public prometheus::Collectable {
 public:
  StatsCollectable(const Stats& stats, std::string patch, std::vector<std::pair<std::string, std::string>> info);
  std::vector<prometheus::MetricFamily> Collect() const override;

 private:
  const Stats& stats_;
  std::string patch_;
  std::vector<std::pair<std::string, std::string>> info_;
};

}  // namespace ruffini::decoder
