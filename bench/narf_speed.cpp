// bench/narf_speed: CPU time per detectNarf call, fast vs pcl implementation, on every k-th frame
// of a TUM sequence (default parameters otherwise, [narf] threads = 1 unless --threads), and how
// well the two agree: the share of each one's keypoints with one of the other's within 1 pixel of
// the reduced image, and the number of frames with identical keypoints.
//   narf_speed <tum_dir> [--every 3] [--repeat 3] [--threads 1] [--only fast|pcl]
// --only times one implementation (for a profiler) and skips the comparison.
// Built by CMake as build/bin/narf_speed (a benchmark, not a test: run it by hand).
#include <time.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <string>

#include "vofusion/core/cli.h"
#include "vofusion/core/errors.h"
#include "vofusion/features/narf_detector.h"
#include "vofusion/io/tum_source.h"

using namespace vofusion;

namespace {
double threadCpuMs() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return t.tv_sec * 1e3 + t.tv_nsec * 1e-6;
}
double processCpuMs() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return t.tv_sec * 1e3 + t.tv_nsec * 1e-6;
}

// Keypoints of `a` with one of `b` within `tol` full-resolution pixels.
int matched(const std::vector<cv::KeyPoint>& a, const std::vector<cv::KeyPoint>& b, float tol) {
  int n = 0;
  for (const auto& k : a)
    n += std::any_of(b.begin(), b.end(), [&](const cv::KeyPoint& o) {
      return std::abs(o.pt.x - k.pt.x) <= tol && std::abs(o.pt.y - k.pt.y) <= tol;
    });
  return n;
}
}  // namespace

int body(int argc, char** argv) {
  const CommandLine cl(argc, argv, {"--every", "--repeat", "--threads", "--only"}, {"--help"});
  if (cl.flag("--help")) {
    std::cout << "usage: narf_speed <tum_dir> [--every 3] [--repeat 3] [--threads 1] [--only fast|pcl]\n"
                 "  NARF keypoints of every --every-th frame, our implementation against PCL's: time and agreement\n";
    return 0;
  }
  if (cl.positional().size() != 1) throw InputError("usage", "expected one TUM folder (see --help)");
  const int every = int(cl.count("--every", 3, 1)), repeat = int(cl.count("--repeat", 3, 1));
  const int threads = int(cl.count("--threads", 1, 1));
  const std::string only = cl.value("--only", "");
  if (!only.empty() && only != "fast" && only != "pcl") throw InputError("--only", "must be fast or pcl, got '" + only + "'");
  TumFolderSource src(cl.positional()[0], {});
  NarfParams fast, pcl;
  fast.implementation = "fast";
  pcl.implementation = "pcl";
  fast.threads = pcl.threads = threads;
  const float tol = float(fast.downsample);  // 1 pixel of the reduced image

  double cpu_fast = 0, cpu_pcl = 0, proc_fast = 0, proc_pcl = 0;
  long calls = 0, n_fast = 0, n_pcl = 0, fast_in_pcl = 0, pcl_in_fast = 0, identical = 0, frames = 0;
  for (std::size_t f = 0; f < src.size(); f += every) {
    const Frame frame = src.read(f);
    std::vector<cv::KeyPoint> a, b;
    for (int r = 0; r < repeat; ++r) {
      double t = threadCpuMs(), p = processCpuMs();
      if (only != "pcl") a = detectNarf(frame.depth, frame.camera, fast);
      cpu_fast += threadCpuMs() - t, proc_fast += processCpuMs() - p;
      t = threadCpuMs(), p = processCpuMs();
      if (only != "fast") b = detectNarf(frame.depth, frame.camera, pcl);
      cpu_pcl += threadCpuMs() - t, proc_pcl += processCpuMs() - p;
      ++calls;
    }
    ++frames;
    n_fast += long(a.size()), n_pcl += long(b.size());
    fast_in_pcl += matched(a, b, tol), pcl_in_fast += matched(b, a, tol);
    bool same = a.size() == b.size();
    for (std::size_t k = 0; same && k < a.size(); ++k) same = a[k].pt == b[k].pt && a[k].response == b[k].response;
    identical += same;
  }
  std::printf("frames %ld (every %d of %zu), %d repeats, threads %d\n", frames, every, src.size(), repeat, threads);
  std::printf("cpu ms/call (calling thread): fast %.2f  pcl %.2f  (x%.1f)\n", cpu_fast / calls, cpu_pcl / calls,
              cpu_pcl / std::max(1e-9, cpu_fast));
  std::printf("cpu ms/call (process, incl. OpenMP threads): fast %.2f  pcl %.2f\n", proc_fast / calls, proc_pcl / calls);
  std::printf("keypoints: fast %ld  pcl %ld;  fast near a pcl one %.1f %%, pcl near a fast one %.1f %% (<= 1 px reduced)\n",
              n_fast, n_pcl, 100.0 * fast_in_pcl / std::max(1L, n_fast), 100.0 * pcl_in_fast / std::max(1L, n_pcl));
  std::printf("frames with identical keypoints and responses: %ld / %ld\n", identical, frames);
  return 0;
}

int main(int argc, char** argv) { return runApp("narf_speed", body, argc, argv); }
