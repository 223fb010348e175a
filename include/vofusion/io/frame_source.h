#pragma once
// Where frames come from: a TUM folder, an MRPT rawlog, a synthetic scene, or a live sensor. The one
// function that opens any of them by name is vofusion/sim/any_source.h (it knows the synthetic kind).
#include <cstddef>
#include <memory>
#include <optional>
#include <string>

#include "vofusion/core/camera.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/frame.h"
#include "vofusion/core/trajectory.h"

namespace vofusion {

// One frame that cannot be read while the frames after it can (a missing, truncated or corrupt
// image, a record whose images do not load): the source has moved past it, and next() goes on with
// the frame after. SkippingSource skips such frames.
class DamagedFrame : public InputError {
 public:
  using InputError::InputError;
  explicit DamagedFrame(const InputError& e) : InputError(e.file(), e.problem()) {}
};

// The recording ends early: the rest of it cannot be read (a rawlog cut off inside a record, as a
// crash while recording leaves it). Thrown in place of the end, after the frames before the damage.
class RecordingCutShort : public InputError {
 public:
  using InputError::InputError;
};

class FrameSource {
 public:
  virtual ~FrameSource() = default;
  // Fills the next frame; false at the end. Throws DamagedFrame for a frame that cannot be read
  // (the next call reads the one after), RecordingCutShort after the last frame of a recording whose
  // rest is damaged, InputError when nothing more can be read.
  virtual bool next(Frame& frame) = 0;
  // Number of frames if known in advance, else 0.
  virtual std::size_t size() const = 0;
  // Back to the first frame (replays, forward/backward long runs).
  virtual void rewind() = 0;
  // Human-readable origin, e.g. the folder or file.
  virtual std::string name() const = 0;
  // The recording's ground truth as it lists it (TUM's groundtruth.txt at the motion-capture stamps; a
  // rawlog's sidecar as tum2rawlog, rgbd-odometry or vofusion wrote it, else the poses its frames
  // carry), for evaluating a run as TUM's tools do; nullptr when it has none beside its frames' own
  // (Frame::groundTruth: synthetic, 7-Scenes).
  virtual const Trajectory* recordedGroundTruth() const { return nullptr; }
};

// A source whose frames can be read by index (a folder, a synthetic sequence): next() and rewind()
// walk read(0), read(1), ... read(size() - 1).
class IndexedFrameSource : public FrameSource {
 public:
  // Reads frame i without moving the cursor.
  virtual Frame read(std::size_t i) const = 0;
  bool next(Frame& frame) override;
  void rewind() override { pos_ = 0; }

 private:
  std::size_t pos_ = 0;
};

struct SourceOptions {
  std::optional<std::string> intrinsics;  // preset or "fx,fy,cx,cy"; overrides what the data says
  double depth_scale = 0.0;               // TUM layout: depth PNG units per metre (5000 TUM, 1000 mm);
                                          // 0 = the folder's camera file, else 5000
  std::size_t max_frames = 0;             // 0 = all
  double max_time_diff = 0.02;            // s, colour<->depth association (TUM benchmark tolerance)
  bool unique_depth = false;              // TUM: one-to-one pairs (associate.py), else nearest colour per depth frame
  bool strict = false;                    // a damaged ground truth stops the run (else it costs the evaluation)
};

// A recording's ground-truth file (TUM format). Damaged: strict, the InputError naming it; else one
// warning line and `instead` (the recording's own ground truth, or none), since it only evaluates (or
// goes along with) the frames. Empty: `instead`, said as damaged when that is empty too.
Trajectory readGroundTruthFile(const std::string& path, const SourceOptions& opts, Trajectory instead = {});

}  // namespace vofusion
