#pragma once
// The standard process metrics Prometheus client libraries export (prometheus-cpp 1.0 does not):
// process_cpu_seconds_total, process_resident_memory_bytes, process_virtual_memory_bytes,
// process_start_time_seconds, process_open_fds, process_threads, read from /proc/self at scrape time.
#include <prometheus/collectable.h>
#include <prometheus/metric_family.h>

#include <memory>
#include <vector>

namespace ruffini::service {

class ProcessCollectable final : public prometheus::Collectable {
 public:
  std::vector<prometheus::MetricFamily> Collect() const override;
};

// The process metrics, one instance per process (registered with a service's exposer).
std::shared_ptr<ProcessCollectable> ProcessMetrics();

}  // namespace ruffini::service
