#pragma once
// MRPT rawlogs of mrpt::obs::CObservation3DRangeScan: a FrameSource and a writer.
//
// Layout written by RawlogWriter for "<dir>/<name>.rawlog":
//   <name>.rawlog            gz-compressed MRPT archive, either observations-only (default) or
//                            (CActionCollection, CSensoryFrame) pairs (needed for odometry actions)
//   <name>_Images/           external storage (MRPT's usual folder): per frame
//                            <label>_<index>_<time>_INTENSITY.png (8-bit BGR) and ..._DEPTH.bin
//                            (MRPT's external range-image matrix)
//   <name>.groundtruth.txt   TUM trajectory (camera-to-world, optical axes), when ground truth is known
// Ground truth also goes into the rawlog as one mrpt::obs::CObservationRobotPose per frame
// (sensorLabel "GROUND_TRUTH", same timestamp as the frame, pose = camera-to-world in the optical
// convention of Frame::groundTruth). A frame whose colour image was taken off its depth's time
// (Frame::colour_offset, TUM fr1: up to 20 ms) is followed by an empty mrpt::obs::CObservationRawDAQ
// (sensorLabel "COLOUR_TIME") stamped at the colour image's time. The range image is depth along the optical axis
// (range_is_depth = true) in units of rangeUnits metres; depth and colour are registered, so
// cameraParams == cameraParamsIntensity and relativePoseIntensityWRTDepth is MRPT's "cameras
// coincide" pose (0,0,0,-90deg,0,-90deg). Everything goes to temporary names and appears on commit().
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <mrpt/obs/CAction.h>
#include <mrpt/obs/CActionRobotMovement3D.h>
#include <mrpt/obs/CObservation.h>
#include <mrpt/obs/CObservation3DRangeScan.h>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/trajectory.h"
#include "vofusion/io/frame_source.h"

namespace vofusion {

// Reads the CObservation3DRangeScans of a rawlog in either format (standalone observations or inside
// sensory frames), with embedded or external ("<name>_Images") images and range images in any
// rangeUnits. Colour: the intensity image as BGR (grey images are expanded; a missing one becomes
// mid-grey). Intrinsics: cameraParams (depth camera), unless SourceOptions::intrinsics overrides.
// Ground truth: "<name>.groundtruth.txt" if it gives poses, else CObservationRobotPose "GROUND_TRUTH"
// entries (a companion file that is empty or damaged gives way to them; said when damaged).
// One camera: the first scan's sensorLabel; scans of other cameras (a rig's, Robot@Home's four) are
// left out, said once with their labels and counts.
// A truncated or corrupt file throws InputError ("<file>: ... at entry N"); while an entry is
// deserialised, MRPT may allocate at most 64 MiB per buffer and 256 MiB in all (ScopedAllocationLimit),
// so corrupt length fields cannot make it allocate gigabytes first.
class RawlogSource : public FrameSource {
 public:
  RawlogSource(const std::string& path, const SourceOptions& opts);
  ~RawlogSource() override;
  bool next(Frame& frame) override;
  std::size_t size() const override { return count_; }
  void rewind() override;
  std::string name() const override { return path_; }
  const Trajectory& groundTruth() const { return gt_; }
  const Trajectory* recordedGroundTruth() const override { return gt_.empty() ? nullptr : &gt_; }
  const std::string& imagesDirectory() const { return images_dir_; }

 private:
  struct Reader;
  std::string path_, images_dir_;
  std::string cut_short_;  // why the frames end before the file does (RecordingCutShort)
  std::string camera_;     // the sensorLabel of the scans read (the first scan's)
  SourceOptions opts_;
  std::size_t count_ = 0, pos_ = 0;
  Trajectory gt_;
  std::vector<double> colour_offsets_;  // per scan in the file: its colour image's offset, s (COLOUR_TIME)
  std::unique_ptr<Reader> reader_;
};

// Whether the observation's colour camera is its depth camera (same pose and intrinsics, or the same
// camera at another resolution): then colour and depth share pixels.
bool colourRegisteredToDepth(const mrpt::obs::CObservation3DRangeScan& obs);
// Depth-camera optical coordinates -> colour-camera optical coordinates, from relativePoseIntensityWRTDepth.
Eigen::Isometry3d colourFromDepth(const mrpt::obs::CObservation3DRangeScan& obs);
// Converts one observation to a Frame (loads external data first). `origin` names the rawlog in errors.
// A colour camera that is not registered to depth has its colour re-projected into the depth camera
// (io/colour_registration.h), as the observation's own cameras say; override_camera replaces the depth
// camera's intrinsics (--intrinsics, or a registered sensor's colour intrinsics), not that decision.
Frame frameFromObservation(const mrpt::obs::CObservation3DRangeScan& obs, const std::string& origin,
                           const std::optional<CameraIntrinsics>& override_camera = std::nullopt);
// Builds an observation (images embedded) from a Frame; depth quantised to range_units metres (a reading
// beyond 65535 units becomes no reading, 0).
mrpt::obs::CObservation3DRangeScan::Ptr observationFromFrame(const Frame& frame, double range_units = 2e-4,
                                                             const std::string& sensor_label = "KINECT");
// An odometry action for the action/sensory-frame format: pose change between consecutive frames
// (camera-to-camera, optical axes), covariance 6x6 (x y z yaw pitch roll; zero = unknown).
mrpt::obs::CActionRobotMovement3D makeOdometryAction(const mrpt::poses::CPose3D& delta, double timestamp,
                                                     const mrpt::math::CMatrixDouble66* cov = nullptr);

struct RawlogWriterOptions {
  enum class Format { Observations, ActionsSensoryFrames };
  Format format = Format::Observations;  // ActionsSensoryFrames is required for writeAction()
  bool external_images = true;           // images in "<name>_Images" (what RawLogViewer expects for big logs)
  double range_units = 2e-4;             // m per range unit: 2e-4 keeps TUM depth exact (5000/m), max 13.1 m
  std::string sensor_label = "KINECT";
  bool ground_truth_observations = true; // CObservationRobotPose "GROUND_TRUTH" for frames with groundTruth
  // A recording (vofusion-grab) rather than a result: written under its final names, each frame's
  // images and then its record on disk before the next frame, so that a crash, a kill or a full disk
  // leaves a rawlog that reads to its last frame (plain, not gzip; synced to the disk once a second).
  // Never replaces an existing recording. Default: a temporary name renamed whole by commit().
  bool in_place = false;
  // Not in place: whether a rawlog (or an images folder) already at the path is replaced. The
  // converters (tum2rawlog, rgbd-simulate) replace only when asked (--overwrite, as MRPT's rawlog-edit):
  // what is there may be a sensor recording, which nothing can make again.
  bool replace = true;
};

// The image files a recording wrote for a frame (RawlogWriter::write in place).
struct RecordedFiles {
  ColourFile colour;
  DepthFile depth;
};

class RawlogWriter {
 public:
  // Throws InputError(path, ...) if the output cannot be created.
  explicit RawlogWriter(const std::string& path, const RawlogWriterOptions& opts = {});
  // Without commit(): temporaries removed, an earlier output left untouched. In place: kept, unless it
  // holds no frame (a run that failed before its first frame leaves no recording to block the folder).
  ~RawlogWriter();
  RawlogWriter(const RawlogWriter&) = delete;
  RawlogWriter& operator=(const RawlogWriter&) = delete;

  // One CObservation3DRangeScan (+ ground-truth observation). Action/SF format: written as the
  // pending actions followed by a sensory frame holding the observation(s). External images: the
  // frame's own files are reused (Frame::colour_file, and Frame::depth_file at the same range_units:
  // a recording's linked, others copied), else the images are encoded and written. A writer in place
  // (a recording) returns the files it wrote, named absolutely, for the frame to carry to later
  // writers (vofusion-grab's poses.rawlog); others return nothing.
  std::optional<RecordedFiles> write(const Frame& frame);
  // Action/SF format only (std::logic_error otherwise): goes into the action collection preceding the
  // next frame's sensory frame.
  void writeAction(const mrpt::obs::CAction& action);
  // Any other observation: observations format: written now; action/SF format: joins the next frame's SF.
  void writeObservation(const mrpt::obs::CObservation& obs);
  // Companion "<name>.groundtruth.txt" (TUM format), written on commit(); a recording in place's with
  // its first frame (given before it), so that a recording killed before commit() has it too.
  void writeGroundTruth(const Trajectory& gt);
  // Flushes, closes and renames everything into place.
  void commit();

  std::size_t framesWritten() const { return frames_; }
  const std::string& path() const { return path_; }
  // "<dir>/<name>_Images" and "<dir>/<name>.groundtruth.txt" for a rawlog path.
  static std::string imagesDirFor(const std::string& rawlog_path);
  static std::string groundTruthPathFor(const std::string& rawlog_path);

 private:
  struct Impl;
  // External images: the frame's colour and depth files beside the rawlog, named in `obs`; a
  // recording's (in place) returned for the frame to carry.
  std::optional<RecordedFiles> writeImagesBeside(const Frame& frame, mrpt::obs::CObservation3DRangeScan& obs);
  std::string path_;
  RawlogWriterOptions opts_;
  std::size_t frames_ = 0;
  std::size_t readings_beyond_range_ = 0;  // depth readings too far for 16 bits of range_units
  bool committed_ = false;
  std::unique_ptr<Impl> impl_;
};

}  // namespace vofusion
