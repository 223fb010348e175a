#pragma once
// One reconstruction run, as both apps drive it (vofusion over a recording, vofusion-grab --live over a
// sensor or a replay): each frame through the Reconstruction and into the outputs' queue, then one
// end-of-run flow: the loop closer's last corrections, the map fused again at the loop-closed poses
// from the recording read a second time, the map saved when asked, every output written.
//
//   RunSession run(cfg, TrackingMode::Joint, "out", out_params, mesh_params);
//   while (source.next(frame)) run.process(frame);
//   json summary = run.finish(info, [&] { return openFrameSource(input); });
#include <exception>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <mrpt/config/CConfigFileBase.h>
#include <nlohmann/json.hpp>

#include "vofusion/core/atomic_file.h"
#include "vofusion/io/frame_source.h"
#include "vofusion/pipeline/reconstruction.h"
#include "vofusion/pipeline/run_outputs.h"

namespace vofusion {

class RegionPremesher;

class RunSession {
 public:
  // Opens the recording again from its first frame, for re-fusion; empty: there is none to read.
  using Reopen = std::function<std::unique_ptr<FrameSource>()>;

  // Throws InputError for a bad configuration or an output folder that cannot be written.
  RunSession(const mrpt::config::CConfigFileBase& cfg, TrackingMode mode, const std::string& out_dir,
             const OutputParams& out_params, const MeshCleanParams& mesh_params);
  ~RunSession();  // without finish(): no outputs replaced

  Reconstruction& reconstruction() { return rec_; }
  const Reconstruction& reconstruction() const { return rec_; }
  // The frame into the reconstruction (Reconstruction::push: one frame late); the frame before it, now
  // tracked, queued for poses.rawlog and returned (none for the first).
  std::optional<FrameReport> process(const Frame& frame);
  // The frame process() holds, tracked and queued now (none if none): the end of the frames. finish()
  // calls it; saveCheckpoint() leaves the held frame out instead.
  std::optional<FrameReport> flush();
  // The end of the run, once: loop closure finished, the map fused again at the corrected poses when
  // loops moved them (from reopen(); without one the mesh keeps the tracked poses),
  // saved to save_volume when given (put in place after the other outputs: a run whose outputs fail
  // leaves an earlier map as it was), and every output written. Returns summary.json's content.
  // A map that cannot be saved costs the map only: its error is mapFailure(), for the caller to end
  // with once the run's own ending is done (its outcome said, its spent files removed).
  nlohmann::json finish(RunInfo info, const Reopen& reopen, const std::optional<std::string>& save_volume = std::nullopt);
  std::exception_ptr mapFailure() const { return map_failure_; }

  // Checkpoints (vofusion --checkpoint-every, --resume <checkpoint>; vofusion-grab --live). `origin`
  // names what the run reads (checkpointOrigin); a checkpoint made by another run is refused.
  struct Checkpoint {
    std::size_t frames = 0;  // frames processed before it
    double seconds = 0.0;    // the frame loop's wall time before it
  };
  // Between frames: the run so far (every stage's state and each frame's report for the outputs) to
  // `path`, atomically: an earlier checkpoint there is replaced only by a whole new one.
  // The frame the reconstruction holds (Reconstruction::push) is not in it: the resumed run reads it
  // again, as the frame after the checkpoint's reports.
  void saveCheckpoint(const std::string& path, const std::string& origin, double seconds) const;
  // The recording (its absolute path), the tracking mode and the settings that decide what is computed
  // from it: [odometry] (and the detectors' sections), [kinfu] and [loop] as the stages read them,
  // defaults included, the scratch folder left out. vofusion-grab --live and vofusion reading its
  // grab.rawlog agree on it, so a live session's checkpoint is resumed offline from its recording.
  static std::string checkpointOrigin(const std::string& input, TrackingMode mode, const mrpt::config::CConfigFileBase& cfg);
  // Whether `path` starts like a checkpoint (else, e.g., a map saved with --save-volume).
  static bool isCheckpoint(const std::string& path);
  // A checkpoint's frames and seconds without loading it; nullopt when `path` is not one.
  static std::optional<Checkpoint> peek(const std::string& path);
  // Before the first frame: the run goes on from the checkpoint. The caller reads the checkpoint's
  // frames from the input again and hands each to replay() (the outputs keep their images and ground
  // truth), then goes on with process(). Throws InputError(path, ...) for a bad or foreign checkpoint.
  Checkpoint resume(const std::string& path, const std::string& origin);
  // The next frame of the input while replaying: false for a frame the run did not process (a live
  // run dropped it), skipped; throws InputError when the input lacks the next processed frame.
  bool replay(const Frame& frame);
  bool replaying() const { return replayed_ < resumed_frames_; }

  // A processed frame's report as the outputs need it (no images, matches or maps): a checkpoint keeps
  // them, so that a resumed run writes poses.rawlog for every frame. 568 bytes, where a FrameReport
  // takes 1152 (a live hour at 30 Hz: 61 against 124 MB).
  struct SavedReport {
    std::uint64_t index = 0;
    double timestamp = 0.0;
    bool tracked = false, fell_back = false, predicted = false, odometry_success = false;
    Eigen::Isometry3d pose, motion;          // camera-to-world; the odometry's motion
    Eigen::Matrix<double, 6, 6> covariance;  // of the motion
  };

 private:
  void refuse(RunInfo& info, const Reopen& reopen);
  void record(const FrameReport& report);  // the frame just tracked into the outputs' queue
  // The map into map's temporary, on the disk; an InputError names map's path.
  void saveMapTo(AtomicPath& map) const;

  // Meshing while tracking, when the mesh is made region by region. Declared before rec_, so it
  // outlives the fusion thread that tells it of shifts; its own thread is stopped first (destructor).
  std::unique_ptr<RegionPremesher> premesher_;
  Reconstruction rec_;
  RunRecorder recorder_;
  bool write_mesh_;  // the map is used at all after the frame loop
  std::vector<SavedReport> reports_;
  std::size_t resumed_frames_ = 0, replayed_ = 0;
  std::string resumed_from_;
  std::exception_ptr map_failure_;
};

}  // namespace vofusion
