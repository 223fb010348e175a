#include "poses_rawlog.h"

#include <mrpt/obs/CObservationRobotPose.h>

#include "vofusion/core/errors.h"

namespace vofusion {

void PosesRawlog::finish(const Reconstruction& rec, const Trajectory& ground_truth) {
  if (const std::optional<InputError> err = stop()) throw *err;
  if (!ground_truth.empty()) writer_.writeGroundTruth(ground_truth);
  // Loop closure: the written path (smoothed, loop-closed: trajectory.txt) follows the frames as
  // "VOFUSION_POSE_OPTIMISED" (the tracked ones went in with each frame as "VOFUSION_POSE"), one per
  // frame in one last sensory frame.
  if (rec.loopCloser())
    for (const StampedPose& sp : rec.trajectory()) {
      mrpt::obs::CObservationRobotPose pose;
      pose.sensorLabel = "VOFUSION_POSE_OPTIMISED";
      pose.timestamp = rawlogTime(sp.timestamp);
      pose.pose.mean = sp.pose;
      writer_.writeObservation(pose);
    }
}

}  // namespace vofusion
