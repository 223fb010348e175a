// vofusion: an RGB-D recording in, a trajectory, a clean coloured mesh and an MRPT 3D scene out.
//   vofusion [<tum_dir|in.rawlog|synthetic[:scene[:shake]]>] --out <dir> [--config f.ini]
//            [--mode joint|paper-handoff|kinfu|odometry] [--max-frames N] [--intrinsics fr1|fr2|fr3|ros|fx,fy,cx,cy]
//            [--depth-scale S] [--no-loop-closure] [--strict]
//            [--raw-mesh] [--dump-config] [--work-dir d] [--save-volume f] [--checkpoint-every S] [--resume f]
// With no input, the bundled synthetic recording (rendered on first run) is used.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <optional>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/cli.h"
#include "vofusion/core/config.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/progress.h"
#include "vofusion/core/stop_signals.h"
#include "vofusion/core/timing.h"
#include "vofusion/sim/default_recording.h"
#include "vofusion/io/frame_source.h"
#include "vofusion/io/prefetching_source.h"
#include "vofusion/io/skipping_source.h"
#include "vofusion/live/live_loop.h"
#include "vofusion/pipeline/reconstruction.h"
#include "vofusion/pipeline/run_outputs.h"
#include "vofusion/pipeline/run_session.h"
#include "vofusion/sim/any_source.h"

using namespace vofusion;

namespace {

const char* kUsage =
    "usage: vofusion [<tum_dir|in.rawlog|synthetic[:scene[:shake]]>] --out <dir> [--config f.ini]\n"
    "                [--mode joint|paper-handoff|kinfu|odometry] [--max-frames N] [--intrinsics fr1|fr2|fr3|ros|fx,fy,cx,cy]\n"
    "                [--depth-scale S] [--no-loop-closure] [--strict] [--raw-mesh] [--dump-config]\n"
    "                [--work-dir d] [--save-volume f] [--checkpoint-every S] [--resume f]\n"
    "  synthetic      a rendered recording with exact ground truth: scene room (default), corridor, bare_wall,\n"
    "                 loop, lookalike or longwalk, trajectory smooth (default) or shake (rgbd-simulate --help)\n"
    "  --max-frames   process at most N frames; a synthetic scene is rendered in N frames (as rgbd-simulate\n"
    "                 --frames N: the same path, not its first N frames)\n"
    "  --strict       stop at the first damaged frame (missing or corrupt image, unreadable record), at a\n"
    "                 recording cut short or at a damaged ground truth. By default a damaged frame is skipped\n"
    "                 with a line naming its file (the first three with each problem), counted in summary.json\n"
    "                 (frames_skipped), and the run goes on; a damaged ground truth costs the evaluation\n"
    "  --depth-scale  TUM-layout folders: depth PNG units per metre (default: the folder's intrinsics.txt /\n"
    "                 camera.yaml, else 5000 as TUM; 1000 for millimetres: RealSense, Azure Kinect, Open3D)\n"
    "  --no-loop-closure  keyframes, place recognition and the pose graph off ([loop] enabled = false);\n"
    "                 trajectory.txt is then the tracked trajectory, its centres smoothed\n"
    "  --work-dir     folder of the spill files of bricks that left the volume beyond [kinfu] world_cache_mib\n"
    "                 and of keyframes beyond [loop] keyframe_cache_mib (default <out>/.tmp; each file is\n"
    "                 deleted as soon as it is created, so it never stays)\n"
    "  --save-volume  at the end, the map (volume + world model) and the camera pose to file f\n"
    "  --checkpoint-every  every S seconds of the frame loop, after its last frame (before the meshing)\n"
    "                 and at Ctrl-C or SIGTERM, the whole run so far to <out>/checkpoint, atomically (the map,\n"
    "                 every stage's state, the position in the input); deleted when the run ends with its\n"
    "                 outputs written\n"
    "  --resume       a checkpoint: the same command goes on from it, to the trajectory and mesh an\n"
    "                 uninterrupted run gives. A map saved with --save-volume: the camera continues from the\n"
    "                 saved pose, the map keeps its frame (the input should continue where the saved run stopped)\n"
    "Ctrl-C or SIGTERM (a batch system's time limit) stops after the frame in hand and writes what was built\n"
    "(summary.json: interrupted, stop_signal; exit 130 or 143). Before the first frame it stops the run with\n"
    "nothing written; after the last, the outputs are written as usual. A second one kills at once.\n";

// What one run was asked for: the command line and the configuration it names, checked.
struct RunPlan {
  std::string out_dir, config_path, input, default_work;
  mrpt::config::CConfigFileMemory cfg;
  TrackingMode mode = TrackingMode::Joint;
  OutputParams out_params;
  MeshCleanParams mesh_params;
  SourceOptions src_opts;
  std::optional<std::string> resume, save_volume;
  bool strict = false;  // stop at the first damaged frame
  double checkpoint_every = 0.0;  // s; 0: no checkpoints
  std::string checkpoint_path;    // <out>/checkpoint
  std::string origin;             // what a checkpoint of this run is for (checked when resuming)
};

// What a checkpoint belongs to (RunSession::checkpointOrigin), and how the frames are read.
std::string runOrigin(const RunPlan& plan, const CommandLine& cl) {
  std::string o = RunSession::checkpointOrigin(plan.input, plan.mode, plan.cfg);
  for (const char* option : {"--intrinsics", "--depth-scale"})
    if (cl.value(option)) o += std::string(option) + " " + *cl.value(option) + "\n";
  // A synthetic input's length shapes its world and path (the loop scene's laps): another length is
  // another recording, though every frame's timestamp is the same.
  if (plan.input.rfind("synthetic", 0) == 0 && !std::filesystem::exists(plan.input))
    o += "--max-frames " + std::to_string(plan.src_opts.max_frames) + "\n";
  return o;
}

// The input's frames, read ahead on another thread, damaged ones skipped unless --strict.
struct Input {
  std::unique_ptr<PrefetchingSource> source;
  const SkippingSource* frames = nullptr;  // owned by source: the frames skipped
};

// warn: one line per frame skipped (false for the second reading of the recording, re-fusion).
Input openInput(const RunPlan& plan, bool warn) {
  auto skipping = std::make_unique<SkippingSource>(openFrameSource(plan.input, plan.src_opts), plan.strict,
                                                   warn ? printWarning : nullptr);
  Input in;
  in.frames = skipping.get();
  in.source = std::make_unique<PrefetchingSource>(std::move(skipping));
  return in;
}

// The configuration file with the command line's overrides; out-of-range values name the file.
void loadConfiguration(const CommandLine& cl, RunPlan& plan) {
  plan.cfg = loadConfig(plan.config_path);
  // A live run's --config (rawlog-grabber's sections beside ours) is checked in our sections, as
  // vofusion-grab checked it: the run resumes from its checkpoint with the file it was started with.
  checkConfigFile(plan.cfg, plan.config_path, withGrabSection(vofusionConfigSections()));
  auto& cfg = plan.cfg;
  if (cl.flag("--no-loop-closure")) cfg.write("loop", "enabled", false);
  // The world model's spill file: --work-dir, else [kinfu] work_dir, else <out>/.tmp.
  plan.default_work = (std::filesystem::path(plan.out_dir) / ".tmp").string();
  if (!cl.value("--work-dir"))  // the file's, before ours replaces it
    loadNamingOrigin(plan.config_path, [&] { checkBareValue(cfg, "kinfu", "work_dir"); });
  if (cl.value("--work-dir")) cfg.write("kinfu", "work_dir", *cl.value("--work-dir"));
  else if (const std::string w = cfg.read_string("kinfu", "work_dir", "auto"); w.empty() || w == "auto")
    cfg.write("kinfu", "work_dir", plan.default_work);
  loadNamingOrigin(plan.config_path, [&] {
    plan.out_params.loadFromConfigFile(cfg, "output");
    plan.mesh_params.loadFromConfigFile(cfg, "mesh");
    checkReconstructionValues(cfg);
    LiveOptions().loadFromConfigFile(cfg, "vofusion-grab");  // unused here, its values checked as vofusion-grab does
  });
  if (cl.flag("--raw-mesh") && !plan.out_params.write_mesh)  // it was left out without a word
    throw InputError("--raw-mesh", "takes effect with [output] mesh = true only (" + plan.config_path + " has mesh = false)");
  if (cl.flag("--raw-mesh")) plan.out_params.save_raw_mesh = true;
}

// --save-volume's file is written after the whole run: a path that cannot be one fails now.
void checkMapPath(const std::string& path) {
  if (path.empty()) throw InputError("usage", "--save-volume needs a file's path");
  std::error_code ec;
  const bool folder = std::filesystem::is_directory(path, ec);
  if (ec && ec != std::errc::no_such_file_or_directory) throw InputError(path, ec.message());
  if (folder) throw InputError(path, "is a folder (--save-volume wants a file's path)");
  if (std::filesystem::path(path).filename().empty())
    throw InputError(path, "names a folder, not a file (--save-volume wants a file's path)");
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  ensureWritableDirectory(parent.empty() ? "." : parent.string());
}

// A run that checkpoints into a folder holding a checkpoint it does not go on from would replace it at
// its first checkpoint and delete its own at the end: an earlier run's, which --resume could still
// finish, would be lost.
void refuseToReplaceACheckpoint(const RunPlan& plan) {
  std::error_code ec;
  if (plan.checkpoint_every <= 0 || !std::filesystem::exists(std::filesystem::symlink_status(plan.checkpoint_path, ec)))
    return;
  if (plan.resume && std::filesystem::equivalent(*plan.resume, plan.checkpoint_path, ec)) return;
  throw InputError(plan.checkpoint_path, "an earlier run's checkpoint, which --checkpoint-every would replace: go on from it "
                                         "with --resume " + plan.checkpoint_path + ", or delete it to start over");
}

RunPlan planRun(const CommandLine& cl) {
  if (cl.positional().size() > 1) throw InputError("usage", "more than one input given");
  const auto out_dir = cl.value("--out");
  if (!out_dir) throw InputError("usage", "--out <dir> is required");
  RunPlan plan;
  plan.out_dir = *out_dir;
  plan.config_path = cl.value("--config", "");
  loadConfiguration(cl, plan);
  plan.mode = parseTrackingMode(cl.value("--mode", "joint"));
  plan.src_opts.max_frames = cl.count("--max-frames", 0, 1);  // not given: every frame
  plan.src_opts.intrinsics = cl.value("--intrinsics");
  if (cl.value("--depth-scale")) plan.src_opts.depth_scale = cl.number("--depth-scale", 5000.0, 1.0, 1e6);
  plan.input = cl.positional().empty() ? defaultRecording() : cl.positional()[0];
  if (stopRequested()) return plan;  // while rendering the default recording: body() says so
  plan.resume = cl.value("--resume");
  plan.strict = plan.src_opts.strict = cl.flag("--strict");
  plan.save_volume = cl.value("--save-volume");
  if (plan.save_volume) checkMapPath(*plan.save_volume);
  plan.checkpoint_every = cl.numberFrom("--checkpoint-every", 0.0, 0.0, 1e6);
  plan.checkpoint_path = (std::filesystem::path(plan.out_dir) / "checkpoint").string();
  refuseToReplaceACheckpoint(plan);
  refuseWritesOverTheInput(plan.input, runOutputPaths(plan.out_dir), plan.save_volume);
  plan.origin = runOrigin(plan, cl);
  return plan;
}

struct FrameLoop {
  std::size_t done = 0, frames_with_depth = 0;
  // Positions of the input read: its frames processed, and those skipped as damaged or dropped live,
  // which the progress counts against the input's length (done alone never reached its end).
  std::size_t read = 0;
  int stop_signal = 0;   // SIGINT or SIGTERM when one stopped the loop before the input's end
  bool interrupted() const { return stop_signal != 0; }
  std::optional<std::size_t> stopped_at;  // interrupted: the frame read and not processed (its position)
  double seconds = 0.0;  // of the frame loop, a resumed checkpoint's included
  std::size_t checkpoints = 0;
  double checkpoint_seconds = 0.0;  // writing them
  std::string checkpoint_error;     // why one could not be written (no more were tried)
};

// Why ICP was refused most often: what a run that tracked no frame tells the user.
std::string mostFrequentRejection(const Reconstruction& rec) {
  const auto& why = rec.icpRejections();
  const auto most = std::max_element(why.begin(), why.end(), [](const auto& a, const auto& b) { return a.second < b.second; });
  return most == why.end() ? "no reason recorded" : toString(most->first);
}

// A run that fails once its frames are read: none had depth, or none was tracked. Resumed from a
// checkpoint it would fail again, and the checkpoint would bar the same folder to the next run.
bool failsAfterItsFrames(const FrameLoop& loop, const Reconstruction& rec) {
  return !loop.interrupted() && (loop.frames_with_depth == 0 || rec.lostFrames() >= loop.done);
}

// --resume <checkpoint>: the run's state from it, and the frames it had processed read again for the
// outputs (poses.rawlog, ground truth): the loop then goes on with the next frame.
FrameLoop resumeCheckpoint(const RunPlan& plan, FrameSource& source, RunSession& run) {
  const RunSession::Checkpoint c = run.resume(*plan.resume, plan.origin);
  Progress progress("vofusion [resuming: reading the checkpoint's frames again]", c.frames);
  FrameLoop loop;
  Frame frame;
  while (run.replaying() && !stopRequested()) {
    if (!source.next(frame))
      throw InputError(*plan.resume, "the input ends before frame " + std::to_string(c.frames) + ", where the checkpoint was made");
    loop.read = std::max(loop.read, std::size_t(frame.index) + 1);
    if (!run.replay(frame)) continue;
    if (cv::countNonZero(frame.depth > 0) > 0) ++loop.frames_with_depth;
    progress.update(++loop.done);
  }
  progress.finish();
  loop.seconds = c.seconds;
  return loop;
}

// Every frame of the source through the run, with progress and checkpoints, until the end, Ctrl-C or
// SIGTERM.
void reconstructFrames(const RunPlan& plan, FrameSource& source, RunSession& run, FrameLoop& loop) {
  const Reconstruction& rec = run.reconstruction();
  Progress progress("vofusion [" + toString(plan.mode) + "]", source.size());
  progress.startAt(std::max(loop.done, loop.read));
  const double before = loop.seconds;
  double last_checkpoint = 0.0;
  // Frames tracked at the last checkpoint (the frame held back is not in one): a resumed run's
  // checkpoint holds those it went on from.
  std::size_t checkpointed_at = loop.done > 0 ? rec.framesProcessed() : std::size_t(-1);
  const auto checkpoint = [&] {
    // Not before the first tracked frame, nor twice over the same ones (the frame held back is in none).
    const std::size_t tracked = rec.framesProcessed();
    if (!loop.checkpoint_error.empty() || tracked == 0 || tracked == checkpointed_at) return;
    const double start = progress.elapsedSeconds();
    try {
      run.saveCheckpoint(plan.checkpoint_path, plan.origin, before + start);
    } catch (const InputError& e) {
      // A checkpoint is a spare (the earlier one stays whole): a full disk costs the checkpoints, not
      // the run, nor what a stop writes.
      loop.checkpoint_error = e.what();
      printWarning(loop.checkpoint_error + "; no more checkpoints this run, which goes on without them");
      return;
    }
    checkpointed_at = rec.framesProcessed();
    last_checkpoint = progress.elapsedSeconds();
    loop.checkpoint_seconds += last_checkpoint - start;
    ++loop.checkpoints;
  };
  Frame frame;
  while (true) {
    bool more = false;
    try {
      more = source.next(frame);
    } catch (const InputError& e) {
      // --strict ends the run at a damaged frame; one met after a stop is past the frame the stop ends
      // at, and the stop writes what was built (it ended the run with nothing written).
      if (!stopRequested()) throw;
      printWarning(std::string(e.what()) + " (read after the stop, which ends the run before it)");
      loop.stop_signal = stopSignal();
      loop.stopped_at = loop.read;
      break;
    }
    if (!more) {  // read first: a stop during the last frame is no interruption
      loop.read = std::max(loop.read, source.size());  // the input's end: every frame read, the damaged last ones too
      progress.update(std::max(loop.done, loop.read));
      break;
    }
    loop.read = std::max(loop.read, std::size_t(frame.index) + 1);
    if (stopRequested()) {
      loop.stop_signal = stopSignal();
      loop.stopped_at = frame.index;
      break;
    }
    if (cv::countNonZero(frame.depth > 0) > 0) ++loop.frames_with_depth;
    run.process(frame);
    ++loop.done;
    if (plan.checkpoint_every > 0 && progress.elapsedSeconds() - last_checkpoint >= plan.checkpoint_every) checkpoint();
    std::string status = "fallbacks " + std::to_string(rec.fallbacks()) + "  lost " + std::to_string(rec.lostFrames());
    if (rec.loopCloser()) status += "  loops " + std::to_string(rec.loopCloser()->activeLoops());
    progress.update(std::max(loop.done, loop.read), status);
  }
  // The last frame given is held back (Reconstruction::push). At the input's end it is tracked now, without
  // a next one, before the last checkpoint; after a stop the checkpoint comes first and leaves it out, so
  // that the resumed run reads it again and refits it with the frame after it, as an uninterrupted run does.
  if (!loop.interrupted()) run.flush();
  const bool built = loop.interrupted() && loop.done > 0;
  const double frame_loop_seconds = progress.elapsedSeconds();  // the last checkpoint's writing is no frame's
  // --resume goes on from here: after a stop, and after the last frame, where the loop-closed
  // re-fusion and the meshing still come (a crash or a batch system's kill there would otherwise cost
  // every frame since the last periodic checkpoint; resumed, the run goes straight to its end phase).
  // Not after a run that fails there.
  if (loop.done > 0 && !failsAfterItsFrames(loop, rec) && plan.checkpoint_every > 0 &&
      rec.framesProcessed() != checkpointed_at)
    checkpoint();
  run.flush();  // after a stop: the outputs written now hold it
  progress.finish(built ? std::string("(") + signalName(loop.stop_signal) + ": writing what was built so far)" : "");
  loop.seconds = before + frame_loop_seconds;
}

// A run whose frames hold no depth, or none of which was tracked, has nothing to write: said in one line
// (an interrupted one writes what it has).
void refuseUntrackedRun(const FrameLoop& loop, const Reconstruction& rec, const std::string& input) {
  if (loop.interrupted()) return;
  if (loop.frames_with_depth == 0) throw InputError(input, "no depth readings in any frame (all depth images are zero)");
  if (rec.lostFrames() >= loop.done)
    throw InputError(input, "no frame was tracked, all " + std::to_string(loop.done) + " lost (" + mostFrequentRejection(rec) + ")");
}

// What summary.json tells of the run beyond the reconstruction: input, timing, stop, checkpoints.
RunInfo runInfoOf(const RunPlan& plan, const FrameLoop& loop, const FrameSource& source, double before_frames,
                  std::size_t resumed_at) {
  RunInfo info;
  info.input = source.name();
  info.config = plan.config_path;
  info.interrupted = loop.interrupted();
  if (loop.interrupted()) info.extra["stop_signal"] = signalName(loop.stop_signal);
  info.seconds = loop.seconds;
  if (const Trajectory* gt = source.recordedGroundTruth()) info.recorded_ground_truth = *gt;
  if (std::isfinite(before_frames)) info.extra["seconds_before_frames"] = before_frames;
  if (plan.checkpoint_every > 0 || resumed_at)
    info.extra["checkpoints"] = {{"every_seconds", plan.checkpoint_every}, {"written", loop.checkpoints},
                                 {"seconds_writing", loop.checkpoint_seconds}, {"resumed_at_frame", resumed_at}};
  if (!loop.checkpoint_error.empty()) info.extra["checkpoints"]["error"] = loop.checkpoint_error;
  return info;
}

// The run's last line: frames, fps, fallbacks, lost and skipped frames, ATE.
void printOutcome(const FrameLoop& loop, const Reconstruction& rec, const nlohmann::json& summary) {
  std::fprintf(stderr, "vofusion: %zu frames, %.1f fps, %zu fallbacks, %zu lost", loop.done, summary.value("fps", 0.0),
               rec.fallbacks(), rec.lostFrames());
  if (const std::size_t skipped = summary.value("frames_skipped", std::size_t(0))) std::fprintf(stderr, ", %zu skipped", skipped);
  if (summary.contains("ate")) std::fprintf(stderr, ", ATE RMSE %.4f m", summary["ate"]["rmse"].get<double>());
  std::fprintf(stderr, "\n");
}

// Once the outputs are whole: a checkpoint this run wrote or went on from has nothing left to resume,
// unless the map could not be saved (`map_failed`): resumed from it, the run writes the map without its
// frames again. Another run's in the same folder (another input, configuration or length) is left for
// its --resume.
void removeSpentFiles(const RunPlan& plan, const FrameLoop& loop, bool map_failed) {
  std::error_code ec;
  const bool resumed_from_it = plan.resume && std::filesystem::equivalent(*plan.resume, plan.checkpoint_path, ec);
  const bool ours = loop.checkpoints > 0 || resumed_from_it;
  if (ours && map_failed && std::filesystem::exists(plan.checkpoint_path, ec)) {
    const std::optional<RunSession::Checkpoint> kept = RunSession::peek(plan.checkpoint_path);
    const std::string again = kept && kept->frames == loop.done
                                  ? "without tracking the frames again"
                                  : "(the frames after its " + std::to_string(kept ? kept->frames : 0) + " are tracked again)";
    std::fprintf(stderr, "vofusion: %s is kept: --resume it with --save-volume to write the map %s\n",
                 plan.checkpoint_path.c_str(), again.c_str());
  } else if (!loop.interrupted() && ours)
    std::filesystem::remove(plan.checkpoint_path, ec);
  std::filesystem::remove(plan.default_work, ec);  // only when empty: the spill file was never a name there
}

int body(int argc, char** argv) {
  const CommandLine cl(argc, argv, {"--out", "--config", "--mode", "--max-frames", "--intrinsics", "--depth-scale", "--work-dir",
                        "--save-volume", "--resume", "--checkpoint-every"},
                       {"--raw-mesh", "--dump-config", "--no-loop-closure", "--strict", "--help"});
  if (cl.flag("--help")) {
    std::cout << kUsage;
    return 0;
  }
  if (cl.flag("--dump-config")) {
    std::cout << dumpConfig(vofusionConfigSections());
    return 0;
  }
  installStopSignals();  // what a stop does here: kUsage's last lines
  const RunPlan plan = planRun(cl);
  if (stopRequested()) return stoppedBeforeTheFirstFrame("vofusion", "");  // while rendering the default recording
  Input input = openInput(plan, true);
  auto& source = input.source;
  RunSession run(plan.cfg, plan.mode, plan.out_dir, plan.out_params, plan.mesh_params);
  std::fprintf(stderr, "vofusion: %s, mode %s, %zu frames -> %s\n", source->name().c_str(), toString(plan.mode).c_str(),
               source->size(), plan.out_dir.c_str());
  FrameLoop loop;
  if (plan.resume && RunSession::isCheckpoint(*plan.resume)) loop = resumeCheckpoint(plan, *source, run);
  else if (plan.resume) run.reconstruction().resumeVolume(*plan.resume);
  const std::size_t resumed_at = loop.done;
  // Start-up (libraries, the input opened, a checkpoint read again): not part of the frame loop, nor
  // of the time after its last frame.
  const double before_frames = secondsSinceProcessStart();
  if (!run.replaying()) reconstructFrames(plan, *source, run, loop);
  if (stopRequested() && (loop.done == 0 || run.replaying())) {  // stopped while starting
    return stoppedBeforeTheFirstFrame("vofusion", plan.resume ? *plan.resume + " is kept" : "");
  }
  if (loop.done == 0) throw InputError(source->name(), "no frames to process");
  if (failsAfterItsFrames(loop, run.reconstruction()) && loop.checkpoints > 0) {
    std::error_code ec;
    std::filesystem::remove(plan.checkpoint_path, ec);  // its own periodic one
  }
  refuseUntrackedRun(loop, run.reconstruction(), source->name());
  RunInfo info = runInfoOf(plan, loop, *source, before_frames, resumed_at);
  source->stop();  // the read ahead of a stopped run is done before its skipped frames are counted
  reportSkipped(*input.frames, info, loop.stopped_at);
  source.reset();
  RunSession::Reopen reopen;  // an interrupted run is not fused again: the user asked it to stop
  if (!loop.interrupted())
    reopen = [&]() -> std::unique_ptr<FrameSource> { return openInput(plan, false).source; };
  else
    info.no_rereading = "interrupted";
  // A stop asked for now has no frame in hand: the outputs are written whatever it says.
  const ScopedStoppingMessage writing("\nthe frames are done and their outputs are being written (Ctrl-C again to kill)\n");
  const auto summary = run.finish(info, reopen, plan.save_volume);
  const Reconstruction& rec = run.reconstruction();
  if (plan.out_params.write_mesh && rec.mapNeedsReintegration() && !rec.reintegrated() && loop.interrupted())
    std::fprintf(stderr, "vofusion: loops corrected the trajectory, but the run was stopped before the map was fused "
                         "again at the corrected poses: the mesh keeps the tracked poses\n");
  printOutcome(loop, rec, summary);
  removeSpentFiles(plan, loop, run.mapFailure() != nullptr);
  if (run.mapFailure()) std::rethrow_exception(run.mapFailure());  // one line naming the map; exit 2
  return loop.interrupted() ? 128 + loop.stop_signal : 0;  // as the shell reports a signal: 130, 143
}

}  // namespace

int main(int argc, char** argv) {
  return runApp("vofusion", body, argc, argv);
}
