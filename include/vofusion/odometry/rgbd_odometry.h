#pragma once
// 6D RGB-D odometry (Figueroa et al., §3.1): frame-to-frame motion from colour + depth keypoints.
// CONTRACT used by fusion/ and the apps; implemented in src/odometry/.
#include <iosfwd>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <mrpt/config/CLoadableOptions.h>
#include <mrpt/math/CMatrixFixed.h>
#include <mrpt/poses/CPose3D.h>

#include "vofusion/core/described_keypoints.h"
#include "vofusion/core/frame.h"
#include "vofusion/core/point_maps.h"
#include "vofusion/core/timing.h"
#include "vofusion/features/brand.h"
#include "vofusion/features/narf_detector.h"
#include "vofusion/features/star_detector.h"
#include "vofusion/registration/rigid_motion.h"

namespace vofusion {

// The values each string key of [odometry] may take (the key table and RgbdOdometry both check them).
inline const std::vector<std::string> kKeypointSets = {"union", "star", "narf"};
inline const std::vector<std::string> kMotionMethods = {"paper", "robust"};
inline const std::vector<std::string> kDepthModes = {"median", "min"};
inline const std::vector<std::string> kColourTimeVelocities = {"interval", "capture", "auto"};

struct OdometryParams : public mrpt::config::CLoadableOptions {
  // Read from the given section (normally [odometry]) plus the fixed sections [star], [narf], [brand],
  // [matching], [motion]; share/odometry.ini documents every key.
  // [odometry]
  std::string keypoints = "union";  // "union" (STAR + NARF, the paper), "star" or "narf"
  std::string motion_method = "robust";  // "paper" (Algorithm 1) or "robust" (RANSAC + LS + Gauss-Newton)
  bool narf_concurrent = true;      // NARF beside STAR, normals and smoothing: its border extraction
                                    // first on every core, its interest search on a second thread
  double union_radius = 3.0;        // pixels; a NARF keypoint this close to a STAR one is a duplicate
  int keyframe_min_inliers = 0;     // match against a keyframe while it keeps this many inliers (0 = frame to frame)
  bool undistort = true;            // undistort keypoint pixels (CameraIntrinsics::dist) before 3D and homography
  int depth_window = 0;             // pixels; half-size of the window the keypoint's depth comes from (0 = centre)
  std::string depth_mode = "median";  // "median" or "min" (nearest) valid reading of that window
  int references = 3;               // frames matched: the previous one and references-1 before it, one joint
                                    // fit (frame to frame only, not with keyframes)
  bool colour_time = true;          // keypoints moved to their depth capture (Frame::colour_offset) at the
                                    // estimated velocity, then fitted again
  // The velocity that move uses: "interval" (the mean over the fitted interval, from the first fit;
  // one correction), "capture" (each frame's own, interpolated between the motions before and after
  // it; repeated to a fixed point) or "auto" (interval until the recording's own frames show that
  // capture fits them better: ColourTimeEvidence). capture is exact when the offsets are (synthetic,
  // hardware-synced sensors); TUM fr1's are partly arrival stamps (share/odometry.ini).
  std::string colour_time_velocity = "auto";
  // [matching]
  int max_hamming = 80;             // bits of 256; matches farther apart are dropped (256 = no limit)
  bool use_homography = true;       // RANSAC homography between matched pixels (the paper's filter)
  double homography_threshold = 10.0;  // pixels; RANSAC reprojection threshold
  int min_matches = 10;             // matches needed after the homography filter, else "too few matches"
  // [motion]
  PaperFitOptions paper;            // hypotheses (N), sample_size (s), paper_inlier_threshold (m)
  RobustFitOptions robust;          // ransac_iterations, inlier_threshold (m at 1 m), gauss_newton_iterations
  int min_inliers = 8;              // the current frame's keypoints among the 3D inliers, else "too few inliers"
  double min_extent = 0.03;         // m; inliers spread less (second axis) = "degenerate geometry"
  double max_rms = 0.04;            // m at <= 1 m depth, scaled like the inlier threshold (z^2); inlier
                                    // RMS above this = "inconsistent matches"
  // Stage parameters.
  // OpenCV's StarDetector defaults except the response threshold: 20 instead of 30 gives ~40 % more
  // keypoints and a lower RPE on fr1_xyz (0.0282 vs 0.0315 m/s) for ~2 ms more per frame.
  StarParams star = [] {
    StarParams s;
    s.response_threshold = 20;
    return s;
  }();
  NarfParams narf;
  BrandParams brand;

  void loadFromConfigFile(const mrpt::config::CConfigFileBase& cfg, const std::string& section) override;
  void saveToConfigFile(mrpt::config::CConfigFileBase& cfg, const std::string& section) const override;
};

struct OdometryResult {
  bool success = false;
  bool started = false;                // the frame became the first reference: no motion, not a failure
  std::string failure;                 // why, when !success ("too few matches", "degenerate geometry", ...)
  mrpt::poses::CPose3D motion;         // current camera pose in the previous camera's frame (T_prev_curr)
  mrpt::math::CMatrixDouble66 covariance;  // of motion, (x y z yaw pitch roll), for CPose3DPDFGaussian
  int keypoints = 0, matches = 0, inliers = 0;  // matches and inliers over all frames matched (references)
  // The current frame's keypoints among the inliers, each once (matched in three references, a keypoint
  // is three inliers but one measurement of the current pose): what min_inliers asks for.
  int inlier_keypoints = 0;
  double rms_error = 0.0;              // m, over the inlier 3D correspondences
  StageTimes times;                    // this frame's per-stage wall time
  // Additions: which frame `motion` is relative to. Usually the previous frame; when that frame was
  // unusable itself (empty, textureless) the odometry keeps the last good frame as the reference.
  std::size_t reference_index = 0;     // Frame::index of the reference
  double reference_timestamp = 0.0;    // s
  int star_keypoints = 0, narf_keypoints = 0;  // before the union and the depth check
  // The fit's inlier correspondences (after the colour-time correction): points of this frame in its
  // camera coordinates and their matches in the reference frame's camera coordinates, m. A tracker
  // weighs them in its own estimate.
  Points3 inlier_current, inlier_reference;
  // The frame's point and normal maps the odometry computed for BRAND (null when it did not, e.g.
  // [brand] use_geometry = false): the pipeline hands them to the tracker, so they are computed once.
  std::shared_ptr<const FrameGeometry> geometry;
  // The frame's own keypoints (all of them, not only the inliers; null on "empty frame"): loop
  // closure keeps them for keyframes.
  std::shared_ptr<const DescribedKeypoints> features;
  // The colour-time correction: whether this frame's keypoints were moved at each frame's own velocity
  // (capture) rather than the interval's; with colour_time_velocity auto, whether capture fitted this
  // frame better (unset when not compared), and the recording's votes so far (ColourTimeEvidence).
  bool colour_time_capture = false;
  std::optional<bool> capture_fitted_better;
  // The frame's colour camera in its depth camera, once the motion after the frame is known too
  // (refitPrevious; Reconstruction::push sets it): the tracker places the colour image there.
  std::optional<Eigen::Isometry3d> colour_motion;
  int colour_time_votes = 0, colour_time_capture_votes = 0;
};

// The previous frame's motion fitted again once the frame after it has been (RgbdOdometry::refitPrevious).
struct OdometryRefit {
  mrpt::poses::CPose3D motion;             // as OdometryResult::motion, relative to the same reference
  mrpt::math::CMatrixDouble66 covariance;  // of motion
  Points3 inlier_current, inlier_reference;  // the same inliers, the current ones placed again
  double rms_error = 0.0;                  // m, over them
  Eigen::Isometry3d colour_motion;         // the frame's colour camera in its depth camera, as placed
};

class RgbdOdometry {
 public:
  explicit RgbdOdometry(const OdometryParams& params = {});
  ~RgbdOdometry();
  // Motion since the reference frame (OdometryResult::reference_index): the previous frame, or after
  // a failure the last frame whose motion was estimated (then, if that fails too, the failed frame);
  // the first frame with keypoints enough to match (or the first after reset()) returns success=false,
  // started=true, failure "first frame"; one before it fails with "too few keypoints".
  OdometryResult process(const Frame& frame);
  // The frames (Frame::index) a later result's reference_index may name (the reference, the last frame
  // with a pose, the last failed frame), with the older references matched beside them. However old.
  std::vector<std::size_t> heldFrames() const;
  // Capture mode: a frame's colour image taken after its depth has its keypoints placed at a velocity
  // extrapolated from the motion before it, until the next frame's motion is known. Called after
  // process(next), the motion process() returned for frame `index` (the frame before next), fitted again
  // on its inliers with them placed at that frame's velocity interpolated between both motions: the
  // velocity its keypoints are placed at as next's reference, so the two motions agree on where they
  // were. nullopt when there is nothing to refit (another mode, no colour offsets, a failed fit, next
  // not matched against it, keyframes, the paper's fit).
  std::optional<OdometryRefit> refitPrevious(std::size_t index) const;
  void reset();
  // Checkpoints: what the next frame is matched against (the reference, the older frames, the last
  // failed frame, their velocities) and the colour-time votes. An odometry with the same parameters
  // that loads the state continues exactly as the saved one would have.
  void saveState(std::ostream& os) const;
  // The state as it was before the last process(): what a reconstruction holding that frame back
  // (Reconstruction::push) saves, so that the frame is processed again after loadState. Before any
  // frame, the fresh state.
  void saveStateBeforeLastFrame(std::ostream& os) const;
  void loadState(std::istream& is);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace vofusion
