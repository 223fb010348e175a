#include "vofusion/fusion/kinfu.h"
#include "vofusion/core/pose_eigen.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <deque>
#include <fstream>

#include <Eigen/Dense>
#include <tbb/parallel_invoke.h>
#include <mrpt/math/CMatrixFixed.h>
#include <opencv2/imgproc.hpp>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/depth_noise.h"
#include "vofusion/core/errors.h"

#include "vofusion/core/parallel.h"

namespace vofusion {

using namespace fusion;

TrackingMode parseTrackingMode(const std::string& s, const std::string& origin) {
  if (s == "joint") return TrackingMode::Joint;
  if (s == "paper-handoff" || s == "paper") return TrackingMode::PaperHandoff;
  if (s == "kinfu") return TrackingMode::KinFu;
  if (s == "odometry") return TrackingMode::Odometry;
  throw InputError(origin, "unknown mode '" + s + "' (expected joint, paper-handoff, kinfu or odometry)");
}

std::string toString(TrackingMode m) {
  switch (m) {
    case TrackingMode::Joint: return "joint";
    case TrackingMode::PaperHandoff: return "paper-handoff";
    case TrackingMode::KinFu: return "kinfu";
    case TrackingMode::Odometry: return "odometry";
  }
  return "?";
}

std::string toString(InitialGuess g) {
  switch (g) {
    case InitialGuess::Prior: return "prior";
    case InitialGuess::ConstantVelocity: return "constant velocity";
    case InitialGuess::LastPose: return "last pose";
  }
  return "?";
}

namespace {



// Motion m scaled to s times its length (rotation angle and translation).
Eigen::Isometry3d scaledMotion(const Eigen::Isometry3d& m, double s) {
  const Eigen::AngleAxisd rot(m.linear());
  Eigen::Isometry3d step = Eigen::Isometry3d::Identity();
  step.linear() = Eigen::AngleAxisd(s * rot.angle(), rot.axis()).toRotationMatrix();
  step.translation() = s * m.translation();
  return step;
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
  bool model_stale = false;  // resumed from a file: the model is ray cast (unhinted) before tracking
  KinFuStats stats;
  // What track() leaves for fuse(): the frame, its finest tracking level (ray-cast hint) and cameras.
  struct Pending {
    bool valid = false;
    cv::Mat depth, rgb, hint;
    CameraIntrinsics cam, track_cam;
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    std::vector<IntensityLevel> intensity;  // mode joint with the photometric term: the frame's pyramid,
    std::vector<CameraIntrinsics> level_cams;  // its levels' cameras
    Eigen::Isometry3d colour_pose = Eigen::Isometry3d::Identity();  // and where its colour was captured
  } pending;
  // Intensity of the frame the model was last ray cast for, on the model's pixel grid (photometric term).
  std::vector<IntensityLevel> model_intensity;

  // Poses of the last tracked frames by Frame::index: a prior's reference is looked up here.
  std::deque<std::pair<std::size_t, Eigen::Isometry3d>> recent;
  // Motion per second over the last two tracked frames, for the constant-velocity prediction.
  Eigen::Isometry3d last_motion = Eigen::Isometry3d::Identity();
  double last_motion_dt = 0.0, last_timestamp = 0.0;
  bool have_last = false;

  const Eigen::Isometry3d* poseOf(std::size_t index) const {
    for (const auto& [i, T] : recent)
      if (i == index) return &T;
    return nullptr;
  }
  // The last pose moved on by the last motion, scaled to the time since the last tracked frame.
  Eigen::Isometry3d constantVelocity(double timestamp) const {
    if (!(last_motion_dt > 0)) return pose;
    return pose * scaledMotion(last_motion, std::clamp((timestamp - last_timestamp) / last_motion_dt, 0.0, 3.0));
  }
  // The camera's motion over `offset` seconds at the last motion's velocity (camera frame): where the
  // colour camera was relative to the depth camera when the two were captured `offset` apart.
  Eigen::Isometry3d colourMotion(double offset) const {
    if (!params.joint_photometric_colour_time || !(last_motion_dt > 0) || offset == 0.0) return Eigen::Isometry3d::Identity();
    return scaledMotion(last_motion, std::clamp(offset / last_motion_dt, -3.0, 3.0));
  }
  void remember(std::size_t index, double timestamp, const Eigen::Isometry3d& T) {
    if (have_last && timestamp > last_timestamp) {
      last_motion = pose.inverse() * T;
      last_motion_dt = timestamp - last_timestamp;
    }
    pose = T;
    last_timestamp = timestamp;
    have_last = true;
    recent.emplace_back(index, T);
    if (recent.size() > 32) recent.pop_front();
  }
  // The prior's matches in world coordinates, each weighed by both points' Kinect noise.
  PointMatches matchesOf(const MotionPrior& prior, const Eigen::Isometry3d& T_world_ref, const Eigen::Isometry3d& guess) const {
    PointMatches pm;
    pm.cauchy = params.joint_match_cauchy;
    const std::size_t n = std::min(prior.current_points.size(), prior.reference_points.size());
    const Eigen::Matrix3d Rr = T_world_ref.linear(), Rc = guess.linear();
    for (std::size_t i = 0; i < n; ++i) {
      const Eigen::Vector3d& p = prior.current_points[i];
      const Eigen::Vector3d& q = prior.reference_points[i];
      const Eigen::Matrix3d C = Rc * rayCovariance(p) * Rc.transpose() + Rr * rayCovariance(q) * Rr.transpose();
      pm.camera_points.push_back(p);
      pm.world_points.push_back(T_world_ref * q);
      pm.information.push_back(C.inverse());
    }
    return pm;
  }
  // ICP's settings per mode. Weak directions keep the initial guess only when it is worth keeping (the
  // prior: mode paper-handoff), or follow the prior's pose (mode joint, see projectiveIcp); from the
  // last pose alone every direction that is not numerically singular is solved.
  IcpParams icpParams(bool joint, bool seeded, bool have_prior) const {
    IcpParams ip = params.icp;
    if (!seeded && !(joint && have_prior)) ip.degenerate_ratio = std::min(ip.degenerate_ratio, params.min_condition);
    if (joint) ip.point_to_plane_sigma = params.joint_icp_sigma;
    return ip;
  }
  // Mode joint: what a turning camera adds to a residual's noise (the depth camera reads its rows over
  // joint_rolling_shutter seconds): that time x the turn rate of the initial guess x the scene depth.
  double rollingShutterSigma(const std::vector<DepthLevel>& levels, const Eigen::Isometry3d& initial, double timestamp) const {
    if (!(params.joint_rolling_shutter > 0) || !have_last || !(timestamp > last_timestamp)) return 0.0;
    const double turn = Eigen::AngleAxisd((pose.inverse() * initial).linear()).angle() / (timestamp - last_timestamp);
    const cv::Mat& d = levels.back().depth;
    return params.joint_rolling_shutter * turn * cv::mean(d, d > 0)[0];
  }
  // Mode joint: the constant-velocity prediction as a motion model, its spread growing with the time
  // since the last tracked frame.
  PosePrior motionModel(const Eigen::Isometry3d& velocity_pose, double timestamp) const {
    PosePrior m;
    m.pose = velocity_pose;
    const double frames_since = have_last ? std::max(1.0, (timestamp - last_timestamp) * 30.0) : 1.0;
    m.sigma_translation = params.motion_sigma_translation * frames_since;
    m.sigma_rotation = params.motion_sigma_rotation * M_PI / 180.0 * frames_since;
    return m;
  }
  // Why an ICP result is not taken ("" when it is): divergence and degeneracy tests, and a jump from
  // the prior's pose when given. Mode joint judges the inliers among the pixels that see the model: a
  // view that is mostly new is no sign of divergence, and there the matches outweigh the few ICP
  // residuals anyway; its weak directions are held by the prior, so no condition test.
  std::string rejection(const IcpResult& icp, bool joint, const Eigen::Isometry3d* prior_pose) const {
    const KinFuParams& P = params;
    const int judged = joint ? icp.in_view : icp.valid_pixels;
    if (!icp.solved) return "ICP system not solvable";
    if (icp.inliers < P.min_inlier_ratio * std::max(1, judged))
      return "too few ICP inliers (" + std::to_string(icp.inliers) + " of " + std::to_string(judged) + ")";
    if (!joint && icp.condition < P.min_condition)
      return "ill-conditioned ICP (eigenvalue ratio " + std::to_string(icp.condition) + ")";
    if (prior_pose) {
      const Eigen::Isometry3d d = prior_pose->inverse() * icp.pose;
      const double dt = d.translation().norm();
      const double da = Eigen::AngleAxisd(d.linear()).angle() * 180.0 / M_PI;
      if (dt > P.max_jump_translation || da > P.max_jump_rotation)
        return "ICP jumped from the prior (" + std::to_string(dt) + " m / " + std::to_string(da) + " deg)";
    }
    return "";
  }

  // Mode joint: the candidate that explains the frame clearly best after a few ICP steps at the
  // coarsest level (so errors ICP corrects anyway do not count); the prior wins ties (where geometry
  // cannot tell, e.g. sliding along a wall). Returns the candidate; `refined` gets its refined pose.
  InitialGuess chooseGuess(const std::vector<DepthLevel>& levels, const IcpParams& ip, bool have_prior,
                           const Eigen::Isometry3d& prior_pose, const Eigen::Isometry3d& velocity_pose) const {
    const std::size_t L = std::min(levels.size(), model_vertices.size()) - 1;
    const std::vector<DepthLevel> coarse{levels[L]};
    const std::vector<cv::Mat> mv{model_vertices[L]}, mn{model_normals[L]};
    IcpParams coarse_ip = ip;
    coarse_ip.iterations = {3, 3, 3};
    coarse_ip.point_to_plane_sigma = 0;
    const double truncation = 0.5 * ip.max_distance;
    auto cost = [&](const Eigen::Isometry3d& T) {
      const IcpResult r = projectiveIcp(coarse, mv, mn, model_pose, T, coarse_ip);
      return scoreAlignment(coarse[0], mv[0], mn[0], model_pose, r.pose, ip, truncation).cost;
    };
    // The candidates' coarse alignments are independent and each runs on one thread: side by side.
    double prior_cost = 0, velocity_cost = 0, last_cost = 0;
    tbb::parallel_invoke([&] { if (have_prior) prior_cost = cost(prior_pose); },
                         [&] { velocity_cost = cost(velocity_pose); }, [&] { last_cost = cost(pose); });
    InitialGuess best = have_prior ? InitialGuess::Prior : InitialGuess::ConstantVelocity;
    double best_cost = have_prior ? prior_cost : velocity_cost;
    const std::pair<InitialGuess, double> others[] = {{InitialGuess::ConstantVelocity, velocity_cost},
                                                      {InitialGuess::LastPose, last_cost}};
    for (const auto& [g, c] : others) {
      if (g == best) continue;
      if (c < params.guess_margin * best_cost) best = g, best_cost = c;
    }
    return best;
  }

  // Mode joint: the photometric term's levels when this frame and the model's reference both have an
  // intensity pyramid on the tracking levels' grids (empty otherwise: no term).
  PhotometricTerms photometricTerms(const std::vector<IntensityLevel>& current, const std::vector<DepthLevel>& levels) const {
    PhotometricTerms t;
    t.params.sigma = params.joint_photometric_sigma;
    t.params.huber = params.joint_photometric_huber;
    t.params.min_gradient = params.joint_photometric_min_gradient;
    const std::size_t n = std::min({current.size(), model_intensity.size(), levels.size(), model_vertices.size()});
    for (std::size_t l = 0; l < n; ++l) {
      if (model_intensity[l].grey.size() != model_vertices[l].size() || current[l].grey.size() != levels[l].depth.size())
        break;
      t.levels.push_back({&model_intensity[l], &current[l], &model_vertices[l], levels[l].camera});
    }
    return t;
  }

  Eigen::Vector3f focusPoint(const Eigen::Isometry3d& T) const {
    return (T.translation() + T.linear().col(2) * params.focus_distance).cast<float>();
  }

  // Depth the last ray cast found per pixel: the hint where the new frame has no reading. The camera
  // moved a little since, so it is only a starting point (the ray cast checks and falls back).
  cv::Mat model_depth;

  void raycastModel(const Eigen::Isometry3d& from, const cv::Mat& frame_depth, const CameraIntrinsics& cam,
                    StageTimes& times, bool hinted = true) {
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
    RaycastMaps maps = hinted ? volume->raycast(from.cast<float>(), cam, &hint, false, true)
                              : volume->raycast(from.cast<float>(), cam, nullptr, false, false);
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

FusionResult KinFu::process(const Frame& frame, const MotionPrior* prior, const FrameGeometry* geometry) {
  FusionResult res = track(frame, prior, geometry);
  fuse(res);
  return res;
}

FusionResult KinFu::track(const Frame& frame, const MotionPrior* prior, const FrameGeometry* geometry) {
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
  if (geometry && geometry->points.size() == frame.depth.size() && geometry->normals.size() == frame.depth.size()) {
    // The frame's shared maps, averaged down: one back-projection and normal map serve BRAND and ICP.
    levels = levelsFromGeometry(*geometry, frame.depth, cam, P.tracking_downsample, P.preprocess);
    track_cam = levels[0].camera;
  } else if (P.tracking_downsample == 2) {
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
  if (s.model_stale) {  // resumed: no ray cast yet; a full one from the saved pose
    s.raycastModel(s.pose, cv::Mat(), track_cam, res.times, false);
    s.model_stale = false;
  }

  // The prior counts only when its reference frame has a pose here.
  const Eigen::Isometry3d* ref_pose = prior ? s.poseOf(prior->reference_index) : nullptr;
  const bool have_prior = ref_pose != nullptr;
  const Eigen::Isometry3d prior_pose = have_prior ? *ref_pose * prior->T_ref_cur : s.pose;
  const Eigen::Isometry3d velocity_pose = s.constantVelocity(frame.timestamp);
  Eigen::Isometry3d new_pose = s.pose;
  // Mode joint's photometric term: this frame's intensity, tracked against now and a reference later.
  std::vector<IntensityLevel> intensity;
  if (s.mode == TrackingMode::Joint && P.joint_photometric_sigma > 0) {
    t0 = std::chrono::steady_clock::now();
    intensity = intensityPyramid(frame.rgb, levels[0].depth.size(), static_cast<int>(levels.size()));
    res.times.add("intensity", seconds(t0));
  }

  if (!s.have_model) {
    res.tracked = true;  // the first frame defines the map
  } else if (s.mode == TrackingMode::Odometry) {
    res.tracked = true;
    res.guess = have_prior ? InitialGuess::Prior : InitialGuess::ConstantVelocity;
    new_pose = have_prior ? prior_pose : velocity_pose;
    res.predicted = !have_prior;
    if (!have_prior) res.reason = prior ? "prior's reference frame has no pose" : "no motion prior";
  } else {
    const bool joint = s.mode == TrackingMode::Joint;
    const bool seeded = s.mode == TrackingMode::PaperHandoff && have_prior;
    IcpParams ip = s.icpParams(joint, seeded, have_prior);
    PointMatches matches;
    if (joint) {
      res.guess = s.chooseGuess(levels, ip, have_prior, prior_pose, velocity_pose);
      if (have_prior) matches = s.matchesOf(*prior, *ref_pose, prior_pose);
    } else {
      res.guess = seeded ? InitialGuess::Prior : InitialGuess::LastPose;
    }
    const Eigen::Isometry3d& initial = res.guess == InitialGuess::Prior              ? prior_pose
                                       : res.guess == InitialGuess::ConstantVelocity ? velocity_pose
                                                                                     : s.pose;
    if (joint) ip.point_to_plane_sigma += s.rollingShutterSigma(levels, initial, frame.timestamp);
    res.icp_sigma = ip.point_to_plane_sigma;
    t0 = std::chrono::steady_clock::now();
    const PosePrior motion = s.motionModel(velocity_pose, frame.timestamp);
    JointTerms terms;
    if (joint) {
      if (!matches.camera_points.empty()) terms.matches = &matches;
      if (s.last_motion_dt > 0 && (motion.sigma_translation > 0 || motion.sigma_rotation > 0)) terms.motion = &motion;
      if (have_prior) terms.weak_anchor = &prior_pose;
    }
    PhotometricTerms photometric = s.photometricTerms(intensity, levels);
    photometric.colour_motion = s.colourMotion(frame.colour_offset);
    photometric.rotation_only = P.joint_photometric_rotation_only;
    if (!photometric.levels.empty()) terms.photometric = &photometric;
    const IcpResult icp = projectiveIcp(levels, s.model_vertices, s.model_normals, s.model_pose, initial, ip, terms);
    res.times.add("icp", seconds(t0));
    res.icp_inliers = icp.inliers;
    res.icp_rms = icp.rms;
    res.condition = icp.condition;
    res.degenerate_dims = icp.degenerate_dims;
    res.match_inliers = icp.point_inliers;
    res.reason = s.rejection(icp, joint, seeded || (joint && have_prior) ? &prior_pose : nullptr);
    if (res.reason.empty()) {
      res.tracked = true;
      new_pose = icp.pose;
    } else if (s.mode != TrackingMode::KinFu && have_prior) {
      res.tracked = res.fell_back = true;
      new_pose = prior_pose;
    } else if (joint) {
      // No motion is dropped: without ICP and without a prior the frame moves on at constant velocity.
      res.tracked = res.predicted = true;
      new_pose = velocity_pose;
    }
  }

  if (res.tracked) s.remember(frame.index, frame.timestamp, new_pose);
  res.pose = toMrpt(s.pose);

  ++s.stats.frames;
  if (res.tracked) ++s.stats.tracked;
  if (res.fell_back) ++s.stats.fell_back;
  if (res.predicted) ++s.stats.predicted;
  if (res.degenerate_dims > 0 && res.reason.empty()) ++s.stats.degenerate;
  if (!res.tracked) ++s.stats.lost;
  if (s.have_model && s.mode != TrackingMode::Odometry) {
    if (res.guess == InitialGuess::Prior) ++s.stats.guess_prior;
    else if (res.guess == InitialGuess::ConstantVelocity) ++s.stats.guess_velocity;
    else ++s.stats.guess_last;
  }
  s.stats.times.merge(res.times);
  if (res.tracked) {
    s.pending = {true, P.integrate_filtered && P.tracking_downsample == 1 ? levels[0].depth : frame.depth, frame.rgb,
                 levels[0].depth, cam, track_cam, s.pose, std::move(intensity), {},
                 s.pose * s.colourMotion(frame.colour_offset)};  // at the velocity this frame's motion updated
    for (const DepthLevel& l : levels) s.pending.level_cams.push_back(l.camera);
  }
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
  // A constant-velocity guess is not fused: nothing measured where the camera was.
  if (!res.predicted && (!res.fell_back || P.integrate_on_fallback)) {
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
    // Not fused (fallback or predicted pose): re-predict the model from the new pose so ICP keeps up.
    s.raycastModel(f.pose, cv::Mat(), f.track_cam, times);
  }
  // The ray cast was from this frame's pose: its intensity is the photometric term's reference.
  if (s.mode == TrackingMode::Joint) {
    s.model_intensity.clear();
    const std::size_t n = std::min({f.intensity.size(), f.level_cams.size(), s.model_vertices.size()});
    for (std::size_t l = 0; l < n; ++l)
      s.model_intensity.push_back(resampleAtModel(f.intensity[l], s.model_vertices[l], f.colour_pose, f.level_cams[l]));
  }
  res.times.merge(times);
  s.stats.times.merge(times);
}

void KinFu::integrateAt(const Frame& frame, const mrpt::poses::CPose3D& cam_to_world) {
  Impl& s = *impl_;
  ++s.stats.frames;
  if (frame.depth.empty() || frame.depth.type() != CV_32FC1) return;
  CameraIntrinsics cam = frame.camera;
  cam.width = frame.depth.cols;
  cam.height = frame.depth.rows;
  s.pose = toEigen(cam_to_world);
  StageTimes times;
  auto t0 = std::chrono::steady_clock::now();
  if (s.volume->shiftIfNeeded(s.focusPoint(s.pose), s.params.shift_threshold)) ++s.stats.shifts;
  times.add("shift", seconds(t0));
  t0 = std::chrono::steady_clock::now();
  s.volume->integrate(frame.depth, frame.rgb, cam, s.pose.cast<float>());
  times.add("integrate", seconds(t0));
  s.have_model = true;
  ++s.stats.tracked;
  s.stats.times.merge(times);
}

mrpt::poses::CPose3D KinFu::pose() const { return toMrpt(impl_->pose); }

TriangleMesh KinFu::extractMesh() const { return impl_->volume->extractMesh(); }

namespace {
constexpr char kMapMagic[16] = {'V', 'O', 'F', 'U', 'S', 'I', 'O', 'N', '-', 'M', 'A', 'P', ' ', '1', '\n', '\0'};
}

void KinFu::save(const std::string& path) const {
  AtomicPath out(path);
  {
    std::ofstream os(out.tmp(), std::ios::binary);
    if (!os) throw InputError(path, "cannot write the map");
    os.write(kMapMagic, sizeof(kMapMagic));
    const Eigen::Matrix4d T = impl_->pose.matrix();
    os.write(reinterpret_cast<const char*>(T.data()), sizeof(double) * 16);
    try {
      impl_->volume->save(os);
    } catch (const std::exception& e) {
      throw InputError(path, std::string("cannot write the map: ") + e.what());
    }
    os.close();
    if (!os) throw InputError(path, "cannot write the map (disk full?)");
  }
  out.commit();
}

void KinFu::resume(const std::string& path) {
  Impl& s = *impl_;
  std::ifstream is(path, std::ios::binary);
  if (!is) throw InputError(path, "cannot open the saved map");
  char magic[sizeof(kMapMagic)];
  if (!is.read(magic, sizeof(magic)) || std::memcmp(magic, kMapMagic, sizeof(kMapMagic)) != 0)
    throw InputError(path, "not a vofusion map (written by --save-volume)");
  Eigen::Matrix4d T;
  if (!is.read(reinterpret_cast<char*>(T.data()), sizeof(double) * 16) || !T.allFinite())
    throw InputError(path, "truncated or corrupt map (camera pose)");
  try {
    s.volume->load(is);
  } catch (const std::exception& e) {
    throw InputError(path, std::string("bad saved map: ") + e.what());
  }
  s.pose.matrix() = T;
  s.have_model = true;
  s.model_stale = true;
  s.have_last = false;
  s.last_motion_dt = 0.0;
  s.recent.clear();
  s.model_depth.release();
  s.model_intensity.clear();
}

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
  st.world = impl_->volume->worldModel().stats();
  return st;
}

const TsdfVolume& KinFu::volume() const { return *impl_->volume; }
const KinFuParams& KinFu::params() const { return impl_->params; }
TrackingMode KinFu::mode() const { return impl_->mode; }

}  // namespace vofusion
