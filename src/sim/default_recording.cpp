#include "vofusion/sim/default_recording.h"

#include <cstdio>
#include <filesystem>

#include "vofusion/core/progress.h"
#include "vofusion/core/stop_signals.h"
#include "vofusion/io/rawlog.h"
#include "vofusion/sim/synthetic_source.h"

namespace fs = std::filesystem;

namespace vofusion {

std::string defaultRecording() {
  const fs::path path = fs::path(VOFUSION_SOURCE_DIR) / "rawlogs" / "generated" / "synthetic_room.rawlog";
  if (fs::exists(path)) return path.string();
  fs::create_directories(path.parent_path());
  std::fprintf(stderr, "vofusion: rendering the default recording %s (first run only)\n", path.c_str());
  return renderRecording(path.string(), sim::SimOptions{}) ? path.string() : std::string();  // room, 300 frames
}

bool renderRecording(const std::string& path, const sim::SimOptions& options) {
  sim::SyntheticSource source(options);
  RawlogWriter writer(path);
  Trajectory gt;
  Progress progress("rgbd-simulate " + options.scene, source.size());
  Frame f;
  // Stopped (Ctrl-C): the writer's staged files go with it, and the next run renders it again.
  while (!stopRequested() && source.next(f)) {
    writer.write(f);
    gt.push_back({f.timestamp, *f.groundTruth});
    progress.update(f.index + 1);
  }
  if (stopRequested()) return false;
  writer.writeGroundTruth(gt);
  writer.commit();
  progress.finish();
  return true;
}

}  // namespace vofusion
