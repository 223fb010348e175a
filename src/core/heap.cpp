#include "vofusion/core/heap.h"

#include <link.h>
#include <malloc.h>
#include <unistd.h>

#include <cstdlib>
#include <cstring>

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

std::optional<std::string> tunablesWithHugePageHeap(const char* current) {
  constexpr const char* kHugePages = "glibc.malloc.hugetlb=1";
  if (current == nullptr || *current == '\0') return std::string(kHugePages);
  if (std::strstr(current, "glibc.malloc.hugetlb=") != nullptr) return std::nullopt;
  return std::string(current) + ":" + kHugePages;
}

namespace {
// A tool preloaded into this process has set itself up here and would not follow a restart (under
// heaptrack a restarted run showed 5 MB and its first seconds). heaptrack and valgrind take their
// library out of LD_PRELOAD once loaded, so their libraries are looked for among those loaded too.
bool toolPreloaded() {
  if (const char* preload = std::getenv("LD_PRELOAD"); preload != nullptr && *preload != '\0') return true;
  bool found = false;
  dl_iterate_phdr(
      [](dl_phdr_info* info, std::size_t, void* data) {
        const char* name = info->dlpi_name;
        if (name == nullptr || (std::strstr(name, "heaptrack") == nullptr && std::strstr(name, "vgpreload") == nullptr))
          return 0;
        *static_cast<bool*>(data) = true;
        return 1;
      },
      &found);
  return found;
}
}  // namespace

void restartWithHugePageHeap(char** argv) {
  // hugetlb=1: glibc advises the kernel to back the blocks it maps (and the heap it grows) with
  // transparent huge pages. Meshing maps and unmaps region-sized blocks (returnFreedHeap), and on a
  // virtual machine each 4 KiB fault is dear: the loop scene's kernel time 12.5 -> 8.2 s and the
  // time after its last frame 46 -> 38 s, peak RSS +5 MiB (bench/results/2026-11-28-huge-pages.md).
  if (argv == nullptr || argv[0] == nullptr) return;
  if (toolPreloaded()) return;
  const std::optional<std::string> tunables = tunablesWithHugePageHeap(std::getenv("GLIBC_TUNABLES"));
  if (!tunables || setenv("GLIBC_TUNABLES", tunables->c_str(), 1) != 0) return;
  execv("/proc/self/exe", argv);
  // execv failed (no /proc): run on with 4 KiB pages; the variable stays set for our children.
}

}  // namespace vofusion
