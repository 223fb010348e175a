// rgbd-simulate --out <dir | file.rawlog> [--scene room|corridor|bare_wall|loop|lookalike|longwalk] [--trajectory smooth|shake] [--frames N] [--fps F] [--pace X]
//               [--no-noise] [--plain] [--seed S] [--size WxH] [--exposure S] [--colour-offset S] [--depth-readout S]
//               [--blackout T:S] [--overwrite]
// Renders a synthetic RGB-D sequence with exact ground truth, as a TUM folder (rgb.txt, depth.txt,
// rgb/, depth/ 16-bit PNG at 5000 units/m, groundtruth.txt, intrinsics.txt) or as an MRPT rawlog.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <set>
#include <string>

#include <opencv2/imgcodecs.hpp>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/cli.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/progress.h"
#include "vofusion/core/stop_signals.h"
#include "vofusion/io/external_files.h"
#include "vofusion/io/png_encode.h"
#include "vofusion/io/rawlog.h"
#include "vofusion/sim/default_recording.h"
#include "vofusion/sim/synthetic_sequence.h"

using namespace vofusion;
namespace fs = std::filesystem;

namespace {
const char* kUsage =
    "usage: rgbd-simulate --out <dir | file.rawlog> [--scene room|corridor|bare_wall|loop|lookalike|longwalk] [--trajectory smooth|shake]\n"
    "                     [--frames N] [--fps F] [--pace X] [--no-noise] [--plain] [--seed S] [--size WxH] [--exposure S] [--colour-offset S] [--depth-readout S]\n"
    "                     [--blackout T:S] [--overwrite]\n"
    "  --out      a folder (TUM RGB-D layout) or a .rawlog file (images in <name>_Images/). A folder this app\n"
    "             wrote is replaced, any other never; a .rawlog only with --overwrite (it may be a recording)\n"
    "  --scene    room (default), corridor (long, camera travels along it), bare_wall (flat textured wall),\n"
    "             loop (a corridor around a block, walked once round: loop closure), lookalike (a corridor repeating every 3 m:\n"
    "             places that look the same and must not be joined), longwalk (a straight corridor walked at 1 m/s:\n"
    "             30 m per 900 frames, 100 m = 3000 frames; memory must not grow with the path, bench/longrun)\n"
    "  --trajectory smooth (default: the scene's hand-held path) or shake: hand shake on top (turns up to\n"
    "             ~150 deg/s), motion-blurred colour taken up to 15 ms off the depth capture (a TUM\n"
    "             folder keeps that offset in rgb.txt, a rawlog in a COLOUR_TIME entry after each frame)\n"
    "  --frames   number of frames (default 300); --fps frame rate, 0.1 to 1000 (default 30)\n"
    "  --pace X   the path played X times as fast (default 1, (0, 4]): at 2 the room turns up to ~37 deg/s;\n"
    "             a corridor (corridor, lookalike, longwalk) is built for the path's time at that pace\n"
    "  --no-noise exact depth instead of the Kinect v1 noise model; --seed S random seed (default 1)\n"
    "  --plain    every surface one plain colour, no texture: only shading shows the geometry (white walls)\n"
    "  --size     image size (default 640x480; intrinsics scaled from fx=fy=525)\n"
    "  --exposure S, --colour-offset S  shake only: colour exposure time (default 0.012 s, [0, 0.1]) and the\n"
    "             largest colour-to-depth capture offset (default 0.015 s, [0, 0.05])\n"
    "  --depth-readout S  depth rows read one after another over S seconds, top first (rolling shutter;\n"
    "             Kinect v1 ~0.03; default 0: all at once, [0, 0.1]); ground truth at the middle row's time\n"
    "  --blackout T:S  the camera covered from T s for S s: no depth, black colour, while the path goes on\n"
    "Ctrl-C or SIGTERM stops the rendering and writes nothing (an earlier output stays as it was).\n";

// "WxH" with a 4:3 aspect: the default camera scaled to that size.
CameraIntrinsics cameraForSize(const std::string& size) {
  int w = 0, h = 0;
  char tail = 0;
  if (std::sscanf(size.c_str(), "%dx%d%c", &w, &h, &tail) != 2 || w <= 0 || h <= 0 || std::int64_t(w) * 3 != std::int64_t(h) * 4)
    throw InputError("--size", "expected WxH with a 4:3 aspect, e.g. 320x240, got '" + size + "'");
  // At least 16 px a side, as ever (24x18 the smallest); at most 4096 wide (6.4 times the Kinect's 640):
  // a frame's buffers grow with its area, and 64000x48000 passed, to fail allocating ~50 GB a frame.
  if (h < 16 || w > 4096)
    throw InputError("--size", "width " + std::to_string(w) + " is outside [24, 4096] px, got '" + size + "'");
  return sim::SimOptions().camera.scaled(w / 640.0);
}

constexpr const char* kIntrinsicsHeader = "# fx fy cx cy (pixels, ";

// What this app writes into a TUM folder; it replaces a folder only when that is all it holds and its
// intrinsics.txt is this app's: a recorded TUM sequence (or anything else) in its place is never lost.
bool madeByThisApp(const fs::path& dir) {
  const std::set<std::string> ours = {"rgb", "depth", "rgb.txt", "depth.txt", "groundtruth.txt", "intrinsics.txt"};
  for (const auto& e : fs::directory_iterator(dir))
    if (!ours.count(e.path().filename().string())) return false;
  std::ifstream intrinsics(dir / "intrinsics.txt");
  std::string first;
  return std::getline(intrinsics, first) && first.rfind(kIntrinsicsHeader, 0) == 0;
}

// False when a stop was asked for before the last frame (nothing written).
bool writeTum(const sim::SyntheticSequence& seq, const std::string& dir) {
  if (fs::exists(dir) && (!fs::is_directory(dir) || (!fs::is_empty(dir) && !madeByThisApp(dir))))
    throw InputError(dir, "exists and is not a folder rgbd-simulate wrote; refusing to replace it");
  AtomicPath out(dir);  // "sim/" names sim, whose parent is the one to make
  ensureWritableDirectory(fs::absolute(out.path()).parent_path().string());
  std::error_code made;
  fs::create_directories(fs::path(out.tmp()) / "rgb", made);
  if (!made) fs::create_directories(fs::path(out.tmp()) / "depth", made);
  if (made) throw InputError(dir, "cannot create the folder: " + made.message());
  std::string rgb_txt = "# colour images\n# timestamp filename\n", depth_txt = "# depth maps\n# timestamp filename\n";
  std::string gt_txt = "# ground truth trajectory (camera-to-world)\n# timestamp tx ty tz qx qy qz qw\n";
  Trajectory gt;
  Progress progress("rgbd-simulate", seq.size());
  for (std::size_t i = 0; i < seq.size(); ++i) {
    if (stopRequested()) return false;
    const Frame f = seq.render(i);
    char name[64];
    std::snprintf(name, sizeof name, "%.6f.png", f.timestamp);
    cv::Mat d16;
    f.depth.convertTo(d16, CV_16U, 5000.0);  // TUM: 5000 units per metre (rounded)
    writeExternalFile((fs::path(out.tmp()) / "rgb" / name).string(), encodeRgb8Png(f.rgb),
                      (fs::path(dir) / "rgb" / name).string(), "image");
    if (!cv::imwrite((fs::path(out.tmp()) / "depth" / name).string(), d16))
      throw InputError(dir, "cannot write images (disk full?)");
    // The colour image under its own capture time (the shake trajectory's colour/depth offset).
    char rgb_stamp[32];
    std::snprintf(rgb_stamp, sizeof rgb_stamp, "%.6f", f.timestamp + f.colour_offset);
    rgb_txt += std::string(rgb_stamp) + " rgb/" + name + "\n";
    depth_txt += std::string(name, std::strlen(name) - 4) + " depth/" + name + "\n";
    gt.push_back({f.timestamp, *f.groundTruth});
    progress.update(i + 1);
  }
  writeFileAtomically((fs::path(out.tmp()) / "rgb.txt").string(), rgb_txt);
  writeFileAtomically((fs::path(out.tmp()) / "depth.txt").string(), depth_txt);
  writeTumTrajectory((fs::path(out.tmp()) / "groundtruth.txt").string(), gt);
  // The TUM layout has no place for intrinsics; TumFolderSource reads this file when present.
  const CameraIntrinsics& c = seq.options().camera;
  char intr[160];
  std::snprintf(intr, sizeof intr, "%s%dx%d, depth registered to colour)\n%.6f %.6f %.6f %.6f\n", kIntrinsicsHeader,
                c.width, c.height, c.fx, c.fy, c.cx, c.cy);
  writeFileAtomically((fs::path(out.tmp()) / "intrinsics.txt").string(), intr);
  if (stopRequested()) return false;
  out.commit();
  progress.finish("-> " + dir);
  return true;
}

// A TUM folder lists each colour image under its own capture time, and a reader pairs it with the
// depth image nearest in time, within 0.02 s (the benchmark's associate.py): an offset of half a
// frame or more pairs it with the next frame's depth, or the colour stamps leave their order.
void requireColourOffsetsATumFolderPairs(const sim::SimOptions& o) {
  const double limit = std::min(SourceOptions().max_time_diff, 0.5 / o.fps);
  if (o.colour_offset_max < limit) return;
  char why[256];
  std::snprintf(why, sizeof why, "%g s at %g fps: a TUM folder's colour images pair with their depth only under %.4g s (half a "
                "frame, at most 0.02 s); write a .rawlog (it keeps each colour image's time) or lower --colour-offset",
                o.colour_offset_max, o.fps, limit);
  throw InputError("--colour-offset", why);
}

int body(int argc, char** argv) {
  const CommandLine cl(argc, argv, {"--out", "--scene", "--trajectory", "--frames", "--seed", "--fps", "--pace", "--size", "--exposure", "--depth-readout",
                                     "--colour-offset", "--blackout"},
                       {"--no-noise", "--plain", "--overwrite", "--help"});
  if (cl.flag("--help")) {
    std::cout << kUsage;
    return 0;
  }
  sim::SimOptions o;
  o.scene = cl.value("--scene", o.scene);
  o.trajectory = cl.value("--trajectory", o.trajectory);
  o.frames = cl.count("--frames", o.frames, 1);
  const std::size_t seed = cl.count("--seed", o.seed);
  if (seed > 0xFFFFFFFFu)
    throw InputError("usage", "--seed expects a whole number below 2^32, got '" + *cl.value("--seed") + "'");
  o.seed = std::uint32_t(seed);  // 2^32 + 1 was seed 1 again
  o.noise = !cl.flag("--no-noise");
  o.textured = !cl.flag("--plain");
  o.fps = cl.numberFrom("--fps", o.fps, 0.1, 1000.0);  // under 0.1 Hz no sensor streams
  o.pace = cl.number("--pace", o.pace);  // range checked by SyntheticSequence
  o.exposure = cl.number("--exposure", o.exposure);            // range checked by SyntheticSequence
  o.colour_offset_max = cl.number("--colour-offset", o.colour_offset_max);
  o.depth_readout = cl.number("--depth-readout", o.depth_readout);  // range checked by SyntheticSequence
  if (const auto size = cl.value("--size")) o.camera = cameraForSize(*size);
  if (const auto blackout = cl.value("--blackout")) {
    char tail = 0;
    if (std::sscanf(blackout->c_str(), "%lf:%lf%c", &o.blackout_start, &o.blackout_seconds, &tail) != 2 ||
        std::isnan(o.blackout_start) || std::isnan(o.blackout_seconds))  // "nan" was a cover "of length 0"
      throw InputError("--blackout", "expected T:S (start and length in s), e.g. 4:1.5, got '" + *blackout + "'");
    // A cover of no length covers no frame (SimOptions takes 0 s as none; between frames: SyntheticSequence).
    if (!(o.blackout_seconds > 0)) throw InputError("--blackout", "'" + *blackout + "' covers no frame (its length is 0)");
  }
  // Options that would change nothing are refused, not ignored: the user expects their effect.
  for (const char* shake_only : {"--exposure", "--colour-offset"})
    if (cl.value(shake_only) && o.trajectory != "shake")
      throw InputError(shake_only, "takes effect with --trajectory shake only");
  if (!cl.positional().empty()) throw InputError("usage", "unexpected argument '" + cl.positional()[0] + "' (see --help)");
  const std::string out = cl.value("--out", "");
  if (out.empty()) throw InputError("usage", "--out <dir | file.rawlog> is required");

  const bool rawlog = fs::path(out).extension() == ".rawlog";
  if (cl.flag("--overwrite") && !rawlog)
    throw InputError("--overwrite", "takes effect with a .rawlog --out only (a folder rgbd-simulate wrote is replaced "
                                    "without it, any other never)");
  if (!rawlog && o.trajectory == "shake") requireColourOffsetsATumFolderPairs(o);
  const sim::SyntheticSequence seq(o);  // validates the scene before any output exists
  installStopSignals(kStoppingWithNothingWritten);
  const bool done = rawlog ? renderRecording(seq, out, cl.flag("--overwrite")) : writeTum(seq, out);
  // A part of a sequence is no sequence: nothing is written (the writers remove their temporaries).
  return done ? 0 : stoppedWithNothingWritten("rgbd-simulate", "");
}

}  // namespace

int main(int argc, char** argv) { return runApp("rgbd-simulate", body, argc, argv); }
