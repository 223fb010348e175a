#include "joint_policy.h"

#include <algorithm>
#include <cmath>

#include <tbb/parallel_invoke.h>

#include "vofusion/core/depth_noise.h"

namespace vofusion::tracking {

using namespace fusion;

IcpParams icpParams(const TrackerParams& P, bool joint, bool seeded, bool have_prior) {
  IcpParams ip = P.icp;
  if (!seeded && !(joint && have_prior)) ip.degenerate_ratio = std::min(ip.degenerate_ratio, kMinCondition);
  if (joint) ip.point_to_plane_sigma = P.joint_icp_sigma;
  return ip;
}

PointMatches matchesOf(const TrackerParams& P, const MotionPrior& prior, const Eigen::Isometry3d& T_world_ref,
                       const Eigen::Isometry3d& guess) {
  PointMatches pm;
  pm.cauchy = kMatchCauchy;
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

double rollingShutterSigma(const TrackerParams& P, const MotionHistory& history, const std::vector<DepthLevel>& levels,
                           const Eigen::Isometry3d& initial, double timestamp) {
  if (!(P.joint_rolling_shutter > 0) || !history.hasLast() || !(timestamp > history.lastTimestamp())) return 0.0;
  // Over stamps a microsecond apart, a prior's turn made a turn rate of kilometres of noise.
  const double turn = Eigen::AngleAxisd((history.pose().inverse() * initial).linear()).angle() /
                      std::max(timestamp - history.lastTimestamp(), kShortestFrameInterval);
  const cv::Mat& d = levels.back().depth;
  return P.joint_rolling_shutter * turn * cv::mean(d, d > 0)[0];
}

PosePrior motionModel(const TrackerParams& P, const MotionHistory& history, const Eigen::Isometry3d& velocity_pose,
                      double timestamp) {
  PosePrior m;
  m.pose = velocity_pose;
  // The velocity pose extrapolates from the last measured frame: its spread grows from there (a
  // predicted frame in between measured nothing).
  const double frames_since = history.hasMeasured() ? std::max(1.0, (timestamp - history.lastMeasuredTimestamp()) * 30.0) : 1.0;
  m.sigma_translation = P.motion_sigma_translation * frames_since;
  m.sigma_rotation = P.motion_sigma_rotation * M_PI / 180.0 * frames_since;
  return m;
}

InitialGuess chooseGuess(const TrackerParams& P, const ModelPrediction& model, const Eigen::Isometry3d& last_pose,
                         const std::vector<DepthLevel>& levels, const IcpParams& ip, bool have_prior,
                         const Eigen::Isometry3d& prior_pose, const Eigen::Isometry3d& velocity_pose) {
  const std::size_t L = std::min(levels.size(), model.vertices.size()) - 1;
  const std::vector<DepthLevel> coarse{levels[L]};
  const std::vector<cv::Mat> mv{model.vertices[L]}, mn{model.normals[L]};
  IcpParams coarse_ip = ip;
  coarse_ip.iterations = {3, 3, 3};
  coarse_ip.point_to_plane_sigma = 0;
  const double truncation = 0.5 * ip.max_distance;
  auto cost = [&](const Eigen::Isometry3d& T) {
    const IcpResult r = projectiveIcp(coarse, mv, mn, model.pose, T, coarse_ip);
    return scoreAlignment(coarse[0], mv[0], mn[0], model.pose, r.pose, ip, truncation).cost;
  };
  // The last pose is the ray cast's own viewpoint: there each pixel pairs with the model pixel it was
  // cast from, so sliding along walls costs nothing and the pixel grids coincide; its coarse cost
  // comes out 2-5x below the true pose's whenever the camera moves along planes (a corridor at 3 m/s:
  // chosen on 89 of 300 frames, 18 of them ending 2-10 cm off the odometry). Beside an odometry
  // prior it is no fair candidate; without one it is still the fallback against constant velocity.
  const bool last_is_candidate = !have_prior;
  // The candidates' coarse alignments are independent and each runs on one thread: side by side.
  double prior_cost = 0, velocity_cost = 0, last_cost = 0;
  tbb::parallel_invoke([&] { if (have_prior) prior_cost = cost(prior_pose); },
                       [&] { velocity_cost = cost(velocity_pose); },
                       [&] { if (last_is_candidate) last_cost = cost(last_pose); });
  InitialGuess best = have_prior ? InitialGuess::Prior : InitialGuess::ConstantVelocity;
  double best_cost = have_prior ? prior_cost : velocity_cost;
  if (have_prior && velocity_cost < kGuessMargin * best_cost) best = InitialGuess::ConstantVelocity, best_cost = velocity_cost;
  if (last_is_candidate && last_cost < kGuessMargin * best_cost) best = InitialGuess::LastPose;
  return best;
}

PhotometricTerms photometricTerms(const TrackerParams& P, const ModelPrediction& model,
                                  const std::vector<IntensityLevel>& current, const std::vector<DepthLevel>& levels) {
  PhotometricTerms t;
  t.params.sigma = P.joint_photometric_sigma;
  t.params.huber = kPhotometricHuber;
  t.params.min_gradient = kPhotometricMinGradient;
  const std::size_t n = std::min({current.size(), model.intensity.size(), levels.size(), model.vertices.size()});
  for (std::size_t l = 0; l < n; ++l) {
    if (model.intensity[l].grey.size() != model.vertices[l].size() || current[l].grey.size() != levels[l].depth.size())
      break;
    t.levels.push_back({&model.intensity[l], &current[l], &model.vertices[l], levels[l].camera});
  }
  return t;
}

std::pair<Rejection, std::string> judge(const TrackerParams& P, const IcpResult& icp, bool joint,
                                        const Eigen::Isometry3d* prior_pose) {
  const int judged = joint ? icp.in_view : icp.valid_pixels;
  if (!icp.solved) return {Rejection::NotSolvable, toString(Rejection::NotSolvable)};
  if (icp.inliers < P.min_inlier_ratio * std::max(1, judged))
    return {Rejection::TooFewInliers, toString(Rejection::TooFewInliers) + " (" + std::to_string(icp.inliers) + " of " +
                                          std::to_string(judged) + ")"};
  if (!joint && icp.condition < kMinCondition)
    return {Rejection::IllConditioned,
            toString(Rejection::IllConditioned) + " (eigenvalue ratio " + std::to_string(icp.condition) + ")"};
  if (prior_pose) {
    const Eigen::Isometry3d d = prior_pose->inverse() * icp.pose;
    const double dt = d.translation().norm();
    const double da = Eigen::AngleAxisd(d.linear()).angle() * 180.0 / M_PI;
    if (dt > P.max_jump_translation || da > P.max_jump_rotation)
      return {Rejection::JumpedFromPrior,
              toString(Rejection::JumpedFromPrior) + " (" + std::to_string(dt) + " m / " + std::to_string(da) + " deg)"};
  }
  return {Rejection::None, ""};
}

}  // namespace vofusion::tracking
