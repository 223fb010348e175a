// Replaces the global operator new/delete (all but the over-aligned forms) and mrpt::aligned_malloc
// for the whole program, to refuse requests beyond a ScopedAllocationLimit. The definitions in the
// executable take precedence over libstdc++'s, AddressSanitizer's (weak) and libmrpt-core's, also
// for the calls MRPT's shared libraries make (through their PLT); tests/test_rawlog_corrupt.cpp
// checks that for each path MRPT's deserialisation allocates through.
#include "vofusion/core/allocation_limit.h"

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <exception>
#include <new>

#include <mrpt/core/aligned_allocator.h>

namespace {

// Constant-initialised, so no TLS init wrapper: the fast path is two compares and a subtraction on
// thread-pointer-relative memory. Outside any scope both bounds are SIZE_MAX.
struct Budget {
  std::size_t max_request = SIZE_MAX;
  std::size_t remaining = SIZE_MAX;  // outside a scope it only ever runs down (reset when it would wrap)
  std::size_t refused_request = 0;
  bool total_exceeded = false;
  int depth = 0;
};
thread_local Budget t_budget;

[[gnu::noinline, gnu::cold]] void overBudget(std::size_t n) {
  Budget& b = t_budget;
  if (b.depth == 0) {  // no scope: 2^64 bytes allocated on this thread since the last reset
    b.remaining = SIZE_MAX - n;
    return;
  }
  // Cleanup code must not be refused (a destructor that throws ends the program): granted, uncounted.
  if (std::uncaught_exceptions() > 0 || std::current_exception()) return;
  if (n > b.max_request) b.refused_request = std::max(b.refused_request, n);
  else b.total_exceeded = true;
  throw std::bad_alloc();
}

inline void charge(std::size_t n) {
  Budget& b = t_budget;
  if (__builtin_expect(n > b.max_request || n > b.remaining, 0)) return overBudget(n);
  b.remaining -= n;
}

// libstdc++'s operator new plus the budget: malloc, retried through the new-handler.
void* allocate(std::size_t n) {
  charge(n);
  if (n == 0) n = 1;
  for (;;) {
    if (void* p = std::malloc(n)) return p;
    const std::new_handler handler = std::get_new_handler();
    if (!handler) throw std::bad_alloc();
    handler();
  }
}

void* allocateNothrow(std::size_t n) noexcept {
  try {
    return allocate(n);
  } catch (...) {
    return nullptr;
  }
}

}  // namespace

void* operator new(std::size_t n) { return allocate(n); }
void* operator new[](std::size_t n) { return allocate(n); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept { return allocateNothrow(n); }
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept { return allocateNothrow(n); }

// libstdc++'s delete is free() as well; defined here so that the pair stays malloc/free also where
// another runtime supplies delete (AddressSanitizer's would report every block as a mismatch).
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { std::free(p); }

// MRPT 2.x's body (size rounded up to the alignment, then aligned_alloc; mrpt::aligned_free is
// free()), plus the budget. mrpt::aligned_calloc calls this one too.
void* mrpt::aligned_malloc(std::size_t size, std::size_t alignment) {
  charge(size);
  if (alignment && size % alignment) size = (size / alignment + 1) * alignment;
  void* p = std::aligned_alloc(alignment, size);
  if (!p && t_budget.depth > 0) throw std::bad_alloc();
  return p;
}

namespace vofusion {

ScopedAllocationLimit::ScopedAllocationLimit(std::size_t max_request, std::size_t max_total)
    : outer_max_request_(t_budget.max_request),
      outer_remaining_(t_budget.remaining),
      start_remaining_(std::min(max_total, t_budget.depth > 0 ? t_budget.remaining : SIZE_MAX)),
      outer_refused_(t_budget.refused_request),
      outer_exceeded_(t_budget.total_exceeded) {
  Budget& b = t_budget;
  b.max_request = std::min(max_request, b.max_request);
  b.remaining = start_remaining_;
  b.refused_request = 0;
  b.total_exceeded = false;
  ++b.depth;
}

ScopedAllocationLimit::~ScopedAllocationLimit() {
  Budget& b = t_budget;
  const std::size_t used = start_remaining_ - b.remaining;
  --b.depth;
  b.max_request = outer_max_request_;
  b.remaining = outer_remaining_ - std::min(used, outer_remaining_);
  b.refused_request = std::max(outer_refused_, b.refused_request);
  b.total_exceeded = outer_exceeded_ || b.total_exceeded;
}

std::size_t ScopedAllocationLimit::refusedRequest() const { return t_budget.refused_request; }
bool ScopedAllocationLimit::totalExceeded() const { return t_budget.total_exceeded; }

}  // namespace vofusion
