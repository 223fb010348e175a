#pragma once
// Data-parallel loops on oneTBB, the task pool OpenCV already runs on (Debian builds it with TBB).
// One pool for the whole process: our per-pixel and per-voxel loops, OpenCV's and the pipeline's
// concurrent stages (odometry beside fusion) share the cores by work stealing. OpenMP's team beside
// TBB's workers spun on idle cores and oversubscribed them (~10 % of the CPU of a paper-mode run).
//
//   parallelFor(0, rows, [&](int y) { ... one row ... });
//   Accum a = parallelReduce(0, rows, Accum{}, [&](int y, Accum& acc) { ... }, joinAccums);
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_group.h>

namespace vofusion {

// body(i) for i in [begin, end), `grain` indices per task at least; serial when `parallel` is false
// (tiny images: a task costs more than the work). With `isolated`, every index runs even when the
// calling task's group is cancelled: for work whose skipping would lose data (parallelForEvery).
template <class Body>
void parallelFor(int begin, int end, const Body& body, int grain = 1, bool parallel = true, bool isolated = false) {
  if (!parallel || end - begin <= grain) {
    for (int i = begin; i < end; ++i) body(i);
    return;
  }
  const auto range = [&body](const tbb::blocked_range<int>& r) {
    for (int i = r.begin(); i != r.end(); ++i) body(i);
  };
  if (!isolated) {
    tbb::parallel_for(tbb::blocked_range<int>(begin, end, grain), range);
    return;
  }
  tbb::task_group_context context(tbb::task_group_context::isolated);
  tbb::parallel_for(tbb::blocked_range<int>(begin, end, grain), range, tbb::auto_partitioner(), context);
}

// Every index, whatever happens to the caller's task group: bricks compressed before being spilled.
template <class Body>
void parallelForEvery(int begin, int end, const Body& body, int grain = 1) {
  parallelFor(begin, end, body, grain, true, true);
}

// Sum-like reduction with a fixed split of [begin, end) into chunks of `grain`: the same inputs give
// bit-identical floating-point results on every run, whatever the thread count or timing.
template <class T, class Body, class Join>
T parallelReduce(int begin, int end, const T& identity, const Body& body, const Join& join, int grain = 16,
                 bool parallel = true) {
  if (!parallel) {
    T acc = identity;
    for (int i = begin; i < end; ++i) body(i, acc);
    return acc;
  }
  return tbb::parallel_deterministic_reduce(
      tbb::blocked_range<int>(begin, end, grain), identity,
      [&body](const tbb::blocked_range<int>& r, T acc) {
        for (int i = r.begin(); i != r.end(); ++i) body(i, acc);
        return acc;
      },
      [&join](T a, const T& b) { join(a, b); return a; });
}

}  // namespace vofusion
