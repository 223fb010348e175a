#include "vofusion/sim/default_recording.h"

#include <cstdio>
#include <filesystem>

#include "vofusion/core/progress.h"
#include "vofusion/core/stop_signals.h"
#include "vofusion/io/rawlog.h"

namespace fs = std::filesystem;

namespace vofusion {

std::string defaultRecording() {
  const fs::path path = fs::path(VOFUSION_SOURCE_DIR) / "rawlogs" / "generated" / "synthetic_room.rawlog";
  if (fs::exists(path)) return path.string();
  fs::create_directories(path.parent_path());
  std::fprintf(stderr, "vofusion: rendering the default recording %s (first run only)\n", path.c_str());
  const sim::SyntheticSequence room{sim::SimOptions{}};  // room, 300 frames, Kinect-like noise
  return renderRecording(room, path.string()) ? path.string() : std::string();
}

bool renderRecording(const sim::SyntheticSequence& seq, const std::string& path, bool replace) {
  // A stop leaves no recording, whatever the app keeps of its own work ("what was done is written").
  const ScopedStoppingMessage stopping(kStoppingWithNothingWritten);
  RawlogWriterOptions options;
  options.replace = replace;
  // Stopped (Ctrl-C): the writer's staged files go with it, and the next run renders it again.
  RawlogWriter out(path, options);
  Trajectory gt;
  Progress progress("rgbd-simulate " + seq.options().scene, seq.size());
  for (std::size_t i = 0; i < seq.size(); ++i) {
    if (stopRequested()) return false;
    const Frame f = seq.render(i);
    out.write(f);
    gt.push_back({f.timestamp, *f.groundTruth});
    progress.update(i + 1);
  }
  out.writeGroundTruth(gt);
  if (stopRequested()) return false;
  out.commit();
  progress.finish("-> " + path);
  return true;
}

}  // namespace vofusion
