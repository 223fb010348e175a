#include "vofusion/sim/default_recording.h"

#include <cstdint>
#include <cstdio>
#include <filesystem>

#include <mrpt/math/CMatrixFixed.h>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/progress.h"
#include "vofusion/core/stop_signals.h"
#include "vofusion/core/text_file.h"
#include "vofusion/io/rawlog.h"

namespace fs = std::filesystem;

namespace vofusion {

namespace {
// FNV-1a over the first and last frames' pixels, stamps and poses: what a change of the simulator
// changes (two frames' renders, ~0.1 s, against the whole recording's).
std::string fingerprint(const sim::SyntheticSequence& seq) {
  std::uint64_t h = 1469598103934665603ull;
  const auto mix = [&h](const void* data, std::size_t n) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 1099511628211ull;
  };
  for (const std::size_t i : {std::size_t(0), seq.size() - 1}) {
    const Frame f = seq.render(i);
    for (const cv::Mat& m : {f.rgb, f.depth}) {
      const cv::Mat c = m.isContinuous() ? m : m.clone();
      mix(c.data, c.total() * c.elemSize());
    }
    mix(&f.timestamp, sizeof f.timestamp);
    if (f.groundTruth) {
      const Eigen::Matrix4d T = f.groundTruth->getHomogeneousMatrixVal<mrpt::math::CMatrixDouble44>().asEigen();
      mix(T.data(), sizeof(double) * 16);
    }
  }
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(h));
  return std::string(hex) + " " + std::to_string(seq.size()) + " frames\n";
}

// The fingerprint beside a recording ("" when there is none).
std::string madeBy(const std::string& stamp) { return entryExists(stamp) ? readTextFile(stamp) : std::string(); }
}  // namespace

std::string recordingRenderedBy(const sim::SyntheticSequence& seq, const std::string& path) {
  const std::string stamp = path + ".made-by";
  const std::string made_by = fingerprint(seq);
  std::error_code ec;
  const bool there = fs::exists(path, ec);
  if (there && madeBy(stamp) == made_by + fileStamp(path) + "\n") return path;
  if (!fs::path(path).parent_path().empty()) fs::create_directories(fs::path(path).parent_path());
  std::fprintf(stderr, "vofusion: rendering the recording %s (%s)\n", path.c_str(),
               there ? "the one there is not this simulator's render" : "first run only");
  if (!renderRecording(seq, path, there)) return {};
  writeFileAtomically(stamp, made_by + fileStamp(path) + "\n");  // the rawlog's: not rendered over since
  return path;
}

std::string defaultRecording() {
  const fs::path path = fs::path(VOFUSION_SOURCE_DIR) / "rawlogs" / "generated" / "synthetic_room.rawlog";
  return recordingRenderedBy(sim::SyntheticSequence{sim::SimOptions{}}, path.string());  // room, 300 frames, Kinect-like noise
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
