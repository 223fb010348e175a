// For test_cli's Heap tests: prints its pid as it starts (twice when it restarts itself), then the pid,
// GLIBC_TUNABLES and its arguments it runs with.
#include <unistd.h>

#include <cstdio>
#include <cstdlib>

#include "vofusion/core/heap.h"

int main(int argc, char** argv) {
  std::printf("start %d\n", int(getpid()));
  std::fflush(stdout);
  vofusion::restartWithHugePageHeap(argv);
  const char* tunables = std::getenv("GLIBC_TUNABLES");
  std::printf("running %d %s", int(getpid()), tunables ? tunables : "(unset)");
  for (int i = 1; i < argc; ++i) std::printf(" %s", argv[i]);
  std::printf("\n");
  return 0;
}
