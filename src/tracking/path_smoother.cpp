#include "vofusion/tracking/path_smoother.h"

#include <algorithm>
#include <cmath>

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <Eigen/Dense>

namespace vofusion {

namespace {

// [first, last) of each run of consecutive measured frames.
std::vector<std::pair<std::size_t, std::size_t>> measuredRuns(const Trajectory& path, const std::vector<bool>& measured) {
  std::vector<std::pair<std::size_t, std::size_t>> runs;
  for (std::size_t i = 0; i < path.size();) {
    if (i >= measured.size() || !measured[i]) {
      ++i;
      continue;
    }
    std::size_t j = i;
    while (j < path.size() && j < measured.size() && measured[j]) ++j;
    runs.push_back({i, j});
    i = j;
  }
  return runs;
}

Eigen::Vector3d centre(const StampedPose& p) { return {p.pose.x(), p.pose.y(), p.pose.z()}; }

// The median interval between consecutive measured frames (0 if none).
double medianInterval(const Trajectory& path, const std::vector<std::pair<std::size_t, std::size_t>>& runs) {
  std::vector<double> dt;
  for (const auto& [first, last] : runs)
    for (std::size_t i = first + 1; i < last; ++i)
      if (path[i].timestamp > path[i - 1].timestamp) dt.push_back(path[i].timestamp - path[i - 1].timestamp);
  if (dt.empty()) return 0.0;
  std::nth_element(dt.begin(), dt.begin() + dt.size() / 2, dt.end());
  return dt[dt.size() / 2];
}

// Frame i's constant-velocity prediction error: c_{i+1} - c_i - r (c_i - c_{i-1}), r = dt_i / dt_{i-1},
// as coefficients on c_{i-1}, c_i, c_{i+1}; and its scale against one interval T (a constant
// acceleration a gives a dt_i (dt_i + dt_{i-1}) / 2, which is a T^2 at T). False: the frames are not
// in time order.
bool predictionError(const Trajectory& path, std::size_t i, double T, double (&coef)[3], double& scale) {
  const double before = path[i].timestamp - path[i - 1].timestamp, after = path[i + 1].timestamp - path[i].timestamp;
  if (!(before > 0.0 && after > 0.0)) return false;
  const double r = after / before;
  coef[0] = r, coef[1] = -(1.0 + r), coef[2] = 1.0;
  scale = after * (after + before) / (2.0 * T * T);
  return true;
}

}  // namespace

PathNoise estimatePathNoise(const Trajectory& path, const std::vector<bool>& measured) {
  PathNoise noise;
  const auto runs = measuredRuns(path, measured);
  noise.interval = medianInterval(path, runs);
  if (!(noise.interval > 0.0)) return noise;
  // Per axis, the scaled prediction errors u_i = e_i / scale_i: white measurement noise gives u_i the
  // variance d_i sigma_m^2 (its coefficients' squares / scale_i^2) and neighbours the covariance
  // c_i sigma_m^2 (their overlapping coefficients' products); the acceleration adds sigma_a^2 to the
  // variance only. Moments matched over the whole path.
  double sum_sq = 0.0, sum_d = 0.0, sum_pairs = 0.0, sum_c = 0.0;
  std::size_t errors = 0;
  for (const auto& [first, last] : runs) {
    bool have_last = false;
    double last_coef[3] = {0.0, 0.0, 0.0}, last_scale = 1.0;
    Eigen::Vector3d last_error = Eigen::Vector3d::Zero();
    for (std::size_t i = first + 1; i + 1 < last; ++i) {
      double coef[3], scale;
      if (!predictionError(path, i, noise.interval, coef, scale)) {
        have_last = false;
        continue;
      }
      const Eigen::Vector3d u = (coef[0] * centre(path[i - 1]) + coef[1] * centre(path[i]) + coef[2] * centre(path[i + 1])) / scale;
      sum_sq += u.squaredNorm();
      sum_d += (coef[0] * coef[0] + coef[1] * coef[1] + coef[2] * coef[2]) / (scale * scale);
      ++errors;
      if (have_last) {  // u_{i-1} reads frames i-2, i-1, i; u_i reads i-1, i, i+1
        sum_pairs += u.dot(last_error);
        sum_c += (last_coef[1] * coef[0] + last_coef[2] * coef[1]) / (last_scale * scale);
        ++noise.pairs;
      }
      std::copy(coef, coef + 3, last_coef), last_scale = scale, last_error = u, have_last = true;
    }
  }
  if (noise.pairs == 0) return noise;
  const double variance = sum_sq / double(3 * errors), d = sum_d / double(errors);
  const double covariance = sum_pairs / double(3 * noise.pairs), c = sum_c / double(noise.pairs);
  if (!(variance > 0.0) || !(c < 0.0)) return noise;
  // rho = covariance / variance lies between 0 (no white noise) and c / d (white noise about a constant
  // velocity, sigma_a = 0; -4/6 at equal intervals). The measured rho is taken as it is, but kept
  // 1.5/sqrt(pairs) of that limit inside it (about three of its standard errors: a short path seldom
  // reaches the limit by chance), so that sigma_a never vanishes (a run would become a straight line);
  // with 2 pairs or fewer nothing is smoothed.
  const double limit = c / d;
  const double rho = std::max(covariance / variance, limit * (1.0 - 1.5 / std::sqrt(double(noise.pairs))));
  if (!(rho < 0.0)) return noise;
  noise.measurement = std::sqrt(rho * variance / c);
  noise.acceleration = std::sqrt(variance * (1.0 - rho / limit));
  return noise;
}

Trajectory smoothPathWith(const Trajectory& path, const std::vector<bool>& measured, const PathNoise& noise) {
  Trajectory out = path;
  if (!noise.smoothed() || !(noise.interval > 0.0)) return out;
  const double w_measurement = 1.0 / (noise.measurement * noise.measurement);
  for (const auto& [first, last] : measuredRuns(path, measured)) {
    const int n = int(last - first);
    if (n < 3) continue;
    // Normal equations of the run's least squares: a band of width 2 about the diagonal.
    std::vector<Eigen::Triplet<double>> entries;
    Eigen::MatrixXd rhs(n, 3);
    for (int k = 0; k < n; ++k) {
      entries.emplace_back(k, k, w_measurement);
      rhs.row(k) = w_measurement * centre(path[first + std::size_t(k)]).transpose();
    }
    for (int k = 1; k + 1 < n; ++k) {
      double coef[3], scale;
      if (!predictionError(path, first + std::size_t(k), noise.interval, coef, scale)) continue;
      const double sigma = noise.acceleration * scale, w = 1.0 / (sigma * sigma);
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) entries.emplace_back(k - 1 + a, k - 1 + b, w * coef[a] * coef[b]);
    }
    Eigen::SparseMatrix<double> A(n, n);
    A.setFromTriplets(entries.begin(), entries.end());
    const Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(A);
    if (solver.info() != Eigen::Success) continue;
    const Eigen::MatrixXd smoothed = solver.solve(rhs);
    for (int k = 0; k < n; ++k) {
      mrpt::poses::CPose3D& pose = out[first + std::size_t(k)].pose;  // its orientation as tracked
      pose.x(smoothed(k, 0)), pose.y(smoothed(k, 1)), pose.z(smoothed(k, 2));
    }
  }
  return out;
}

Trajectory smoothPath(const Trajectory& path, const std::vector<bool>& measured, PathSmoothing* out) {
  const PathNoise noise = estimatePathNoise(path, measured);
  Trajectory smoothed = smoothPathWith(path, measured, noise);
  if (out) {
    *out = PathSmoothing{noise, 0.0, 0.0};
    for (std::size_t i = 0; i < path.size(); ++i) {
      const double d = path[i].pose.distanceTo(smoothed[i].pose);
      out->mean_shift += d / double(path.size());
      out->max_shift = std::max(out->max_shift, d);
    }
  }
  return smoothed;
}

}  // namespace vofusion
