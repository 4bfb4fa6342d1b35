#pragma once
// A counting semaphore whose timed wait sleeps in the kernel until it is released or the deadline passes.
//
// Why not std::counting_semaphore: libstdc++ 12 (Debian 12's compiler) implements try_acquire_for with a
// spin-then-back-off policy (bits/atomic_timed_wait.h, __timed_backoff_spin_policy): it spins and yields, and
// when the cores are busy it keeps yielding until the release comes instead of blocking in the kernel
// (measured: 0 to 1 kernel waits and 114 to 138 yields for 300 releases at 1 ms with every core busy). In the
// demo (four decoders, the sim, the aggregator and a controller on two cores) the decoder threads made about
// 4.6 context switches per frame between them that way, 2.3 with this class (docs/demo.md, "Load"). POSIX
// semaphores wait in the kernel (a futex in glibc), and sem_clockwait takes a CLOCK_MONOTONIC deadline, so a
// wall-clock step cannot stretch or cut a wait (Boost.Interprocess's interprocess_semaphore::timed_wait takes a
// wall-clock deadline, which is why this wraps sem_t itself).
#include <semaphore.h>

#include <cerrno>
#include <chrono>
#include <ctime>
#include <stdexcept>

namespace ruffini::service {

class Semaphore {
 public:
  explicit Semaphore(unsigned initial = 0) {
    if (sem_init(&sem_, 0, initial) != 0) throw std::runtime_error("sem_init failed");
  }
  ~Semaphore() { sem_destroy(&sem_); }
  Semaphore(const Semaphore&) = delete;
  Semaphore& operator=(const Semaphore&) = delete;

  // Wakes one waiter (or lets the next acquire pass). False when the count is at SEM_VALUE_MAX (EOVERFLOW):
  // the release is lost, which a waiter that also polls its ring survives. The decoder takes one count back for
  // each message it discards, so its counts stay within its rings' sizes.
  bool release() noexcept { return sem_post(&sem_) == 0; }

  bool try_acquire() noexcept {
    while (sem_trywait(&sem_) != 0) {
      if (errno != EINTR) return false;
    }
    return true;
  }

  // Waits at most `timeout` (measured on the monotonic clock); false on time-out.
  template <class Rep, class Period>
  bool try_acquire_for(std::chrono::duration<Rep, Period> timeout) noexcept {
    timespec deadline{};
    clock_gettime(CLOCK_MONOTONIC, &deadline);
    const auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(timeout).count();
    if (ns <= 0) return try_acquire();
    deadline.tv_sec += static_cast<time_t>(ns / 1'000'000'000);
    deadline.tv_nsec += static_cast<long>(ns % 1'000'000'000);
    if (deadline.tv_nsec >= 1'000'000'000) {
      deadline.tv_nsec -= 1'000'000'000;
      ++deadline.tv_sec;
    }
    for (;;) {
      if (sem_clockwait(&sem_, CLOCK_MONOTONIC, &deadline) == 0) return true;
      if (errno != EINTR) return false;  // ETIMEDOUT (or EINVAL, which a valid deadline never gives)
    }
  }

 private:
  sem_t sem_;
};

}  // namespace ruffini::service
