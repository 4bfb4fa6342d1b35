#pragma once
// A latency histogram a real-time thread can observe without a lock: fixed buckets of relaxed atomics,
// turned into a Prometheus histogram at scrape time. prometheus::Histogram::Observe takes a mutex that the
// scrape also takes (FACTS.md), which a real-time thread must never wait on; hence this.
#include <array>
#include <atomic>
#include <cstdint>
#include <limits>

#include <prometheus/client_metric.h>

namespace ruffini::service {

class AtomicHistogram {
 public:
  // Upper bounds, seconds: 1 µs to 100 ms.
  static constexpr std::array<double, 14> kBounds = {1e-6, 2e-6, 5e-6, 1e-5, 2e-5, 5e-5, 1e-4,
                                                     2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2, 1e-1};
  void ObserveNs(std::int64_t ns) noexcept {
    if (ns < 0) ns = 0;
    const double s = static_cast<double>(ns) * 1e-9;
    std::size_t i = 0;
    while (i < kBounds.size() && s > kBounds[i]) ++i;
    counts_[i].fetch_add(1, std::memory_order_relaxed);
    sum_ns_.fetch_add(static_cast<std::uint64_t>(ns), std::memory_order_relaxed);
  }
  // Cumulative buckets, count and sum (s) into m.histogram.
  void Fill(prometheus::ClientMetric& m) const {
    std::uint64_t cumulative = 0;
    m.histogram.bucket.clear();
    for (std::size_t i = 0; i < kBounds.size(); ++i) {
      cumulative += counts_[i].load(std::memory_order_relaxed);
      m.histogram.bucket.push_back({cumulative, kBounds[i]});
    }
    cumulative += counts_[kBounds.size()].load(std::memory_order_relaxed);
    m.histogram.bucket.push_back({cumulative, std::numeric_limits<double>::infinity()});
    m.histogram.sample_count = cumulative;
    m.histogram.sample_sum = static_cast<double>(sum_ns_.load(std::memory_order_relaxed)) * 1e-9;
  }

 private:
  std::array<std::atomic<std::uint64_t>, kBounds.size() + 1> counts_{};  // the last: above every bound
  std::atomic<std::uint64_t> sum_ns_{0};
};

}  // namespace ruffini::service
