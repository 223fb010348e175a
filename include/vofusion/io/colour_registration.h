#pragma once
// Colour for every depth pixel when the colour camera is not the depth camera (a rawlog whose
// CObservation3DRangeScan has relativePoseIntensityWRTDepth other than "coincide" or its own
// cameraParamsIntensity): each depth reading is back-projected with the depth intrinsics, moved into
// the colour camera, projected with the colour intrinsics (Brown distortion k1 k2 p1 p2 k3) and the
// colour read there (bilinear). Pixels without a reading, or seen outside the colour image, are black
// (0, 0, 0: no colour, which fusion paints nothing with).
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "vofusion/core/camera.h"

namespace vofusion {

// colour: CV_8UC3 of colour_cam's size; depth: CV_32F metres of depth_cam's size;
// T_colour_depth: depth-camera optical coordinates -> colour-camera optical coordinates.
cv::Mat colourInDepthCamera(const cv::Mat& colour, const cv::Mat& depth, const CameraIntrinsics& depth_cam,
                            const CameraIntrinsics& colour_cam, const Eigen::Isometry3d& T_colour_depth);

}  // namespace vofusion
