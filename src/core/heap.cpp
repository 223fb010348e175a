#include "vofusion/core/heap.h"

#include <malloc.h>

namespace vofusion {

void keepFreedHeapForFrames() {
  mallopt(M_MMAP_THRESHOLD, 32 << 20);  // glibc's maximum
  mallopt(M_TRIM_THRESHOLD, 512 << 20);
}

void returnFreedHeap() {
  // glibc's default thresholds (128 KiB); setting them keeps them fixed rather than adaptive.
  mallopt(M_MMAP_THRESHOLD, 128 << 10);
  mallopt(M_TRIM_THRESHOLD, 128 << 10);
  malloc_trim(0);  // every arena, free pages in the middle of the heap too
}

}  // namespace vofusion
