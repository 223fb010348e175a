#include "vofusion/sim/default_recording.h"

#include <cstdio>
#include <filesystem>

#include "vofusion/core/progress.h"
#include "vofusion/io/rawlog.h"
#include "vofusion/sim/synthetic_source.h"

namespace fs = std::filesystem;

namespace vofusion {

std::string defaultRecording() {
  const fs::path path = fs::path(VOFUSION_SOURCE_DIR) / "rawlogs" / "generated" / "synthetic_room.rawlog";
  if (fs::exists(path)) return path.string();
  fs::create_directories(path.parent_path());
  std::fprintf(stderr, "vofusion: rendering the default recording %s (first run only)\n", path.c_str());
  sim::SyntheticSource source(sim::SimOptions{});  // room, 300 frames, Kinect-like noise
  RawlogWriter writer(path.string());
  Trajectory gt;
  Progress progress("rgbd-simulate room", source.size());
  Frame f;
  while (source.next(f)) {
    writer.write(f);
    gt.push_back({f.timestamp, *f.groundTruth});
    progress.update(f.index + 1);
  }
  writer.writeGroundTruth(gt);
  writer.commit();
  progress.finish();
  return path.string();
}

}  // namespace vofusion
