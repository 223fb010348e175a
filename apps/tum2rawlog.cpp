// tum2rawlog <tum_dir> <out.rawlog> [--intrinsics fr1|fr2|fr3|ros|fx,fy,cx,cy] [--max-frames N]
//            [--depth-scale S] [--format obs|sf] [--embed-images] [--range-units U] [--strict] [--overwrite]
// One CObservation3DRangeScan per associated colour/depth pair; images in "<out>_Images"; ground truth
// as CObservationRobotPose "GROUND_TRUTH" per frame plus "<out>.groundtruth.txt" (the full TUM file).
#include <iostream>
#include <memory>
#include <string>

#include "vofusion/core/cli.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/progress.h"
#include "vofusion/core/stop_signals.h"
#include "vofusion/io/rawlog.h"
#include "vofusion/io/skipping_source.h"
#include "vofusion/io/tum_source.h"

using namespace vofusion;

namespace {
const char* kUsage =
    "usage: tum2rawlog <tum_dir> <out.rawlog> [--intrinsics fr1|fr2|fr3|ros|fx,fy,cx,cy] [--max-frames N]\n"
    "                  [--depth-scale S] [--format obs|sf] [--embed-images] [--range-units U] [--strict]\n"
    "                  [--overwrite]\n"
    "  --intrinsics   camera preset or values (default: the folder's intrinsics.txt / camera.yaml, else\n"
    "                 freiburg1/2/3 from its name, else 525/319.5/239.5); a preset (640x480) is scaled to\n"
    "                 images of the same shape (320x240: halved)\n"
    "  --max-frames   convert only the first N associated frames\n"
    "  --depth-scale  depth PNG units per metre (default: intrinsics.txt / camera.yaml, else 5000 as TUM)\n"
    "  --format       obs: observations only (default); sf: action/sensory-frame pairs\n"
    "  --embed-images keep images inside the rawlog instead of <out>_Images/\n"
    "  --range-units  metres per range unit, 1e-6 to 0.01 (default 2e-4 = TUM's 1/5000, lossless)\n"
    "  --strict       stop at the first damaged frame or a damaged groundtruth.txt (default: skip the frame,\n"
    "                 or convert without ground truth, say so, convert the rest)\n"
    "  --overwrite    replace <out.rawlog> (and <out>_Images/) when they exist (default: refuse; it may be a\n"
    "                 sensor recording)\n"
    "Ctrl-C or SIGTERM stops the conversion and writes nothing (an earlier <out.rawlog> stays as it was).\n";

int body(int argc, char** argv) {
  const CommandLine cl(argc, argv, {"--intrinsics", "--max-frames", "--format", "--range-units", "--depth-scale"},
                       {"--embed-images", "--strict", "--overwrite", "--help"});
  if (cl.flag("--help")) {
    std::cout << kUsage;
    return 0;
  }
  SourceOptions so;
  so.intrinsics = cl.value("--intrinsics");
  so.max_frames = cl.count("--max-frames", so.max_frames, 1);
  if (cl.value("--depth-scale")) so.depth_scale = cl.number("--depth-scale", 5000.0, 1.0, 1e6);
  RawlogWriterOptions wo;
  const std::string format = cl.value("--format", "obs");
  if (format == "obs") wo.format = RawlogWriterOptions::Format::Observations;
  else if (format == "sf") wo.format = RawlogWriterOptions::Format::ActionsSensoryFrames;
  else throw InputError("--format", "expected obs or sf, got '" + format + "'");
  wo.external_images = !cl.flag("--embed-images");
  wo.range_units = cl.numberFrom("--range-units", wo.range_units, 1e-6, 0.01);  // 1e-6: 6.5 cm of range in 16 bits
  wo.replace = cl.flag("--overwrite");
  const auto& pos = cl.positional();
  if (pos.size() != 2) throw InputError("usage", "expected <tum_dir> <out.rawlog> (see --help)");

  so.strict = cl.flag("--strict");
  if (so.intrinsics) CameraIntrinsics::parse(*so.intrinsics);  // before touching anything
  auto tum = std::make_unique<TumFolderSource>(pos[0], so);  // validates the lists before any output exists
  const Trajectory ground_truth = tum->groundTruth();
  // A damaged frame costs that frame, as in vofusion (io/skipping_source.h).
  SkippingSource src(std::move(tum), so.strict, printWarning);
  installStopSignals(kStoppingWithNothingWritten);
  RawlogWriter out(pos[1], wo);
  if (!ground_truth.empty()) out.writeGroundTruth(ground_truth);
  Progress progress("tum2rawlog", src.size());
  Frame f;
  std::size_t n = 0;
  while (src.next(f)) {
    // A part of a conversion is no recording: nothing is written (`out` removes its temporaries).
    if (stopRequested()) return stoppedWithNothingWritten("tum2rawlog", " after " + std::to_string(n) + " frames");
    out.write(f);
    progress.update(++n + src.skipped().size());
  }
  if (stopRequested()) return stoppedWithNothingWritten("tum2rawlog", " after the last frame");
  out.commit();
  const std::size_t skipped = src.skipped().size();
  progress.finish("-> " + pos[1] + (skipped ? " (" + std::to_string(skipped) + " damaged frames skipped)" : ""));
  return 0;
}

}  // namespace

int main(int argc, char** argv) { return runApp("tum2rawlog", body, argc, argv); }
