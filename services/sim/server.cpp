#include "server.h"

#include <spdlog/spdlog.h>

#include <array>
#include <boost/asio.hpp>
#include <chrono>
#include <cmath>
#include <cstring>
#include <deque>
#include <limits>
#include <list>
#include <utility>

#include "ruffini/error.h"

namespace ruffini::sim {

namespace asio = boost::asio;
using asio::ip::tcp;
using Buffer = std::shared_ptr<const std::vector<std::uint8_t>>;

// --- Server ------------------------------------------------------------------------------------------------

struct SimServer::Impl {
  struct StreamClient : std::enable_shared_from_this<StreamClient> {
    explicit StreamClient(tcp::socket s) : socket(std::move(s)) {}
    tcp::socket socket;
    std::deque<Buffer> queue;
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
    // Catch up on missed deadlines, a bounded number per wake-up so the command port stays served.
    for (int i = 0; i < 64 && Deadline(next_sample) <= now; ++i) Emit(next_sample++);
    timer.expires_at(Deadline(next_sample));
    timer.async_wait([this](const boost::system::error_code& ec) {
      if (!ec && !stopped) Tick();
    });
  }

  void Emit(std::uint64_t k) {
    source->Sample(k, peaks);
    const auto& f = config.faults;
    if (f.nan_every != 0 && (k + 1) % f.nan_every == 0) peaks[0][0] = std::numeric_limits<double>::quiet_NaN();
    ingest::PeakSample s;
    s.serial_number = k;
    // The sample's own time (its deadline), on the Unix clock: exactly one period apart, even when a late
    // wake-up sends several samples at once.
    s.timestamp_ns = unix_start_ns + std::chrono::duration_cast<std::chrono::nanoseconds>(Deadline(k) - start).count();
    for (std::size_t c = 0; c < peaks.size(); ++c) {
      std::size_t n = 0;
      const bool inject = c == 0 && f.nan_every != 0 && (k + 1) % f.nan_every == 0;
      for (const double nm : peaks[c]) {
        if (!std::isnan(nm) || (inject && n == 0)) seen[c][n++] = nm;  // a grating it cannot see is left out
      }
      s.channel_peaks_nm[c] = std::span<const double>(seen[c].data(), n);
    }
    auto frame = std::make_shared<std::vector<std::uint8_t>>(ingest::EncodedSize(s));
    if (ingest::EncodePeaks(s, *frame) != frame->size()) {
      spdlog::error("sample {}: cannot encode the frame", k);
      return;
    }
    state.last_frame = *frame;
    if (f.drop_every != 0 && (k + 1) % f.drop_every == 0) return;  // a lost sample: its serial is skipped
    if (!state.streaming) return;
    const Buffer shared = std::move(frame);
    const std::size_t max_queue = static_cast<std::size_t>(config.rate_hz) * 2;  // 2 s of backlog
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
        cl->queue.push_back(shared);
        ++cl->sent;
        if (f.disconnect_after != 0 && cl->sent >= f.disconnect_after) cl->closing = true;
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
    asio::async_write(cl->socket, asio::buffer(*cl->queue.front()),
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
    start = std::chrono::steady_clock::now();
    unix_start_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                        std::chrono::system_clock::now().time_since_epoch())
                        .count();
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
