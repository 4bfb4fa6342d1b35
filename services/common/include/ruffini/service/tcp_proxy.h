#pragma once
// A TCP proxy on 127.0.0.1 (port 0) in front of one target, to play a bad network between real processes (the
// process tests, and `ruffini soak`, which puts some links through one). Every accepted connection gets its own connection to the target, and the proxy can
//   - forward (the default),
//   - Freeze() the connections open now: stop forwarding in both directions without closing anything (a host
//     that lost power, a dead middlebox; the peers' kernels still hold their sockets open). Connections
//     accepted later are forwarded.
//   - Throttle(bytes_per_s): forward at most that many bytes a second in each direction of each connection
//     (current and later ones; 0: unlimited).
//   - CloseAll(): close both sides of every connection (the peers see FIN); CloseFrozen() only the frozen ones.
// One thread, poll() on a handful of sockets, header-only, POSIX. Hand-written rather than Boost.Asio: freezing
// is "stop polling these sockets" and throttling a token bucket in the same loop; Asio would need an async
// state machine per direction for the same.
#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <pthread.h>
#include <sched.h>

namespace ruffini::service {

class TcpProxy {
 public:
  explicit TcpProxy(int target_port) : target_port_(target_port) {
    listen_fd_ = socket(AF_INET, SOCK_STREAM, 0);
    const int one = 1;
    setsockopt(listen_fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    sockaddr_in a = Loopback(0);
    if (bind(listen_fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 || listen(listen_fd_, 16) != 0) return;
    socklen_t len = sizeof a;
    getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&a), &len);
    port_ = ntohs(a.sin_port);
    SetNonBlocking(listen_fd_);
    thread_ = std::thread([this] { Run(); });
  }
  ~TcpProxy() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
    for (auto& c : conns_) c->Close();
    if (listen_fd_ >= 0) close(listen_fd_);
  }
  TcpProxy(const TcpProxy&) = delete;
  TcpProxy& operator=(const TcpProxy&) = delete;

  // Runs the proxy's thread under SCHED_FIFO at `priority` (1..99; needs CAP_SYS_NICE): a test's stand-in for
  // the network, which must not wait for a core behind the processes under test. False when refused.
  bool SetRealtimePriority(int priority) {
    sched_param p{};
    p.sched_priority = priority;
    return thread_.joinable() && pthread_setschedparam(thread_.native_handle(), SCHED_FIFO, &p) == 0;
  }
  [[nodiscard]] int port() const noexcept { return port_; }  // 0: could not listen
  [[nodiscard]] std::string address() const { return "127.0.0.1:" + std::to_string(port_); }
  // Connections accepted so far (a client's reconnects show here).
  [[nodiscard]] int accepted() const noexcept { return accepted_.load(); }

  void Freeze() {
    std::lock_guard lock(mu_);
    for (auto& c : conns_) c->frozen = true;
  }
  // Closes the connections Freeze() froze (when the peers have long given up on them: keeps fds bounded).
  void CloseFrozen() {
    std::lock_guard lock(mu_);
    for (auto& c : conns_) {
      if (c->frozen) c->Close();
    }
  }
  void Throttle(std::int64_t bytes_per_s) { bytes_per_s_ = bytes_per_s; }
  void CloseAll() {
    std::lock_guard lock(mu_);
    for (auto& c : conns_) c->Close();
  }

 private:
  struct Direction {
    std::vector<char> buf;  // read from `from`, not yet written to `to`
    std::size_t off = 0;
    double tokens = 0;      // bytes this direction may still forward (throttled)
  };
  struct Conn {
    int client = -1, server = -1;
    bool frozen = false;
    Direction up, down;  // client -> server, server -> client
    void Close() {
      if (client >= 0) close(client);
      if (server >= 0) close(server);
      client = server = -1;
    }
    [[nodiscard]] bool open() const { return client >= 0 && server >= 0; }
  };

  static sockaddr_in Loopback(int port) {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    return a;
  }
  static void SetNonBlocking(int fd) { fcntl(fd, F_SETFL, fcntl(fd, F_GETFL) | O_NONBLOCK); }

  void Accept() {
    for (;;) {
      const int c = accept(listen_fd_, nullptr, nullptr);
      if (c < 0) return;
      const int s = socket(AF_INET, SOCK_STREAM, 0);
      sockaddr_in a = Loopback(target_port_);
      if (connect(s, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {  // loopback: immediate
        close(c);
        close(s);
        continue;
      }
      const int one = 1;
      setsockopt(c, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
      setsockopt(s, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
      SetNonBlocking(c);
      SetNonBlocking(s);
      auto conn = std::make_unique<Conn>();
      conn->client = c;
      conn->server = s;
      std::lock_guard lock(mu_);
      conns_.push_back(std::move(conn));
      accepted_.fetch_add(1);
    }
  }

  // Moves bytes from -> to as far as the sockets and the throttle allow; false when either side ended.
  bool Pump(int from, int to, Direction& d, bool readable, std::int64_t limit) {
    if (d.off == d.buf.size() && readable) {
      std::size_t want = 65536;
      if (limit > 0) want = static_cast<std::size_t>(std::max(0.0, std::min<double>(static_cast<double>(want), d.tokens)));
      if (want > 0) {
        d.buf.resize(want);
        const ssize_t n = read(from, d.buf.data(), want);
        if (n == 0 || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK)) return false;
        d.buf.resize(n > 0 ? static_cast<std::size_t>(n) : 0);
        d.off = 0;
        if (limit > 0 && n > 0) d.tokens -= static_cast<double>(n);
      }
    }
    if (d.off < d.buf.size()) {
      const ssize_t n = send(to, d.buf.data() + d.off, d.buf.size() - d.off, MSG_NOSIGNAL);
      if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK) return false;
      if (n > 0) d.off += static_cast<std::size_t>(n);
    }
    return true;
  }

  void Run() {
    auto last = std::chrono::steady_clock::now();
    while (!stop_) {
      std::vector<pollfd> fds{{listen_fd_, POLLIN, 0}};
      std::vector<Conn*> polled;
      {
        std::lock_guard lock(mu_);
        for (auto& c : conns_) {
          if (!c->open() || c->frozen) continue;
          // Read a side only when what was read from it is delivered and the throttle allows (else poll()
          // would report it readable at once, again and again); write a side when bytes wait for it.
          const std::int64_t limit = bytes_per_s_.load();
          auto events = [&](const Direction& read_dir, const Direction& write_dir) {
            const bool can_read = read_dir.off == read_dir.buf.size() && (limit <= 0 || read_dir.tokens >= 1.0);
            return static_cast<short>((can_read ? POLLIN : 0) | (write_dir.off < write_dir.buf.size() ? POLLOUT : 0));
          };
          fds.push_back({c->client, events(c->up, c->down), 0});
          fds.push_back({c->server, events(c->down, c->up), 0});
          polled.push_back(c.get());
        }
      }
      // 2 ms while throttling (the token bucket's granularity); otherwise poll() wakes on traffic and 20 ms
      // bounds how late a new command (Freeze, Throttle) is seen.
      poll(fds.data(), fds.size(), bytes_per_s_.load() > 0 ? 2 : 20);
      if (fds[0].revents & POLLIN) Accept();
      const auto now = std::chrono::steady_clock::now();
      const double dt = std::chrono::duration<double>(now - last).count();
      last = now;
      const std::int64_t limit = bytes_per_s_.load();
      std::lock_guard lock(mu_);
      for (std::size_t i = 0; i < polled.size(); ++i) {
        Conn& c = *polled[i];
        if (!c.open() || c.frozen) continue;  // closed or frozen by a command meanwhile
        if (limit > 0) {
          // At most one second's worth banked, so a pause does not become a burst.
          for (Direction* d : {&c.up, &c.down}) {
            d->tokens = std::min(static_cast<double>(limit), d->tokens + dt * static_cast<double>(limit));
          }
        }
        const short cev = fds[1 + 2 * i].revents, sev = fds[2 + 2 * i].revents;
        const bool ok = Pump(c.client, c.server, c.up, (cev & (POLLIN | POLLHUP | POLLERR)) != 0, limit) &&
                        Pump(c.server, c.client, c.down, (sev & (POLLIN | POLLHUP | POLLERR)) != 0, limit);
        if (!ok) c.Close();  // one side ended: end the other (a FIN or RST passes through)
      }
      // Closed connections go (a client that reconnects for hours must not grow the list).
      std::erase_if(conns_, [](const std::unique_ptr<Conn>& c) { return !c->open(); });
    }
  }

  int target_port_ = 0, port_ = 0, listen_fd_ = -1;
  std::atomic<bool> stop_{false};
  std::atomic<int> accepted_{0};
  std::atomic<std::int64_t> bytes_per_s_{0};
  std::mutex mu_;
  std::vector<std::unique_ptr<Conn>> conns_;
  std::thread thread_;
};

}  // namespace ruffini::service
