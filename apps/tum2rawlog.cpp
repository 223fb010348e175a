// tum2rawlog <tum_dir> <out.rawlog> [--intrinsics fr1|fr2|fr3|ros|fx,fy,cx,cy] [--max-frames N]
//            [--format obs|sf] [--embed-images] [--range-units 2e-4|1e-3]
// One CObservation3DRangeScan per associated colour/depth pair; images in "<out>_Images"; ground truth
// as CObservationRobotPose "GROUND_TRUTH" per frame plus "<out>.groundtruth.txt" (the full TUM file).
#include <cstdlib>
#include <iostream>
#include <string>
#include <vector>

#include "vofusion/core/errors.h"
#include "vofusion/core/progress.h"
#include "vofusion/io/rawlog.h"
#include "vofusion/io/tum_source.h"

using namespace vofusion;

namespace {
const char* kUsage =
    "usage: tum2rawlog <tum_dir> <out.rawlog> [--intrinsics fr1|fr2|fr3|ros|fx,fy,cx,cy] [--max-frames N]\n"
    "                  [--format obs|sf] [--embed-images] [--range-units U]\n"
    "  --intrinsics   camera preset or values (default: from the folder name freiburg1/2/3)\n"
    "  --max-frames   convert only the first N associated frames\n"
    "  --format       obs: observations only (default); sf: action/sensory-frame pairs\n"
    "  --embed-images keep images inside the rawlog instead of <out>_Images/\n"
    "  --range-units  metres per range unit (default 2e-4 = TUM's 1/5000, lossless)\n";
}

int main(int argc, char** argv) {
  try {
    std::vector<std::string> pos;
    SourceOptions so;
    RawlogWriterOptions wo;
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      auto value = [&]() -> std::string {
        if (i + 1 >= argc) throw InputError(a, "needs a value");
        return argv[++i];
      };
      if (a == "-h" || a == "--help") {
        std::cout << kUsage;
        return 0;
      } else if (a == "--intrinsics") {
        so.intrinsics = value();
      } else if (a == "--max-frames") {
        const std::string v = value();
        char* end = nullptr;
        const long n = std::strtol(v.c_str(), &end, 10);
        if (v.empty() || *end || n <= 0) throw InputError(a, "expected a positive integer, got '" + v + "'");
        so.max_frames = std::size_t(n);
      } else if (a == "--format") {
        const std::string v = value();
        if (v == "obs") wo.format = RawlogWriterOptions::Format::Observations;
        else if (v == "sf") wo.format = RawlogWriterOptions::Format::ActionsSensoryFrames;
        else throw InputError(a, "expected obs or sf, got '" + v + "'");
      } else if (a == "--embed-images") {
        wo.external_images = false;
      } else if (a == "--range-units") {
        const std::string v = value();
        char* end = nullptr;
        wo.range_units = std::strtod(v.c_str(), &end);
        if (v.empty() || *end || !(wo.range_units > 0) || wo.range_units > 0.01)
          throw InputError(a, "expected metres per unit such as 2e-4 or 1e-3, got '" + v + "'");
      } else if (!a.empty() && a[0] == '-') {
        throw InputError(a, "unknown option (see --help)");
      } else {
        pos.push_back(a);
      }
    }
    if (pos.size() != 2) {
      std::cerr << kUsage;
      return 2;
    }
    if (so.intrinsics) CameraIntrinsics::parse(*so.intrinsics);  // before touching anything
    TumFolderSource src(pos[0], so);  // validates the lists before any output exists
    RawlogWriter out(pos[1], wo);
    if (!src.groundTruth().empty()) out.writeGroundTruth(src.groundTruth());
    Progress progress("tum2rawlog", src.size());
    Frame f;
    std::size_t n = 0;
    while (src.next(f)) {
      out.write(f);
      progress.update(++n);
    }
    out.commit();
    progress.finish("-> " + pos[1]);
    return 0;
  } catch (const InputError& e) {
    std::cerr << "tum2rawlog: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "tum2rawlog: " << e.what() << "\n";
    return 1;
  }
}
