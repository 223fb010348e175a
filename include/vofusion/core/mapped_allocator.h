#pragma once
// An allocator for the long-lived arrays that grow with the map (the world model's brick index, the
// place index's tables): every buffer is an anonymous mapping of its own, and pages not yet written
// are not resident. So such an array reserves room for a long walk up front (address space, not
// memory: MAP_NORESERVE) and never has to move: growing by copying would hold the old and the new
// array at once, and from glibc's heap (runApp keeps blocks up to 32 MiB there for the frame loop)
// each outgrown buffer would stay behind as a hole that the process's RSS keeps.
#include <sys/mman.h>

#include <cstddef>
#include <new>

namespace vofusion {

template <class T>
struct MappedAllocator {
  using value_type = T;
  MappedAllocator() = default;
  template <class U>
  MappedAllocator(const MappedAllocator<U>&) noexcept {}

  T* allocate(std::size_t n) {
    if (n == 0) return nullptr;
    if (n > std::size_t(-1) / sizeof(T)) throw std::bad_array_new_length();
    void* p = ::mmap(nullptr, n * sizeof(T), PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
    if (p == MAP_FAILED) throw std::bad_alloc();
    return static_cast<T*>(p);
  }
  void deallocate(T* p, std::size_t n) noexcept {
    if (p) ::munmap(p, n * sizeof(T));
  }
  template <class U>
  bool operator==(const MappedAllocator<U>&) const noexcept { return true; }
  template <class U>
  bool operator!=(const MappedAllocator<U>&) const noexcept { return false; }
};

}  // namespace vofusion
