#pragma once
// A test-only TCP proxy on 127.0.0.1 (port 0) that can freeze its links the way a vanished host or a dead
// network segment does: a frozen connection stops forwarding in both directions but keeps both sockets open
// (no FIN, no RST), so only a keepalive or a watchdog can tell. Freeze() freezes every connection open now
// and every new one; LiftForNew() lets new connections through again while the frozen ones stay frozen.
// Boost.Asio on one thread of its own; header-only (Boost::headers).
#include <boost/asio.hpp>

#include <array>
#include <atomic>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

namespace ruffini::testing {

class FreezeProxy {
 public:
  explicit FreezeProxy(int upstream_port)
      : upstream_(boost::asio::ip::make_address("127.0.0.1"), static_cast<unsigned short>(upstream_port)),
        acceptor_(io_, {boost::asio::ip::make_address("127.0.0.1"), 0}) {
    port_ = acceptor_.local_endpoint().port();
    Accept();
    thread_ = std::thread([this] { io_.run(); });
  }
  ~FreezeProxy() {
    io_.stop();
    thread_.join();
  }
  FreezeProxy(const FreezeProxy&) = delete;
  FreezeProxy& operator=(const FreezeProxy&) = delete;

  [[nodiscard]] int port() const noexcept { return port_; }
  [[nodiscard]] std::string address() const { return "127.0.0.1:" + std::to_string(port_); }
  [[nodiscard]] int connections() const { return accepted_.load(); }

  void Freeze() {
    freeze_new_ = true;
    std::lock_guard lock(mu_);
    for (auto& weak : links_) {
      if (auto link = weak.lock()) link->frozen = true;
    }
  }
  void LiftForNew() { freeze_new_ = false; }

 private:
  struct Link {
    explicit Link(boost::asio::io_context& io) : client(io), server(io) {}
    boost::asio::ip::tcp::socket client, server;
    std::array<char, 16384> up{}, down{};
    std::atomic<bool> frozen{false};
  };

  void Accept() {
    auto link = std::make_shared<Link>(io_);
    acceptor_.async_accept(link->client, [this, link](boost::system::error_code ec) {
      if (ec) return;
      ++accepted_;
      link->frozen = freeze_new_.load();
      {
        std::lock_guard lock(mu_);
        links_.push_back(link);
        held_.push_back(link);  // a frozen link's sockets stay open until the proxy goes
      }
      link->server.async_connect(upstream_, [this, link](boost::system::error_code ec2) {
        if (ec2) return;
        Pump(link, link->client, link->server, link->up);
        Pump(link, link->server, link->client, link->down);
      });
      Accept();
    });
  }

  // Reads from `from` and writes to `to` until an error, or forever nothing once frozen.
  void Pump(const std::shared_ptr<Link>& link, boost::asio::ip::tcp::socket& from, boost::asio::ip::tcp::socket& to,
            std::array<char, 16384>& buf) {
    from.async_read_some(boost::asio::buffer(buf), [this, link, &from, &to, &buf](boost::system::error_code ec, std::size_t n) {
      if (link->frozen) return;  // swallow it and read no more: the peer's data piles up in its socket
      if (ec) {
        boost::system::error_code ignored;
        to.shutdown(boost::asio::ip::tcp::socket::shutdown_send, ignored);
        return;
      }
      boost::asio::async_write(to, boost::asio::buffer(buf.data(), n), [this, link, &from, &to, &buf](boost::system::error_code ec2, std::size_t) {
        if (ec2 || link->frozen) return;
        Pump(link, from, to, buf);
      });
    });
  }

  boost::asio::io_context io_;
  boost::asio::ip::tcp::endpoint upstream_;
  boost::asio::ip::tcp::acceptor acceptor_;
  int port_ = 0;
  std::atomic<int> accepted_{0};
  std::atomic<bool> freeze_new_{false};
  std::mutex mu_;
  std::vector<std::weak_ptr<Link>> links_;
  std::vector<std::shared_ptr<Link>> held_;
  std::thread thread_;
};

}  // namespace ruffini::testing
