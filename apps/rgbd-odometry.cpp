// rgbd-odometry <tum_dir|in.rawlog|synthetic[:scene]> --out <dir> [--config f.ini] [--max-frames N]
//               [--depth-scale S] [--set section.key=value]... [--no-rawlog] [--strict] [--dump-config]
// The 6D RGB-D odometry alone (Figueroa et al. §3.1): writes <dir>/trajectory.txt (TUM format) and
// <dir>/odometry.rawlog (the input observations, each preceded by the visual-odometry action).
// With ground truth in the input it also prints ATE and RPE (1 s).
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/cli.h"
#include "vofusion/core/config.h"
#include "vofusion/live/live_loop.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/progress.h"
#include "vofusion/core/stop_signals.h"
#include "vofusion/core/trajectory.h"
#include "vofusion/eval/trajectory_eval.h"
#include "vofusion/io/frame_source.h"
#include "vofusion/io/rawlog.h"
#include "vofusion/io/skipping_source.h"
#include "vofusion/odometry/odometry_source.h"
#include "vofusion/pipeline/run_outputs.h"
#include "vofusion/sim/any_source.h"

using namespace vofusion;

namespace {
const char* kUsage =
    "usage: rgbd-odometry <tum_dir|in.rawlog|synthetic[:scene]> --out <dir> [options]\n"
    "  --config F         INI file ([odometry] [star] [narf] [brand] [matching] [motion]; see share/odometry.ini);\n"
    "                     a whole vofusion config is fine: its other sections' keys are checked for typos, not used\n"
    "  --max-frames N     process at most N frames; a synthetic scene is rendered in N frames (as rgbd-simulate\n"
    "                     --frames N: the same path, not its first N frames)\n"
    "  --depth-scale S    TUM-layout folders: depth PNG units per metre (default: the folder's camera file, else 5000)\n"
    "  --set S.K=V        override one key of the odometry's sections, e.g. --set odometry.motion_method=paper\n"
    "  --no-rawlog        write only trajectory.txt\n"
    "  --strict           stop at the first damaged frame or a damaged ground truth (default: skip the frame with\n"
    "                     a warning line, the first three with each problem, and go on)\n"
    "  --dump-config      print the defaults as INI and exit\n"
    "Ctrl-C or SIGTERM stops after the frame in hand and writes trajectory.txt and the rawlog so far (exit 130\n"
    "or 143; before the first frame nothing is written); a second one kills at once.\n";

// The command line's options besides --help, --dump-config and --depth-scale.
struct Args {
  std::string input, out, config;
  std::vector<std::string> sets;
  std::size_t max_frames = 0;
  bool rawlog = true;
};

Args parseArgs(const CommandLine& cl) {
  Args a;
  a.out = cl.value("--out", "");
  a.config = cl.value("--config", "");
  a.sets = cl.values("--set");
  a.max_frames = cl.count("--max-frames", 0, 1);
  a.rawlog = !cl.flag("--no-rawlog");
  if (cl.positional().size() > 1) throw InputError(cl.positional()[1], "unexpected extra argument (see --help)");
  if (cl.positional().empty() || a.out.empty())
    throw InputError("usage", "expected <tum_dir|in.rawlog|synthetic[:scene]> --out <dir> (see --help)");
  a.input = cl.positional()[0];
  return a;
}

// The odometry's parameters: defaults, then the --config file, then the --set overrides. Each is
// checked on its own, so that a bad key or value names where it was written; --set takes the odometry's
// sections only (nothing else is run).
OdometryParams loadParams(const Args& a, const std::vector<ConfigSection>& known) {
  auto cfg = loadConfig(a.config);
  checkConfigFile(cfg, a.config, withGrabSection(vofusionConfigSections()));  // a whole vofusion or vofusion-grab config is fine
  OdometryParams params;
  loadNamingOrigin(a.config, [&] { params.loadFromConfigFile(cfg, "odometry"); });
  if (a.sets.empty()) return params;
  mrpt::config::CConfigFileMemory sets;
  for (const std::string& text : a.sets) {
    const Setting s = parseSetting(text);
    for (auto* c : {&sets, &cfg}) c->write(s.section, s.key, s.value);
  }
  checkConfigKeys(sets, "--set", known);
  loadNamingOrigin("--set", [&] { params.loadFromConfigFile(cfg, "odometry"); });
  return params;
}

std::unique_ptr<RawlogWriter> openOdometryRawlog(const std::string& out) {
  RawlogWriterOptions wo;
  wo.format = RawlogWriterOptions::Format::ActionsSensoryFrames;
  return std::make_unique<RawlogWriter>((std::filesystem::path(out) / "odometry.rawlog").string(), wo);
}

// What a run over the input gathers besides the odometry's own state.
struct RunStats {
  Trajectory est, gt;
  StageTimes io_times;
  double odo_seconds = 0;
  std::size_t frames_with_depth = 0;
  int stopped_by = 0;  // SIGINT or SIGTERM when one stopped the loop before the input's end
};

// Runs the odometry over every frame of `source` (until Ctrl-C or SIGTERM), writing the frames and
// actions to `writer` (if any).
RunStats runOdometry(FrameSource& source, OdometrySource& odo, RawlogWriter* writer) {
  RunStats run;
  Progress progress("odometry", source.size());
  Frame frame;
  while (true) {
    {
      ScopedStageTimer t(run.io_times, "read");
      if (!source.next(frame)) break;  // read first: a stop during the last frame is no interruption
    }
    if (stopRequested()) {
      run.stopped_by = stopSignal();
      break;
    }
    const auto t0 = std::chrono::steady_clock::now();
    if (cv::countNonZero(frame.depth > 0) > 0) ++run.frames_with_depth;
    const OdometryResult r = odo.process(frame);
    run.odo_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    run.est.push_back({frame.timestamp, odo.pose()});
    if (frame.groundTruth) run.gt.push_back({frame.timestamp, *frame.groundTruth});
    if (writer) {
      ScopedStageTimer t(run.io_times, "write");
      if (auto a = odo.action()) writer->writeAction(*a);
      writer->write(frame);
    }
    char extra[128];
    std::snprintf(extra, sizeof extra, "kp %d  matches %d  inliers %d (%d keypoints)  failed %zu", r.keypoints,
                  r.matches, r.inliers, r.inlier_keypoints, odo.failures());
    progress.update(odo.frames(), extra);
  }
  const bool done_some = run.stopped_by && !run.est.empty();
  progress.finish(done_some ? std::string("(") + signalName(run.stopped_by) + ": writing what was done so far)" : "");
  return run;
}

// Per-stage breakdown (ms per frame); NARF runs beside the others unless narf_concurrent=false.
void printTimes(const OdometrySource& odo, const RunStats& run) {
  const double n = double(odo.frames());
  std::fprintf(stderr, "per-stage time (ms/frame):");
  for (const auto& [stage, s] : odo.times().seconds) std::fprintf(stderr, "  %s %.1f", stage.c_str(), 1e3 * s / n);
  for (const auto& [stage, s] : run.io_times.seconds) std::fprintf(stderr, "  %s %.1f", stage.c_str(), 1e3 * s / n);
  std::fprintf(stderr, "\n");
  std::printf("frames %zu  failed %zu  odometry %.1f fps\n", odo.frames(), odo.failures(), n / run.odo_seconds);
}

// ATE and RPE (1 s) against the ground truth, when the input has enough of it.
void printAccuracy(const Trajectory& gt, const Trajectory& est) {
  if (gt.size() >= 3) {
    const AteResult ate = computeAte(gt, est);
    const RpeResult rpe = computeRpe(gt, est, 1.0);
    if (ate.success) std::printf("ATE rmse %.4f m  (%zu poses)\n", ate.trans.rmse, ate.trans.count);
    if (rpe.success) std::printf("RPE(1s) rmse %.4f m  %.3f deg\n", rpe.trans.rmse, rpe.rot_deg.rmse);
  }
}

// The trajectory, and the rawlog with its ground truth when one is written: the recording's own where
// it lists one (a later run evaluates against it as TUM's tools do), else the frames'.
void writeOutputs(const std::string& traj_path, const RunStats& run, const Trajectory* recorded, RawlogWriter* writer) {
  // The trajectory goes in place after the rawlog, whose commit is what fails on a full disk: a run
  // that fails there leaves the earlier trajectory, never a new one beside an earlier rawlog.
  AtomicPath trajectory(traj_path);
  try {
    writeTumTrajectory(trajectory.tmp(), run.est);
  } catch (const InputError& e) {
    throw InputError(traj_path, e.problem());  // the temporary is gone by the time this is read
  }
  trajectory.prepare();  // its bytes on the disk before the rawlog replaces an earlier one
  if (writer) {
    if (recorded) writer->writeGroundTruth(*recorded);
    else if (!run.gt.empty()) writer->writeGroundTruth(run.gt);
    writer->commit();
  }
  trajectory.commit();
}

int body(int argc, char** argv) {
  const CommandLine cl(argc, argv, {"--out", "--config", "--max-frames", "--set", "--depth-scale"},
                       {"--no-rawlog", "--dump-config", "--strict", "--help"});
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
  const Args args = parseArgs(cl);
  const OdometryParams params = loadParams(args, known);

  SourceOptions so;
  so.max_frames = args.max_frames;
  if (cl.value("--depth-scale")) so.depth_scale = cl.number("--depth-scale", 5000.0, 1.0, 1e6);
  // A damaged frame costs that frame (io/skipping_source.h), unless --strict.
  so.strict = cl.flag("--strict");
  SkippingSource source(openFrameSource(args.input, so), so.strict, printWarning);
  ensureWritableDirectory(args.out);
  const std::string traj_path = (std::filesystem::path(args.out) / "trajectory.txt").string();
  std::unique_ptr<RawlogWriter> writer;
  if (args.rawlog) writer = openOdometryRawlog(args.out);

  OdometrySource odo(params);
  installStopSignals();  // the first Ctrl-C or SIGTERM writes what was done; a second one kills at once
  const RunStats run = runOdometry(source, odo, writer.get());
  if (run.est.empty() && run.stopped_by) {
    return stoppedBeforeTheFirstFrame("rgbd-odometry");
  }
  if (run.est.empty()) throw InputError(args.input, "no frames");
  if (run.frames_with_depth == 0 && !run.stopped_by)
    throw InputError(args.input, "no depth readings in any frame (all depth images are zero)");
  const Trajectory* recorded = source.recordedGroundTruth();
  writeOutputs(traj_path, run, recorded, writer.get());
  if (!source.skipped().empty()) std::fprintf(stderr, "%zu damaged frames skipped\n", source.skipped().size());
  printTimes(odo, run);
  // As TUM's tools evaluate it: against the recording's ground truth at its own stamps, where it lists one.
  printAccuracy(recorded ? *recorded : run.gt, run.est);
  return run.stopped_by ? 128 + run.stopped_by : 0;  // the shell's code for the signal: 130, 143
}

}  // namespace

int main(int argc, char** argv) { return runApp("rgbd-odometry", body, argc, argv); }
