#include "vofusion/tracking/tracker.h"

#include <algorithm>
#include <chrono>
#include <optional>
#include <stdexcept>
#include <tuple>

#include "frame_check.h"
#include "joint_policy.h"
#include "vofusion/core/depth_image.h"
#include "vofusion/core/pose_eigen.h"
#include "vofusion/core/state_archive.h"
#include "vofusion/tracking/motion_history.h"

namespace vofusion {

using namespace fusion;

struct Tracker::Impl {
  TrackerParams params;
  TrackingMode mode;
  MotionHistory history;
  TrackerStats stats;
  // What track() leaves for the map (frameToFuse) until it was fused: the frame as the map takes it.
  std::optional<FrameToFuse> pending;
  // relocalise(): where the next frame is, as its prior (ICP starts there and may not jump from it).
  std::optional<Eigen::Isometry3d> placed;
  // Mode joint: the last tracked frame, which checks the model's pull (frame_check.h).
  std::optional<tracking::ReferenceFrame> reference;

  Impl(const TrackerParams& p, TrackingMode m, const Eigen::Isometry3d& initial) : params(p), mode(m), history(initial) {}

  // Where the colour camera was relative to the depth camera (mode joint's photometric term).
  // The estimator's, when it knew the motion after the frame too; else the last motion's velocity.
  Eigen::Isometry3d colourMotion(const Frame& frame, const MotionPrior* prior) const {
    if (!params.joint_photometric_colour_time) return Eigen::Isometry3d::Identity();
    if (prior && prior->colour_motion) return *prior->colour_motion;
    return history.motionOver(frame.colour_offset);
  }
  std::vector<DepthLevel> trackingLevels(const Frame& frame, const FrameGeometry* geometry, const CameraIntrinsics& cam,
                                         CameraIntrinsics& track_cam) const;
  // Mode odometry: the prior's pose, else the constant-velocity prediction.
  Eigen::Isometry3d trackOdometry(const Frame& frame, const MotionPrior* prior, FusionResult& res) const;
  // Modes with ICP: the frame's pose from ICP against the map's model, or the fallback the mode allows.
  Eigen::Isometry3d trackIcp(const Frame& frame, const MotionPrior* prior, const std::vector<DepthLevel>& levels,
                             const std::vector<IntensityLevel>& intensity, const ModelPrediction& model, FusionResult& res);
  struct IcpStart;
  IcpStart icpStart(const Frame& frame, const MotionPrior* prior) const;
  // ICP's pose if judge() accepts it (or the frame check's, when the model pulled ICP away), else the
  // fallback the mode allows.
  Eigen::Isometry3d acceptOrFallBack(const IcpResult& icp, const IcpStart& s, const std::vector<DepthLevel>& levels,
                                     const IcpParams& ip, FusionResult& res);
  // Why a first frame with this depth (the tracking level's) cannot start the map; None when it can.
  Rejection cannotStartMap(const cv::Mat& depth, const ModelSource& map) const;
  void count(const FusionResult& res, bool had_model);
  void keepForFusion(const Frame& frame, const MotionPrior* prior, const std::vector<DepthLevel>& levels, const CameraIntrinsics& cam,
                     const CameraIntrinsics& track_cam, std::vector<IntensityLevel> intensity, const FusionResult& res);
};

// The tracking levels at trackingDownsample's resolution.
std::vector<DepthLevel> Tracker::Impl::trackingLevels(const Frame& frame, const FrameGeometry* geometry,
                                                      const CameraIntrinsics& cam, CameraIntrinsics& track_cam) const {
  const TrackerParams& P = params;
  const int downsample = trackingDownsample(frame.depth.cols);
  track_cam = cam;
  if (geometry && geometry->points.size() == frame.depth.size() && geometry->normals.size() == frame.depth.size()) {
    // The frame's shared maps, averaged down: one back-projection and normal map serve BRAND and ICP.
    std::vector<DepthLevel> levels = levelsFromGeometry(*geometry, frame.depth, cam, downsample, P.preprocess);
    track_cam = levels[0].camera;
    return levels;
  }
  if (downsample == 2) {
    PreprocessParams pp = P.preprocess;
    pp.sigma_spatial *= 0.5f;
    pp.kernel = std::max(3, ((pp.kernel + 1) / 2) | 1);
    if (P.preprocess.kernel <= 1) pp.kernel = P.preprocess.kernel;
    std::vector<DepthLevel> levels =
        preprocessDepth(downsampleDepth(clipDepth(frame.depth, pp.min_depth, pp.max_depth), pp.sigma_depth), cam.scaled(0.5), pp);
    track_cam = levels[0].camera;  // the halved image's size: an odd row or column is dropped
    return levels;
  }
  return preprocessDepth(frame.depth, cam, P.preprocess);
}

Eigen::Isometry3d Tracker::Impl::trackOdometry(const Frame& frame, const MotionPrior* prior, FusionResult& res) const {
  const Eigen::Isometry3d* ref_pose = prior ? history.poseOf(prior->reference_index) : nullptr;
  res.tracked = true;
  // Relocalised (a keyframe placed the frame; no odometry reaches across the loss): the keyframe's
  // pose, verified as a loop is. This mode has no map to check it against; predicting from the held
  // pose instead kept every later frame lost.
  if (!ref_pose && placed) {
    res.guess = InitialGuess::Prior;
    return *placed;
  }
  res.guess = ref_pose ? InitialGuess::Prior : InitialGuess::ConstantVelocity;
  res.predicted = !ref_pose;
  if (ref_pose) return *ref_pose * prior->T_ref_cur;
  res.rejection = prior ? Rejection::PriorReferenceUnknown : Rejection::NoPrior;
  res.reason = toString(res.rejection);
  return history.constantVelocity(frame.timestamp);
}

// Where a frame's ICP may start: the prior (the odometry's, when its reference frame has a pose here),
// relocalisation's placement, the constant-velocity prediction or the last pose.
struct Tracker::Impl::IcpStart {
  const Eigen::Isometry3d* ref_pose;  // the prior's reference frame's pose, null when none
  bool have_prior;
  Eigen::Isometry3d prior_pose, velocity_pose;
  bool joint, seeded;  // mode joint; mode paper-handoff with a prior (ICP seeded by the odometry)
};

Tracker::Impl::IcpStart Tracker::Impl::icpStart(const Frame& frame, const MotionPrior* prior) const {
  IcpStart s;
  // The prior counts only when its reference frame has a pose here.
  s.ref_pose = prior ? history.poseOf(prior->reference_index) : nullptr;
  s.have_prior = s.ref_pose != nullptr || placed;
  s.prior_pose = s.ref_pose ? *s.ref_pose * prior->T_ref_cur : placed ? *placed : history.pose();
  s.velocity_pose = history.constantVelocity(frame.timestamp);
  s.joint = mode == TrackingMode::Joint;
  s.seeded = mode == TrackingMode::PaperHandoff && s.have_prior;
  return s;
}

Eigen::Isometry3d Tracker::Impl::trackIcp(const Frame& frame, const MotionPrior* prior, const std::vector<DepthLevel>& levels,
                                          const std::vector<IntensityLevel>& intensity, const ModelPrediction& model,
                                          FusionResult& res) {
  const TrackerParams& P = params;
  const IcpStart s = icpStart(frame, prior);
  IcpParams ip = tracking::icpParams(P, s.joint, s.seeded, s.have_prior);
  PointMatches matches;
  if (s.joint) {
    res.guess = tracking::chooseGuess(P, model, history.pose(), levels, ip, s.have_prior, s.prior_pose, s.velocity_pose);
    if (s.ref_pose) matches = tracking::matchesOf(P, *prior, *s.ref_pose, s.prior_pose);
  } else {
    res.guess = s.seeded ? InitialGuess::Prior : InitialGuess::LastPose;
  }
  const Eigen::Isometry3d& initial = res.guess == InitialGuess::Prior              ? s.prior_pose
                                     : res.guess == InitialGuess::ConstantVelocity ? s.velocity_pose
                                                                                   : history.pose();
  // Added to the noise, not in quadrature: the readout's skew is one error over the whole frame, not
  // noise of each point (in quadrature every shared half was worse, by 0.15-0.86 mm:
  // bench/results/2026-12-07-thirteenth-session.md).
  if (s.joint) ip.point_to_plane_sigma += tracking::rollingShutterSigma(P, history, levels, initial, frame.timestamp);
  res.icp_sigma = ip.point_to_plane_sigma;
  const auto t0 = std::chrono::steady_clock::now();
  const PosePrior motion = tracking::motionModel(P, history, s.velocity_pose, frame.timestamp);
  JointTerms terms;
  if (s.joint) {
    if (!matches.camera_points.empty()) terms.matches = &matches;
    if (history.hasMotion() && (motion.sigma_translation > 0 || motion.sigma_rotation > 0)) terms.motion = &motion;
    if (s.have_prior) terms.weak_anchor = &s.prior_pose;
  }
  PhotometricTerms photometric = tracking::photometricTerms(P, model, intensity, levels);
  photometric.colour_motion = colourMotion(frame, prior);
  photometric.rotation_only = P.joint_photometric_rotation_only;
  if (!photometric.levels.empty()) terms.photometric = &photometric;
  const IcpResult icp = projectiveIcp(levels, model.vertices, model.normals, model.pose, initial, ip, terms);
  res.times.add("icp", secondsSince(t0));
  res.icp_inliers = icp.inliers;
  res.icp_rms = icp.rms;
  res.condition = icp.condition;
  res.degenerate_dims = icp.degenerate_dims;
  res.match_inliers = icp.point_inliers;
  return acceptOrFallBack(icp, s, levels, ip, res);
}

Eigen::Isometry3d Tracker::Impl::acceptOrFallBack(const IcpResult& icp, const IcpStart& s,
                                                  const std::vector<DepthLevel>& levels, const IcpParams& ip,
                                                  FusionResult& res) {
  const TrackerParams& P = params;
  std::tie(res.rejection, res.reason) =
      tracking::judge(P, icp, s.joint, s.seeded || (s.joint && s.have_prior) ? &s.prior_pose : nullptr);
  if (res.rejection == Rejection::None) {
    res.tracked = true;
    if (s.joint && s.ref_pose && reference && history.hasMotion() && tracking::worthChecking(P, icp.pose, s.prior_pose)) {
      const auto t1 = std::chrono::steady_clock::now();
      const IcpResult own = tracking::trackAgainstFrame(*reference, levels, s.prior_pose, ip);
      res.times.add("frame_check", secondsSince(t1));
      // In the frame-to-frame estimate's weak directions it is the prior (its anchor), so it agrees with
      // the prior there by construction. Overruling only when it has none was measured worse: shake
      // seeds 3 / 5 +1.5 / +1.9 mm, loop seed 5 +3.0 mm (bench/results/2026-12-07-fourteenth-session.md).
      res.model_overruled = own.solved && tracking::modelPulledAway(P, icp.pose, own.pose, s.prior_pose);
      if (res.model_overruled) return own.pose;
    }
    return icp.pose;
  }
  if (mode != TrackingMode::KinFu && s.have_prior) {
    res.tracked = res.fell_back = true;
    return s.prior_pose;
  }
  if (s.joint) {
    // No motion is dropped: without ICP and without a prior the frame moves on at constant velocity.
    res.tracked = res.predicted = true;
    return s.velocity_pose;
  }
  return history.pose();
}

void Tracker::Impl::count(const FusionResult& res, bool had_model) {
  ++stats.frames;
  if (res.tracked) ++stats.tracked;
  if (res.fell_back) ++stats.fell_back;
  if (res.model_overruled) ++stats.model_overruled;
  if (res.predicted) ++stats.predicted;
  if (res.degenerate_dims > 0 && res.reason.empty()) ++stats.degenerate;
  if (!res.tracked) ++stats.lost;
  if (had_model && mode != TrackingMode::Odometry) {
    if (res.guess == InitialGuess::Prior) ++stats.guess_prior;
    else if (res.guess == InitialGuess::ConstantVelocity) ++stats.guess_velocity;
    else ++stats.guess_last;
  }
  stats.times.merge(res.times);
}

void Tracker::Impl::keepForFusion(const Frame& frame, const MotionPrior* prior, const std::vector<DepthLevel>& levels, const CameraIntrinsics& cam,
                                  const CameraIntrinsics& track_cam, std::vector<IntensityLevel> intensity,
                                  const FusionResult& res) {
  FrameToFuse f;
  // A constant-velocity guess is not fused: nothing measured where the camera was.
  f.integrate = !res.predicted && (!res.fell_back || params.integrate_on_fallback);
  // The raw depth: the tracking levels are a half-resolution copy at 640 px, or (with the odometry's
  // geometry) the raw depth clipped, never a filtered one at the frame's size (the retired key
  // integrate_filtered, docs/tracking.md).
  f.depth = frame.depth;
  f.rgb = frame.rgb;
  f.hint = levels[0].depth;
  f.cam = cam;
  f.track_cam = track_cam;
  f.pose = history.pose();
  f.intensity = std::move(intensity);
  for (const DepthLevel& l : levels) f.level_cams.push_back(l.camera);
  f.colour_pose = history.pose() * colourMotion(frame, prior);  // the prior's, else at the velocity this frame's motion updated
  pending = std::move(f);
}

Tracker::Tracker(const TrackerParams& params, TrackingMode mode, const Eigen::Isometry3d& initial_pose)
    : impl_(std::make_unique<Impl>(params, mode, initial_pose)) {}

Tracker::~Tracker() = default;

namespace {
bool hasReadingIn(const cv::Mat& depth, const std::pair<float, float>& range) {
  cv::Mat in;
  cv::inRange(depth, range.first, range.second, in);
  return cv::countNonZero(in) > 0;
}
}  // namespace

// The first frame starts the map only with readings in [min_depth, max_depth]: one without (a camera
// face down on a desk) would start an empty model that no later frame can track against. In mode
// kinfu, which has no odometry to go on from until the map holds a surface, they must be fused too (a
// wall between integrate_max_depth, 3.5 m, and max_depth, 4 m, started an empty map, and every frame
// after it was lost); the other modes' fallbacks build the map from such a start.
Rejection Tracker::Impl::cannotStartMap(const cv::Mat& depth, const ModelSource& map) const {
  if (cv::countNonZero(depth) == 0) return Rejection::NoReadingInRange;
  if (mode == TrackingMode::KinFu && !hasReadingIn(depth, map.fusedDepthRange())) return Rejection::NoReadingFused;
  return Rejection::None;
}

FusionResult Tracker::track(const Frame& frame, const MotionPrior* prior, const FrameGeometry* geometry, ModelSource& map) {
  Impl& s = *impl_;
  s.pending.reset();
  FusionResult res;
  // A damaged prior would carry NaN into the pose, the map and every later frame: the frame is tracked
  // as if the estimator had given nothing.
  if (prior && !fusion::isFinite(*prior)) prior = nullptr;
  // No reading at all (a covered lens, a sensor glitch): nothing to track, the frame is lost.
  const auto lost = [&](Rejection why) {
    res.rejection = why;
    res.reason = toString(res.rejection);
    res.pose = toMrpt(s.history.pose());
    ++s.stats.frames;
    ++s.stats.lost;
    s.placed.reset();  // a placement is for the frame tracked next: this one
    return res;
  };
  requireMetricDepth(frame.depth, "Tracker");
  if (!hasDepthReading(frame.depth)) return lost(Rejection::NoDepth);
  CameraIntrinsics cam = frame.camera, track_cam;
  cam.width = frame.depth.cols;
  cam.height = frame.depth.rows;
  auto t0 = std::chrono::steady_clock::now();
  const std::vector<DepthLevel> levels = s.trackingLevels(frame, geometry, cam, track_cam);
  res.times.add("preprocess", secondsSince(t0));
  const bool had_model = map.hasModel();
  if (!had_model)
    if (const Rejection why = s.cannotStartMap(levels[0].depth, map); why != Rejection::None) return lost(why);
  map.predictIfStale(s.history.pose(), track_cam, res.times);  // a resumed map: a full ray cast first
  // Mode joint's photometric term: this frame's intensity, tracked against now and a reference later.
  std::vector<IntensityLevel> intensity;
  if (s.mode == TrackingMode::Joint && s.params.joint_photometric_sigma > 0) {
    t0 = std::chrono::steady_clock::now();
    intensity = intensityPyramid(frame.rgb, levels[0].depth.size(), static_cast<int>(levels.size()));
    res.times.add("intensity", secondsSince(t0));
  }
  Eigen::Isometry3d new_pose = s.history.pose();
  if (!had_model) {
    res.tracked = true;  // the first frame defines the map
  } else if (s.mode == TrackingMode::Odometry) {
    new_pose = s.trackOdometry(frame, prior, res);
  } else {
    new_pose = s.trackIcp(frame, prior, levels, intensity, map.model(), res);
  }
  if (res.tracked) s.history.remember(frame.index, frame.timestamp, new_pose, !res.predicted);
  // A frame at a constant-velocity guess is no reference for the next one: neither its depth (the
  // frame check would pull the next frame onto the guess) nor its intensity (the photometric term would
  // pair the next frame's pixels with model points seen from where the camera was not).
  const bool measured = res.tracked && !res.predicted;
  if (s.mode == TrackingMode::Joint) s.reference = measured ? std::optional(tracking::ReferenceFrame{levels, new_pose}) : std::nullopt;
  if (!measured) intensity.clear();
  res.pose = toMrpt(s.history.pose());
  s.placed.reset();
  s.count(res, had_model);
  if (res.tracked) s.keepForFusion(frame, prior, levels, cam, track_cam, std::move(intensity), res);
  return res;
}

const FrameToFuse* Tracker::frameToFuse() const { return impl_->pending ? &*impl_->pending : nullptr; }

void Tracker::fused(bool shifted, const StageTimes& times) {
  impl_->pending.reset();
  if (shifted) ++impl_->stats.shifts;
  impl_->stats.times.merge(times);
}

bool Tracker::placeAt(const Frame& frame, const Eigen::Isometry3d& cam_to_world) {
  Impl& s = *impl_;
  ++s.stats.frames;
  requireMetricDepth(frame.depth, "Tracker");
  if (frame.depth.empty()) return false;
  s.history.setPose(cam_to_world);
  ++s.stats.tracked;
  return true;
}

Eigen::Isometry3d Tracker::pose() const { return impl_->history.pose(); }

void Tracker::holdFrames(std::vector<std::size_t> frames) { impl_->history.hold(std::move(frames)); }

void Tracker::relocalise(const Eigen::Isometry3d& cam_to_world, bool as_prior) {
  impl_->history.restart(cam_to_world);
  impl_->placed.reset();
  impl_->reference.reset();
  if (as_prior) impl_->placed = impl_->history.pose();
}

void Tracker::saveState(std::ostream& os) const {
  const Impl& s = *impl_;
  if (s.pending) throw std::logic_error("Tracker::saveState: a tracked frame was not fused yet");
  auto a = state::archiveOf(os);
  state::tag(a, "tracker");
  s.history.saveState(a);
  const TrackerStats& st = s.stats;
  for (std::size_t n : {st.frames, st.tracked, st.fell_back, st.predicted, st.lost, st.shifts, st.guess_prior,
                        st.guess_velocity, st.guess_last, st.degenerate, st.model_overruled})
    a << uint64_t(n);
  state::write(a, st.times);
  tracking::write(a, s.reference);
}

void Tracker::loadState(std::istream& is) {
  Impl& s = *impl_;
  auto a = state::archiveOf(is);
  state::expectTag(a, "tracker");
  s.history.loadState(a);
  TrackerStats& st = s.stats;
  for (std::size_t* n : {&st.frames, &st.tracked, &st.fell_back, &st.predicted, &st.lost, &st.shifts, &st.guess_prior,
                         &st.guess_velocity, &st.guess_last, &st.degenerate, &st.model_overruled}) {
    uint64_t v = 0;
    a >> v;
    *n = v;
  }
  state::read(a, st.times);
  tracking::read(a, s.reference);
  s.pending.reset();
}

TrackerStats Tracker::stats() const { return impl_->stats; }

}  // namespace vofusion
