// vofusion-grab: record an RGB-D sensor (MRPT hwdrivers, e.g. COpenNI2Sensor) into a rawlog, and
// optionally reconstruct live. --replay plays a TUM folder or rawlog through the same live path.
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>
#include <thread>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/cli.h"
#include "vofusion/core/config.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/progress.h"
#include "vofusion/io/frame_source.h"
#include "vofusion/io/rawlog.h"
#include "vofusion/live/live_loop.h"
#include "vofusion/live/live_source.h"
#include "vofusion/live/live_viewer.h"
#include "vofusion/core/triangle_mesh.h"
#include "vofusion/pipeline/reconstruction.h"
#include "vofusion/pipeline/run_outputs.h"
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
    "                     [--verbose] [--dump-config]\n"
    "  Records the sensor of --config (default share/grab-openni2.ini) to DIR/grab.rawlog until\n"
    "  Ctrl-C or --max-frames. --live also reconstructs online (window unless --no-gui) and writes\n"
    "  the same outputs as vofusion into DIR. --replay plays a recording at its recorded rate instead\n"
    "  of a sensor. Frames the processing cannot keep up with are dropped (oldest first) and counted;\n"
    "  the recording itself never drops. DIR/grab-summary.txt holds the counts.\n";

std::atomic<bool> g_stop{false};

void onSignal(int) {
  g_stop = true;
  std::signal(SIGINT, SIG_DFL);  // a second Ctrl-C kills at once
}

struct Args {
  std::string config, sensor, out, replay, mode;
  double depth_scale = 0.0;  // --replay of a TUM-layout folder: depth units per metre (0 = its camera file / 5000)
  bool live, gui, record, verbose, dump;
  std::optional<std::size_t> max_frames, queue;
  std::optional<double> speed;
  int work_ms;
};

Args parseArgs(int argc, char** argv) {
  const CommandLine cl(argc, argv,
                       {"--config", "--sensor", "--out", "--replay", "--mode", "--max-frames", "--queue", "--speed",
                        "--simulate-work-ms", "--depth-scale"},
                       {"--live", "--no-gui", "--no-record", "--verbose", "--dump-config", "--help"});
  if (cl.flag("--help")) {
    std::fputs(kUsage, stdout);
    std::exit(0);
  }
  if (!cl.positional().empty()) throw InputError("usage", "unexpected argument '" + cl.positional()[0] + "'");
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
  if (cl.value("--max-frames")) a.max_frames = cl.count("--max-frames", 0);
  if (cl.value("--queue")) a.queue = cl.count("--queue", 0);
  if (cl.value("--speed")) a.speed = cl.number("--speed", 1.0);
  a.work_ms = int(cl.count("--simulate-work-ms", 0));
  if (a.speed && *a.speed < 0) throw InputError("--speed", "must not be negative");
  if (a.queue && *a.queue < 1) throw InputError("--queue", "must be at least 1");
  if (!a.live && !a.record) throw InputError("--no-record", "without --live there is nothing left to do");
  return a;
}

// Our sections are checked for typos; the sensor sections belong to MRPT's drivers.
std::vector<ConfigSection> ownSections(const LiveOptions& live, const OutputParams& out, const MeshCleanParams& mesh) {
  auto sections = reconstructionConfigSections();
  sections.push_back({kSection, &live});
  sections.push_back({"output", &out});
  sections.push_back({"mesh", &mesh});
  return sections;
}

void checkOwnSections(const mrpt::config::CConfigFileBase& cfg, const std::string& origin,
                      const std::vector<ConfigSection>& known) {
  mrpt::config::CConfigFileMemory own;
  for (const auto& [section, params] : known) {
    std::vector<std::string> keys;
    cfg.getAllKeys(section, keys);
    for (const auto& k : keys)
      if (k != "rawlog-grabber-ignore") own.write(section, k, cfg.read_string(section, k, ""));
  }
  checkConfigKeys(own, origin, known);
}

std::string summaryText(const LiveStats& s, const std::string& source, std::size_t recorded, std::size_t queue) {
  std::ostringstream o;
  o << "source: " << source << "\n"
    << "frames_played: " << s.played << "\n"
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

int run(const Args& args) {
  // Configuration: the sensor's file (rawlog-grabber format) plus our [vofusion-grab] section.
  std::string config = args.config;
  if (config.empty() && args.replay.empty()) config = std::string(VOFUSION_SHARE_DIR) + "/grab-openni2.ini";
  const auto cfg = loadConfig(config);
  LiveOptions opts;
  const OutputParams default_out;
  const MeshCleanParams default_mesh;
  const auto known = ownSections(opts, default_out, default_mesh);
  if (args.dump) {
    std::fputs(dumpConfig(known).c_str(), stdout);
    return 0;
  }
  checkOwnSections(cfg, config, known);
  opts.loadFromConfigFile(cfg, kSection);
  OutputParams out_params;
  MeshCleanParams mesh_params;
  out_params.loadFromConfigFile(cfg, "output");
  mesh_params.loadFromConfigFile(cfg, "mesh");
  if (args.max_frames) opts.max_frames = *args.max_frames;
  if (args.queue) opts.queue_capacity = *args.queue;
  if (args.speed) opts.replay_speed = *args.speed;

  // Reconstruction settings come from the same file; mistakes there fail now, not mid-run.
  std::optional<TrackingMode> mode;
  if (args.live) mode = parseTrackingMode(args.mode, "--mode");

  ensureWritableDirectory(args.out);

  // The source: a replay, or the sensor (fails here, in one line, when none can be opened).
  std::unique_ptr<LiveSource> source;
  std::string label = "KINECT";
  if (!args.replay.empty()) {
    SourceOptions so;
    so.depth_scale = args.depth_scale;
    source = std::make_unique<ReplaySource>(openFrameSource(args.replay, so), opts.replay_speed);
  } else {
    const std::string section = findSensorSection(cfg, args.sensor, config);
    label = cfg.read_string(section, "sensorLabel", label);
    source = std::make_unique<SensorSource>(cfg, section, opts.sensor_timeout, config, args.verbose);
  }

  std::unique_ptr<RawlogWriter> writer;
  if (args.record) {
    RawlogWriterOptions wopts;
    wopts.sensor_label = label;
    writer = std::make_unique<RawlogWriter>((fs::path(args.out) / "grab.rawlog").string(), wopts);
  }

  std::unique_ptr<Reconstruction> rec;
  std::unique_ptr<RunRecorder> outputs;  // the same outputs as vofusion, for what was reconstructed
  if (args.live) {
    rec = std::make_unique<Reconstruction>(cfg, *mode);
    outputs = std::make_unique<RunRecorder>(args.out, out_params, mesh_params);
  }
  std::unique_ptr<LiveViewer> viewer;
  if (args.live && args.gui) viewer = std::make_unique<LiveViewer>("vofusion-grab: " + source->name());

  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);

  // The consumer: the reconstruction when --live, else nothing (recording happens on the grab
  // thread). --simulate-work-ms adds a fixed cost per frame (tests force drops with it).
  LiveStats latest;
  std::size_t lost_in_a_row = 0, loops_shown = 0;
  FrameConsumer consumer = [&](const Frame& frame) {
    if (args.work_ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(args.work_ms));
    if (!rec) return;
    const FrameReport r = rec->process(frame);
    outputs->add(frame, r);
    lost_in_a_row = r.tracked ? 0 : lost_in_a_row + 1;
    if (viewer) {
      LiveView view;
      view.image = rec->renderView(frame.camera);
      view.pose = r.pose;
      view.tracking = r.tracked ? (r.fell_back ? "tracking (odometry fallback)" : "tracking")
                                : "LOST" + (r.note.empty() ? std::string() : ": " + r.note);
      if (const loop::LoopCloser* lc = rec->loopCloser()) addNewLoops(*lc, loops_shown, view);
      viewer->show(view, latest);
      if (!viewer->isOpen()) g_stop = true;  // closing the window ends the run
    }
  };

  LiveHooks hooks;
  hooks.stop = &g_stop;
  if (writer) hooks.on_grabbed = [&](const Frame& f, const mrpt::obs::CObservation3DRangeScan::Ptr&) { writer->write(f); };
  std::size_t total = source->size();
  if (opts.max_frames > 0 && (total == 0 || total > opts.max_frames)) total = opts.max_frames;
  Progress progress(args.live ? "live" : "recording", total);
  hooks.on_tick = [&](const LiveStats& s) {
    latest = s;
    progress.update(s.played, "processed " + std::to_string(s.processed) + "  dropped " + std::to_string(s.dropped));
    if (viewer) viewer->status(s);
  };

  std::fprintf(stderr, "vofusion-grab: %s from %s (queue %zu, Ctrl-C to stop)\n",
               args.live ? "reconstructing" : "recording", source->name().c_str(), opts.queue_capacity);
  const LiveStats stats = runLive(*source, consumer, opts, hooks);
  progress.finish("processed " + std::to_string(stats.processed) + "  dropped " + std::to_string(stats.dropped) +
                  "  (" + stopReasonName(stats.stop) + ")");

  // Everything recorded so far is written, whatever stopped the run.
  const std::size_t recorded = writer ? writer->framesWritten() : 0;
  if (writer) writer->commit();
  if (rec && rec->framesProcessed() > 0) {
    // Loop closure: the poses are corrected now; the map, fused live at the tracked poses, is fused
    // again at the corrected ones from the recording when there is one.
    rec->finish();
    std::optional<std::size_t> refused;
    if (rec->mapNeedsReintegration() && recorded > 0) {
      auto again = openFrameSource((fs::path(args.out) / "grab.rawlog").string(), SourceOptions{});
      refused = rec->reintegrate([&](Frame& f) { return again->next(f); });
    } else if (rec->mapNeedsReintegration()) {
      std::fprintf(stderr, "vofusion-grab: loops corrected the trajectory; the mesh keeps the tracked poses "
                           "(record with the reconstruction to have it fused again at the corrected ones)\n");
    }
    RunInfo info;
    info.input = source->name();
    info.config = config;
    info.interrupted = stats.stop == StopReason::Interrupted || !stats.ok();
    info.seconds = stats.seconds;
    info.extra = {{"live", {{"played", stats.played}, {"processed", stats.processed}, {"dropped", stats.dropped},
                            {"queue_capacity", opts.queue_capacity}, {"stop", stopReasonName(stats.stop)}}}};
    if (refused) info.extra["loop_closure_reintegration"] = {{"frames_fused", *refused}, {"from", "grab.rawlog"}};
    outputs->finish(*rec, info);
  }
  writeFileAtomically((fs::path(args.out) / "grab-summary.txt").string(),
                      summaryText(stats, source->name(), recorded, opts.queue_capacity));
  std::fprintf(stderr, "vofusion-grab: %zu played, %zu processed, %zu dropped; %zu recorded to %s\n", stats.played,
               stats.processed, stats.dropped, recorded, args.out.c_str());
  if (!stats.ok()) {
    std::fprintf(stderr, "vofusion-grab: stopped: %s (everything recorded so far was written)\n", stats.error.c_str());
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(parseArgs(argc, argv));
  } catch (const InputError& e) {
    std::fprintf(stderr, "vofusion-grab: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "vofusion-grab: %s\n", oneLineMessage(e).c_str());
    return 1;
  }
}
