// Replaces the global operator new/delete (all but the over-aligned forms) and mrpt::aligned_malloc
// for the whole program, to refuse oversized requests inside a ScopedAllocationLimit. The
// definitions in the executable take precedence over libstdc++'s, AddressSanitizer's (weak) and
// libmrpt-core's, also for the calls MRPT's shared libraries make (through their PLT);
// tests/test_rawlog_corrupt.cpp checks that for each path MRPT's deserialisation uses.
#include "vofusion/core/allocation_limit.h"

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <new>

#include <mrpt/core/aligned_allocator.h>

namespace {

// Constant-initialised, so no TLS init wrapper: one thread-pointer-relative load per allocation.
thread_local std::size_t t_limit = SIZE_MAX;  // SIZE_MAX: no scope active
thread_local std::size_t t_refused = 0;

[[noreturn, gnu::noinline, gnu::cold]] void refuse(std::size_t n) {
  t_refused = std::max(t_refused, n);
  throw std::bad_alloc();
}

// libstdc++'s operator new plus the limit: malloc, retried through the new-handler.
void* allocate(std::size_t n) {
  if (n > t_limit) refuse(n);
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
// free()), plus the limit. mrpt::aligned_calloc calls this one too.
void* mrpt::aligned_malloc(std::size_t size, std::size_t alignment) {
  if (size > t_limit) refuse(size);
  if (alignment && size % alignment) size = (size / alignment + 1) * alignment;
  void* p = std::aligned_alloc(alignment, size);
  if (!p && t_limit != SIZE_MAX) refuse(size);
  return p;
}

namespace vofusion {

ScopedAllocationLimit::ScopedAllocationLimit(std::size_t max_bytes)
    : outer_limit_(t_limit), outer_refused_(t_refused) {
  t_limit = std::min(max_bytes, t_limit);
  t_refused = 0;
}

ScopedAllocationLimit::~ScopedAllocationLimit() {
  t_limit = outer_limit_;
  t_refused = std::max(outer_refused_, t_refused);
}

std::size_t ScopedAllocationLimit::refused() const { return t_refused; }

}  // namespace vofusion
