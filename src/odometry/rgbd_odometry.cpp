#include "vofusion/odometry/rgbd_odometry.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <future>
#include <optional>

#include <Eigen/Dense>
#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include "vofusion/features/keypoint_union.h"

namespace vofusion {

namespace {

double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// What a frame contributes to matching: described keypoints with their 3D points.
struct FrameFeatures {
  std::vector<cv::KeyPoint> keypoints;
  std::vector<cv::Point2f> pixels;  // keypoint positions, undistorted when asked to (homography input)
  cv::Mat descriptors;  // CV_8U, 32 bytes per keypoint
  Points3 points;       // camera frame, m
  std::size_t index = 0;
  double timestamp = 0.0;
  int star = 0, narf = 0;
};

// Depth of a keypoint: the median or nearest valid reading of the (2r+1)^2 window (the centre reading
// alone is noisy at the edges where keypoints like to sit); 0 if the window has no reading.
float keypointDepth(const cv::Mat& depth, int x, int y, int r, bool nearest) {
  if (r <= 0) return depth.at<float>(y, x);
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

struct RgbdOdometry::Impl {
  OdometryParams params;
  BrandExtractor brand;
  // The keyframe new frames are matched against, and the last frame with a pose relative to it
  // (T_kf_last); with keyframes off both are the previous usable frame.
  std::optional<FrameFeatures> reference, last;
  Eigen::Isometry3d T_kf_last = Eigen::Isometry3d::Identity();
  explicit Impl(const OdometryParams& p) : params(p), brand(p.brand) {}

  FrameFeatures extract(const Frame& frame, StageTimes& times) const;
  // Motion T_ref_cur from matching, homography filter and rigid fit; fills matches, inliers,
  // rms_error, failure and the stage times of r.
  bool estimate(const FrameFeatures& ref, const FrameFeatures& cur, OdometryResult& r, RigidFit& fit) const;
};

FrameFeatures RgbdOdometry::Impl::extract(const Frame& frame, StageTimes& times) const {
  FrameFeatures f;
  f.index = frame.index;
  f.timestamp = frame.timestamp;
  const bool want_star = params.keypoints != "narf", want_narf = params.keypoints != "star";

  // NARF is the slow part: start it first, on its own thread, when asked to.
  std::vector<cv::KeyPoint> narf_kps;
  std::future<std::pair<std::vector<cv::KeyPoint>, double>> narf_job;
  auto runNarf = [&frame, this] {
    const auto t0 = std::chrono::steady_clock::now();
    auto k = detectNarf(frame.depth, frame.camera, params.narf);
    return std::make_pair(std::move(k), secondsSince(t0));
  };
  if (want_narf && params.narf_concurrent) narf_job = std::async(std::launch::async, runNarf);

  cv::Mat gray;
  {
    ScopedStageTimer t(times, "grey");
    if (frame.rgb.channels() == 3) cv::cvtColor(frame.rgb, gray, cv::COLOR_BGR2GRAY);
    else gray = frame.rgb;
  }
  std::vector<cv::KeyPoint> star_kps;
  if (want_star) {
    ScopedStageTimer t(times, "star");
    star_kps = detectStar(gray, params.star);
  }
  cv::Mat points, normals, smoothed;
  {
    ScopedStageTimer t(times, "normals");
    points = depthToPointMap(frame.depth, frame.camera);
    if (params.brand.use_geometry)
      normals = computeNormalMap(points, params.brand.normal_window, float(params.brand.max_depth_step));
    else
      normals = cv::Mat(points.size(), CV_32FC3, cv::Scalar::all(std::nan("")));
    smoothed = brand.smooth(gray);
  }
  if (want_narf) {
    if (params.narf_concurrent) {
      const auto t0 = std::chrono::steady_clock::now();
      auto [k, secs] = narf_job.get();
      narf_kps = std::move(k);
      times.add("narf", secs);
      times.add("narf_wait", secondsSince(t0));
    } else {
      ScopedStageTimer t(times, "narf");
      narf_kps = detectNarf(frame.depth, frame.camera, params.narf);
    }
  }
  f.star = int(star_kps.size());
  f.narf = int(narf_kps.size());
  {
    ScopedStageTimer t(times, "brand");
    f.keypoints = mergeKeypoints(star_kps, narf_kps, float(params.union_radius));
    brand.computeSmoothed(smoothed, points, normals, f.keypoints, f.descriptors);
  }
  {
    ScopedStageTimer t(times, "points");
    // Pixels to 3D: the depth image is registered to the distorted colour image, so the reading is
    // taken at the keypoint's own pixel and the ray through its undistorted position.
    std::vector<cv::Point2f> px(f.keypoints.size());
    for (std::size_t i = 0; i < px.size(); ++i) px[i] = f.keypoints[i].pt;
    const auto& dist = frame.camera.dist;
    const bool distorted = std::any_of(dist.begin(), dist.end(), [](double d) { return d != 0.0; });
    const CameraIntrinsics& c = frame.camera;
    if (params.undistort && distorted && !px.empty()) {
      const cv::Matx33d K(c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1);
      cv::undistortPoints(px, px, K, std::vector<double>(dist.begin(), dist.end()), cv::noArray(), K);
    }
    const bool nearest = params.depth_mode == "min";
    f.points.reserve(px.size());
    f.pixels.reserve(px.size());
    std::vector<cv::KeyPoint> kept;
    cv::Mat kept_desc(0, f.descriptors.cols, f.descriptors.type());
    kept.reserve(px.size());
    for (std::size_t i = 0; i < px.size(); ++i) {
      const auto& k = f.keypoints[i];
      // A NARF keypoint stands for a block of the reduced depth image whose value is the block's
      // nearest reading (it sits on foreground borders): take that reading, not the centre pixel's.
      const bool narf = k.class_id == 1 && params.narf.downsample > 1;
      const float z = narf ? keypointDepth(frame.depth, cvRound(k.pt.x), cvRound(k.pt.y), params.narf.downsample / 2, true)
                           : keypointDepth(frame.depth, cvRound(k.pt.x), cvRound(k.pt.y), params.depth_window, nearest);
      if (!(z > 0.f)) continue;
      f.points.emplace_back((px[i].x - c.cx) * z / c.fx, (px[i].y - c.cy) * z / c.fy, z);
      f.pixels.push_back(px[i]);
      kept.push_back(k);
      kept_desc.push_back(f.descriptors.row(int(i)));
    }
    f.keypoints.swap(kept);
    f.descriptors = kept_desc;
  }
  return f;
}

RgbdOdometry::RgbdOdometry(const OdometryParams& params) : impl_(std::make_unique<Impl>(params)) {}
RgbdOdometry::~RgbdOdometry() = default;
void RgbdOdometry::reset() {
  impl_->reference.reset();
  impl_->last.reset();
}

bool RgbdOdometry::Impl::estimate(const FrameFeatures& ref, const FrameFeatures& cur, OdometryResult& r,
                                  RigidFit& fit) const {
  const OdometryParams& P = params;
  auto fail = [&r](const std::string& why) {
    r.failure = why;
    return false;
  };
  r.matches = r.inliers = 0;
  r.rms_error = 0.0;
  // Brute-force Hamming matching with cross-check (query = current, train = reference).
  std::vector<cv::DMatch> matches;
  {
    ScopedStageTimer t(r.times, "matching");
    if (!ref.descriptors.empty() && !cur.descriptors.empty())
      cv::BFMatcher(cv::NORM_HAMMING, true).match(cur.descriptors, ref.descriptors, matches);
    std::vector<cv::DMatch> close;
    for (const auto& m : matches)
      if (m.distance <= P.max_hamming) close.push_back(m);
    matches.swap(close);
  }
  if (int(matches.size()) < std::max(P.min_matches, 4)) {
    r.matches = int(matches.size());
    return fail("too few matches");
  }
  if (P.use_homography) {
    ScopedStageTimer t(r.times, "homography");
    std::vector<cv::Point2f> a, b;
    for (const auto& m : matches) a.push_back(cur.pixels[m.queryIdx]), b.push_back(ref.pixels[m.trainIdx]);
    std::vector<uchar> mask;
    const cv::Mat H = cv::findHomography(a, b, cv::RANSAC, P.homography_threshold, mask, 2000, 0.995);
    if (H.empty()) return fail("degenerate geometry (no homography)");
    std::vector<cv::DMatch> kept;
    for (std::size_t i = 0; i < matches.size(); ++i)
      if (mask[i]) kept.push_back(matches[i]);
    matches.swap(kept);
  }
  r.matches = int(matches.size());
  if (r.matches < P.min_matches) return fail("too few matches");

  // T_ref_cur maps current-frame points onto the reference frame's.
  Points3 src, dst;
  for (const auto& m : matches) src.push_back(cur.points[m.queryIdx]), dst.push_back(ref.points[m.trainIdx]);
  {
    ScopedStageTimer t(r.times, "motion");
    fit = P.motion_method == "paper" ? fitPaper(src, dst, P.paper) : fitRobust(src, dst, P.robust);
  }
  r.inliers = int(fit.inliers.size());
  r.rms_error = fit.rms;
  if (!fit.ok) return fail(fit.failure);
  if (r.inliers < P.min_inliers) return fail("too few inliers");
  if (secondaryExtent(src, fit.inliers) < P.min_extent) return fail("degenerate geometry (inliers nearly collinear)");
  if (fit.rms > P.max_rms) return fail("inconsistent matches (inlier RMS too large)");
  return true;
}

OdometryResult RgbdOdometry::process(const Frame& frame) {
  OdometryResult r;
  r.covariance.setIdentity();
  const OdometryParams& P = impl_->params;
  Impl& m = *impl_;
  auto fail = [&r](const std::string& why) {
    r.success = false;
    r.failure = why;
    return r;
  };
  if (!frame.valid()) return fail("empty frame");

  FrameFeatures cur = m.extract(frame, r.times);
  r.keypoints = int(cur.keypoints.size());
  r.star_keypoints = cur.star;
  r.narf_keypoints = cur.narf;
  if (!m.reference) {
    m.reference = std::move(cur);
    m.last.reset();
    m.T_kf_last.setIdentity();
    r.reference_index = frame.index;
    r.reference_timestamp = frame.timestamp;
    return fail("first frame");
  }
  // `motion` is relative to the last frame with a pose (the previous one unless that failed).
  const FrameFeatures& last = m.last ? *m.last : *m.reference;
  r.reference_index = last.index;
  r.reference_timestamp = last.timestamp;
  // A frame with almost nothing to match (textureless, no depth) cannot be anyone's reference:
  // keep the last good one so the next frame can bridge the gap.
  if (int(cur.keypoints.size()) < P.min_matches) return fail("too few keypoints (textureless or no depth)");

  // Against the keyframe first; a failed or weak keyframe match falls back to the last frame and
  // the current frame becomes the new keyframe. Any failure makes it the new reference too.
  RigidFit fit;
  bool ok = m.estimate(*m.reference, cur, r, fit);
  Eigen::Isometry3d T_last_cur = m.T_kf_last.inverse() * fit.T;
  const bool keep_keyframe = P.keyframe_min_inliers > 0 && ok && r.inliers >= P.keyframe_min_inliers;
  if (!keep_keyframe && m.last) {
    OdometryResult r2;
    RigidFit fit2;
    if (m.estimate(*m.last, cur, r2, fit2) || !ok) {
      ok = r2.failure.empty();
      fit = fit2;
      T_last_cur = fit2.T;
      r.matches = r2.matches, r.inliers = r2.inliers, r.rms_error = r2.rms_error, r.failure = r2.failure;
    }
    r.times.merge(r2.times);
  }
  if (keep_keyframe) {
    m.T_kf_last = fit.T;
    m.last = std::move(cur);
  } else {
    m.reference = std::move(cur);
    m.last.reset();
    m.T_kf_last.setIdentity();
  }
  if (!ok) return fail(r.failure);

  Eigen::Matrix4d M = T_last_cur.matrix();
  mrpt::math::CMatrixDouble44 Mm;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) Mm(i, j) = M(i, j);
  r.motion = mrpt::poses::CPose3D(Mm);
  // The covariance is the one of the fit that gave the motion (keyframe-to-current when a keyframe
  // was kept: an upper bound on the frame-to-frame uncertainty).
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 6; ++j) r.covariance(i, j) = fit.covariance(i, j);
  r.failure.clear();
  r.success = true;
  return r;
}

}  // namespace vofusion
