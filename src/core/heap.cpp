#include "vofusion/core/heap.h"

#include <malloc.h>

#include <algorithm>
#include <cstdlib>
#include <optional>
#include <string>

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

namespace {
// The value of `key` in a GLIBC_TUNABLES string (key=value pairs separated by ':').
std::optional<std::string> tunable(const char* tunables, const std::string& key) {
  if (tunables == nullptr) return std::nullopt;
  const std::string all(tunables);
  for (std::size_t at = 0; at <= all.size();) {
    const std::size_t end = std::min(all.find(':', at), all.size());
    const std::string pair = all.substr(at, end - at);
    if (pair.compare(0, key.size() + 1, key + "=") == 0) return pair.substr(key.size() + 1);
    at = end + 1;
  }
  return std::nullopt;
}
}  // namespace

bool heapAsksForHugePages() {
  const std::optional<std::string> v = tunable(std::getenv("GLIBC_TUNABLES"), "glibc.malloc.hugetlb");
  return v && !v->empty() && *v != "0";
}

}  // namespace vofusion
