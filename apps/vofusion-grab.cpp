// vofusion-grab: record an RGB-D sensor (MRPT hwdrivers, e.g. COpenNI2Sensor) into a rawlog, and
// optionally reconstruct live. --replay plays a TUM folder or rawlog through the same live path.
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <chrono>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/cli.h"
#include "vofusion/core/config.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/heap.h"
#include "vofusion/core/progress.h"
#include "vofusion/core/stop_signals.h"
#include "vofusion/io/frame_source.h"
#include "vofusion/io/rawlog.h"
#include "vofusion/io/skipping_source.h"
#include "vofusion/live/live_loop.h"
#include "vofusion/live/live_source.h"
#include "vofusion/live/live_viewer.h"
#include "vofusion/core/triangle_mesh.h"
#include "vofusion/pipeline/reconstruction.h"
#include "vofusion/pipeline/run_outputs.h"
#include "vofusion/pipeline/run_session.h"
#include "vofusion/sim/any_source.h"

namespace fs = std::filesystem;
using namespace vofusion;

namespace {

// Loops accepted since the last call, for the live window: a line between the two keyframes'
// tracked poses (where the window drew the path) and a status line.
void addNewLoops(const loop::LoopCloser& lc, std::size_t& shown, LiveView& view) {
  const std::vector<loop::LoopRecord> loops = lc.loops();
  if (loops.size() <= shown) return;
  const std::vector<loop::KeyframePose> kf = lc.keyframes();
  auto pose = [](const Eigen::Isometry3d& T) { return mrpt::poses::CPose3D(mrpt::math::CMatrixDouble44(T.matrix())); };
  for (; shown < loops.size(); ++shown) {
    const loop::LoopRecord& l = loops[shown];
    if (l.from_keyframe < kf.size() && l.to_keyframe < kf.size())
      view.new_loops.push_back({pose(kf[l.from_keyframe].tracked), pose(kf[l.to_keyframe].tracked)});
    char line[200];
    std::snprintf(line, sizeof line, "loop closed: frames %zu and %zu, correction %.1f cm %.1f deg (%zu loops)",
                  l.from_frame, l.to_frame, 100.0 * l.correction_m, l.correction_deg, loops.size());
    view.loop_status = line;
  }
}

const char* kSection = "vofusion-grab";  // our own keys; sensor sections belong to MRPT

const char* kUsage =
    "usage: vofusion-grab [--config grab.ini] [--sensor SECTION] [--out DIR] [--live] [--no-gui]\n"
    "                     [--replay TUM_DIR|FILE.rawlog [--depth-scale S]] [--max-frames N] [--queue N] [--speed X]\n"
    "                     [--mode joint|paper-handoff|kinfu|odometry] [--no-record] [--simulate-work-ms MS]\n"
    "                     [--checkpoint-every S] [--verbose] [--dump-config]\n"
    "  Records the sensor of --config (default <source>/share/grab-openni2.ini; none with --replay) to\n"
    "  DIR/grab.rawlog (DIR default ./grab) until\n"
    "  Ctrl-C, SIGTERM or --max-frames (0: no limit, as the config's max_frames = 0; a second\n"
    "  Ctrl-C or SIGTERM kills at once). --live also\n"
    "  reconstructs online (window unless --no-gui) and writes the same outputs as vofusion into DIR.\n"
    "  --replay plays a recording at its recorded rate instead of a sensor. Frames the processing\n"
    "  cannot keep up with are dropped (oldest first) and counted; the recording itself never drops.\n"
    "  DIR/grab-summary.txt holds the counts.\n"
    "  --checkpoint-every  --live with a recording: every S seconds (default 60, 0 = never) and after the\n"
    "  last frame, the whole reconstruction to DIR/checkpoint. After a crash, `vofusion DIR/grab.rawlog\n"
    "  --out DIR --resume DIR/checkpoint` finishes it from there; a session that ends normally deletes it.\n"
    "  An earlier run's checkpoint in DIR is never replaced: the session does not start.\n";


struct Args {
  std::string config, sensor, out, replay, mode;
  double depth_scale = 0.0;  // --replay of a TUM-layout folder: depth units per metre (0 = its camera file / 5000)
  bool live, gui, record, verbose, dump;
  std::optional<std::size_t> max_frames, queue;
  std::optional<double> speed;
  int work_ms;
  double checkpoint_every;  // s; 0: none
};

// --live with a recording: a checkpoint a minute. One stops the frame loop ~0.3 s for a desk-sized
// map (xyz_first300: frames dropped then, never recorded ones); a crash costs at most a minute of
// reconstruction, done again offline from grab.rawlog.
constexpr double kDefaultCheckpointSeconds = 60.0;

Args parseArgs(int argc, char** argv) {
  const CommandLine cl(argc, argv,
                       {"--config", "--sensor", "--out", "--replay", "--mode", "--max-frames", "--queue", "--speed",
                        "--simulate-work-ms", "--depth-scale", "--checkpoint-every"},
                       {"--live", "--no-gui", "--no-record", "--verbose", "--dump-config", "--help"});
  if (cl.flag("--help")) {
    std::fputs(kUsage, stdout);
    std::exit(0);
  }
  if (!cl.positional().empty()) throw InputError("usage", "unexpected argument '" + cl.positional()[0] + "' (see --help)");
  Args a;
  a.config = cl.value("--config", "");
  a.sensor = cl.value("--sensor", "");
  a.out = cl.value("--out", "grab");
  a.replay = cl.value("--replay", "");
  if (cl.value("--depth-scale")) a.depth_scale = cl.number("--depth-scale", 5000.0, 1.0, 1e6);
  a.mode = cl.value("--mode", "joint");
  a.live = cl.flag("--live");
  a.gui = !cl.flag("--no-gui");
  a.record = !cl.flag("--no-record");
  a.verbose = cl.flag("--verbose");
  a.dump = cl.flag("--dump-config");
  // 0 as in the config's max_frames: no limit (lifts one the config sets).
  if (cl.value("--max-frames")) a.max_frames = cl.count("--max-frames", 0);
  if (cl.value("--queue")) a.queue = cl.count("--queue", 0);
  if (cl.value("--speed")) a.speed = cl.number("--speed", 1.0);
  a.work_ms = int(cl.count("--simulate-work-ms", 0));
  if (a.speed && !LiveOptions::replaySpeedInRange(*a.speed))
    throw InputError("--speed", "must be 0 (as fast as frames load) or in [0.001, 1000] x the recorded rate");
  // Options that would change nothing are refused, as rgbd-simulate does: the run they were meant for
  // is not the one asked for.
  if (cl.value("--mode") && !a.live) throw InputError("--mode", "needs --live (without it nothing is reconstructed)");
  if (a.replay.empty())
    for (const char* replay_only : {"--depth-scale", "--speed"})
      if (cl.value(replay_only)) throw InputError(replay_only, "needs --replay (a sensor gives its own)");
  if (!a.replay.empty() && !a.sensor.empty())
    throw InputError("--sensor", "with --replay the frames come from the recording, not a sensor: give one of the two");
  a.checkpoint_every = a.live && a.record ? kDefaultCheckpointSeconds : 0.0;
  if (cl.value("--checkpoint-every")) {
    if (!a.live || !a.record)
      throw InputError("--checkpoint-every", "needs --live and the recording (a checkpoint is resumed from grab.rawlog)");
    a.checkpoint_every = cl.numberFrom("--checkpoint-every", 0.0, 0.0, 1e6);
  }
  if (a.queue && !(*a.queue >= 1 && *a.queue <= LiveOptions::kMostQueued))
    throw InputError("--queue", "must be in [1, 1000] frames (each waiting frame holds ~2 MB)");
  if (!a.live && !a.record) throw InputError("--no-record", "without --live there is nothing left to do");
  return a;
}

std::string summaryText(const LiveStats& s, const std::string& source, std::size_t recorded, std::size_t queue,
                        std::size_t skipped) {
  std::ostringstream o;
  o << "source: " << source << "\n"
    << "frames_played: " << s.played << "\n"
    << "frames_skipped: " << skipped << "\n"
    << "frames_processed: " << s.processed << "\n"
    << "frames_dropped: " << s.dropped << "\n"
    << "frames_recorded: " << recorded << "\n"
    << "queue_capacity: " << queue << "\n"
    << "max_queue: " << s.max_queue << "\n"
    << "seconds: " << s.seconds << "\n"
    << "played_fps: " << s.playedFps() << "\n"
    << "processed_fps: " << s.processedFps() << "\n"
    << "stop: " << stopReasonName(s.stop) << "\n"
    << "error: " << s.error << "\n";
  return o.str();
}

// What a grab was asked for: the sensor's configuration file (rawlog-grabber format) with our
// [vofusion-grab], [output] and [mesh] sections, checked; reconstruction settings fail now, not mid-run.
struct GrabPlan {
  std::string config;
  mrpt::config::CConfigFileMemory cfg;
  LiveOptions opts;
  OutputParams out_params;
  MeshCleanParams mesh_params;
  std::optional<TrackingMode> mode;  // --live
};

GrabPlan planGrab(const Args& args) {
  GrabPlan plan;
  plan.config = args.config;
  if (plan.config.empty() && args.replay.empty()) plan.config = std::string(VOFUSION_SHARE_DIR) + "/grab-openni2.ini";
  plan.cfg = loadConfig(plan.config);
  loadNamingOrigin(plan.config, [&] { checkBareValue(plan.cfg, "kinfu", "work_dir"); });
  checkKnownSections(plan.cfg, plan.config, withGrabSection(vofusionConfigSections()));  // the sensor sections are MRPT's drivers'
  loadNamingOrigin(plan.config, [&] {
    plan.opts.loadFromConfigFile(plan.cfg, kSection);
    plan.out_params.loadFromConfigFile(plan.cfg, "output");
    plan.mesh_params.loadFromConfigFile(plan.cfg, "mesh");
    if (args.live) checkReconstructionValues(plan.cfg);  // now, before the recording is created
  });
  if (args.max_frames) plan.opts.max_frames = *args.max_frames;
  if (args.queue) plan.opts.queue_capacity = *args.queue;
  if (args.speed) plan.opts.replay_speed = *args.speed;
  if (args.live) plan.mode = parseTrackingMode(args.mode, "--mode");
  // A replay of a run's poses.rawlog into that run's folder: the live run's would replace it.
  if (args.live && !args.replay.empty()) refuseWritesOverTheInput(args.replay, runOutputPaths(args.out), std::nullopt);
  return plan;
}

// What frames come from: a replay, or the sensor.
struct GrabSource {
  std::unique_ptr<LiveSource> live;
  const SkippingSource* replayed = nullptr;  // a replay's frames (owned by `live`), with the damaged ones it skipped
  std::size_t skipped() const { return replayed ? replayed->skipped().size() : 0; }
  // A replay's own ground truth (FrameSource::recordedGroundTruth), nullptr for a sensor.
  const Trajectory* recordedGroundTruth() const { return replayed ? replayed->recordedGroundTruth() : nullptr; }
};

// A replay, or the sensor (fails here, in one line, when none can be opened); `label` gets the
// sensor's label for the recording.
GrabSource openGrabSource(const Args& args, const GrabPlan& plan, std::string& label) {
  GrabSource src;
  if (!args.replay.empty()) {
    SourceOptions so;
    so.depth_scale = args.depth_scale;
    // A damaged frame of the recording costs that frame, as in vofusion (io/skipping_source.h).
    auto frames = std::make_unique<SkippingSource>(openFrameSource(args.replay, so), false, printWarning);
    src.replayed = frames.get();
    src.live = std::make_unique<ReplaySource>(std::move(frames), plan.opts.replay_speed);
    return src;
  }
  const std::string section = findSensorSection(plan.cfg, args.sensor, plan.config);
  label = plan.cfg.read_string(section, "sensorLabel", label);
  // It names the recording's image files: a '/' would put them in folders, a long one past a file
  // name's 255 bytes.
  if (label.find('/') != std::string::npos || label.size() > 100)
    throw InputError(plan.config, "[" + section + "] sensorLabel: '" + label.substr(0, 40) + (label.size() > 40 ? "...'" : "'") +
                                      " cannot name the recording's image files (no '/', at most 100 characters)");
  src.live = std::make_unique<SensorSource>(plan.cfg, section, plan.opts.sensor_timeout, plan.config, args.verbose);
  return src;
}

// --checkpoint-every: the reconstruction so far to DIR/checkpoint, between two frames, for `vofusion
// DIR/grab.rawlog --resume DIR/checkpoint` (the origin names that recording).
struct LiveCheckpoints {
  double every = 0.0;  // s; 0: none
  std::string path, origin;
  std::chrono::steady_clock::time_point start = std::chrono::steady_clock::now(), last = start;
  std::size_t written = 0;
  std::size_t frames_at_last = 0;  // frames processed at the last one written
  double seconds_writing = 0.0;
  std::string error;  // why one could not be written: no more are tried

  void maybeWrite(const RunSession& run) {
    const auto now = std::chrono::steady_clock::now();
    if (every <= 0 || !error.empty() || std::chrono::duration<double>(now - last).count() < every) return;
    if (run.reconstruction().framesProcessed() <= frames_at_last) return;  // nothing tracked since (one is held back)
    write(run, now);
  }
  // After the session's last frame, before its end phase (the map fused again, the meshing): a crash
  // there is resumed at the end phase instead of tracking again every frame since the last one.
  void writeLast(const RunSession& run) {
    // The last frame taken is still held back (finishLive tracks it): not in the checkpoint, which a
    // resumed run goes on from by reading it again from the recording, with the frames after it.
    if (every <= 0 || !error.empty() || run.reconstruction().framesProcessed() <= frames_at_last) return;
    try {
      write(run, std::chrono::steady_clock::now());
    } catch (const std::exception& e) {  // a spare: the outputs come whatever it meets
      error = oneLineMessage(e);
      printWarning(error + "; the session's outputs are written without it");
    }
  }

 private:
  void write(const RunSession& run, std::chrono::steady_clock::time_point now) {
    try {
      // The frames it covers were recorded before they came here: on the disk first (records and
      // images), or after a power cut the checkpoint would name frames the recording lost.
      syncFileSystemOf(path);
      run.saveCheckpoint(path, origin, std::chrono::duration<double>(now - start).count());
    } catch (const InputError& e) {
      // A checkpoint is a spare; the recording is what cannot be made again: it goes on without them.
      error = e.what();
      printWarning(error + "; no more checkpoints this session, which goes on without them");
      return;
    }
    last = std::chrono::steady_clock::now();
    seconds_writing += std::chrono::duration<double>(last - now).count();
    ++written;
    frames_at_last = run.reconstruction().framesProcessed();
  }
};

// The consumer: the reconstruction when --live, else nothing (recording happens on the grab thread).
// --simulate-work-ms adds a fixed cost per frame (tests force drops with it).
struct LiveConsumer {
  const Args& args;
  RunSession* run;       // null without --live
  LiveViewer* viewer;    // null without a window
  const LiveStats& latest;
  LiveCheckpoints& checkpoints;
  std::size_t loops_shown = 0;

  void operator()(const Frame& frame) {
    if (args.work_ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(args.work_ms));
    if (!run) return;
    const std::optional<FrameReport> r = run->process(frame);  // the frame before this one
    try {
      checkpoints.maybeWrite(*run);
      if (viewer && r) show(frame, *r);
    } catch (const std::exception& e) {
      throw FrameDoneError(oneLineMessage(e));  // the frame is in the reconstruction (held, tracked next): processed
    }
  }

  void show(const Frame& frame, const FrameReport& r) {
    const Reconstruction& rec = run->reconstruction();
    LiveView view;
    // Only for a redraw (~10 Hz): a ray cast of the map per frame, and its wait for the frame's fusion
    // (which would otherwise overlap the next frame's odometry), cost every frame at 30 Hz.
    if (viewer->wantsImage()) view.image = rec.renderView(frame.camera);
    view.pose = r.pose;
    view.tracking = r.tracked ? (r.fell_back ? "tracking (odometry fallback)" : "tracking")
                              : "LOST" + (r.note.empty() ? std::string() : ": " + r.note);
    if (const loop::LoopCloser* lc = rec.loopCloser()) addNewLoops(*lc, loops_shown, view);
    viewer->show(view, latest);
    if (!viewer->isOpen()) requestStop();  // closing the window ends the run
  }
};

// The reconstruction's end: the same outputs as vofusion, the map fused again from grab.rawlog when
// loops moved the poses and the run recorded.
void finishLive(RunSession& run, const LiveStats& stats, const GrabPlan& plan, const GrabSource& source,
                const std::string& out, std::size_t recorded, const LiveCheckpoints& checkpoints) {
  run.flush();  // the last frame taken: tracked without a next one
  if (run.reconstruction().framesProcessed() == 0) return;
  RunInfo info;
  info.app = "vofusion-grab";
  info.input = source.live->name();
  info.config = plan.config;
  info.interrupted = stats.stop == StopReason::Interrupted || !stats.ok();
  info.seconds = stats.seconds;
  if (const Trajectory* gt = source.recordedGroundTruth()) info.recorded_ground_truth = *gt;
  info.extra = {{"live", {{"played", stats.played}, {"processed", stats.processed}, {"dropped", stats.dropped},
                          {"queue_capacity", plan.opts.queue_capacity}, {"stop", stopReasonName(stats.stop)}}}};
  // As vofusion's summary says it; a window closed stops the run with no signal.
  if (stats.stop == StopReason::Interrupted && stopSignal() != 0) info.extra["stop_signal"] = signalName(stopSignal());
  if (checkpoints.every > 0)
    info.extra["checkpoints"] = {{"every_seconds", checkpoints.every}, {"written", checkpoints.written},
                                 {"seconds_writing", checkpoints.seconds_writing}};
  if (!checkpoints.error.empty()) info.extra["checkpoints"]["error"] = checkpoints.error;
  if (source.replayed) reportSkipped(*source.replayed, info);
  RunSession::Reopen reopen;
  if (recorded > 0)
    reopen = [out] { return openFrameSource((fs::path(out) / "grab.rawlog").string(), SourceOptions{}); };
  run.finish(info, reopen);
  const Reconstruction& rec = run.reconstruction();
  if (plan.out_params.write_mesh && rec.mapNeedsReintegration() && !rec.reintegrated() && recorded == 0)
    std::fprintf(stderr, "vofusion-grab: loops corrected the trajectory; the mesh keeps the tracked poses "
                         "(record with the reconstruction to have it fused again at the corrected ones)\n");
}

// Everything recorded so far is written, whatever stopped the run; then grab-summary.txt and the
// reconstruction's outputs.
int finishGrab(const LiveStats& stats, const GrabPlan& plan, const GrabSource& source, RawlogWriter* writer,
               RunSession* session, const Args& args, LiveCheckpoints& checkpoints) {
  const std::size_t recorded = writer ? writer->framesWritten() : 0;
  // A recording whose last sync failed (EIO) is in place, if maybe not whole on the disk: the
  // reconstruction's outputs are still written, then the failure is said (it lost them all).
  std::string recording_error;
  if (writer) {
    try {
      writer->commit();
    } catch (const InputError& e) {
      recording_error = oneLineMessage(e);
    }
  }
  // Only after a session that ended well (a failed one keeps no checkpoint it would be refused by next
  // time), over a recording that is whole on the disk: a checkpoint names the recording's frames.
  if (session && stats.ok() && recording_error.empty()) checkpoints.writeLast(*session);
  try {
    // The grab's own counts before the reconstruction's outputs, which may fail after a failed run.
    writeFileAtomically((fs::path(args.out) / "grab-summary.txt").string(),
                        summaryText(stats, source.live->name(), recorded, plan.opts.queue_capacity, source.skipped()));
    if (session) finishLive(*session, stats, plan, source, args.out, recorded, checkpoints);
  } catch (const std::exception& e) {
    if (!recording_error.empty()) std::fprintf(stderr, "vofusion-grab: the recording may not be whole on the disk: %s\n", recording_error.c_str());
    if (stats.ok()) throw;
    // What stopped the run (a full disk) may stop the outputs after it too, or they fail on their own
    // (a folder where trajectory.txt goes): one line with the first cause, then the second.
    const std::string kept =
        writer ? std::to_string(recorded) + " frames recorded before it" : "nothing recorded (--no-record)";
    std::fprintf(stderr, "vofusion-grab: stopped: %s (%s; writing the outputs then failed too: %s)\n", stats.error.c_str(),
                 kept.c_str(), oneLineMessage(e).c_str());
    return 1;  // as a run stopped by a failure whose outputs were written
  }
  const std::string skipped = source.skipped() ? ", " + std::to_string(source.skipped()) + " skipped as damaged" : "";
  std::fprintf(stderr, "vofusion-grab: %zu played%s, %zu processed, %zu dropped; %zu recorded to %s\n", stats.played,
               skipped.c_str(), stats.processed, stats.dropped, recorded, args.out.c_str());
  if (!stats.ok())
    std::fprintf(stderr, "vofusion-grab: stopped: %s (everything recorded so far was written)\n", stats.error.c_str());
  if (!recording_error.empty())
    std::fprintf(stderr, "vofusion-grab: the recording may not be whole on the disk: %s (the other outputs were written)\n",
                 recording_error.c_str());
  if (!stats.ok() || !recording_error.empty()) return 1;
  std::error_code ec;
  if (checkpoints.written > 0) fs::remove(checkpoints.path, ec);  // the outputs are whole: nothing to resume
  return 0;
}

// --live checkpoints to DIR/checkpoint, and a session that ends well deletes it: one already there is an
// interrupted run's (vofusion --checkpoint-every, or a killed session), which would be replaced, then
// deleted, and that run could no longer be finished.
void refuseToReplaceACheckpoint(const Args& args) {
  if (args.checkpoint_every <= 0) return;
  const std::string path = (fs::path(args.out) / "checkpoint").string();
  std::error_code ec;
  if (fs::is_regular_file(fs::symlink_status(path, ec)))
    throw InputError(path, "an earlier run's checkpoint, which this session's checkpoints would replace: finish that "
                           "run with vofusion <its input> --out " + args.out + " --resume " + path +
                           ", or delete it (or --checkpoint-every 0)");
}

// <out>/grab.rawlog, written in place: a recording valid to its last frame whatever stops the program.
// A replay's own ground truth goes beside it from its first frame, as tum2rawlog writes it: a run on
// grab.rawlog (a killed session finished offline) evaluates as this one does.
std::unique_ptr<RawlogWriter> openRecording(const std::string& out, const std::string& label, const Trajectory* gt) {
  RawlogWriterOptions wopts;
  wopts.sensor_label = label;
  wopts.in_place = true;
  auto writer = std::make_unique<RawlogWriter>((fs::path(out) / "grab.rawlog").string(), wopts);
  if (gt) writer->writeGroundTruth(*gt);
  return writer;
}

int run(const Args& args) {
  if (args.dump) {
    std::fputs(dumpConfig(withGrabSection(vofusionConfigSections())).c_str(), stdout);
    return 0;
  }
  const GrabPlan plan = planGrab(args);
  refuseToReplaceACheckpoint(args);
  std::string label = "KINECT";
  const GrabSource source = openGrabSource(args, plan, label);
  ensureWritableDirectory(args.out);  // once there is something to record: no sensor leaves no empty folder
  // Before the recording is created: a Ctrl-C from here on lets the writer's end remove an empty one
  // (it was left, and refused the next run into the folder).
  installStopSignals();  // Ctrl-C or SIGTERM stops cleanly; a second one kills at once
  std::unique_ptr<RawlogWriter> writer;
  if (args.record) writer = openRecording(args.out, label, source.recordedGroundTruth());
  std::unique_ptr<RunSession> session;  // the same outputs as vofusion, for what was reconstructed
  if (plan.mode) session = std::make_unique<RunSession>(plan.cfg, *plan.mode, args.out, plan.out_params, plan.mesh_params);
  std::unique_ptr<LiveViewer> viewer;
  if (args.live && args.gui) viewer = std::make_unique<LiveViewer>("vofusion-grab: " + source.live->name());

  LiveCheckpoints checkpoints;
  if (session) {
    checkpoints.every = args.checkpoint_every;
    checkpoints.path = (fs::path(args.out) / "checkpoint").string();
    checkpoints.origin = RunSession::checkpointOrigin((fs::path(args.out) / "grab.rawlog").string(), *plan.mode, plan.cfg);
  }
  LiveStats latest;
  LiveConsumer consumer{args, session.get(), viewer.get(), latest, checkpoints};
  LiveHooks hooks;
  hooks.stop = &stopFlag();
  if (writer)
    hooks.on_grabbed = [&](Frame& f, const mrpt::obs::CObservation3DRangeScan::Ptr&) {
      // The files it wrote go with the frame: poses.rawlog links them.
      if (auto files = writer->write(f)) f.colour_file = files->colour, f.depth_file = files->depth;
    };
  std::size_t total = source.live->size();
  if (plan.opts.max_frames > 0 && (total == 0 || total > plan.opts.max_frames)) total = plan.opts.max_frames;
  Progress progress(args.live ? "live" : "recording", total);
  hooks.on_tick = [&](const LiveStats& s) {
    latest = s;
    progress.update(s.played, "processed " + std::to_string(s.processed) + "  dropped " + std::to_string(s.dropped));
    if (viewer) viewer->status(s);
  };
  std::fprintf(stderr, "vofusion-grab: %s from %s (queue %zu, Ctrl-C to stop)\n",
               args.live ? "reconstructing" : "recording", source.live->name().c_str(), plan.opts.queue_capacity);
  const LiveStats stats = runLive(*source.live, std::ref(consumer), plan.opts, hooks);
  progress.finish("processed " + std::to_string(stats.processed) + "  dropped " + std::to_string(stats.dropped) +
                  "  (" + stopReasonName(stats.stop) + ")");
  return finishGrab(stats, plan, source, writer.get(), session.get(), args, checkpoints);
}

int body(int argc, char** argv) { return run(parseArgs(argc, argv)); }

}  // namespace

// runApp: one error line "vofusion-grab: error: ...", exit code 2 for bad input; freed frame buffers
// stay in the heap (without it the live loop page-faulted its frame-sized buffers in again every frame:
// 362k minor faults, 3.2 s of system time on xyz_first300).
int main(int argc, char** argv) { return runApp("vofusion-grab", body, argc, argv); }
