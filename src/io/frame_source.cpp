#include "vofusion/io/frame_source.h"

#include "vofusion/core/progress.h"

#include <new>

#include <opencv2/core.hpp>

namespace vofusion {

bool IndexedFrameSource::next(Frame& frame) {
  if (pos_ >= size()) return false;
  const std::size_t index = pos_++;
  try {
    frame = read(index);
  } catch (const InputError& e) {
    // The folder and its lists were checked when the source opened: what fails now is this frame's.
    throw DamagedFrame(e);
  } catch (const std::bad_alloc&) {
    // An image no check bounds (another format, decoded by OpenCV): its frame, not the run, as a
    // rawlog's.
    throw DamagedFrame(InputError(name(), "frame " + std::to_string(index) + ": its images need more memory than there is"));
  } catch (const cv::Exception& e) {
    throw DamagedFrame(InputError(name(), "frame " + std::to_string(index) + ": its images cannot be decoded (" + e.err + ")"));
  }
  return true;
}

Trajectory readGroundTruthFile(const std::string& path, const SourceOptions& opts, Trajectory instead) {
  try {
    Trajectory gt = readTumTrajectory(path);
    if (!gt.empty()) return gt;
    // Present but empty (a download cut short, a file left to fill in): said, as a damaged one is.
    if (instead.empty()) throw InputError(path, "holds no poses");
  } catch (const InputError& e) {
    if (opts.strict) throw;
    printWarning(std::string(e.what()) + (instead.empty()
                                              ? " (read without ground truth: nothing is evaluated or converted from it)"
                                              : " (the recording's own ground truth is used)"));
  }
  return instead;
}

}  // namespace vofusion
