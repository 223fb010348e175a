// For test_cli's Heap tests: prints its pid as it starts (twice when it restarts itself), then the pid,
// its process name, whether the restart marker is left, GLIBC_TUNABLES and the arguments it runs with.
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>

#include "vofusion/core/heap.h"

int main(int argc, char** argv) {
  std::printf("start %d\n", int(getpid()));
  std::fflush(stdout);
  vofusion::restartWithHugePageHeap(argv);
  std::string name;
  std::getline(std::ifstream("/proc/self/comm"), name);
  const char* tunables = std::getenv("GLIBC_TUNABLES");
  std::printf("running %d %s %s %s", int(getpid()), name.c_str(),
              std::getenv("VOFUSION_HEAP_RESTARTED") ? "marker-left" : "no-marker", tunables ? tunables : "(unset)");
  for (int i = 1; i < argc; ++i) std::printf(" %s", argv[i]);
  std::printf("\n");
  return 0;
}
