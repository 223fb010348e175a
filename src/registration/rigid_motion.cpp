#include "vofusion/registration/rigid_motion.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>

#include <Eigen/Dense>
#include <Eigen/Geometry>

#include "vofusion/core/depth_noise.h"

namespace vofusion {

namespace {

// Kinect-like noise of a correspondence (m): both points' depth noise grows with z^2.
double pointSigma(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return 0.002 + 0.0015 * (a.z() * a.z() + b.z() * b.z());
}

// MRPT's CPose3D convention: R = Rz(yaw) Ry(pitch) Rx(roll).
Eigen::Isometry3d fromVector(const Eigen::Matrix<double, 6, 1>& p) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = (Eigen::AngleAxisd(p[3], Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(p[4], Eigen::Vector3d::UnitY()) *
                Eigen::AngleAxisd(p[5], Eigen::Vector3d::UnitX()))
                   .toRotationMatrix();
  T.translation() = p.head<3>();
  return T;
}

Eigen::Matrix<double, 6, 1> toVector(const Eigen::Isometry3d& T) {
  const Eigen::Matrix3d R = T.linear();
  Eigen::Matrix<double, 6, 1> p;
  p.head<3>() = T.translation();
  // yaw, pitch, roll as mrpt::poses::CPose3D::getYawPitchRoll.
  const double pitch = std::atan2(-R(2, 0), std::hypot(R(0, 0), R(1, 0)));
  double yaw, roll;
  if (std::abs(R(2, 0)) < 1.0 - 1e-9) {
    yaw = std::atan2(R(1, 0), R(0, 0));
    roll = std::atan2(R(2, 1), R(2, 2));
  } else {  // gimbal lock
    yaw = std::atan2(-R(0, 1), R(1, 1));
    roll = 0;
  }
  p[3] = yaw; p[4] = pitch; p[5] = roll;
  return p;
}

std::vector<int> allIndices(std::size_t n) {
  std::vector<int> v(n);
  std::iota(v.begin(), v.end(), 0);
  return v;
}

double squaredError(const Eigen::Isometry3d& T, const Eigen::Vector3d& s, const Eigen::Vector3d& d) {
  return (T * s - d).squaredNorm();
}

// A random sample of k distinct indices that are not (nearly) collinear.
bool drawSample(std::size_t n, int k, std::mt19937& rng, const Points3& src, std::vector<int>& sample) {
  std::uniform_int_distribution<int> pick(0, int(n) - 1);
  for (int attempt = 0; attempt < 20; ++attempt) {
    sample.clear();
    while (int(sample.size()) < k) {
      const int i = pick(rng);
      if (std::find(sample.begin(), sample.end(), i) == sample.end()) sample.push_back(i);
    }
    const Eigen::Vector3d a = src[sample[1]] - src[sample[0]], b = src[sample[2]] - src[sample[0]];
    if (a.cross(b).norm() > 1e-4) return true;  // triangle area > 0.5 cm^2
  }
  return false;
}

}  // namespace

Eigen::Isometry3d umeyamaRigid(const Points3& src, const Points3& dst, const std::vector<int>& subset) {
  const std::vector<int> idx = subset.empty() ? allIndices(src.size()) : subset;
  Eigen::Matrix3Xd a(3, idx.size()), b(3, idx.size());
  for (std::size_t i = 0; i < idx.size(); ++i) {
    a.col(i) = src[idx[i]];
    b.col(i) = dst[idx[i]];
  }
  Eigen::Isometry3d T;
  T.matrix() = Eigen::umeyama(a, b, false);
  return T;
}

double secondaryExtent(const Points3& pts, const std::vector<int>& subset) {
  const std::vector<int> idx = subset.empty() ? allIndices(pts.size()) : subset;
  if (idx.size() < 3) return 0.0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (int i : idx) mean += pts[i];
  mean /= double(idx.size());
  Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
  for (int i : idx) C += (pts[i] - mean) * (pts[i] - mean).transpose();
  C /= double(idx.size());
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(C);
  return std::sqrt(std::max(0.0, es.eigenvalues()[1]));  // ascending: [1] is the middle one
}

namespace {
// Whitening of each residual T s - d: the inverse Cholesky factor of R C_s R^T + C_d (R from T0), or
// 1 / pointSigma without the ray noise model.
std::vector<Eigen::Matrix3d> whiteners(const Points3& src, const Points3& dst, const std::vector<int>& idx,
                                       const Eigen::Isometry3d& T0, bool ray_noise) {
  std::vector<Eigen::Matrix3d> w(idx.size());
  const Eigen::Matrix3d R = T0.linear();
  for (std::size_t k = 0; k < idx.size(); ++k) {
    const Eigen::Vector3d &s = src[idx[k]], &d = dst[idx[k]];
    if (ray_noise) {
      const Eigen::Matrix3d C = R * rayCovariance(s) * R.transpose() + rayCovariance(d);
      w[k] = Eigen::Matrix3d(C.llt().matrixL()).inverse();
    } else {
      w[k] = Eigen::Matrix3d::Identity() / pointSigma(s, d);
    }
  }
  return w;
}

// The axes fromVector's three angles turn a point about (R = Rz(yaw) Ry(pitch) Rx(roll)): each angle's
// axis as the rotations before it left it (z; Rz y; Rz Ry x), so d(R s)/d(angle) = axis x (R s). The
// closed form replaced a central-difference Jacobian (12 evaluations of every residual a step): the
// odometry 1 ms a frame faster on xyz_first300.
struct AngleAxes {
  Eigen::Vector3d yaw, pitch, roll;
  explicit AngleAxes(const Eigen::Matrix<double, 6, 1>& p) {
    const Eigen::Matrix3d Rz = Eigen::AngleAxisd(p[3], Eigen::Vector3d::UnitZ()).toRotationMatrix();
    yaw = Eigen::Vector3d::UnitZ();
    pitch = Rz * Eigen::Vector3d::UnitY();
    roll = Rz * Eigen::AngleAxisd(p[4], Eigen::Vector3d::UnitY()) * Eigen::Vector3d::UnitX();
  }
};

// The fit's covariance: H^-1 scaled by the residuals' variance per degree of freedom (1e3 I if H is
// singular).
Eigen::Matrix<double, 6, 6> fitCovariance(const Eigen::Matrix<double, 6, 6>& H, double chi2, std::size_t matches) {
  const double dof = std::max(1.0, 3.0 * double(matches) - 6.0);
  Eigen::FullPivLU<Eigen::Matrix<double, 6, 6>> lu(H);
  return lu.isInvertible() ? Eigen::Matrix<double, 6, 6>(lu.inverse() * (chi2 / dof))
                           : Eigen::Matrix<double, 6, 6>(Eigen::Matrix<double, 6, 6>::Identity() * 1e3);
}
}  // namespace

Eigen::Isometry3d refineGaussNewton(const Points3& src, const Points3& dst, const std::vector<int>& subset,
                                    const Eigen::Isometry3d& T0, int iterations,
                                    Eigen::Matrix<double, 6, 6>* covariance, bool ray_noise, double cauchy) {
  const std::vector<int> idx = subset.empty() ? allIndices(src.size()) : subset;
  Eigen::Matrix<double, 6, 1> p = toVector(T0);
  const std::vector<Eigen::Matrix3d> w = whiteners(src, dst, idx, T0, ray_noise);
  // Cauchy kernel by iteratively reweighted least squares: each pass weighs a whitened residual e by
  // 1 / (1 + (e/c)^2), fixed while the step is solved and tested (all ones without a kernel).
  std::vector<double> sw(idx.size(), 1.0);
  auto cost = [&](const Eigen::Matrix<double, 6, 1>& q) {
    const Eigen::Isometry3d T = fromVector(q);
    double sum = 0;
    for (std::size_t k = 0; k < idx.size(); ++k) sum += (sw[k] * (w[k] * (T * src[idx[k]] - dst[idx[k]]))).squaredNorm();
    return sum;
  };
  auto reweight = [&](const Eigen::Matrix<double, 6, 1>& q) {
    if (cauchy <= 0) return;
    const Eigen::Isometry3d T = fromVector(q);
    for (std::size_t k = 0; k < idx.size(); ++k) {
      const double e = (w[k] * (T * src[idx[k]] - dst[idx[k]])).norm() / cauchy;
      sw[k] = 1.0 / std::sqrt(1.0 + e * e);
    }
  };
  // The normal equations, summed point by point with the Jacobian in closed form: chi^2, H = J^T J
  // and g = J^T r at q.
  auto normalEquations = [&](const Eigen::Matrix<double, 6, 1>& q, Eigen::Matrix<double, 6, 6>& JtJ, Eigen::Matrix<double, 6, 1>& Jtr) {
    const Eigen::Isometry3d T = fromVector(q);
    const AngleAxes axes(q);
    JtJ.setZero();
    Jtr.setZero();
    double sum = 0;
    for (std::size_t k = 0; k < idx.size(); ++k) {
      const Eigen::Vector3d Rs = T.linear() * src[idx[k]];
      const Eigen::Matrix3d W = sw[k] * w[k];
      const Eigen::Vector3d r = W * (Rs + T.translation() - dst[idx[k]]);
      Eigen::Matrix<double, 3, 6> J;
      J.leftCols<3>() = W;
      J.col(3) = W * axes.yaw.cross(Rs);
      J.col(4) = W * axes.pitch.cross(Rs);
      J.col(5) = W * axes.roll.cross(Rs);
      JtJ.noalias() += J.transpose() * J;
      Jtr.noalias() += J.transpose() * r;
      sum += r.squaredNorm();
    }
    return sum;
  };
  Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Identity();
  Eigen::Matrix<double, 6, 1> g;
  double chi2 = 0;
  for (int it = 0; it <= iterations; ++it) {
    reweight(p);
    if (it == iterations && !covariance) break;  // H at the solution is only for the covariance
    chi2 = normalEquations(p, H, g);
    if (it == iterations) break;  // last pass only evaluates H at the solution
    const Eigen::Matrix<double, 6, 1> step = H.ldlt().solve(-g);
    if (!step.allFinite()) break;
    if (cost(p + step) > chi2) break;  // no improvement: keep p
    p += step;
    if (step.norm() < 1e-10) { iterations = it + 1; }
  }
  if (covariance) *covariance = fitCovariance(H, chi2, idx.size());
  return fromVector(p);
}

RigidFit fitPaper(const Points3& src, const Points3& dst, const PaperFitOptions& o) {
  RigidFit fit;
  const int n = int(src.size()), s = std::max(3, o.sample_size);
  if (n < s) {
    fit.failure = "too few correspondences";
    return fit;
  }
  std::mt19937 rng(o.seed);
  std::vector<int> sample;
  double best = std::numeric_limits<double>::infinity();
  for (int h = 0; h < o.hypotheses; ++h) {
    if (!drawSample(src.size(), s, rng, src, sample)) continue;
    const Eigen::Isometry3d T = umeyamaRigid(src, dst, sample);
    double sum = 0;
    for (int i = 0; i < n; ++i) sum += squaredError(T, src[i], dst[i]);
    const double rms = std::sqrt(sum / n);
    if (rms < best) best = rms, fit.T = T;
  }
  if (!std::isfinite(best)) {
    fit.failure = "degenerate geometry";
    return fit;
  }
  fit.rms_all = best;
  double sum_in = 0;
  const double thr2 = o.inlier_threshold * o.inlier_threshold;
  for (int i = 0; i < n; ++i) {
    const double e = squaredError(fit.T, src[i], dst[i]);
    if (e <= thr2) fit.inliers.push_back(i), sum_in += e;
  }
  fit.rms = fit.inliers.empty() ? best : std::sqrt(sum_in / fit.inliers.size());
  fit.rms_at_1m = fit.rms;  // Algorithm 1's inliers are within a fixed distance at any depth
  // Covariance only (T unchanged), over the inliers: the outliers' residuals would scale it by their
  // chi^2. With fewer than 3 inliers, over all as before.
  refineGaussNewton(src, dst, fit.inliers.size() >= 3 ? fit.inliers : std::vector<int>{}, fit.T, 0, &fit.covariance);
  fit.ok = true;
  return fit;
}

// RMS of the inliers' residuals, each scaled to 1 m depth by the noise's z^2 growth.
double rmsAtOneMetre(const Eigen::Isometry3d& T, const Points3& src, const Points3& dst, const std::vector<int>& in) {
  if (in.empty()) return 0.0;
  double sum = 0;
  for (const int i : in) {
    const double z = std::max(1.0, 0.5 * (src[i].z() + dst[i].z()));
    sum += squaredError(T, src[i], dst[i]) / (z * z * z * z);
  }
  return std::sqrt(sum / in.size());
}

namespace {

// The correspondences whose squared error under T is within their own threshold thr2[i].
void inliersUnder(const Eigen::Isometry3d& T, const Points3& src, const Points3& dst, const std::vector<double>& thr2,
                  std::vector<int>& in) {
  in.clear();
  for (int i = 0; i < int(src.size()); ++i)
    if (squaredError(T, src[i], dst[i]) <= thr2[i]) in.push_back(i);
}

// RANSAC over 3-point Umeyama fits: the largest inlier set any hypothesis had (empty when none drew).
std::vector<int> ransacInliers(const Points3& src, const Points3& dst, const std::vector<double>& thr2,
                               const RobustFitOptions& o) {
  const int n = int(src.size());
  std::mt19937 rng(o.seed);
  std::vector<int> sample, in, best_in;
  int needed = o.iterations;
  for (int h = 0; h < std::min(needed, o.iterations); ++h) {
    if (!drawSample(src.size(), 3, rng, src, sample)) continue;
    inliersUnder(umeyamaRigid(src, dst, sample), src, dst, thr2, in);
    if (in.size() > best_in.size()) {
      best_in = in;
      // Adaptive stop: enough draws for 99.9 % probability of one all-inlier sample.
      const double ratio = double(best_in.size()) / n;
      const double p_good = ratio * ratio * ratio;
      if (p_good > 0.999999) needed = h + 1;
      // (in double: a first hypothesis with a handful of inliers asks for more draws than an int holds)
      else if (p_good > 0) needed = int(std::min<double>(o.iterations, std::ceil(std::log(1e-3) / std::log1p(-p_good)) + 1));
    }
  }
  return best_in;
}

}  // namespace

RigidFit fitRobust(const Points3& src, const Points3& dst, const RobustFitOptions& o, bool with_covariance) {
  RigidFit fit;
  const int n = int(src.size());
  if (n < 3) {
    fit.failure = "too few correspondences";
    return fit;
  }
  // Each pair's threshold grows with its depth as the sensor's noise does (z^2).
  std::vector<double> thr2(n);
  for (int i = 0; i < n; ++i) {
    const double z = std::max(1.0, 0.5 * (src[i].z() + dst[i].z()));
    const double t = o.inlier_threshold * z * z;
    thr2[i] = t * t;
  }
  auto inliersOf = [&](const Eigen::Isometry3d& T, std::vector<int>& in) { inliersUnder(T, src, dst, thr2, in); };
  std::vector<int> in, best_in = ransacInliers(src, dst, thr2, o);
  if (best_in.size() < 3) {
    fit.failure = "degenerate geometry";
    return fit;
  }
  // Least squares on the inliers, re-selecting them with the better model twice.
  Eigen::Isometry3d T = umeyamaRigid(src, dst, best_in);
  for (int r = 0; r < 2; ++r) {
    inliersOf(T, in);
    if (in.size() < 3) break;
    best_in = in;
    T = umeyamaRigid(src, dst, best_in);
  }
  T = refineGaussNewton(src, dst, best_in, T, o.gauss_newton_iterations, with_covariance ? &fit.covariance : nullptr, o.ray_noise,
                        o.cauchy);
  inliersOf(T, in);
  if (in.size() >= 3) best_in = in;
  fit.T = T;
  fit.inliers = best_in;
  double sum_in = 0, sum_all = 0;
  for (int i = 0; i < n; ++i) sum_all += squaredError(T, src[i], dst[i]);
  for (int i : best_in) sum_in += squaredError(T, src[i], dst[i]);
  fit.rms = std::sqrt(sum_in / best_in.size());
  fit.rms_all = std::sqrt(sum_all / n);
  fit.rms_at_1m = rmsAtOneMetre(T, src, dst, best_in);
  fit.ok = true;
  return fit;
}

}  // namespace vofusion
