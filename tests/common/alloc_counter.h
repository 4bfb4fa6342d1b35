#pragma once
// Counts heap allocations while armed, by replacing the global operator new. Include it in exactly one
// translation unit of a test binary (the replacement is program-wide), and keep such tests in their own binary.
#include <atomic>
#include <cstdlib>
#include <new>

namespace ruffini::testing {
inline std::atomic<bool> g_alloc_armed{false};
inline std::atomic<long> g_allocations{0};

// Allocations made by f().
template <typename F>
long CountAllocations(F&& f) {
  g_allocations = 0;
  g_alloc_armed = true;
  f();
  g_alloc_armed = false;
  return g_allocations.load();
}
}  // namespace ruffini::testing

void* operator new(std::size_t n) {
  if (ruffini::testing::g_alloc_armed.load(std::memory_order_relaxed)) {
    ruffini::testing::g_allocations.fetch_add(1, std::memory_order_relaxed);
  }
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
