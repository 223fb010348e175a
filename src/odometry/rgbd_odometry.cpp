#include "vofusion/odometry/rgbd_odometry.h"

#include "vofusion/core/config.h"
#include "vofusion/core/depth_image.h"
#include "vofusion/core/pose_eigen.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <deque>
#include <future>
#include <limits>
#include <optional>
#include <stdexcept>

#include <Eigen/Dense>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "vofusion/features/hamming_matcher.h"
#include "vofusion/features/keypoint_union.h"
#include "vofusion/io/png_decode.h"  // asBgr8
#include "vofusion/odometry/colour_time_evidence.h"
#include "vofusion/core/state_archive.h"
#include "vofusion/core/task_thread.h"

namespace vofusion {

namespace {

// A camera's velocity at one instant, in its own coordinates: the colour-time correction moves a
// keypoint over the frame's colour offset with it.
struct CameraVelocity {
  Eigen::Vector3d angular = Eigen::Vector3d::Zero();  // rad/s, rotation axis times rate
  Eigen::Vector3d linear = Eigen::Vector3d::Zero();   // m/s

  // The mean velocity of the motion T_a_b (camera b in camera a) taken over dt seconds.
  static CameraVelocity over(const Eigen::Isometry3d& T_a_b, double dt) {
    const Eigen::AngleAxisd rot(T_a_b.linear());
    return {rot.angle() / dt * rot.axis(), T_a_b.translation() / dt};
  }
  // This velocity and `next`, the velocity `gap` seconds later, taken to change linearly: the value
  // `at` seconds after this one's instant (past `gap`: extrapolated).
  CameraVelocity towards(const CameraVelocity& next, double gap, double at) const {
    const double s = at / gap;
    return {angular + s * (next.angular - angular), linear + s * (next.linear - linear)};
  }
  // Camera pose `offset` seconds later in this instant's camera coordinates.
  Eigen::Isometry3d motionOver(double offset) const {
    Eigen::Isometry3d D = Eigen::Isometry3d::Identity();
    const double angle = angular.norm() * offset;
    if (angular.norm() > 0) D.linear() = Eigen::AngleAxisd(angle, angular.normalized()).toRotationMatrix();
    D.translation() = offset * linear;
    return D;
  }
};

// What a frame contributes to matching: described keypoints with their 3D points.
struct FrameFeatures {
  std::vector<cv::KeyPoint> keypoints;
  std::vector<cv::Point2f> pixels;  // keypoint positions, undistorted when asked to (homography input)
  cv::Mat descriptors;  // CV_8U, 32 bytes per keypoint
  Points3 points;       // camera frame, m
  std::size_t index = 0;
  double timestamp = 0.0;      // s, depth capture
  double colour_offset = 0.0;  // s, colour capture minus depth capture
  cv::Mat depth;               // kept (shared) to re-read depths at colour-time-corrected pixels
  CameraIntrinsics camera;
  // The mean velocity since the frame before it (set once its motion is known), and the velocity its
  // colour-time drift is taken at (the mean over its colour offset): that mean at first, interpolated once
  // the next frame's motion is known (final).
  std::optional<CameraVelocity> arrival, velocity;
  double arrival_seconds = 0.0;  // the interval `arrival` is the mean over
  bool velocity_final = false;
  int star = 0, narf = 0;
};

// Depth of a keypoint: the median or nearest valid reading of the (2r+1)^2 window (the centre reading
// alone is noisy at the edges where keypoints like to sit); 0 if the window has no reading.
float keypointDepth(const cv::Mat& depth, int x, int y, int r, bool nearest) {
  if (r <= 0) return depth.at<float>(y, x);
  r = std::min(r, 10);  // the buffer's reach ([odometry] depth_window and [narf] downsample are checked to fit)
  float v[21 * 21];
  int n = 0;
  for (int yy = std::max(0, y - r); yy <= std::min(depth.rows - 1, y + r); ++yy) {
    const float* d = depth.ptr<float>(yy);
    for (int xx = std::max(0, x - r); xx <= std::min(depth.cols - 1, x + r); ++xx)
      if (d[xx] > 0.f) v[n++] = d[xx];
  }
  if (n == 0) return 0.f;
  if (nearest) return *std::min_element(v, v + n);
  std::nth_element(v, v + n / 2, v + n);
  return v[n / 2];
}

}  // namespace

namespace {
// The string keys, resolved once (the key table has checked them): nothing compares strings per frame.
enum class KeypointSet { Union, Star, Narf };
enum class MotionMethod { Paper, Robust };
enum class ColourTimeVelocity { Interval, Capture, Auto };

KeypointSet keypointSetOf(const OdometryParams& p) {
  checkChoice("odometry", "keypoints", p.keypoints, kKeypointSets);
  return p.keypoints == "star" ? KeypointSet::Star : p.keypoints == "narf" ? KeypointSet::Narf : KeypointSet::Union;
}
MotionMethod motionMethodOf(const OdometryParams& p) {
  checkChoice("odometry", "motion_method", p.motion_method, kMotionMethods);
  return p.motion_method == "paper" ? MotionMethod::Paper : MotionMethod::Robust;
}
ColourTimeVelocity colourTimeVelocityOf(const OdometryParams& p) {
  checkChoice("odometry", "colour_time_velocity", p.colour_time_velocity, kColourTimeVelocities);
  if (p.colour_time_velocity == "auto") return ColourTimeVelocity::Auto;
  return p.colour_time_velocity == "capture" ? ColourTimeVelocity::Capture : ColourTimeVelocity::Interval;
}
bool nearestDepthOf(const OdometryParams& p) {
  checkChoice("odometry", "depth_mode", p.depth_mode, kDepthModes);
  return p.depth_mode == "min";
}
}  // namespace

struct RgbdOdometry::Impl {
  OdometryParams params;
  const KeypointSet keypoints;
  const MotionMethod motion;
  const bool nearest_depth;  // depth_mode min: a keypoint's depth is its window's nearest reading
  const ColourTimeVelocity colour_velocity;
  BrandExtractor brand;
  // auto: which velocity the recording's frames have fitted better so far; the correction follows it.
  ColourTimeEvidence evidence;
  bool vote_this_frame = false;  // auto: whether this frame's fit is compared (ColourTimeEvidence::wantsVote)
  ColourTimeVelocity activeVelocity() const {
    if (colour_velocity != ColourTimeVelocity::Auto) return colour_velocity;
    return evidence.captureFitsBetter() ? ColourTimeVelocity::Capture : ColourTimeVelocity::Interval;
  }
  // The keyframe new frames are matched against, and the last frame with a pose relative to it
  // (T_kf_last); with keyframes off both are the previous usable frame.
  std::optional<FrameFeatures> reference, last;
  // The newest frame whose motion failed (while `reference` stays the last good frame): the next
  // frame is matched against it only when the good reference no longer matches.
  std::optional<FrameFeatures> failed;
  Eigen::Isometry3d T_kf_last = Eigen::Isometry3d::Identity();
  // NARF's interest search beside the rest of each frame's extraction, always on this thread (a thread
  // per frame made its heap fresh pages each time); none when NARF runs inline or not at all.
  std::unique_ptr<TaskThread> narf_thread;
  explicit Impl(const OdometryParams& p)
      : params(p), keypoints(keypointSetOf(p)), motion(motionMethodOf(p)), nearest_depth(nearestDepthOf(p)),
        colour_velocity(colourTimeVelocityOf(p)), brand(p.brand) {
    if (keypoints != KeypointSet::Star && params.narf_concurrent) narf_thread = std::make_unique<TaskThread>("vof-narf");
  }

  // Extraction in two steps, so the STAR part can be matched while NARF still runs on its thread:
  // begin() detects STAR, builds the normals and describes the STAR keypoints; finish() waits for
  // NARF and appends its keypoints (those not within union_radius of a STAR one detected).
  struct Extraction {
    std::future<std::pair<std::vector<cv::KeyPoint>, double>> narf_job;
    std::vector<cv::KeyPoint> star;
    cv::Mat points, normals, smoothed;
    Extraction() = default;
    Extraction(const Extraction&) = delete;
    Extraction& operator=(const Extraction&) = delete;
    // A search not taken (the frame's extraction threw midway) is waited for: it reads the frame's depth,
    // and a TaskThread's future, unlike std::async's, does not wait when dropped.
    ~Extraction() {
      if (narf_job.valid()) narf_job.wait();
    }
  };
  FrameFeatures begin(const Frame& frame, Extraction& ex, StageTimes& times) const;
  void finish(const Frame& frame, Extraction& ex, FrameFeatures& f, StageTimes& times) const;
  // Describes kps and appends those with a descriptor and a depth reading to f.
  void describe(const Frame& frame, const Extraction& ex, std::vector<cv::KeyPoint> kps, FrameFeatures& f) const;
  // Depth reading for keypoint k at (distorted) pixel `at`: NARF keypoints take the nearest reading of
  // their block, others the configured window.
  float depthOf(const cv::Mat& depth, const cv::KeyPoint& k, cv::Point2f at) const;
  // Keypoint i of f where it was at the depth capture: its bearing is from the colour image, taken
  // colour_offset earlier or later; `drift` is the camera motion over that offset (depth-time camera
  // <- colour-time camera). The pixel moves by the predicted image motion and the depth is re-read there.
  Eigen::Vector3d atDepthTime(const FrameFeatures& f, int i, const Eigen::Isometry3d& drift) const;
  // Frames before the reference (frame to frame: the previous ones), with their pose in the
  // reference's coordinates (T_ref_frame), newest first.
  struct OlderFrame {
    const FrameFeatures* features;
    Eigen::Isometry3d T_ref_frame;
  };
  std::deque<std::pair<FrameFeatures, Eigen::Isometry3d>> older;

  // Matches of cur against ref after the Hamming limit and the homography filter; "" or why too few.
  // `split` holds the matching of cur's descriptors known so far (may be empty).
  std::string matchPair(const FrameFeatures& ref, const FrameFeatures& cur, CrossCheckedHammingMatcher& split, StageTimes& times,
                        std::vector<cv::DMatch>& matches) const;
  // Motion T_ref_cur from matching (against ref and the older frames; split[0] for ref, split[1 + i]
  // for older[i]), homography filter and one rigid fit over all correspondences; fills matches,
  // inliers, rms_error, failure and the stage times of r.
  // The colour-time correction's velocities from one fit: the mean over the fitted interval, and at the
  // reference's and the current frame's capture.
  struct FitVelocities {
    CameraVelocity interval, at_reference, at_current;
  };
  FitVelocities velocitiesOf(const FrameFeatures& ref, const FrameFeatures& cur, const Eigen::Isometry3d& T_ref_cur,
                             ColourTimeVelocity mode) const;
  // A correspondence: a current keypoint and a keypoint of ref or of an older frame (whose pose in
  // ref's coordinates is T_ref_frame).
  struct Corr {
    const FrameFeatures* frame;
    Eigen::Isometry3d T_ref_frame;
    int query, train;
  };
  // Every correspondence's two points at their frames' depth captures (src: current frame, dst: in
  // ref's coordinates), moved at the velocities of the motion T_ref_cur that `mode` takes.
  void placeAtDepthTime(const FrameFeatures& ref, const FrameFeatures& cur, const std::vector<Corr>& corr,
                        const Eigen::Isometry3d& T_ref_cur, ColourTimeVelocity mode, Points3& src, Points3& dst) const;
  // auto: whether capture's correction leaves a smaller median residual than interval's. Both start from
  // the fit before any correction and refine on its inliers (Gauss-Newton, no second RANSAC), so neither
  // is favoured by being the one the frame's fit used.
  bool captureFitsBetter(const FrameFeatures& ref, const FrameFeatures& cur, const std::vector<Corr>& corr,
                         const RigidFit& uncorrected) const;
  // The rigid fit of src onto dst, with the colour-time correction where the frames' colour and depth
  // were taken apart (`uncorrected`: the fit before it, when it ran).
  RigidFit fitAtDepthTime(const FrameFeatures& ref, const FrameFeatures& cur, const std::vector<Corr>& corr,
                          ColourTimeVelocity mode, Points3& src, Points3& dst, std::optional<RigidFit>& uncorrected) const;
  // The fit's counts and inlier points into the result (inlier_keypoints: distinct current keypoints).
  static void reportFit(const RigidFit& fit, const std::vector<Corr>& corr, const Points3& src, const Points3& dst,
                        OdometryResult& r);
  // What a fit leaves for refitPrevious(): the current keypoint of each inlier, and whether the keypoints
  // were placed at capture velocities (the correction ran in capture mode).
  struct FitDetail {
    std::vector<int> inlier_query;
    bool capture_corrected = false;
  };
  bool estimate(const FrameFeatures& ref, const std::vector<OlderFrame>& older, const FrameFeatures& cur,
                std::vector<CrossCheckedHammingMatcher>& split, OdometryResult& r, RigidFit& fit,
                FitVelocities& velocities, FitDetail* detail = nullptr) const;

  // process()'s steps. The frame's features, its STAR part matched against the references while NARF
  // runs (split[0]: the reference, split[1 + i]: older[i]); the result's keypoint counts and shared maps.
  FrameFeatures extract(const Frame& frame, const std::vector<OlderFrame>& older,
                        std::vector<CrossCheckedHammingMatcher>& split, OdometryResult& r) const;
  // The motion of the current frame relative to the last frame with a pose, as far as it got.
  struct Motion {
    bool ok = false;
    bool keep_keyframe = false;  // the keyframe matched well: it stays the reference
    RigidFit fit;
    Eigen::Isometry3d T_last_cur = Eigen::Isometry3d::Identity();
    Eigen::Isometry3d T_last_fitref = Eigen::Isometry3d::Identity();  // the fit's reference coordinates -> last's
    FitDetail detail;  // of the fit against the reference (cleared when another reference gave the motion)
  };
  // Against the keyframe first; a failed or weak keyframe match falls back to the last frame, and after
  // a failure to the failed frame (which then becomes the reference).
  Motion estimateMotion(FrameFeatures& cur, const std::vector<OlderFrame>& older_frames,
                        std::vector<CrossCheckedHammingMatcher>& split, OdometryResult& r);
  // Another reference when the first did not do: the motion and the correspondences come from it.
  bool tryReference(FrameFeatures& other, FrameFeatures& cur, Motion& mo, OdometryResult& r) const;
  // A fit's velocities become the reference's (final: the motions on both sides are known) and the
  // current frame's (its arrival, and its velocity until the next frame's motion is known).
  static void keepVelocities(FrameFeatures& ref, FrameFeatures& cur, const FitVelocities& v);
  // After a motion: the current frame becomes the last frame or the new reference.
  void advance(FrameFeatures cur, const Motion& mo);

  // A frame's fit as refitPrevious() places it again: the frame (a copy: advance() moves the original
  // on, and drops it with references 1), its inliers' keypoints and their matches in the reference's
  // coordinates (at their own depth captures, which stay), the fit, and the frame's final velocity once
  // the next frame's fit has set it.
  struct Refittable {
    FrameFeatures frame;
    std::vector<int> query;
    Points3 reference;
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    std::optional<CameraVelocity> final_velocity;
  };
  std::optional<Refittable> newest;    // the last processed frame's, waiting for the next frame's fit
  std::optional<Refittable> previous;  // the frame before it, final_velocity set: what refitPrevious() fits
  // process()'s bookkeeping for them: `mo` is frame cur's motion against `reference`.
  void keepRefittable(const FrameFeatures& cur, const Motion& mo, const OdometryResult& r);

  // What the next frame is matched against: what a checkpoint keeps (the refits need none of it: after
  // a checkpoint no frame waits for one).
  struct MatchingState {
    ColourTimeEvidence evidence;
    std::optional<FrameFeatures> reference, last, failed;
    std::deque<std::pair<FrameFeatures, Eigen::Isometry3d>> older;
    Eigen::Isometry3d T_kf_last = Eigen::Isometry3d::Identity();
  };
  MatchingState matchingState() const { return {evidence, reference, last, failed, older, T_kf_last}; }
  // As it was before the last process() (saveStateBeforeLastFrame); copies share the images.
  std::optional<MatchingState> before_last;
  static void writeState(std::ostream& os, const MatchingState& s);
};

FrameFeatures RgbdOdometry::Impl::begin(const Frame& frame, Extraction& ex, StageTimes& times) const {
  FrameFeatures f;
  f.index = frame.index;
  f.timestamp = frame.timestamp;
  f.colour_offset = frame.colour_offset;
  f.depth = frame.depth;
  f.camera = frame.camera;
  // NARF is the longest chain: its border extraction first, on every core, then its interest search
  // (serial) on its own thread beside everything else.
  if (keypoints != KeypointSet::Star && params.narf_concurrent) {
    NarfPrepared prepared;
    {
      ScopedStageTimer t(times, "narf_prepare");
      prepared = prepareNarf(frame.depth, frame.camera, params.narf);
    }
    ex.narf_job = narf_thread->run([prepared = std::move(prepared)] {
      const auto t0 = std::chrono::steady_clock::now();
      auto k = detectNarf(prepared);
      return std::make_pair(std::move(k), secondsSince(t0));
    });
  }

  cv::Mat gray;
  {
    ScopedStageTimer t(times, "grey");
    // A library caller's BGRA or 16-bit colour is read as the loaders read it (8-bit BGR).
    if (frame.rgb.type() == CV_8UC1) gray = frame.rgb;
    else cv::cvtColor(frame.rgb.type() == CV_8UC3 ? frame.rgb : asBgr8(frame.rgb), gray, cv::COLOR_BGR2GRAY);
  }
  if (keypoints != KeypointSet::Narf) {
    ScopedStageTimer t(times, "star");
    ex.star = detectStar(gray, params.star);
  }
  {
    ScopedStageTimer t(times, "normals");
    ex.points = depthToPointMap(frame.depth, frame.camera);
    if (params.brand.use_geometry)
      ex.normals = computeNormalMap(ex.points, params.brand.normal_window, float(params.brand.max_depth_step));
    else
      ex.normals = cv::Mat(ex.points.size(), CV_32FC3, cv::Scalar::all(std::nan("")));
    ex.smoothed = brand.smooth(gray);
  }
  f.star = int(ex.star.size());
  {
    ScopedStageTimer t(times, "brand");
    describe(frame, ex, ex.star, f);
  }
  return f;
}

void RgbdOdometry::Impl::finish(const Frame& frame, Extraction& ex, FrameFeatures& f, StageTimes& times) const {
  if (keypoints == KeypointSet::Star) return;
  std::vector<cv::KeyPoint> narf;
  if (ex.narf_job.valid()) {
    const auto t0 = std::chrono::steady_clock::now();
    auto [k, secs] = ex.narf_job.get();
    narf = std::move(k);
    times.add("narf", secs);
    times.add("narf_wait", secondsSince(t0));
  } else {
    ScopedStageTimer t(times, "narf");
    narf = detectNarf(frame.depth, frame.camera, params.narf);
  }
  f.narf = int(narf.size());
  ScopedStageTimer t(times, "brand");
  // The union: STAR keypoints first, then the NARF ones that are not duplicates of them, against every
  // STAR keypoint detected, kept or not. Against the kept ones only (a NARF keypoint beside a STAR blob
  // that BRAND or the depth dropped then stays) was measured twice and does not carry over (rpy -0.4 mm,
  // its halves -0.6 / 0 mm, the loop scene's seed 5 +2.5 mm): bench/results/2026-12-05-narf-keypoint-pixel.md.
  std::vector<cv::KeyPoint> merged = mergeKeypoints(ex.star, narf, float(params.union_radius));
  describe(frame, ex, std::vector<cv::KeyPoint>(merged.begin() + std::ptrdiff_t(ex.star.size()), merged.end()), f);
}

void RgbdOdometry::Impl::describe(const Frame& frame, const Extraction& ex, std::vector<cv::KeyPoint> kps,
                                  FrameFeatures& f) const {
  cv::Mat desc;
  brand.computeSmoothed(ex.smoothed, ex.points, ex.normals, kps, desc);
  // Pixels to 3D: the depth image is registered to the distorted colour image, so the reading is
  // taken at the keypoint's own pixel and the ray through its undistorted position.
  std::vector<cv::Point2f> px(kps.size());
  for (std::size_t i = 0; i < px.size(); ++i) px[i] = kps[i].pt;
  const CameraIntrinsics& c = frame.camera;
  const bool distorted = std::any_of(c.dist.begin(), c.dist.end(), [](double d) { return d != 0.0; });
  if (params.undistort && distorted && !px.empty()) {
    const cv::Matx33d K(c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1);
    cv::undistortPoints(px, px, K, std::vector<double>(c.dist.begin(), c.dist.end()), cv::noArray(), K);
  }
  if (f.descriptors.empty()) f.descriptors = cv::Mat(0, 32, CV_8U);
  for (std::size_t i = 0; i < px.size(); ++i) {
    const float z = depthOf(frame.depth, kps[i], kps[i].pt);
    if (!(z > 0.f)) continue;
    f.points.emplace_back((px[i].x - c.cx) * z / c.fx, (px[i].y - c.cy) * z / c.fy, z);
    f.pixels.push_back(px[i]);
    f.keypoints.push_back(kps[i]);
    f.descriptors.push_back(desc.row(int(i)));
  }
}

float RgbdOdometry::Impl::depthOf(const cv::Mat& depth, const cv::KeyPoint& k, cv::Point2f at) const {
  const int x = cvRound(at.x), y = cvRound(at.y);
  if (x < 0 || y < 0 || x >= depth.cols || y >= depth.rows) return 0.f;
  // A NARF keypoint stands for a block of the reduced depth image whose value is the block's nearest
  // reading (it sits on foreground borders): take that reading, not the centre pixel's.
  if (k.class_id == 1 && params.narf.downsample > 1) return narfBlockDepth(depth, at, params.narf.downsample);
  return keypointDepth(depth, x, y, params.depth_window, nearest_depth);
}

Eigen::Vector3d RgbdOdometry::Impl::atDepthTime(const FrameFeatures& f, int i, const Eigen::Isometry3d& drift) const {
  const CameraIntrinsics& c = f.camera;
  const Eigen::Vector3d q = drift * f.points[i];
  if (!(q.z() > 0)) return f.points[i];
  const cv::Point2f moved(float(c.fx * q.x() / q.z() + c.cx), float(c.fy * q.y() / q.z() + c.cy));
  // The depth image is indexed by distorted pixels; over a pixel or two the distortion only shifts.
  const float z = depthOf(f.depth, f.keypoints[i], f.keypoints[i].pt + (moved - f.pixels[i]));
  if (!(z > 0.f)) return q;
  return {(moved.x - c.cx) * z / c.fx, (moved.y - c.cy) * z / c.fy, z};
}

RgbdOdometry::RgbdOdometry(const OdometryParams& params) : impl_(std::make_unique<Impl>(params)) {}
RgbdOdometry::~RgbdOdometry() = default;
void RgbdOdometry::reset() {
  impl_->newest.reset();
  impl_->previous.reset();
  impl_->before_last.reset();
  impl_->reference.reset();
  impl_->last.reset();
  impl_->failed.reset();
  impl_->older.clear();
}

std::string RgbdOdometry::Impl::matchPair(const FrameFeatures& ref, const FrameFeatures& cur, CrossCheckedHammingMatcher& split,
                                          StageTimes& times, std::vector<cv::DMatch>& matches) const {
  const OdometryParams& P = params;
  // Brute-force Hamming matching with cross-check (query = current, train = reference).
  matches.clear();
  {
    ScopedStageTimer t(times, "matching");
    split.add(cur.descriptors, ref.descriptors);
    for (const auto& m : split.crossChecked())
      if (m.distance <= P.max_hamming) matches.push_back(m);
  }
  if (int(matches.size()) < std::max(P.min_matches, 4)) return "too few matches";
  if (P.use_homography) {
    ScopedStageTimer t(times, "homography");
    std::vector<cv::Point2f> a, b;
    for (const auto& m : matches) a.push_back(cur.pixels[m.queryIdx]), b.push_back(ref.pixels[m.trainIdx]);
    std::vector<uchar> mask;
    const cv::Mat H = cv::findHomography(a, b, cv::RANSAC, P.homography_threshold, mask, 2000, 0.995);
    if (H.empty()) return "degenerate geometry (no homography)";
    std::vector<cv::DMatch> kept;
    for (std::size_t i = 0; i < matches.size(); ++i)
      if (mask[i]) kept.push_back(matches[i]);
    matches.swap(kept);
  }
  if (int(matches.size()) < P.min_matches) return "too few matches";
  return "";
}

RgbdOdometry::Impl::FitVelocities RgbdOdometry::Impl::velocitiesOf(const FrameFeatures& ref, const FrameFeatures& cur,
                                                                  const Eigen::Isometry3d& T_ref_cur,
                                                                  ColourTimeVelocity mode) const {
  const double dt = cur.timestamp - ref.timestamp;
  FitVelocities v;
  v.interval = CameraVelocity::over(T_ref_cur, dt);
  v.at_reference = v.at_current = v.interval;
  if (mode != ColourTimeVelocity::Capture) return v;
  if (ref.velocity_final) {
    v.at_reference = *ref.velocity;
  } else if (ref.arrival && ref.arrival_seconds > 0) {
    // Two mean velocities, each taken as the velocity at its interval's middle, changing linearly:
    // interpolated halfway through the reference's colour offset, the mean velocity over that offset
    // (at the capture itself the shake's ATE was 0.0258 m with the refit, 0.0235 there). The current
    // frame keeps the interval's mean until refitPrevious(): extrapolating the two to its capture
    // measured worse (the shake's frame-to-frame motion 9.6 vs 6.3 mm off).
    const double gap = 0.5 * (ref.arrival_seconds + dt);
    v.at_reference = ref.arrival->towards(v.interval, gap, 0.5 * ref.arrival_seconds + 0.5 * ref.colour_offset);
  }
  return v;
}

void RgbdOdometry::Impl::placeAtDepthTime(const FrameFeatures& ref, const FrameFeatures& cur, const std::vector<Corr>& corr,
                                          const Eigen::Isometry3d& T_ref_cur, ColourTimeVelocity mode, Points3& src,
                                          Points3& dst) const {
  const FitVelocities v = velocitiesOf(ref, cur, T_ref_cur, mode);
  const bool own = mode == ColourTimeVelocity::Capture;
  const auto drift = [&](const FrameFeatures& f) {  // f's colour-time camera in its depth-time camera
    const CameraVelocity& at = &f == &ref ? v.at_reference : own && f.velocity ? *f.velocity : v.interval;
    return at.motionOver(f.colour_offset);
  };
  const Eigen::Isometry3d dc = v.at_current.motionOver(cur.colour_offset);
  for (std::size_t k = 0; k < corr.size(); ++k) {
    const Corr& c = corr[k];
    src[k] = atDepthTime(cur, c.query, dc);
    dst[k] = c.T_ref_frame * atDepthTime(*c.frame, c.train, drift(*c.frame));
  }
}

namespace {
// Median over all correspondences of |T src - dst|, each divided by max(1, z^2) (the Kinect noise's
// growth, as the inlier threshold): which placement of the points the data agree with.
double medianResidualAt1m(const Points3& src, const Points3& dst, const Eigen::Isometry3d& T) {
  if (src.empty()) return 0.0;
  std::vector<double> e(src.size());
  for (std::size_t k = 0; k < src.size(); ++k) e[k] = (T * src[k] - dst[k]).norm() / std::max(1.0, src[k].z() * src[k].z());
  std::nth_element(e.begin(), e.begin() + std::ptrdiff_t(e.size() / 2), e.end());
  return e[e.size() / 2];
}
}  // namespace

bool RgbdOdometry::Impl::captureFitsBetter(const FrameFeatures& ref, const FrameFeatures& cur, const std::vector<Corr>& corr,
                                           const RigidFit& uncorrected) const {
  const RobustFitOptions& o = params.robust;
  const auto residualAfter = [&](ColourTimeVelocity mode, int passes) {
    Points3 src(corr.size()), dst(corr.size());
    Eigen::Isometry3d T = uncorrected.T;
    for (int pass = 0; pass < passes; ++pass) {
      placeAtDepthTime(ref, cur, corr, T, mode, src, dst);
      T = refineGaussNewton(src, dst, uncorrected.inliers, T, std::max(1, o.gauss_newton_iterations), nullptr, o.ray_noise, o.cauchy);
    }
    return medianResidualAt1m(src, dst, T);
  };
  return residualAfter(ColourTimeVelocity::Capture, 3) < residualAfter(ColourTimeVelocity::Interval, 1);
}

RigidFit RgbdOdometry::Impl::fitAtDepthTime(const FrameFeatures& ref, const FrameFeatures& cur, const std::vector<Corr>& corr,
                                            ColourTimeVelocity mode, Points3& src, Points3& dst,
                                            std::optional<RigidFit>& uncorrected) const {
  const OdometryParams& P = params;
  // Only the last fit's covariance is reported: the fits before it skip computing theirs.
  auto fitMotion = [&](bool last) {
    return motion == MotionMethod::Paper ? fitPaper(src, dst, P.paper) : fitRobust(src, dst, P.robust, last);
  };
  // Bearings are from colour, depths from depth images taken up to 20 ms apart: move every point to
  // its frame's depth capture at the camera's velocity and fit again. The velocities come from the
  // fit they correct: "capture" repeats the correction on its own result (three passes; the shake's
  // ATE is 0.0129 / 0.0095 / 0.0084 m in mode odometry after 2 / 3 / 4); "interval" corrects once.
  const bool offsets = cur.colour_offset != 0.0 ||
                       std::any_of(corr.begin(), corr.end(), [](const Corr& c) { return c.frame->colour_offset != 0.0; });
  // The velocity is the motion over the interval; carried over more than three of it (stamps 2 ms
  // apart, colour 15 ms off) it moved keypoints by a guess: no correction then (the tracker's
  // motionOver clamps there instead: it has no uncorrected estimate to keep).
  double largest_offset = std::abs(cur.colour_offset);
  for (const Corr& c : corr) largest_offset = std::max(largest_offset, std::abs(c.frame->colour_offset));
  const bool correct = P.colour_time && offsets && cur.timestamp > ref.timestamp &&
                       largest_offset <= 3.0 * (cur.timestamp - ref.timestamp);
  const int passes = !correct ? 0 : mode == ColourTimeVelocity::Capture ? 3 : 1;
  RigidFit fit = fitMotion(passes == 0);
  if (correct) uncorrected = fit;
  for (int pass = 0; pass < passes && fit.ok; ++pass) {
    placeAtDepthTime(ref, cur, corr, fit.T, mode, src, dst);
    fit = fitMotion(pass == passes - 1);
  }
  return fit;
}

void RgbdOdometry::Impl::reportFit(const RigidFit& fit, const std::vector<Corr>& corr, const Points3& src, const Points3& dst,
                                   OdometryResult& r) {
  r.matches = int(corr.size());
  r.inliers = int(fit.inliers.size());
  r.rms_error = fit.rms;
  r.inlier_current.clear();
  r.inlier_reference.clear();
  std::vector<int> inlier_keypoints;
  for (const int k : fit.inliers) {
    r.inlier_current.push_back(src[k]);
    r.inlier_reference.push_back(dst[k]);
    inlier_keypoints.push_back(corr[std::size_t(k)].query);
  }
  std::sort(inlier_keypoints.begin(), inlier_keypoints.end());
  r.inlier_keypoints = int(std::unique(inlier_keypoints.begin(), inlier_keypoints.end()) - inlier_keypoints.begin());
}

bool RgbdOdometry::Impl::estimate(const FrameFeatures& ref, const std::vector<OlderFrame>& older,
                                  const FrameFeatures& cur, std::vector<CrossCheckedHammingMatcher>& split, OdometryResult& r,
                                  RigidFit& fit, FitVelocities& velocities, FitDetail* detail) const {
  const OdometryParams& P = params;
  auto fail = [&r](const std::string& why) {
    r.failure = why;
    return false;
  };
  r.matches = r.inliers = r.inlier_keypoints = 0;
  r.rms_error = 0.0;
  // Correspondences: current point -> a reference point in the reference frame's coordinates. Older
  // frames' points come through their pose in the reference frame, so one fit sees every match.
  std::vector<Corr> corr;
  std::vector<cv::DMatch> matches;
  split.resize(1 + older.size());
  const std::string why = matchPair(ref, cur, split[0], r.times, matches);
  r.matches = int(matches.size());
  if (!why.empty()) return fail(why);
  for (const auto& m : matches) corr.push_back({&ref, Eigen::Isometry3d::Identity(), m.queryIdx, m.trainIdx});
  for (std::size_t i = 0; i < older.size(); ++i)
    if (matchPair(*older[i].features, cur, split[1 + i], r.times, matches).empty())
      for (const auto& m : matches) corr.push_back({older[i].features, older[i].T_ref_frame, m.queryIdx, m.trainIdx});

  // T_ref_cur maps current-frame points onto the reference frame's.
  Points3 src(corr.size()), dst(corr.size());
  for (std::size_t k = 0; k < corr.size(); ++k) {
    src[k] = cur.points[corr[k].query];
    dst[k] = corr[k].T_ref_frame * corr[k].frame->points[corr[k].train];
  }
  const ColourTimeVelocity mode = activeVelocity();
  std::optional<RigidFit> uncorrected;  // the fit before the colour-time correction, when there was one
  {
    ScopedStageTimer t(r.times, "motion");
    fit = fitAtDepthTime(ref, cur, corr, mode, src, dst, uncorrected);
  }
  r.colour_time_capture = mode == ColourTimeVelocity::Capture;
  // Offsets under a millisecond move no keypoint measurably: no evidence either way.
  const bool informative = std::max(std::abs(cur.colour_offset), std::abs(ref.colour_offset)) >= ColourTimeEvidence::kMinOffset;
  if (vote_this_frame && uncorrected && uncorrected->ok && fit.ok && informative) {
    ScopedStageTimer t(r.times, "colour_time_vote");
    r.capture_fitted_better = captureFitsBetter(ref, cur, corr, *uncorrected);
  }
  // The history capture needs (kept whatever the mode: auto may switch to capture).
  if (fit.ok && cur.timestamp > ref.timestamp) velocities = velocitiesOf(ref, cur, fit.T, ColourTimeVelocity::Capture);
  reportFit(fit, corr, src, dst, r);
  if (detail) {
    detail->capture_corrected = uncorrected.has_value() && mode == ColourTimeVelocity::Capture;
    detail->inlier_query.clear();
    for (const int k : fit.inliers) detail->inlier_query.push_back(corr[std::size_t(k)].query);
  }
  if (!fit.ok) return fail(fit.failure);
  if (r.inlier_keypoints < P.min_inliers) return fail("too few inliers");
  if (secondaryExtent(src, fit.inliers) < P.min_extent) return fail("degenerate geometry (inliers nearly collinear)");
  // Against the noise the inliers were chosen with (it grows with z^2): far scenes are not inconsistent.
  if (fit.rms_at_1m > P.max_rms) return fail("inconsistent matches (inlier RMS too large)");
  return true;
}

namespace {
OdometryResult failed(OdometryResult& r, const std::string& why) {
  r.success = false;
  r.failure = why;
  return r;
}

// r with the motion found, as an MRPT pose, and the covariance of the fit that gave it
// (keyframe-to-current when a keyframe was kept: an upper bound on the frame-to-frame uncertainty).
OdometryResult succeeded(OdometryResult& r, const Eigen::Isometry3d& T_last_cur, const Eigen::Matrix<double, 6, 6>& covariance) {
  r.motion = toMrpt(T_last_cur);
  r.covariance = mrpt::math::CMatrixDouble66(covariance);
  r.failure.clear();
  r.success = true;
  return r;
}

// Metric depth, and colour of its size: keypoints found in the colour image are looked up in the
// depth's maps, pixel for pixel.
void requireRegisteredDepth(const Frame& frame) {
  requireMetricDepth(frame.depth, "RgbdOdometry");
  if (frame.rgb.size() != frame.depth.size())
    throw std::invalid_argument("RgbdOdometry: colour " + std::to_string(frame.rgb.cols) + "x" +
                                std::to_string(frame.rgb.rows) + " and depth " + std::to_string(frame.depth.cols) +
                                "x" + std::to_string(frame.depth.rows) + " differ in size");
}
}  // namespace

FrameFeatures RgbdOdometry::Impl::extract(const Frame& frame, const std::vector<OlderFrame>& older,
                                          std::vector<CrossCheckedHammingMatcher>& split, OdometryResult& r) const {
  Extraction ex;
  FrameFeatures cur = begin(frame, ex, r.times);
  split = std::vector<CrossCheckedHammingMatcher>(1 + older.size());
  if (reference && ex.narf_job.valid()) {
    ScopedStageTimer t(r.times, "matching");
    split[0].add(cur.descriptors, reference->descriptors);
    for (std::size_t i = 0; i < older.size(); ++i) split[1 + i].add(cur.descriptors, older[i].features->descriptors);
  }
  finish(frame, ex, cur, r.times);
  if (params.brand.use_geometry) r.geometry = std::make_shared<const FrameGeometry>(FrameGeometry{ex.points, ex.normals});
  r.features = std::make_shared<const DescribedKeypoints>(DescribedKeypoints{cur.descriptors, cur.points});
  r.keypoints = int(cur.keypoints.size());
  r.star_keypoints = cur.star;
  r.narf_keypoints = cur.narf;
  return cur;
}

void RgbdOdometry::Impl::keepVelocities(FrameFeatures& ref, FrameFeatures& cur, const FitVelocities& v) {
  // A velocity is a motion over its interval: kept only where it will be carried over at most three of
  // it, the correction's own limit (fitAtDepthTime). Stamps 1 us apart made a frame's motion 10^4 m/s,
  // and the next frame's reference keypoints moved 30 m over their 9 ms colour offset. Neither frame
  // keeps one then: the next interval's stands in.
  const double dt = cur.timestamp - ref.timestamp;
  if (!(dt > 0.0 && std::max(std::abs(ref.colour_offset), std::abs(cur.colour_offset)) <= 3.0 * dt)) return;
  if (!ref.velocity_final) ref.velocity = v.at_reference;
  ref.velocity_final = true;
  cur.arrival = v.interval;
  cur.arrival_seconds = dt;
  cur.velocity = v.at_current;
}

bool RgbdOdometry::Impl::tryReference(FrameFeatures& other, FrameFeatures& cur, Motion& mo, OdometryResult& r) const {
  OdometryResult r2;
  RigidFit fit2;
  FitVelocities velocities2;
  std::vector<CrossCheckedHammingMatcher> fresh;
  const bool ok2 = estimate(other, {}, cur, fresh, r2, fit2, velocities2);
  r.times.merge(r2.times);
  if (!ok2 && mo.ok) return false;
  if (ok2) keepVelocities(other, cur, velocities2);
  mo.fit = fit2;
  mo.detail = {};
  mo.T_last_cur = fit2.T;
  mo.T_last_fitref.setIdentity();
  r.matches = r2.matches, r.inliers = r2.inliers, r.inlier_keypoints = r2.inlier_keypoints, r.rms_error = r2.rms_error,
  r.failure = r2.failure;
  r.colour_time_capture = r2.colour_time_capture, r.capture_fitted_better = r2.capture_fitted_better;
  r.inlier_current = std::move(r2.inlier_current);
  r.inlier_reference = std::move(r2.inlier_reference);
  mo.ok = ok2;
  return ok2;
}

RgbdOdometry::Impl::Motion RgbdOdometry::Impl::estimateMotion(FrameFeatures& cur, const std::vector<OlderFrame>& older_frames,
                                                              std::vector<CrossCheckedHammingMatcher>& split,
                                                              OdometryResult& r) {
  Motion mo;
  FitVelocities velocities;
  vote_this_frame = colour_velocity == ColourTimeVelocity::Auto && evidence.wantsVote();
  mo.ok = estimate(*reference, older_frames, cur, split, r, mo.fit, velocities, &mo.detail);
  if (mo.ok) keepVelocities(*reference, cur, velocities);
  mo.T_last_cur = T_kf_last.inverse() * mo.fit.T;
  mo.T_last_fitref = T_kf_last.inverse();
  mo.keep_keyframe = params.keyframe_min_inliers > 0 && mo.ok && r.inliers >= params.keyframe_min_inliers;
  if (!mo.keep_keyframe && last) tryReference(*last, cur, mo, r);
  // The last good reference no longer matches after a failure: try the failed frame (the caller knows
  // its pose from elsewhere, e.g. ICP); it becomes the reference.
  if (!mo.ok && failed && tryReference(*failed, cur, mo, r)) {
    r.reference_index = failed->index;
    r.reference_timestamp = failed->timestamp;
    reference = std::move(*failed);
    older.clear();
    last.reset();
    T_kf_last.setIdentity();
  }
  return mo;
}

void RgbdOdometry::Impl::advance(FrameFeatures cur, const Motion& mo) {
  if (mo.keep_keyframe) {
    T_kf_last = mo.fit.T;
    last = std::move(cur);
    return;
  }
  // The previous frame joins the older ones, all re-expressed in the current frame.
  std::deque<std::pair<FrameFeatures, Eigen::Isometry3d>> next;
  const Eigen::Isometry3d T_cur_last = mo.T_last_cur.inverse();
  if (params.keyframe_min_inliers <= 0 && params.references > 1) {
    next.emplace_back(std::move(*reference), T_cur_last);
    for (auto& [f, T] : older)
      if (int(next.size()) < params.references - 1) next.emplace_back(std::move(f), T_cur_last * T);
  }
  older = std::move(next);
  reference = std::move(cur);
  last.reset();
  T_kf_last.setIdentity();
}

void RgbdOdometry::Impl::keepRefittable(const FrameFeatures& cur, const Motion& mo, const OdometryResult& r) {
  previous.reset();
  // The frame before this one is refitted when this fit was against it and gave it its final velocity.
  if (newest && mo.ok && mo.detail.capture_corrected && reference && reference->index == newest->frame.index &&
      reference->velocity_final && reference->velocity) {
    previous = std::move(newest);
    previous->final_velocity = *reference->velocity;
  }
  newest.reset();
  // Frame to frame and the robust fit only: a keyframe's motion is not the frame's own interval, and the
  // paper's fit has no Gauss-Newton to refine with.
  if (!mo.ok || !mo.detail.capture_corrected || mo.keep_keyframe || params.keyframe_min_inliers > 0 ||
      motion != MotionMethod::Robust)
    return;
  newest = Refittable{cur, mo.detail.inlier_query, r.inlier_reference, mo.fit.T, std::nullopt};
}

std::optional<OdometryRefit> RgbdOdometry::refitPrevious(std::size_t index) const {
  const Impl& m = *impl_;
  if (!m.previous || m.previous->frame.index != index) return std::nullopt;
  const Impl::Refittable& p = *m.previous;
  const Eigen::Isometry3d drift = p.final_velocity->motionOver(p.frame.colour_offset);
  OdometryRefit out;
  out.colour_motion = drift;
  out.inlier_current.resize(p.query.size());
  for (std::size_t i = 0; i < p.query.size(); ++i) out.inlier_current[i] = m.atDepthTime(p.frame, p.query[i], drift);
  out.inlier_reference = p.reference;
  const RobustFitOptions& o = m.params.robust;
  Eigen::Matrix<double, 6, 6> covariance;
  const Eigen::Isometry3d T = refineGaussNewton(out.inlier_current, out.inlier_reference, {}, p.T,
                                                std::max(1, o.gauss_newton_iterations), &covariance, o.ray_noise, o.cauchy);
  double sq = 0.0;
  for (std::size_t i = 0; i < p.query.size(); ++i) sq += (T * out.inlier_current[i] - out.inlier_reference[i]).squaredNorm();
  out.rms_error = p.query.empty() ? 0.0 : std::sqrt(sq / double(p.query.size()));
  out.motion = toMrpt(T);
  out.covariance = mrpt::math::CMatrixDouble66(covariance);
  return out;
}

std::vector<std::size_t> RgbdOdometry::heldFrames() const {
  const Impl& m = *impl_;
  std::vector<std::size_t> held;
  for (const auto* f : {&m.reference, &m.last, &m.failed})
    if (*f) held.push_back((*f)->index);
  for (const auto& [f, T] : m.older) held.push_back(f.index);
  return held;
}

OdometryResult RgbdOdometry::process(const Frame& frame) {
  OdometryResult r;
  r.covariance.setIdentity();
  const OdometryParams& P = impl_->params;
  Impl& m = *impl_;
  // The state this frame is matched against, kept once the frame is done (not when it threw: the state
  // before it is then the one kept already).
  struct KeepBefore {
    Impl& m;
    Impl::MatchingState before;
    const int exceptions = std::uncaught_exceptions();
    ~KeepBefore() {
      if (std::uncaught_exceptions() == exceptions) m.before_last = std::move(before);
    }
  } keep_before{m, m.matchingState()};
  if (!frame.valid()) return failed(r, "empty frame");
  requireRegisteredDepth(frame);
  // Frame to frame, the frames before the previous one join the fit (references > 1).
  std::vector<Impl::OlderFrame> older;
  if (P.keyframe_min_inliers <= 0)
    for (const auto& [f, T] : m.older) older.push_back({&f, T});
  std::vector<CrossCheckedHammingMatcher> split;
  FrameFeatures cur = m.extract(frame, older, split, r);
  // `motion` is relative to the last frame with a pose (the previous one unless that failed); before
  // the start, to the frame itself.
  const FrameFeatures* last = m.last ? &*m.last : m.reference ? &*m.reference : nullptr;
  r.reference_index = last ? last->index : frame.index;
  r.reference_timestamp = last ? last->timestamp : frame.timestamp;
  // A frame with almost nothing to match (textureless, no depth) cannot be anyone's reference: a
  // sensor's blank first frames leave the start to the first frame with keypoints, and later the last
  // good frame is kept so that the next frame can bridge the gap.
  if (int(cur.keypoints.size()) < P.min_matches) return failed(r, "too few keypoints (textureless or no depth)");
  if (!m.reference) {
    m.older.clear();
    m.reference = std::move(cur);
    m.last.reset();
    m.T_kf_last.setIdentity();
    r.started = true;
    return failed(r, "first frame");
  }
  const Impl::Motion mo = m.estimateMotion(cur, older, split, r);
  m.keepRefittable(cur, mo, r);
  if (!mo.ok) {
    // The last good frame stays the reference (its pose is known): the next frame bridges the gap.
    m.failed = std::move(cur);
    return failed(r, r.failure);
  }
  m.failed.reset();
  if (r.capture_fitted_better) m.evidence.add(*r.capture_fitted_better);
  r.colour_time_votes = m.evidence.compared();
  r.colour_time_capture_votes = m.evidence.captureBetter();
  for (auto& p : r.inlier_reference) p = mo.T_last_fitref * p;
  m.advance(std::move(cur), mo);

  return succeeded(r, mo.T_last_cur, mo.fit.covariance);
}


// Checkpoints ----------------------------------------------------------------------------------------

namespace {

void writeVelocity(state::Archive& a, const CameraVelocity& v) {
  state::write(a, v.angular);
  state::write(a, v.linear);
}
void readVelocity(state::Archive& a, CameraVelocity& v) {
  state::read(a, v.angular);
  state::read(a, v.linear);
}

void writeFeatures(state::Archive& a, const FrameFeatures& f) {
  state::write(a, f.keypoints);
  state::write(a, f.pixels);
  state::write(a, f.descriptors);
  state::write(a, f.points);
  a << uint64_t(f.index) << f.timestamp << f.colour_offset;
  state::write(a, f.depth);
  state::write(a, f.camera);
  state::writeOptional(a, f.arrival, [&](const CameraVelocity& v) { writeVelocity(a, v); });
  state::writeOptional(a, f.velocity, [&](const CameraVelocity& v) { writeVelocity(a, v); });
  a << f.arrival_seconds << f.velocity_final << int32_t(f.star) << int32_t(f.narf);
}

void readFeatures(state::Archive& a, FrameFeatures& f) {
  state::read(a, f.keypoints);
  state::read(a, f.pixels);
  state::read(a, f.descriptors);
  state::read(a, f.points);
  uint64_t index = 0;
  a >> index >> f.timestamp >> f.colour_offset;
  f.index = index;
  state::read(a, f.depth);
  state::read(a, f.camera);
  state::readOptional(a, f.arrival, [&](CameraVelocity& v) { readVelocity(a, v); });
  state::readOptional(a, f.velocity, [&](CameraVelocity& v) { readVelocity(a, v); });
  int32_t star = 0, narf = 0;
  a >> f.arrival_seconds >> f.velocity_final >> star >> narf;
  f.star = star, f.narf = narf;
}

}  // namespace

void RgbdOdometry::Impl::writeState(std::ostream& os, const MatchingState& s) {
  auto a = state::archiveOf(os);
  state::tag(a, "odometry");
  s.evidence.saveState(a);
  for (const auto* f : {&s.reference, &s.last, &s.failed})
    state::writeOptional(a, *f, [&](const FrameFeatures& x) { writeFeatures(a, x); });
  a << uint64_t(s.older.size());
  for (const auto& [f, T] : s.older) {
    writeFeatures(a, f);
    state::write(a, T);
  }
  state::write(a, s.T_kf_last);
}

void RgbdOdometry::saveState(std::ostream& os) const { Impl::writeState(os, impl_->matchingState()); }

void RgbdOdometry::saveStateBeforeLastFrame(std::ostream& os) const {
  Impl::writeState(os, impl_->before_last ? *impl_->before_last : Impl::MatchingState());
}

void RgbdOdometry::loadState(std::istream& is) {
  Impl& s = *impl_;
  auto a = state::archiveOf(is);
  state::expectTag(a, "odometry");
  s.newest.reset();  // a checkpoint is taken between frames: no frame waits for its refit
  s.previous.reset();
  s.before_last.reset();
  s.evidence.loadState(a);
  for (auto* f : {&s.reference, &s.last, &s.failed})
    state::readOptional(a, *f, [&](FrameFeatures& x) { readFeatures(a, x); });
  uint64_t n = 0;
  a >> n;
  if (n > 1024) throw std::runtime_error("checkpoint: bad odometry history");
  s.older.clear();
  for (uint64_t i = 0; i < n; ++i) {
    s.older.emplace_back();
    readFeatures(a, s.older.back().first);
    state::read(a, s.older.back().second);
  }
  state::read(a, s.T_kf_last);
}

}  // namespace vofusion
