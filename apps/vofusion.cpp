// vofusion: an RGB-D recording in, a trajectory, a clean coloured mesh and an MRPT 3D scene out.
//   vofusion [<tum_dir|in.rawlog|synthetic[:scene]>] --out <dir> [--config f.ini]
//            [--mode joint|paper-handoff|kinfu|odometry] [--max-frames N] [--intrinsics fr1|fr2|fr3|fx,fy,cx,cy]
//            [--depth-scale S] [--no-loop-closure]
//            [--raw-mesh] [--dump-config] [--work-dir d] [--save-volume f] [--resume f]
// With no input, the bundled synthetic recording (rendered on first run) is used.
#include <atomic>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <iostream>

#include "vofusion/core/cli.h"
#include "vofusion/core/config.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/progress.h"
#include "vofusion/sim/default_recording.h"
#include "vofusion/io/frame_source.h"
#include "vofusion/io/prefetching_source.h"
#include "vofusion/pipeline/reconstruction.h"
#include "vofusion/pipeline/run_outputs.h"
#include "vofusion/sim/any_source.h"

using namespace vofusion;

namespace {

std::atomic<bool> g_stop{false};
void onSigint(int) { g_stop = true; }

const char* kUsage =
    "usage: vofusion [<tum_dir|in.rawlog|synthetic[:scene]>] --out <dir> [--config f.ini]\n"
    "                [--mode joint|paper-handoff|kinfu|odometry] [--max-frames N] [--intrinsics fr1|fr2|fr3|fx,fy,cx,cy]\n"
    "                [--depth-scale S] [--no-loop-closure] [--raw-mesh] [--dump-config]\n"
    "                [--work-dir d] [--save-volume f] [--resume f]\n"
    "  --depth-scale  TUM-layout folders: depth PNG units per metre (default: the folder's intrinsics.txt /\n"
    "                 camera.yaml, else 5000 as TUM; 1000 for millimetres: RealSense, Azure Kinect, Open3D)\n"
    "  --no-loop-closure  keyframes, place recognition and the pose graph off ([loop] enabled = false);\n"
    "                 trajectory.txt is then the tracked trajectory\n"
    "  --work-dir     folder of the spill file of bricks that left the volume beyond [kinfu] world_cache_mib\n"
    "                 (default <out>/.tmp; the file is deleted as soon as it is created, so it never stays)\n"
    "  --save-volume  at the end, the map (volume + world model) and the camera pose to file f\n"
    "  --resume       start from a map saved with --save-volume: the camera continues from the saved pose,\n"
    "                 the map keeps its frame (the input should continue where the saved run stopped)\n";

std::vector<ConfigSection> allSections(const OutputParams& out, const MeshCleanParams& mesh) {
  auto sections = reconstructionConfigSections();
  sections.push_back({"mesh", &mesh});
  sections.push_back({"output", &out});
  return sections;
}

int body(int argc, char** argv) {
  const CommandLine cl(argc, argv, {"--out", "--config", "--mode", "--max-frames", "--intrinsics", "--depth-scale", "--work-dir",
                        "--save-volume", "--resume"},
                       {"--raw-mesh", "--dump-config", "--no-loop-closure", "--help"});
  if (cl.flag("--help")) {
    std::cout << kUsage;
    return 0;
  }
  const OutputParams default_out;
  const MeshCleanParams default_mesh;
  if (cl.flag("--dump-config")) {
    std::cout << dumpConfig(allSections(default_out, default_mesh));
    return 0;
  }
  if (cl.positional().size() > 1) throw InputError("usage", "more than one input given");
  const auto out_dir = cl.value("--out");
  if (!out_dir) throw InputError("usage", "--out <dir> is required");

  const std::string config_path = cl.value("--config", "");
  auto cfg = loadConfig(config_path);
  checkConfigKeys(cfg, config_path, allSections(default_out, default_mesh));
  if (cl.flag("--no-loop-closure")) cfg.write("loop", "enabled", false);
  // The world model's spill file: --work-dir, else [kinfu] work_dir, else <out>/.tmp.
  const std::string default_work = (std::filesystem::path(*out_dir) / ".tmp").string();
  if (cl.value("--work-dir")) cfg.write("kinfu", "work_dir", *cl.value("--work-dir"));
  else if (const std::string w = cfg.read_string("kinfu", "work_dir", "auto"); w.empty() || w == "auto")
    cfg.write("kinfu", "work_dir", default_work);
  const TrackingMode mode = parseTrackingMode(cl.value("--mode", "joint"));
  OutputParams out_params;
  MeshCleanParams mesh_params;
  try {  // out-of-range values: name the file they came from
    out_params.loadFromConfigFile(cfg, "output");
    mesh_params.loadFromConfigFile(cfg, "mesh");
    OdometryParams().loadFromConfigFile(cfg, "odometry");
    KinFuParams().loadFromConfigFile(cfg, "kinfu");
    loop::LoopParams().loadFromConfigFile(cfg, "loop");
  } catch (const InputError& e) {
    if (config_path.empty()) throw;
    throw InputError(config_path, e.what());
  }
  if (cl.flag("--raw-mesh")) out_params.save_raw_mesh = true;

  SourceOptions src_opts;
  src_opts.max_frames = cl.count("--max-frames", 0);
  src_opts.intrinsics = cl.value("--intrinsics");
  if (cl.value("--depth-scale")) src_opts.depth_scale = cl.number("--depth-scale", 5000.0, 1.0, 1e6);
  const std::string input = cl.positional().empty() ? defaultRecording() : cl.positional()[0];
  auto source = std::make_unique<PrefetchingSource>(openFrameSource(input, src_opts));
  Reconstruction rec(cfg, mode);
  if (cl.value("--resume")) rec.resumeVolume(*cl.value("--resume"));
  RunRecorder recorder(*out_dir, out_params, mesh_params);

  std::signal(SIGINT, onSigint);
  std::fprintf(stderr, "vofusion: %s, mode %s, %zu frames -> %s\n", source->name().c_str(), toString(mode).c_str(),
               source->size(), out_dir->c_str());
  Progress progress("vofusion [" + toString(mode) + "]", source->size());
  Frame frame;
  std::size_t done = 0, frames_with_depth = 0;
  while (!g_stop && source->next(frame)) {
    if (cv::countNonZero(frame.depth > 0) > 0) ++frames_with_depth;
    const FrameReport report = rec.process(frame);
    recorder.add(frame, report);
    ++done;
    std::string status = "fallbacks " + std::to_string(rec.fallbacks()) + "  lost " + std::to_string(rec.lostFrames());
    if (rec.loopCloser()) status += "  loops " + std::to_string(rec.loopCloser()->activeLoops());
    progress.update(done, status);
  }
  const bool interrupted = g_stop;
  std::signal(SIGINT, SIG_DFL);  // a second Ctrl-C while writing outputs kills as usual
  progress.finish(interrupted ? "(interrupted: writing what was built so far)" : "");
  if (done == 0) throw InputError(source->name(), "no frames to process");
  if (frames_with_depth == 0 && !interrupted)
    throw InputError(source->name(), "no depth readings in any frame (all depth images are zero)");
  const std::string source_name = source->name();
  source.reset();
  rec.finish();
  RunInfo info;
  if (rec.mapNeedsReintegration() && !interrupted) {
    // Loops moved the poses: the map, fused at the tracked ones, is fused again at the corrected ones
    // (reading the recording a second time rather than keeping every frame in memory).
    auto again = std::make_unique<PrefetchingSource>(openFrameSource(input, src_opts));
    Progress refuse("vofusion [re-fusing at the loop-closed poses]", done);
    const std::size_t fused = rec.reintegrate([&](Frame& f) { return again->next(f); },
                                              [&](std::size_t n) { refuse.update(n); });
    refuse.finish();
    info.extra["loop_closure_reintegration"] = {{"frames_fused", fused}, {"seconds", refuse.elapsedSeconds()}};
  }

  if (cl.value("--save-volume")) rec.saveVolume(*cl.value("--save-volume"));

  info.input = source_name;
  info.config = config_path;
  info.interrupted = interrupted;
  info.seconds = progress.elapsedSeconds();
  const auto summary = recorder.finish(rec, info);
  std::fprintf(stderr, "vofusion: %zu frames, %.1f fps, %zu fallbacks, %zu lost", done, summary.value("fps", 0.0),
               rec.fallbacks(), rec.lostFrames());
  if (summary.contains("ate")) std::fprintf(stderr, ", ATE RMSE %.4f m", summary["ate"]["rmse"].get<double>());
  std::fprintf(stderr, "\n");
  std::error_code ec;
  std::filesystem::remove(default_work, ec);  // only when empty: the spill file was never a name there
  return interrupted ? 130 : 0;
}

}  // namespace

int main(int argc, char** argv) { return runApp("vofusion", body, argc, argv); }
