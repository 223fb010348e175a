#pragma once
// glibc heap settings for the two phases of a run. While frames stream, frame-sized buffers (MBs)
// are freed and allocated again every frame: kept in the heap they are reused instead of being
// mapped fresh and faulted in page by page (1.2 M page faults, 2 s of kernel time in a 300-frame
// run). Once the frames are done, meshing and CGAL allocate hundreds of MiB one region at a time:
// kept in the heap, what one region freed stays counted in the process's RSS through the rest.
// Where a block of 2 MiB or more is mapped fresh, transparent huge pages fault it in 2 MiB at a time,
// not 4 KiB.
#include <optional>
#include <string>

namespace vofusion {

// For the frame loop (runApp calls it): large buffers from the heap, freed memory kept.
void keepFreedHeapForFrames();
// After the frame loop: glibc's defaults again (large blocks mapped and unmapped, the heap's top
// trimmed) and the free memory held so far returned to the kernel now.
void returnFreedHeap();

// GLIBC_TUNABLES with glibc.malloc.hugetlb=1 added to `current` (null: unset); nullopt when
// `current` already sets glibc.malloc.hugetlb (the user's choice stands).
std::optional<std::string> tunablesWithHugePageHeap(const char* current);
// The kernel gives no transparent huge pages at all ("[never]" in /sys/kernel/mm/transparent_hugepage/enabled).
bool kernelHugePagesOff();
// Whether this process's GLIBC_TUNABLES asks for huge pages (glibc.malloc.hugetlb set, not 0).
bool heapAsksForHugePages();
// glibc reads its tunables only when a program starts, so an app's main() calls this first: it
// restarts the program in place (same pid, same name, same arguments: execv of its own file) once,
// with GLIBC_TUNABLES from tunablesWithHugePageHeap. It does not restart, and returns, when:
// - the variable already sets glibc.malloc.hugetlb (GLIBC_TUNABLES=glibc.malloc.hugetlb=0 turns this
//   off, e.g. to debug in gdb, where main() would be reached twice);
// - a tool is preloaded (LD_PRELOAD set, as valgrind's is, or heaptrack's library loaded): it would not follow;
// - the kernel's transparent huge pages are off ("[never]"): nothing to gain;
// - the program runs set-user-ID or with file capabilities (glibc may drop the variable), or was
//   started through the dynamic loader, or /proc is missing, or the restart fails (the environment is
//   then put back as it came);
// - this process is the restarted one.
void restartWithHugePageHeap(char** argv);

}  // namespace vofusion
