// rgbd-odometry <tum_dir|in.rawlog|synthetic[:scene]> --out <dir> [--config f.ini] [--max-frames N]
//               [--set section.key=value]... [--no-rawlog] [--dump-config]
// The 6D RGB-D odometry alone (Figueroa et al. §3.1): writes <dir>/trajectory.txt (TUM format) and
// <dir>/odometry.rawlog (the input observations, each preceded by the visual-odometry action).
// With ground truth in the input it also prints ATE and RPE (1 s).
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include "vofusion/core/cli.h"
#include "vofusion/core/config.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/progress.h"
#include "vofusion/core/trajectory.h"
#include "vofusion/eval/trajectory_eval.h"
#include "vofusion/io/frame_source.h"
#include "vofusion/io/rawlog.h"
#include "vofusion/odometry/odometry_source.h"
#include "vofusion/sim/any_source.h"

using namespace vofusion;

namespace {
const char* kUsage =
    "usage: rgbd-odometry <tum_dir|in.rawlog|synthetic[:scene]> --out <dir> [options]\n"
    "  --config F         INI file ([odometry] [star] [narf] [brand] [matching] [motion]; see share/odometry.ini)\n"
    "  --max-frames N     process at most N frames\n"
    "  --depth-scale S    TUM-layout folders: depth PNG units per metre (default: the folder's camera file, else 5000)\n"
    "  --set S.K=V        override one key, e.g. --set odometry.motion_method=paper\n"
    "  --no-rawlog        write only trajectory.txt\n"
    "  --dump-config      print the defaults as INI and exit\n";

int body(int argc, char** argv) {
  const CommandLine cl(argc, argv, {"--out", "--config", "--max-frames", "--set", "--depth-scale"},
                       {"--no-rawlog", "--dump-config", "--help"});
  const OdometryParams defaults;
  const std::vector<ConfigSection> known{{"odometry", &defaults}};
  if (cl.flag("--help")) {
    std::cout << kUsage;
    return 0;
  }
  if (cl.flag("--dump-config")) {
    std::cout << dumpConfig(known);
    return 0;
  }
  const std::string out = cl.value("--out", ""), config = cl.value("--config", "");
  const std::vector<std::string> sets = cl.values("--set");
  const std::size_t max_frames = cl.count("--max-frames", 0, 1);
  const bool rawlog = !cl.flag("--no-rawlog");
  if (cl.positional().size() > 1) throw InputError(cl.positional()[1], "unexpected extra argument (see --help)");
  if (cl.positional().empty() || out.empty())
    throw InputError("usage", "expected <tum_dir|in.rawlog|synthetic[:scene]> --out <dir> (see --help)");
  const std::string input = cl.positional()[0];

  auto cfg = loadConfig(config);
  for (const std::string& s : sets) {
    const auto dot = s.find('.'), eq = s.find('=');
    if (dot == std::string::npos || eq == std::string::npos || eq < dot)
      throw InputError("--set " + s, "expected section.key=value");
    cfg.write(s.substr(0, dot), s.substr(dot + 1, eq - dot - 1), s.substr(eq + 1));
  }
  checkConfigKeys(cfg, config.empty() ? "--set" : config, known);
  OdometryParams params;
  try {
    params.loadFromConfigFile(cfg, "odometry");
  } catch (const InputError& e) {  // name the file the bad value came from
    throw InputError(config.empty() ? "--set" : config, e.what());
  }

  SourceOptions so;
  so.max_frames = max_frames;
  if (cl.value("--depth-scale")) so.depth_scale = cl.number("--depth-scale", 5000.0, 1.0, 1e6);
  auto source = openFrameSource(input, so);
  ensureWritableDirectory(out);
  const std::string traj_path = (std::filesystem::path(out) / "trajectory.txt").string();
  std::unique_ptr<RawlogWriter> writer;
  if (rawlog) {
    RawlogWriterOptions wo;
    wo.format = RawlogWriterOptions::Format::ActionsSensoryFrames;
    writer = std::make_unique<RawlogWriter>((std::filesystem::path(out) / "odometry.rawlog").string(), wo);
  }

  OdometrySource odo(params);
  Trajectory est, gt;
  Progress progress("odometry", source->size());
  Frame frame;
  StageTimes io_times;
  double odo_seconds = 0;
  std::size_t frames_with_depth = 0;
  while (true) {
    {
      ScopedStageTimer t(io_times, "read");
      if (!source->next(frame)) break;
    }
    const auto t0 = std::chrono::steady_clock::now();
    if (cv::countNonZero(frame.depth > 0) > 0) ++frames_with_depth;
    const OdometryResult r = odo.process(frame);
    odo_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    est.push_back({frame.timestamp, odo.pose()});
    if (frame.groundTruth) gt.push_back({frame.timestamp, *frame.groundTruth});
    if (writer) {
      ScopedStageTimer t(io_times, "write");
      if (auto a = odo.action()) writer->writeAction(*a);
      writer->write(frame);
    }
    char extra[128];
    std::snprintf(extra, sizeof extra, "kp %d  matches %d  inliers %d  failed %zu", r.keypoints, r.matches,
                  r.inliers, odo.failures());
    progress.update(odo.frames(), extra);
  }
  progress.finish();
  if (est.empty()) throw InputError(input, "no frames");
  if (frames_with_depth == 0) throw InputError(input, "no depth readings in any frame (all depth images are zero)");
  writeTumTrajectory(traj_path, est);
  if (writer) {
    if (!gt.empty()) writer->writeGroundTruth(gt);
    writer->commit();
  }

  // Per-stage breakdown (ms per frame); NARF runs beside the others unless narf_concurrent=false.
  const double n = double(odo.frames());
  std::fprintf(stderr, "per-stage time (ms/frame):");
  for (const auto& [stage, s] : odo.times().seconds) std::fprintf(stderr, "  %s %.1f", stage.c_str(), 1e3 * s / n);
  for (const auto& [stage, s] : io_times.seconds) std::fprintf(stderr, "  %s %.1f", stage.c_str(), 1e3 * s / n);
  std::fprintf(stderr, "\n");
  std::printf("frames %zu  failed %zu  odometry %.1f fps\n", odo.frames(), odo.failures(), n / odo_seconds);
  if (gt.size() >= 3) {
    const AteResult ate = computeAte(gt, est);
    const RpeResult rpe = computeRpe(gt, est, 1.0);
    if (ate.success) std::printf("ATE rmse %.4f m  (%zu poses)\n", ate.trans.rmse, ate.trans.count);
    if (rpe.success) std::printf("RPE(1s) rmse %.4f m  %.3f deg\n", rpe.trans.rmse, rpe.rot_deg.rmse);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) { return runApp(nullptr, body, argc, argv); }
