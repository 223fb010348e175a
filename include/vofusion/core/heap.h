#pragma once
// glibc heap settings for the two phases of a run. While frames stream, frame-sized buffers (MBs)
// are freed and allocated again every frame: kept in the heap they are reused instead of being
// mapped fresh and faulted in page by page (1.2 M page faults, 2 s of kernel time in a 300-frame
// run). Once the frames are done, meshing and CGAL allocate hundreds of MiB one region at a time:
// kept in the heap, what one region freed stays counted in the process's RSS through the rest.
// Pages are the kernel's default size: transparent huge pages (glibc.malloc.hugetlb=1) made meshing
// slower and its system time 1.3-7x as long in 2026-12-03's runs (docs/memory.md).

namespace vofusion {

// For the frame loop (runApp calls it): large buffers from the heap, freed memory kept.
void keepFreedHeapForFrames();
// After the frame loop: glibc's defaults again (large blocks mapped and unmapped, the heap's top
// trimmed) and the free memory held so far returned to the kernel now.
void returnFreedHeap();

// Whether this process's GLIBC_TUNABLES asks for huge pages (glibc.malloc.hugetlb set, not 0): a user's
// own choice, reported in summary.json.
bool heapAsksForHugePages();

}  // namespace vofusion
