#include "server.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <boost/asio.hpp>
#include <chrono>
#include <cmath>
#include <cstring>
#include <ctime>
#include <deque>
#include <iterator>
#include <limits>
#include <list>
#include <utility>

#include "ruffini/error.h"

namespace ruffini::sim {

namespace asio = boost::asio;
using asio::ip::tcp;
using Buffer = std::shared_ptr<const std::vector<std::uint8_t>>;

namespace {

std::int64_t UnixNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// True for the fault's samples: every N-th, i.e. serial k with (k + 1) mod N = 0 (never when N = 0).
constexpr bool Every(std::uint64_t n, std::uint64_t k) noexcept { return n != 0 && (k + 1) % n == 0; }

// How late a frame's write starts after its timestamp (system_clock at the write minus t_ns), in fixed
// buckets: no allocation, one clock read per write.
class WriteLag {
 public:
  void Add(std::int64_t lag_ns) noexcept {
    ++count_;
    sum_ns_ += lag_ns;
    min_ns_ = std::min(min_ns_, lag_ns);
    max_ns_ = std::max(max_ns_, lag_ns);
    std::size_t b = 0;
    while (b < kBoundsUs.size() && lag_ns > kBoundsUs[b] * 1000) ++b;
    ++buckets_[b];
  }
  void Log() const {
    if (count_ == 0) return;
    spdlog::info("write lag (system_clock at the write minus the frame's t_ns, {} writes on time): min {:.1f} us, "
                 "mean {:.1f} us, p50 <= {} us, p99 <= {} us, p99.9 <= {} us, max {:.1f} us",
                 count_, double(min_ns_) / 1e3, double(sum_ns_) / double(count_) / 1e3, Quantile(0.5),
                 Quantile(0.99), Quantile(0.999), double(max_ns_) / 1e3);
  }

 private:
  // The bucket bound (us) that holds quantile q; "inf" past the last bound.
  [[nodiscard]] std::string Quantile(double q) const {
    const auto want = static_cast<std::uint64_t>(std::ceil(q * double(count_)));
    std::uint64_t seen = 0;
    for (std::size_t b = 0; b < kBoundsUs.size(); ++b) {
      seen += buckets_[b];
      if (seen >= want) return std::to_string(kBoundsUs[b]);
    }
    return "inf";
  }
  static constexpr std::array<std::int64_t, 18> kBoundsUs = {1,   2,   5,   10,   15,   20,   30,   40,    50,
                                                             75,  100, 200, 500, 1000, 2000, 5000, 10000, 100000};
  std::array<std::uint64_t, kBoundsUs.size() + 1> buckets_{};
  std::uint64_t count_ = 0;
  std::int64_t sum_ns_ = 0;
  std::int64_t min_ns_ = std::numeric_limits<std::int64_t>::max();
  std::int64_t max_ns_ = std::numeric_limits<std::int64_t>::min();
};

}  // namespace

// --- Server ------------------------------------------------------------------------------------------------

struct SimServer::Impl {
  // One write to stream clients: a frame, or a fault's garbage.
  struct Outgoing {
    Buffer bytes;
    std::int64_t t_ns = -1;  // the frame's timestamp; -1: not a frame (garbage)
    bool late = false;       // held by a stall and sent in its burst (left out of the write-lag figures)
  };
  // Injected faults so far.
  struct FaultCounts {
    std::uint64_t dropped = 0, nan = 0, missing = 0, garbage = 0, disconnected = 0, stalls = 0, sent_late = 0;
    bool operator==(const FaultCounts&) const = default;
  };
  struct StreamClient : std::enable_shared_from_this<StreamClient> {
    explicit StreamClient(tcp::socket s) : socket(std::move(s)) {}
    tcp::socket socket;
    std::deque<Outgoing> queue;
    std::uint64_t sent = 0;  // frames queued to this client
    bool closing = false;    // close once the queue is written
    bool closed = false;
    std::array<std::uint8_t, 256> scratch{};
  };
  struct CommandClient : std::enable_shared_from_this<CommandClient> {
    explicit CommandClient(tcp::socket s) : socket(std::move(s)) {}
    tcp::socket socket;
    std::vector<std::uint8_t> in;
    std::deque<Buffer> queue;
    bool closed = false;
    std::array<std::uint8_t, 4096> scratch{};
  };

  Impl(ServerConfig c, std::unique_ptr<FrameSource> s)
      : config(std::move(c)), source(std::move(s)), command_acceptor(io), stream_acceptor(io), timer(io),
        signals(io) {
    if (!source) throw InputError("ruffini-sim: no frame source");
    if (!(config.rate_hz >= 100.0 && config.rate_hz <= 5000.0)) {
      throw InputError("--rate-hz: " + std::to_string(config.rate_hz) + " must lie in 100..5000");
    }
    state.channels = source->channels();
    state.serial_number = config.serial_number;
    state.firmware_version = config.firmware_version;
    peaks.resize(source->channels());
    const auto& f = config.faults;
    if ((f.stall_after == 0) != (f.stall_ms == 0)) {
      throw InputError("--stall-after (" + std::to_string(f.stall_after) + ") and --stall-ms (" +
                       std::to_string(f.stall_ms) + ") go together: both set or both 0");
    }
    if (f.stall_ms > kMaxStallMs) {
      throw InputError("--stall-ms: " + std::to_string(f.stall_ms) + " must lie in 1.." + std::to_string(kMaxStallMs));
    }
    // 2 s of frames behind, plus room for a stall's burst (and one garbage burst a frame at most).
    buffer_samples = static_cast<std::uint64_t>(std::ceil(config.rate_hz * kMaxStallMs / 1000.0));
    const auto stall_samples = static_cast<std::size_t>(std::ceil(config.rate_hz * f.stall_ms / 1000.0));
    max_queue = (static_cast<std::size_t>(config.rate_hz) * 2 + stall_samples) * (f.garbage_every != 0 ? 2 : 1);
    next_stall_at = f.stall_after;
    Open(command_acceptor, config.command_port, "--command-port");
    Open(stream_acceptor, config.stream_port, "--stream-port");
    bound_command_port = command_acceptor.local_endpoint().port();
    bound_stream_port = stream_acceptor.local_endpoint().port();
  }

  void Open(tcp::acceptor& a, std::uint16_t port, const char* what) {
    boost::system::error_code ec;
    const auto address = asio::ip::make_address(config.host, ec);
    if (ec) throw InputError("--host: '" + config.host + "' is not an IP address: " + ec.message());
    const tcp::endpoint ep(address, port);
    a.open(ep.protocol(), ec);
    if (!ec) a.set_option(tcp::acceptor::reuse_address(true), ec);
    if (!ec) a.bind(ep, ec);
    if (!ec) a.listen(asio::socket_base::max_listen_connections, ec);
    if (ec) {
      throw InputError(std::string(what) + ": cannot listen on " + config.host + ":" + std::to_string(port) + ": " +
                       ec.message());
    }
  }

  // Sample k's deadline: an absolute time on the steady clock, so late ticks never accumulate drift.
  [[nodiscard]] std::chrono::steady_clock::time_point Deadline(std::uint64_t k) const {
    return start + std::chrono::nanoseconds(static_cast<std::int64_t>(std::llround(static_cast<double>(k) * 1e9 /
                                                                                    config.rate_hz)));
  }

  void Tick() {
    const auto now = std::chrono::steady_clock::now();
    NoteLateWakeUp(now);
    // Catch up on missed deadlines, a bounded number per wake-up so the command port stays served.
    for (int i = 0; i < 64 && Deadline(next_sample) <= now; ++i) Emit(next_sample++);
    if (next_sample >= next_summary) {  // at most one fault summary a second of samples, and only on news
      next_summary = next_sample + static_cast<std::uint64_t>(config.rate_hz);
      if (!(counts == logged_counts)) LogFaults("faults so far");
    }
    timer.expires_at(Deadline(next_sample));
    timer.async_wait([this](const boost::system::error_code& ec) {
      if (!ec && !stopped) Tick();
    });
  }

  // A wake-up more than kLateWakeUp after the deadline it was set for is logged with what the thread did
  // meanwhile: its CPU time since the previous wake-up against the wall time. Little CPU over a long gap: the
  // thread was not running (a core was not given to it); CPU time close to the gap: the work itself took it.
  // A soak's silences can then be traced to the sim or ruled out (docs/soak.md).
  static constexpr std::chrono::milliseconds kLateWakeUp{10};
  static std::int64_t ThreadCpuNs() noexcept {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
  }
  void NoteLateWakeUp(std::chrono::steady_clock::time_point now) {
    const std::int64_t cpu = ThreadCpuNs();
    const auto late = now - Deadline(next_sample);
    if (last_tick.time_since_epoch().count() != 0 && late > kLateWakeUp) {
      ++late_wake_ups;
      const double gap_ms = std::chrono::duration<double, std::milli>(now - last_tick).count();
      spdlog::warn("late wake-up: sample {} {:.1f} ms after its deadline; since the previous wake-up {:.1f} ms of "
                   "wall time, {:.1f} ms of this thread's CPU time",
                   next_sample, std::chrono::duration<double, std::milli>(late).count(), gap_ms,
                   static_cast<double>(cpu - last_tick_cpu_ns) / 1e6);
    }
    last_tick = now;
    last_tick_cpu_ns = cpu;
  }

  // The first fault of a kind is logged at once; the rest are counted (and summarised once a second).
  static void Count(std::uint64_t& counter, const char* what, std::uint64_t k) {
    if (++counter == 1) spdlog::info("fault: {} (sample {}); further ones are counted", what, k);
  }

  void LogFaults(const char* what) {
    logged_counts = counts;
    spdlog::info("{}: dropped {}, nan {}, missing {}, garbage {}, disconnected {}, stalls {}, sent_late {}", what,
                 counts.dropped, counts.nan, counts.missing, counts.garbage, counts.disconnected, counts.stalls,
                 counts.sent_late);
  }

  // --stall-after / --stall-ms, before sample k is made: a stall starts at sample next_stall_at and ends at the
  // first sample whose deadline is stall_ms after the stall's first; that sample goes out right after the held
  // burst, and the next stall starts stall_after samples later.
  void StallBefore(std::uint64_t k) {
    const auto& f = config.faults;
    if (f.stall_after == 0) return;
    if (stalling && Deadline(k) >= stall_end) {
      stalling = false;
      next_stall_at = k + f.stall_after;
      spdlog::info("fault: stall over at sample {}: {} held sample(s) go out late in one burst", k, held_frames);
      counts.sent_late += held_frames;
      for (auto& o : held) Broadcast(std::move(o));
      held.clear();
      held_frames = 0;
    }
    if (!stalling && k >= next_stall_at) {
      stalling = true;
      stall_end = Deadline(k) + std::chrono::milliseconds(f.stall_ms);
      ++counts.stalls;
      spdlog::info("fault: stall {} from sample {}: nothing sent for {} ms, samples held", counts.stalls, k, f.stall_ms);
    }
  }

  void Emit(std::uint64_t k) {
    StallBefore(k);
    source->Sample(k, peaks);
    const auto& f = config.faults;
    ingest::PeakSample s;
    s.serial_number = k;
    // The sample's scheduled send time (its deadline), on the Unix clock: exactly one period apart, even when a
    // late wake-up sends several samples at once. docs/sim.md has the measured gap to the socket write.
    s.timestamp_ns = unix_start_ns + std::chrono::duration_cast<std::chrono::nanoseconds>(Deadline(k) - start).count();
    // A held sample fills the simulated instrument's 2 s buffer.
    if (stalling) {
      const std::uint64_t used = (100 * (held_frames + 1) + buffer_samples - 1) / buffer_samples;
      s.buffer_available = static_cast<std::uint8_t>(100 - std::min<std::uint64_t>(used, 100));
    }
    std::size_t missing_grating = kGratings;  // none
    if (Every(f.missing_every, k)) {
      missing_grating = static_cast<std::size_t>(((k + 1) / f.missing_every - 1) % kGratings);
      Count(counts.missing, "a grating's peak left out of channel 0 (--missing-every)", k);
    }
    for (std::size_t c = 0; c < peaks.size(); ++c) {
      std::size_t n = 0;
      for (std::size_t g = 0; g < kGratings; ++g) {
        const double nm = peaks[c][g];
        if (!std::isnan(nm) && !(c == 0 && g == missing_grating)) seen[c][n++] = nm;  // a dark grating is left out
      }
      // The instrument lists a channel's peaks by wavelength: a hard press can push a peak past its
      // neighbour's (docs/twin.md, "Hard presses").
      std::sort(seen[c].begin(), seen[c].begin() + static_cast<std::ptrdiff_t>(n));
      if (c == 0 && Every(f.nan_every, k)) {
        seen[0][0] = std::numeric_limits<double>::quiet_NaN();
        n = std::max<std::size_t>(n, 1);
        Count(counts.nan, "a NaN as channel 0's first peak (--nan-every)", k);
      }
      s.channel_peaks_nm[c] = std::span<const double>(seen[c].data(), n);
    }
    auto frame = std::make_shared<std::vector<std::uint8_t>>(ingest::EncodedSize(s));
    if (ingest::EncodePeaks(s, *frame) != frame->size()) {
      spdlog::error("sample {}: cannot encode the frame", k);
      return;
    }
    state.last_frame = *frame;
    if (Every(f.drop_every, k)) {  // a lost sample: its serial is skipped
      Count(counts.dropped, "a sample not sent (--drop-every)", k);
      return;
    }
    if (!state.streaming) return;
    Outgoing out{std::move(frame), s.timestamp_ns, stalling};
    if (Every(f.garbage_every, k)) {
      Count(counts.garbage, "16 garbage bytes before the sample's frame (--garbage-every)", k);
      Outgoing junk{garbage, -1, stalling};
      if (stalling) {
        held.push_back(std::move(junk));
      } else {
        Broadcast(std::move(junk));
      }
    }
    if (stalling) {
      held.push_back(std::move(out));
      ++held_frames;
      return;
    }
    Broadcast(std::move(out));
  }

  // Queues one write to every stream client (a frame counts towards --disconnect-after, garbage does not).
  void Broadcast(Outgoing out) {
    const auto& f = config.faults;
    const bool is_frame = out.t_ns >= 0;
    for (auto it = streams.begin(); it != streams.end();) {
      auto& cl = *it;
      if (cl->closed) {
        it = streams.erase(it);
        spdlog::info("stream client gone ({} now)", streams.size());
        continue;
      }
      if (!cl->closing) {
        if (cl->queue.size() >= max_queue) {
          spdlog::warn("stream client too slow (2 s behind): disconnecting it");
          Close(*cl);
          it = streams.erase(it);
          continue;
        }
        cl->queue.push_back(out);
        if (is_frame) ++cl->sent;
        if (is_frame && f.disconnect_after != 0 && cl->sent >= f.disconnect_after) {
          cl->closing = true;
          ++counts.disconnected;
          spdlog::info("fault: disconnecting a stream client after {} frames (--disconnect-after)", cl->sent);
        }
        if (cl->queue.size() == 1) WriteStream(cl);
      }
      ++it;
    }
  }

  // Stream and command clients alike: shut the socket down once.
  template <typename Client>
  static void Close(Client& cl) {
    if (cl.closed) return;
    cl.closed = true;
    boost::system::error_code ec;
    cl.socket.shutdown(tcp::socket::shutdown_both, ec);
    cl.socket.close(ec);
  }

  void WriteStream(const std::shared_ptr<StreamClient>& cl) {
    const Outgoing& out = cl->queue.front();
    // Measured at the write's start: with nothing else queued on the socket Asio tries the send() at once.
    if (out.t_ns >= 0 && !out.late) write_lag.Add(UnixNowNs() - out.t_ns);
    asio::async_write(cl->socket, asio::buffer(*out.bytes),
                      [this, cl](const boost::system::error_code& ec, std::size_t) {
                        if (cl->closed) return;
                        if (ec) {
                          Close(*cl);
                          return;
                        }
                        cl->queue.pop_front();
                        if (!cl->queue.empty()) {
                          WriteStream(cl);
                        } else if (cl->closing) {
                          Close(*cl);
                        }
                      });
  }

  void ReadStream(const std::shared_ptr<StreamClient>& cl) {
    // A stream client sends nothing; a read only tells us when it goes away.
    cl->socket.async_read_some(asio::buffer(cl->scratch), [this, cl](const boost::system::error_code& ec, std::size_t) {
      if (cl->closed) return;
      if (ec) {
        Close(*cl);
        return;
      }
      ReadStream(cl);
    });
  }

  void AcceptStream() {
    stream_acceptor.async_accept([this](const boost::system::error_code& ec, tcp::socket s) {
      if (stopped) return;
      if (!ec) {
        boost::system::error_code ignored;
        s.set_option(tcp::no_delay(true), ignored);
        auto cl = std::make_shared<StreamClient>(std::move(s));
        streams.push_back(cl);
        ReadStream(cl);
        spdlog::info("stream client connected ({} now)", streams.size());
      }
      AcceptStream();
    });
  }


  void ReadCommand(const std::shared_ptr<CommandClient>& cl) {
    cl->socket.async_read_some(asio::buffer(cl->scratch), [this, cl](const boost::system::error_code& ec,
                                                                     std::size_t n) {
      if (cl->closed) return;
      if (ec) {
        Close(*cl);
        return;
      }
      cl->in.insert(cl->in.end(), cl->scratch.begin(), cl->scratch.begin() + static_cast<std::ptrdiff_t>(n));
      for (;;) {
        ingest::Command cmd;
        const auto r = ingest::DecodeCommand(cl->in, cmd);
        if (r.status == ingest::MessageResult::Status::kNeedMore) break;
        if (r.status == ingest::MessageResult::Status::kRejected) {
          spdlog::warn("command client sent a bad request ({}): disconnecting it", ingest::ReasonName(r.reason));
          Close(*cl);
          return;
        }
        cl->queue.push_back(std::make_shared<const std::vector<std::uint8_t>>(AnswerCommand(cmd, state)));
        if (cl->queue.size() == 1) WriteCommand(cl);
        cl->in.erase(cl->in.begin(), cl->in.begin() + static_cast<std::ptrdiff_t>(r.consumed));
      }
      ReadCommand(cl);
    });
  }

  void WriteCommand(const std::shared_ptr<CommandClient>& cl) {
    asio::async_write(cl->socket, asio::buffer(*cl->queue.front()),
                      [this, cl](const boost::system::error_code& ec, std::size_t) {
                        if (cl->closed) return;
                        if (ec) {
                          Close(*cl);
                          return;
                        }
                        cl->queue.pop_front();
                        if (!cl->queue.empty()) WriteCommand(cl);
                      });
  }

  void AcceptCommand() {
    command_acceptor.async_accept([this](const boost::system::error_code& ec, tcp::socket s) {
      if (stopped) return;
      if (!ec) {
        auto cl = std::make_shared<CommandClient>(std::move(s));
        commands.push_back(cl);
        commands.remove_if([](const auto& c) { return c->closed; });
        ReadCommand(cl);
      }
      AcceptCommand();
    });
  }

  void Shutdown() {
    if (stopped) return;
    stopped = true;
    boost::system::error_code ec;
    command_acceptor.close(ec);
    stream_acceptor.close(ec);
    timer.cancel();
    signals.cancel(ec);
    for (auto& cl : streams) Close(*cl);
    for (auto& cl : commands) Close(*cl);
    streams.clear();
    commands.clear();
    const auto& f = config.faults;
    if (f.drop_every || f.nan_every || f.missing_every || f.garbage_every || f.disconnect_after || f.stall_after) {
      LogFaults("fault totals");
    }
    write_lag.Log();
    spdlog::info("late wake-ups (more than {} ms after the deadline): {}", kLateWakeUp.count(), late_wake_ups);
  }

  void Run() {
    signals.add(SIGINT);
    signals.add(SIGTERM);
    signals.async_wait([this](const boost::system::error_code& ec, int signo) {
      if (ec) return;
      spdlog::info("signal {}: shutting down", signo);
      Shutdown();
    });
    AcceptCommand();
    AcceptStream();
    // The Unix time at `start`: the midpoint of two system_clock reads around the steady one (tens of ns apart).
    const std::int64_t before_ns = UnixNowNs();
    start = std::chrono::steady_clock::now();
    const std::int64_t after_ns = UnixNowNs();
    unix_start_ns = before_ns + (after_ns - before_ns) / 2;
    // A scenario's time 0 on the Unix clock, for whoever lines the script up with what the services report
    // (`ruffini soak` reads this line).
    spdlog::info("sample 0 is at Unix time {} ns", unix_start_ns);
    next_sample = 0;
    Tick();
    io.run();
  }

  ServerConfig config;
  std::unique_ptr<FrameSource> source;
  asio::io_context io;
  tcp::acceptor command_acceptor;
  tcp::acceptor stream_acceptor;
  asio::steady_timer timer;
  asio::signal_set signals;
  std::list<std::shared_ptr<StreamClient>> streams;
  std::list<std::shared_ptr<CommandClient>> commands;
  CommandState state;
  std::vector<Wavelengths> peaks;
  std::array<Wavelengths, ingest::kChannels> seen{};
  std::chrono::steady_clock::time_point start;
  std::int64_t unix_start_ns = 0;  // Unix time at `start`
  std::uint64_t next_sample = 0;
  std::chrono::steady_clock::time_point last_tick{};
  std::int64_t last_tick_cpu_ns = 0;
  std::uint64_t late_wake_ups = 0;  // more than kLateWakeUp after their deadline
  std::uint64_t next_summary = 0;
  std::size_t max_queue = 0;           // writes queued to one stream client before it counts as too slow
  FaultCounts counts, logged_counts;
  const Buffer garbage = std::make_shared<const std::vector<std::uint8_t>>(std::begin(kGarbage), std::end(kGarbage));
  // --stall-after: the stall in progress and what it holds.
  bool stalling = false;
  std::uint64_t next_stall_at = 0;
  std::chrono::steady_clock::time_point stall_end;
  std::vector<Outgoing> held;
  std::uint64_t held_frames = 0;
  std::uint64_t buffer_samples = 1;  // the simulated instrument's buffer: kMaxStallMs of samples
  WriteLag write_lag;
  bool stopped = false;
  std::uint16_t bound_command_port = 0;
  std::uint16_t bound_stream_port = 0;
};

SimServer::SimServer(ServerConfig config, std::unique_ptr<FrameSource> source)
    : impl_(std::make_unique<Impl>(std::move(config), std::move(source))) {}
SimServer::~SimServer() = default;

std::uint16_t SimServer::command_port() const noexcept { return impl_->bound_command_port; }
std::uint16_t SimServer::stream_port() const noexcept { return impl_->bound_stream_port; }

void SimServer::Run() { impl_->Run(); }
void SimServer::Stop() {
  asio::post(impl_->io, [this] { impl_->Shutdown(); });
}

}  // namespace ruffini::sim
