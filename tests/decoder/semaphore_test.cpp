// service::Semaphore, the decoder's hand-off between its ingest, decode and publish threads: counts, times
// out, wakes a waiter on release, and waits in the kernel instead of polling (the reason it replaced
// std::counting_semaphore: semaphore.h).
#include "ruffini/service/semaphore.h"

#include <gtest/gtest.h>
#include <sys/resource.h>

#include <atomic>
#include <chrono>
#include <thread>
#include <vector>
#include <algorithm>

namespace {

using ruffini::service::Semaphore;
using namespace std::chrono_literals;

long VoluntarySwitchesOfThisThread() {
  rusage u{};
  getrusage(RUSAGE_THREAD, &u);
  return u.ru_nvcsw;
}

TEST(Semaphore, CountsReleases) {
  Semaphore s(0);
  EXPECT_FALSE(s.try_acquire());
  s.release();
  s.release();
  s.release();
  EXPECT_TRUE(s.try_acquire());
  EXPECT_TRUE(s.try_acquire_for(0ms));
  EXPECT_TRUE(s.try_acquire_for(1ms));
  EXPECT_FALSE(s.try_acquire());
  EXPECT_FALSE(s.try_acquire_for(-5ms));  // a deadline already past: a plain try
}

TEST(Semaphore, ATimedWaitWithoutAReleaseTimesOutNoEarlierThanAsked) {
  Semaphore s(0);
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_FALSE(s.try_acquire_for(30ms));
  EXPECT_GE(std::chrono::steady_clock::now() - t0, 30ms);
}

TEST(Semaphore, AReleaseWakesAWaiterLongBeforeItsTimeout) {
  Semaphore s(0);
  std::atomic<bool> got{false};
  const auto t0 = std::chrono::steady_clock::now();
  std::thread waiter([&] { got = s.try_acquire_for(60s); });
  std::this_thread::sleep_for(20ms);
  s.release();
  waiter.join();
  EXPECT_TRUE(got.load());
  // Only a wake-up by the release returns true; the bound here is far above any scheduling delay.
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 30s);
}

// libstdc++ 12's std::counting_semaphore::try_acquire_for, with every core busy, never blocks in the kernel: it
// yields in a loop until the release comes (measured: 0-1 voluntary context switches and 114-138 yields for
// 300 releases at 1 ms). A kernel wait blocks once per release. The load here (one busy thread per core) lasts
// about 0.3 s.
TEST(Semaphore, UnderFullLoadAWaiterSleepsInTheKernelInsteadOfYieldingInALoop) {
  std::atomic<bool> stop_busy{false};
  std::vector<std::thread> busy;
  for (unsigned i = 0; i < std::max(1u, std::thread::hardware_concurrency()); ++i) {
    busy.emplace_back([&] {
      while (!stop_busy.load(std::memory_order_relaxed)) {
      }
    });
  }
  constexpr int kReleases = 300;
  Semaphore s(0);
  long voluntary = 0;
  int acquired = 0;
  // The waiter takes every release (however late a loaded machine runs it), within an overall bound.
  std::thread waiter([&] {
    const long before = VoluntarySwitchesOfThisThread();
    const auto give_up = std::chrono::steady_clock::now() + 30s;
    while (acquired < kReleases && std::chrono::steady_clock::now() < give_up) {
      if (s.try_acquire_for(15ms)) ++acquired;
    }
    voluntary = VoluntarySwitchesOfThisThread() - before;
  });
  auto next = std::chrono::steady_clock::now();
  for (int i = 0; i < kReleases; ++i) {
    next += 1ms;
    std::this_thread::sleep_until(next);
    s.release();
  }
  waiter.join();
  stop_busy = true;
  for (auto& t : busy) t.join();
  EXPECT_EQ(acquired, kReleases);
  EXPECT_GE(voluntary, kReleases / 2) << "the waiter blocked in the kernel " << voluntary << " times for " << kReleases
                                      << " releases";
}

}  // namespace
