#pragma once
// A counting semaphore whose timed wait sleeps in the kernel until it is released or the deadline passes.
//
// Why not std::counting_semaphore: libstdc++ 12 (Debian 12's compiler) implements try_acquire_for by
// polling. Its timed back-off spin policy yields, then sleeps for half the time already waited, again and
// again until the deadline, and only then waits on the futex (bits/atomic_timed_wait.h,
// __timed_backoff_spin_policy). A decoder thread waiting 1 ms for the next frame made about nine context
// switches per frame that way and noticed a release up to half its wait late; with four decoders, the sim,
// the aggregator and a controller on two cores, those switches were most of the machine's load
// (docs/demo.md, "Load"). POSIX semaphores wait in the kernel (a futex in glibc), and
// sem_clockwait takes a CLOCK_MONOTONIC deadline, so a wall-clock step cannot stretch or cut a wait.
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

  // Wakes one waiter (or lets the next acquire pass). The count is bounded by the rings it counts (far below
  // SEM_VALUE_MAX), so sem_post cannot overflow here.
  void release() noexcept { sem_post(&sem_); }

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
