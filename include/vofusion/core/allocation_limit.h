#pragma once
// A per-thread ceiling on single heap requests, for code that lets a file's length fields size its
// buffers before the data is read: MRPT's deserialisation resizes (and zero-fills) strings, vectors
// and matrices to whatever an archive claims, so one corrupt field costs gigabytes before the read
// fails.
//
// While a ScopedAllocationLimit lives, a request above the limit made on the same thread through
//  - the global operator new / new[] (std::string, std::vector, ...): throws std::bad_alloc
//    (the nothrow forms return nullptr);
//  - mrpt::aligned_malloc (MRPT's matrices and aligned vectors): throws std::bad_alloc, as does a
//    failed one (MRPT's allocator would hand nullptr to a vector that writes through it).
// Other threads, and code outside a scope, allocate exactly as before.
//
// allocation_limit.cpp replaces those functions for the whole program and defines this class, so a
// program that sets a limit always links the replacements (also from the static library). Not
// covered: malloc/realloc called directly and OpenCV's cv::Mat buffers (CImage pixels) -- these are
// not zero-filled, so an unbacked size costs address space but not memory -- and over-aligned new
// (alignment > 16), which stays the C++ runtime's.
#include <cstddef>

namespace vofusion {

class ScopedAllocationLimit {
 public:
  // Scopes nest; an inner scope can only tighten the limit.
  explicit ScopedAllocationLimit(std::size_t max_bytes);
  ~ScopedAllocationLimit();  // restores the enclosing limit
  ScopedAllocationLimit(const ScopedAllocationLimit&) = delete;
  ScopedAllocationLimit& operator=(const ScopedAllocationLimit&) = delete;

  // Largest request refused on this thread since the scope began (0: none), for error messages.
  std::size_t refused() const;

 private:
  std::size_t outer_limit_, outer_refused_;
};

}  // namespace vofusion
