// bench/longrun: memory must stay bounded on long runs. Replays a TUM sequence forward and backward
// alternately (0..n-1, n-2..0, 1.. : a continuous camera path) through the whole pipeline
// (Reconstruction: odometry + KinectFusion with volume shifting) for N frames, and reports peak and
// current RSS, fps, volume shifts, world-model size and tracking counts every K frames.
// With synthetic:<scene> (e.g. synthetic:longwalk, a straight corridor walked at 1 m/s) the frames are
// rendered in order instead, and each checkpoint also gives the path walked so far (ground truth).
//   longrun <tum_dir|synthetic:scene> [--frames 10000] [--every 1000] [--mode joint|paper-handoff|kinfu|odometry]
//           [--config f.ini] [--json out.json]
// Built by CMake as build/bin/longrun (a benchmark, not a test: run it by hand, see bench/README.md).
#include <malloc.h>
#include <sys/resource.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "vofusion/core/cli.h"
#include "vofusion/core/config.h"
#include "vofusion/core/errors.h"
#include "vofusion/eval/trajectory_eval.h"
#include "vofusion/io/frame_source.h"
#include "vofusion/io/tum_source.h"
#include "vofusion/pipeline/reconstruction.h"
#include "vofusion/pipeline/run_outputs.h"
#include "vofusion/sim/any_source.h"

using namespace vofusion;

namespace {

double peakRssMiB() {
  rusage u{};
  ::getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;  // KiB on Linux
}

// The heap as glibc sees it (all arenas): in use by the program, and free but still held (which
// counts in RSS once touched: fragmentation, not data).
std::pair<double, double> heapInUseAndFreeMiB() {
  const struct mallinfo2 m = ::mallinfo2();
  return {double(m.uordblks + m.hblkhd) / (1024.0 * 1024.0), double(m.fordblks) / (1024.0 * 1024.0)};
}

double currentRssMiB() {
  std::ifstream f("/proc/self/statm");
  long pages_total = 0, pages_resident = 0;
  f >> pages_total >> pages_resident;
  return pages_resident * double(::sysconf(_SC_PAGESIZE)) / (1024.0 * 1024.0);
}

// Frame k of the long run -> index into the sequence, bouncing at both ends without repeating them.
std::size_t pingPong(std::size_t k, std::size_t n) {
  if (n < 2) return 0;
  const std::size_t period = 2 * (n - 1);
  const std::size_t p = k % period;
  return p < n ? p : period - p;
}

int body(int argc, char** argv) {
  const CommandLine cl(argc, argv, {"--frames", "--every", "--mode", "--config", "--json"}, {"--help"});
  const char* usage = "usage: longrun <tum_dir|synthetic:scene> [--frames 10000] [--every 1000] "
                      "[--mode joint|paper-handoff|kinfu|odometry] [--config f.ini] [--json out.json]\n";
  if (cl.flag("--help")) {
    std::cout << usage;
    return 0;
  }
  if (cl.positional().size() != 1) throw InputError("usage", "expected one input (see --help)");
  const std::size_t total = cl.count("--frames", 10000), every = std::max<std::size_t>(1, cl.count("--every", 1000));
  const std::string config_path = cl.value("--config", "");
  const auto cfg = loadConfig(config_path);
  checkConfigKeys(cfg, config_path, vofusionConfigSections());
  const TrackingMode mode = parseTrackingMode(cl.value("--mode", "joint"));

  const std::string input = cl.positional()[0];
  const bool synthetic = input.rfind("synthetic", 0) == 0;
  SourceOptions so;
  so.max_frames = total;
  std::unique_ptr<FrameSource> src;
  if (synthetic) src = openFrameSource(input, so);
  else src = std::make_unique<TumFolderSource>(input, SourceOptions{});
  const std::size_t n = src->size();
  double path_m = 0.0;
  std::optional<Eigen::Vector3d> last_position;
  Reconstruction rec(cfg, mode);
  const double fps_stamp = 30.0;  // Hz: the replay's own timeline, strictly increasing
  Trajectory gt;
  nlohmann::json checkpoints = nlohmann::json::array();
  const auto t0 = std::chrono::steady_clock::now();
  auto t_last = t0;
  std::size_t shifts_last = 0;
  std::printf("%8s %7s %10s %10s %8s %8s %10s %10s %9s %6s\n", "frames", "path_m", "peakRSS", "RSS", "fps", "shifts",
              "bricks_vol", "bricks_wm", "fallbacks", "lost");
  for (std::size_t k = 0; k < total; ++k) {
    Frame f;
    if (synthetic) {
      if (!src->next(f)) break;
    } else {
      f = static_cast<TumFolderSource&>(*src).read(pingPong(k, n));
      f.index = k;
      f.timestamp = k / fps_stamp;
    }
    if (f.groundTruth) {
      gt.push_back({f.timestamp, *f.groundTruth});
      const Eigen::Vector3d p(f.groundTruth->x(), f.groundTruth->y(), f.groundTruth->z());
      if (last_position) path_m += (p - *last_position).norm();
      last_position = p;
    }
    rec.process(f);
    if ((k + 1) % every == 0 || k + 1 == total) {
      const auto now = std::chrono::steady_clock::now();
      const double dt = std::chrono::duration<double>(now - t_last).count();
      const std::size_t done_in_window = (k + 1) % every == 0 ? every : (k + 1) % every;
      t_last = now;
      const KinFuStats ks = rec.fusionStats();
      const auto [heap_used, heap_free] = heapInUseAndFreeMiB();
      nlohmann::json c = {{"heap_in_use_mib", heap_used},
                          {"heap_free_held_mib", heap_free},
                          {"keyframes", rec.loopCloser() ? rec.loopCloser()->storeStats().keyframes : 0},
                          {"keyframes_in_ram", rec.loopCloser() ? rec.loopCloser()->storeStats().in_ram : 0},
                          {"max_queued_keyframes", rec.loopCloser() ? rec.loopCloser()->queueStats().first : 0},
                          {"frames", k + 1},
                          {"path_m", path_m},
                          {"ms_per_frame_window", 1000.0 * dt / done_in_window},
                          {"world_model_cache_mib", ks.world.ram_bytes / (1024.0 * 1024.0)},
                          {"bricks_spilled", ks.world.spilled},
                          {"spill_file_mib", ks.world.spill_file_bytes / (1024.0 * 1024.0)},
                          {"spill_seconds", ks.world.spill_seconds},
                          {"peak_rss_mib", peakRssMiB()},
                          {"rss_mib", currentRssMiB()},
                          {"fps_window", done_in_window / dt},
                          {"volume_shifts", ks.shifts},
                          {"shifts_in_window", ks.shifts - shifts_last},
                          {"bricks_in_volume", ks.bricks_in_volume},
                          {"bricks_in_world_model", ks.bricks_in_world_model},
                          {"tsdf_memory_mib", ks.memory_bytes / (1024.0 * 1024.0)},
                          {"fallbacks", rec.fallbacks()},
                          {"lost", rec.lostFrames()},
                          {"odometry_failures", rec.odometryFailures()}};
      shifts_last = ks.shifts;
      std::printf("%8zu %7.1f %9.0fM %9.0fM %8.2f %8zu %10zu %10zu %9zu %6zu\n", k + 1, path_m, c["peak_rss_mib"].get<double>(),
                  c["rss_mib"].get<double>(), c["fps_window"].get<double>(), ks.shifts, ks.bricks_in_volume,
                  ks.bricks_in_world_model, rec.fallbacks(), rec.lostFrames());
      std::fflush(stdout);
      checkpoints.push_back(c);
    }
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  nlohmann::json out = {{"sequence", src->name()},  {"sequence_frames", n},          {"frames", total},
                        {"mode", toString(mode)}, {"config", config_path},          {"seconds", seconds},
                        {"fps", total / seconds}, {"checkpoints", checkpoints}};
  const AteResult ate = computeAte(gt, rec.trajectory());
  if (ate.success) out["ate_rmse_m"] = ate.trans.rmse, out["ate_max_m"] = ate.trans.max;
  std::printf("%zu frames in %.0f s (%.2f fps)%s\n", total, seconds, total / seconds,
              ate.success ? (", ATE RMSE " + std::to_string(ate.trans.rmse) + " m").c_str() : "");
  if (const auto j = cl.value("--json")) {
    std::ofstream f(*j);
    f << out.dump(1) << "\n";
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) { return runApp("longrun", body, argc, argv); }
