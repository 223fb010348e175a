#pragma once
// Per-thread bounds on heap requests, for code that lets a file's length fields size its buffers
// before the data is read: MRPT's deserialisation resizes (and zero-fills) strings, vectors, deques
// and matrices to whatever an archive claims, so one corrupt field costs gigabytes before the read
// fails -- in one buffer, or in millions of small deque blocks.
//
// While a ScopedAllocationLimit lives, a request made on the same thread through
//  - the global operator new / new[] (std::string, std::vector, std::deque, ...), or
//  - mrpt::aligned_malloc (MRPT's matrices and aligned vectors; a failed one throws as well, where
//    MRPT's own would hand nullptr to a vector that writes through it)
// throws std::bad_alloc (the nothrow forms return nullptr) if it is larger than max_request or if
// the bytes requested since the scope began (frees are not credited) would exceed max_total.
// Exceptions: while an exception is propagating or being handled, requests are granted and not
// counted -- cleanup code (destructors, catch blocks) may allocate, and throwing there would end
// the program. Other threads, and code outside a scope, allocate exactly as before.
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
  // Scopes nest: an inner scope can only tighten max_request, and what it uses counts for the outer.
  ScopedAllocationLimit(std::size_t max_request, std::size_t max_total);
  ~ScopedAllocationLimit();  // restores the enclosing limits
  ScopedAllocationLimit(const ScopedAllocationLimit&) = delete;
  ScopedAllocationLimit& operator=(const ScopedAllocationLimit&) = delete;

  // What was refused on this thread since the scope began, for error messages: the largest request
  // above max_request (0: none), and whether max_total ran out.
  std::size_t refusedRequest() const;
  bool totalExceeded() const;

 private:
  std::size_t outer_max_request_, outer_remaining_, start_remaining_, outer_refused_;
  bool outer_exceeded_;
};

}  // namespace vofusion
