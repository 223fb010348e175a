#include "vofusion/core/heap.h"

#include <link.h>
#include <malloc.h>
#include <sys/auxv.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdlib>
#include <cstring>
#include <fstream>

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
constexpr const char* kHugePageKey = "glibc.malloc.hugetlb";
// Set for the restarted process only (it takes it out again): there is never a second restart, even
// where glibc would take the tunable out of the environment.
constexpr const char* kRestartedMarker = "VOFUSION_HEAP_RESTARTED";

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

// A tool preloaded into this process has set itself up here and would not follow a restart (under
// heaptrack a restarted run showed 5 MB and its first seconds). valgrind's library stays in
// LD_PRELOAD; heaptrack takes its own out once loaded, so it is looked for among those loaded too.
bool toolPreloaded() {
  if (const char* preload = std::getenv("LD_PRELOAD"); preload != nullptr && *preload != '\0') return true;
  bool found = false;
  dl_iterate_phdr(
      [](dl_phdr_info* info, std::size_t, void* data) {
        if (info->dlpi_name == nullptr || std::strstr(info->dlpi_name, "heaptrack") == nullptr) return 0;
        *static_cast<bool*>(data) = true;
        return 1;
      },
      &found);
  return found;
}

// The program's own file, resolved, so that the restarted process keeps its name ("vofusion", not
// "exe", in ps, top and pkill); nullopt without /proc or when the program was started through the
// dynamic loader (ld-linux-x86-64.so.2 ./vofusion: the file is the loader, which would take the
// first argument for the program).
std::optional<std::string> ownFile() {
  std::array<char, 4096> path{};
  const ssize_t n = readlink("/proc/self/exe", path.data(), path.size() - 1);
  if (n <= 0) return std::nullopt;
  const std::string file(path.data(), std::size_t(n));
  const std::string name = file.substr(file.find_last_of('/') + 1);
  if (name.rfind("ld-", 0) == 0 || name.rfind("ld.so", 0) == 0) return std::nullopt;
  return file;
}
}  // namespace

std::optional<std::string> tunablesWithHugePageHeap(const char* current) {
  const std::string huge_pages = std::string(kHugePageKey) + "=1";
  if (current == nullptr || *current == '\0') return huge_pages;
  if (tunable(current, kHugePageKey)) return std::nullopt;
  return std::string(current) + ":" + huge_pages;
}

bool kernelHugePagesOff() {
  std::string mode;
  std::getline(std::ifstream("/sys/kernel/mm/transparent_hugepage/enabled"), mode);
  return mode.find("[never]") != std::string::npos;
}

bool heapAsksForHugePages() {
  const std::optional<std::string> v = tunable(std::getenv("GLIBC_TUNABLES"), kHugePageKey);
  return v && !v->empty() && *v != "0";
}

void restartWithHugePageHeap(char** argv) {
  // hugetlb=1: glibc advises the kernel to back the blocks of 2 MiB and more it maps, and the heap as
  // it grows, with transparent huge pages. Meshing maps and unmaps region-sized blocks
  // (returnFreedHeap), and on a virtual machine each 4 KiB fault is dear: the loop scene's system
  // time 13.0 -> 8.2 s and its time after the last frame 48 -> 37 s, peak RSS +3-21 MiB
  // (bench/results/2026-11-28-huge-pages.md).
  if (std::getenv(kRestartedMarker) != nullptr) {
    unsetenv(kRestartedMarker);  // our own children start afresh
    return;
  }
  if (argv == nullptr || argv[0] == nullptr || getauxval(AT_SECURE) != 0 || toolPreloaded() ||
      kernelHugePagesOff())  // a restart would cost 0.3 s for nothing
    return;
  const char* before = std::getenv("GLIBC_TUNABLES");
  const std::optional<std::string> tunables = tunablesWithHugePageHeap(before);
  const std::optional<std::string> file = ownFile();
  if (!tunables || !file) return;
  const std::optional<std::string> restore = before ? std::optional<std::string>(before) : std::nullopt;
  if (setenv("GLIBC_TUNABLES", tunables->c_str(), 1) == 0 && setenv(kRestartedMarker, "1", 1) == 0)
    execv(file->c_str(), argv);
  // No restart: run on with 4 KiB pages, the environment as it came.
  unsetenv(kRestartedMarker);
  if (restore) setenv("GLIBC_TUNABLES", restore->c_str(), 1);
  else unsetenv("GLIBC_TUNABLES");
}

}  // namespace vofusion
