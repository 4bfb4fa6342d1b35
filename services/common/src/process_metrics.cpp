#include "ruffini/service/process_metrics.h"

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace ruffini::service {

namespace {

prometheus::MetricFamily One(const char* name, const char* help, prometheus::MetricType type, double v) {
  prometheus::MetricFamily f{name, help, type, {}};
  prometheus::ClientMetric m;
  if (type == prometheus::MetricType::Counter) m.counter.value = v;
  else m.gauge.value = v;
  f.metric.push_back(m);
  return f;
}

}  // namespace

std::vector<prometheus::MetricFamily> ProcessCollectable::Collect() const {
  std::vector<prometheus::MetricFamily> out;
  const double tick = static_cast<double>(sysconf(_SC_CLK_TCK));
  const double page = static_cast<double>(sysconf(_SC_PAGESIZE));
  // /proc/self/stat: fields after the command (which is in parentheses and may hold spaces).
  std::ifstream stat("/proc/self/stat");
  std::string text((std::istreambuf_iterator<char>(stat)), std::istreambuf_iterator<char>());
  const auto close = text.rfind(')');
  if (close != std::string::npos && tick > 0) {
    std::istringstream in(text.substr(close + 2));
    std::vector<std::string> f;
    std::string w;
    while (in >> w) f.push_back(w);
    // f[0] is field 3 (state): utime 14, stime 15, num_threads 20, starttime 22, vsize 23, rss 24.
    if (f.size() > 21) {
      const double utime = std::stod(f[11]), stime = std::stod(f[12]);
      out.push_back(One("process_cpu_seconds_total", "Total user and system CPU time spent in seconds.",
                        prometheus::MetricType::Counter, (utime + stime) / tick));
      out.push_back(One("process_threads", "Number of OS threads in the process.", prometheus::MetricType::Gauge,
                        std::stod(f[17])));
      out.push_back(One("process_virtual_memory_bytes", "Virtual memory size in bytes.", prometheus::MetricType::Gauge,
                        std::stod(f[20])));
      out.push_back(One("process_resident_memory_bytes", "Resident memory size in bytes.",
                        prometheus::MetricType::Gauge, std::stod(f[21]) * page));
      std::ifstream up("/proc/uptime");
      double uptime = 0;
      if (up >> uptime) {
        const double boot = static_cast<double>(time(nullptr)) - uptime;
        out.push_back(One("process_start_time_seconds", "Start time of the process since unix epoch in seconds.",
                          prometheus::MetricType::Gauge, boot + std::stod(f[19]) / tick));
      }
    }
  }
  std::error_code ec;
  std::size_t fds = 0;
  for (auto it = std::filesystem::directory_iterator("/proc/self/fd", ec); !ec && it != std::filesystem::directory_iterator();
       it.increment(ec)) {
    ++fds;
  }
  out.push_back(One("process_open_fds", "Number of open file descriptors.", prometheus::MetricType::Gauge,
                    static_cast<double>(fds)));
  return out;
}

std::shared_ptr<ProcessCollectable> ProcessMetrics() {
  static const auto instance = std::make_shared<ProcessCollectable>();
  return instance;
}

}  // namespace ruffini::service
