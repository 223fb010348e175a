#include "vofusion/fusion/kinfu.h"

#include <chrono>
#include <cmath>

#include <Eigen/Dense>
#include <mrpt/math/CMatrixFixed.h>
#include <opencv2/imgproc.hpp>

#include "vofusion/core/errors.h"

#include "vofusion/core/parallel.h"

namespace vofusion {

using namespace fusion;

TrackingMode parseTrackingMode(const std::string& s, const std::string& origin) {
  if (s == "paper") return TrackingMode::Paper;
  if (s == "kinfu") return TrackingMode::KinFu;
  if (s == "odometry") return TrackingMode::Odometry;
  throw InputError(origin, "unknown mode '" + s + "' (expected paper, kinfu or odometry)");
}

std::string toString(TrackingMode m) {
  switch (m) {
    case TrackingMode::Paper: return "paper";
    case TrackingMode::KinFu: return "kinfu";
    case TrackingMode::Odometry: return "odometry";
  }
  return "?";
}

namespace {

Eigen::Isometry3d toEigen(const mrpt::poses::CPose3D& p) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = p.getRotationMatrix().asEigen();
  T.translation() = Eigen::Vector3d(p.x(), p.y(), p.z());
  return T;
}

mrpt::poses::CPose3D toMrpt(const Eigen::Isometry3d& T) {
  mrpt::math::CMatrixDouble44 M;
  M.asEigen() = T.matrix();
  return mrpt::poses::CPose3D(M);
}

double seconds(std::chrono::steady_clock::time_point a) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - a).count();
}

}  // namespace

struct KinFu::Impl {
  KinFuParams params;
  TrackingMode mode;
  Eigen::Isometry3d pose;             // camera-to-world of the last frame
  std::unique_ptr<TsdfVolume> volume;
  // Model ray-cast from `model_pose` after the last integration, one map per pyramid level.
  std::vector<cv::Mat> model_vertices, model_normals;
  Eigen::Isometry3d model_pose = Eigen::Isometry3d::Identity();
  bool have_model = false;  // a frame was fused: the next one is tracked against the map
  KinFuStats stats;
  // What track() leaves for fuse(): the frame, its finest tracking level (ray-cast hint) and cameras.
  struct Pending {
    bool valid = false;
    cv::Mat depth, rgb, hint;
    CameraIntrinsics cam, track_cam;
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  } pending;

  Eigen::Vector3f focusPoint(const Eigen::Isometry3d& T) const {
    return (T.translation() + T.linear().col(2) * params.focus_distance).cast<float>();
  }

  // Depth the last ray cast found per pixel: the hint where the new frame has no reading. The camera
  // moved a little since, so it is only a starting point (the ray cast checks and falls back).
  cv::Mat model_depth;

  void raycastModel(const Eigen::Isometry3d& from, const cv::Mat& frame_depth, const CameraIntrinsics& cam,
                    StageTimes& times) {
    const auto t0 = std::chrono::steady_clock::now();
    // Only rays with a hint are cast: ICP pairs the next frame's readings with model pixels next to
    // where this frame had readings (or the last prediction had a surface). Rays without one marched
    // from min_depth through partly observed bricks, three quarters of all ray-cast samples, mostly
    // to find nothing. Hints outside the fused depth range have no surface to find.
    cv::Mat hint(cam.height, cam.width, CV_32F);
    const bool have_frame = frame_depth.size() == hint.size(), have_last = model_depth.size() == hint.size();
    const float lo = params.tsdf.min_depth, hi = params.tsdf.max_depth;
    for (int y = 0; y < hint.rows; ++y) {
      const float* d = have_frame ? frame_depth.ptr<float>(y) : nullptr;
      const float* m = have_last ? model_depth.ptr<float>(y) : nullptr;
      float* h = hint.ptr<float>(y);
      for (int x = 0; x < hint.cols; ++x) {
        const float z = d ? d[x] : 0.f;
        h[x] = z >= lo && z <= hi ? z : (m ? m[x] : 0.f);
      }
    }
    RaycastMaps maps = volume->raycast(from.cast<float>(), cam, &hint, false, true);
    model_depth = maps.depth;
    const int levels = std::max(1, params.preprocess.levels);
    model_vertices.assign(levels, cv::Mat());
    model_normals.assign(levels, cv::Mat());
    model_vertices[0] = maps.vertices;
    model_normals[0] = maps.normals;
    for (int l = 1; l < levels; ++l)
      downsampleMaps(model_vertices[l - 1], model_normals[l - 1], model_vertices[l], model_normals[l]);
    model_pose = from;
    have_model = true;
    times.add("raycast", seconds(t0));
  }
};

KinFu::KinFu(const KinFuParams& params, TrackingMode mode, const mrpt::poses::CPose3D& initial_pose)
    : impl_(std::make_unique<Impl>()) {
  impl_->params = params;
  impl_->mode = mode;
  impl_->pose = toEigen(initial_pose);
  impl_->volume = std::make_unique<TsdfVolume>(params.tsdf, impl_->focusPoint(impl_->pose));
}

KinFu::~KinFu() = default;

FusionResult KinFu::process(const Frame& frame, const OdometryResult* odom) {
  FusionResult res = track(frame, odom);
  fuse(res);
  return res;
}

FusionResult KinFu::track(const Frame& frame, const OdometryResult* odom) {
  Impl& s = *impl_;
  s.pending.valid = false;
  const KinFuParams& P = s.params;
  FusionResult res;
  if (frame.depth.empty() || frame.depth.type() != CV_32FC1) {
    res.reason = "no depth image";
    res.pose = toMrpt(s.pose);
    ++s.stats.frames;
    ++s.stats.lost;
    return res;
  }
  CameraIntrinsics cam = frame.camera;
  cam.width = frame.depth.cols;
  cam.height = frame.depth.rows;

  auto t0 = std::chrono::steady_clock::now();
  // Tracking at half resolution: a quarter of the filtering, ray casting and ICP work; the finest
  // ICP level is then 320x240, which KinFu-style coarse-to-fine tracking hardly misses.
  CameraIntrinsics track_cam = cam;
  std::vector<DepthLevel> levels;
  if (P.tracking_downsample == 2) {
    PreprocessParams pp = P.preprocess;
    pp.sigma_spatial *= 0.5f;
    pp.kernel = std::max(3, ((pp.kernel + 1) / 2) | 1);
    if (P.preprocess.kernel <= 1) pp.kernel = P.preprocess.kernel;
    track_cam = cam.scaled(0.5);
    levels = preprocessDepth(downsampleDepth(clipDepth(frame.depth, pp.min_depth, pp.max_depth), pp.sigma_depth),
                             track_cam, pp);
  } else {
    levels = preprocessDepth(frame.depth, cam, P.preprocess);
  }
  res.times.add("preprocess", seconds(t0));

  const bool odom_ok = odom && odom->success;
  const Eigen::Isometry3d predicted = odom_ok ? s.pose * toEigen(odom->motion) : s.pose;
  Eigen::Isometry3d new_pose = s.pose;

  if (!s.have_model) {
    res.tracked = true;  // the first frame defines the map
  } else if (s.mode == TrackingMode::Odometry) {
    res.tracked = odom_ok;
    if (odom_ok) new_pose = predicted;
    else res.reason = odom ? "odometry failed: " + odom->failure : "no odometry";
  } else {
    const bool seeded = s.mode == TrackingMode::Paper && odom_ok;
    t0 = std::chrono::steady_clock::now();
    // Weak directions keep the initial guess only when it is worth keeping (the odometry); from the
    // last pose alone (mode kinfu) every direction that is not numerically singular is solved.
    IcpParams ip = P.icp;
    if (!seeded) ip.degenerate_ratio = std::min(ip.degenerate_ratio, P.min_condition);
    const IcpResult icp = projectiveIcp(levels, s.model_vertices, s.model_normals, s.model_pose,
                                        seeded ? predicted : s.pose, ip);
    res.times.add("icp", seconds(t0));
    res.icp_inliers = icp.inliers;
    res.icp_rms = icp.rms;
    res.condition = icp.condition;
    res.degenerate_dims = icp.degenerate_dims;
    // Divergence / degeneracy tests.
    if (!icp.solved) res.reason = "ICP system not solvable";
    else if (icp.inliers < P.min_inlier_ratio * std::max(1, icp.valid_pixels))
      res.reason = "too few ICP inliers (" + std::to_string(icp.inliers) + " of " + std::to_string(icp.valid_pixels) + ")";
    else if (icp.condition < P.min_condition)
      res.reason = "ill-conditioned ICP (eigenvalue ratio " + std::to_string(icp.condition) + ")";
    else if (seeded) {
      const Eigen::Isometry3d d = predicted.inverse() * icp.pose;
      const double dt = d.translation().norm();
      const double da = Eigen::AngleAxisd(d.linear()).angle() * 180.0 / M_PI;
      if (dt > P.max_jump_translation || da > P.max_jump_rotation)
        res.reason = "ICP jumped " + std::to_string(dt) + " m / " + std::to_string(da) + " deg from the odometry";
    }
    if (res.reason.empty()) {
      res.tracked = true;
      new_pose = icp.pose;
    } else if (s.mode == TrackingMode::Paper && odom_ok) {
      res.tracked = true;
      res.fell_back = true;
      new_pose = predicted;
    }
  }

  if (res.tracked) s.pose = new_pose;
  res.pose = toMrpt(s.pose);

  ++s.stats.frames;
  if (res.tracked) ++s.stats.tracked;
  if (res.fell_back) ++s.stats.fell_back;
  if (res.degenerate_dims > 0 && res.reason.empty()) ++s.stats.degenerate;
  if (!res.tracked) ++s.stats.lost;
  s.stats.times.merge(res.times);
  if (res.tracked)
    s.pending = {true, P.integrate_filtered && P.tracking_downsample == 1 ? levels[0].depth : frame.depth, frame.rgb,
                 levels[0].depth, cam, track_cam, s.pose};
  return res;
}

void KinFu::fuse(FusionResult& res) {
  Impl& s = *impl_;
  const KinFuParams& P = s.params;
  if (!s.pending.valid) return;
  s.pending.valid = false;
  const Impl::Pending& f = s.pending;
  s.have_model = true;  // the map exists from the first fused (or tracked) frame on
  StageTimes times;
  // Fuse, move the volume with the camera, and predict the surface for the next frame.
  if (!res.fell_back || P.integrate_on_fallback) {
    auto t0 = std::chrono::steady_clock::now();
    if (s.volume->shiftIfNeeded(s.focusPoint(f.pose), P.shift_threshold)) {
      res.shifted = true;
      ++s.stats.shifts;
    }
    times.add("shift", seconds(t0));
    t0 = std::chrono::steady_clock::now();
    s.volume->integrate(f.depth, f.rgb, f.cam, f.pose.cast<float>());
    times.add("integrate", seconds(t0));
    res.integrated = true;
    // Mode odometry has no ICP: nothing reads the predicted model.
    if (s.mode != TrackingMode::Odometry) s.raycastModel(f.pose, f.hint, f.track_cam, times);
  } else if (s.mode != TrackingMode::Odometry) {
    // Not fused (fallback pose): re-predict the model from the new pose so ICP keeps up.
    s.raycastModel(f.pose, cv::Mat(), f.track_cam, times);
  }
  res.times.merge(times);
  s.stats.times.merge(times);
}

mrpt::poses::CPose3D KinFu::pose() const { return toMrpt(impl_->pose); }

TriangleMesh KinFu::extractMesh() const { return impl_->volume->extractMesh(); }

cv::Mat KinFu::renderView(const mrpt::poses::CPose3D& cam_to_world, const CameraIntrinsics& cam, bool coloured) const {
  const Eigen::Isometry3f T = toEigen(cam_to_world).cast<float>();
  const RaycastMaps maps = impl_->volume->raycast(T, cam, nullptr, coloured);
  cv::Mat img(cam.height, cam.width, CV_8UC3, cv::Scalar(0, 0, 0));
  const Eigen::Vector3f c = T.translation();
  parallelFor(0, cam.height, [&](int y) {
    for (int x = 0; x < cam.width; ++x) {
      const cv::Vec3f& v = maps.vertices.ptr<cv::Vec3f>(y)[x];
      const cv::Vec3f& n = maps.normals.ptr<cv::Vec3f>(y)[x];
      if (std::isnan(v[0]) || std::isnan(n[0])) continue;
      const Eigen::Vector3f to_cam = (c - Eigen::Vector3f(v[0], v[1], v[2])).normalized();
      const float lambert = std::max(0.f, to_cam.dot(Eigen::Vector3f(n[0], n[1], n[2])));
      const float shade = 0.2f + 0.8f * lambert;
      if (coloured) {
        const cv::Vec3b& col = maps.colours.ptr<cv::Vec3b>(y)[x];
        img.ptr<cv::Vec3b>(y)[x] = cv::Vec3b(cv::saturate_cast<uchar>(col[0] * shade), cv::saturate_cast<uchar>(col[1] * shade),
                                             cv::saturate_cast<uchar>(col[2] * shade));
      } else {
        const uchar g = cv::saturate_cast<uchar>(255.f * shade);
        img.ptr<cv::Vec3b>(y)[x] = cv::Vec3b(g, g, g);
      }
    }
  });
  return img;
}

KinFuStats KinFu::stats() const {
  KinFuStats st = impl_->stats;
  st.bricks_in_volume = impl_->volume->bricksInVolume();
  st.bricks_in_world_model = impl_->volume->bricksInWorldModel();
  st.memory_bytes = impl_->volume->memoryBytes();
  return st;
}

const TsdfVolume& KinFu::volume() const { return *impl_->volume; }
const KinFuParams& KinFu::params() const { return impl_->params; }
TrackingMode KinFu::mode() const { return impl_->mode; }

}  // namespace vofusion
