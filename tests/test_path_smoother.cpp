// The tracked path's smoothing (tracking/path_smoother.h): noise levels read off the path, centres
// brought closer to the truth, runs ending at unmeasured frames, and the least squares' minimum.
#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "vofusion/core/pose_eigen.h"
#include "vofusion/tracking/path_smoother.h"

using namespace vofusion;

namespace {

constexpr double kInterval = 1.0 / 30.0;

struct Walk {
  Trajectory truth, measured;
};

// A camera walking with random acceleration (sigma_a per frame) and turning, sampled at 30 Hz with
// jittered stamps; `measured` gets the centres with white noise (sigma_m) added, `truth` without.
Walk walk(std::size_t frames, double sigma_a, double sigma_m, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> unit(0.0, 1.0);
  std::uniform_real_distribution<double> jitter(-0.002, 0.002);
  Eigen::Vector3d c(0.0, 0.0, 0.0), v(0.02, 0.0, 0.01);  // m, m per frame interval
  Walk w;
  double last_t = 0.0;
  for (std::size_t i = 0; i < frames; ++i) {
    const double t = double(i) * kInterval + jitter(rng);
    if (i > 0) {  // the velocity changes at the frames, the camera moves with it in between
      v += sigma_a * Eigen::Vector3d(unit(rng), unit(rng), unit(rng));
      c += v * (t - last_t) / kInterval;
    }
    last_t = t;
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = Eigen::AngleAxisd(0.01 * double(i), Eigen::Vector3d(0.2, 1.0, 0.1).normalized()).toRotationMatrix();
    T.translation() = c;
    w.truth.push_back({t, toMrpt(T)});
    T.translation() += sigma_m * Eigen::Vector3d(unit(rng), unit(rng), unit(rng));
    w.measured.push_back({t, toMrpt(T)});
  }
  return w;
}

// The whole path as one run of measured frames.
Trajectory smoothWhole(const Trajectory& path, PathNoise& noise) {
  PathSmoothing how;
  const Trajectory smoothed = smoothPath(path, std::vector<bool>(path.size(), true), &how);
  noise = how.noise;
  return smoothed;
}

double rmsError(const Trajectory& a, const Trajectory& b) {
  double sum = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) sum += std::pow(a[i].pose.distanceTo(b[i].pose), 2);
  return std::sqrt(sum / double(a.size()));
}

}  // namespace

// sigma_a = sigma_m: neighbouring errors correlate by -4/7, inside the clamp. Over 3000 frames the
// correlation's standard error is ~0.02: sigma_m to ~2 %, sigma_a to ~10 %.
TEST(PathSmoother, NoiseLevelsAreReadOffThePath) {
  for (std::uint32_t seed = 1; seed <= 5; ++seed) {
    const auto [truth, measured] = walk(3000, 0.002, 0.002, seed);
    const PathNoise n = estimatePathNoise(measured, std::vector<bool>(measured.size(), true));
    EXPECT_NEAR(n.interval, kInterval, 0.002) << seed;
    EXPECT_GT(n.pairs, 2900u) << seed;
    EXPECT_NEAR(n.measurement, 0.002, 0.0002) << seed;
    EXPECT_NEAR(n.acceleration, 0.002, 0.0008) << seed;
  }
}

// White noise about a constant velocity (sigma_a = 0) correlates neighbours by -2/3: the estimate keeps
// some acceleration there, so a run is smoothed, not laid on a straight line.
TEST(PathSmoother, WhiteNoiseAboutAConstantVelocityKeepsSomeAcceleration) {
  const auto [truth, measured] = walk(300, 0.0, 0.003, 6);
  PathNoise n;
  const Trajectory smoothed = smoothWhole(measured, n);
  ASSERT_TRUE(n.smoothed());
  EXPECT_GT(n.acceleration, 0.0);
  EXPECT_NEAR(n.measurement, 0.003, 0.0006);
  EXPECT_LT(rmsError(smoothed, truth), 0.6 * rmsError(measured, truth));
}

TEST(PathSmoother, CentresComeCloserToTheTruthOrientationsStay) {
  for (std::uint32_t seed = 1; seed <= 5; ++seed) {
    const auto [truth, measured] = walk(300, 0.001, 0.003, seed);
    PathNoise n;
    const Trajectory smoothed = smoothWhole(measured, n);
    ASSERT_TRUE(n.smoothed()) << seed;
    EXPECT_LT(rmsError(smoothed, truth), 0.6 * rmsError(measured, truth)) << seed;
    for (std::size_t i = 0; i < smoothed.size(); ++i) {
      ASSERT_EQ(smoothed[i].timestamp, measured[i].timestamp);
      ASSERT_EQ(smoothed[i].pose.getRotationMatrix(), measured[i].pose.getRotationMatrix()) << i;
    }
  }
}

// Acceleration only: neighbouring errors do not correlate (beyond sampling, ~0.02 over 3000 frames),
// so the measurement noise found is a small fraction of the acceleration's and the path barely moves.
TEST(PathSmoother, ANoiselessPathIsAlmostUntouched) {
  for (std::uint32_t seed = 1; seed <= 5; ++seed) {
    const auto [truth, measured] = walk(3000, 0.001, 0.0, seed);
    PathNoise n;
    const Trajectory smoothed = smoothWhole(truth, n);
    EXPECT_LT(n.measurement, 0.15 * 0.001) << seed;
    EXPECT_LT(rmsError(smoothed, truth), 1e-4) << seed;
  }
}

TEST(PathSmoother, RunsEndAtUnmeasuredFrames) {
  auto [truth, measured] = walk(200, 0.001, 0.003, 2);  // lost frames are written into it
  // Frames 100-109 lost (pose held), then found again 0.5 m away: nothing is smoothed across them.
  std::vector<bool> fused(measured.size(), true);
  for (std::size_t i = 100; i < 110; ++i) {
    fused[i] = false;
    measured[i].pose = measured[99].pose;
  }
  for (std::size_t i = 110; i < measured.size(); ++i) measured[i].pose.x(measured[i].pose.x() + 0.5);
  PathSmoothing how;
  const Trajectory smoothed = smoothPath(measured, fused, &how);
  ASSERT_TRUE(how.noise.smoothed());
  // How far the centres moved, as reported.
  double largest = 0.0;
  for (std::size_t i = 0; i < smoothed.size(); ++i) largest = std::max(largest, smoothed[i].pose.distanceTo(measured[i].pose));
  EXPECT_EQ(how.max_shift, largest);
  EXPECT_GT(how.mean_shift, 0.0);
  for (std::size_t i = 100; i < 110; ++i) EXPECT_EQ(smoothed[i].pose.asVectorVal(), measured[i].pose.asVectorVal()) << i;
  EXPECT_LT(smoothed[99].pose.distanceTo(measured[99].pose), 0.01);
  EXPECT_LT(smoothed[110].pose.distanceTo(measured[110].pose), 0.01);
}

// The smoothed centres minimise the cost path_smoother.h states, written out here on its own: no
// coordinate moved by +-0.1 mm lowers it.
TEST(PathSmoother, TheCentresAreTheLeastSquaresMinimum) {
  const Trajectory measured = walk(12, 0.002, 0.004, 4).measured;  // the cost lambda reads it
  PathNoise noise;
  noise.measurement = 0.004, noise.acceleration = 0.002, noise.interval = kInterval;
  const std::vector<bool> all(measured.size(), true);
  const Trajectory smoothed = smoothPathWith(measured, all, noise);
  const auto cost = [&](const Trajectory& p) {
    double c = 0.0;
    for (std::size_t i = 0; i < p.size(); ++i) c += std::pow(p[i].pose.distanceTo(measured[i].pose) / noise.measurement, 2);
    for (std::size_t i = 1; i + 1 < p.size(); ++i) {
      const double before = p[i].timestamp - p[i - 1].timestamp, after = p[i + 1].timestamp - p[i].timestamp;
      const Eigen::Vector3d c0 = toEigen(p[i - 1].pose).translation(), c1 = toEigen(p[i].pose).translation(),
                            c2 = toEigen(p[i + 1].pose).translation();
      const Eigen::Vector3d e = (c2 - c1) - (after / before) * (c1 - c0);
      const double sigma = noise.acceleration * after * (after + before) / (2.0 * kInterval * kInterval);
      c += e.squaredNorm() / (sigma * sigma);
    }
    return c;
  };
  const double best = cost(smoothed);
  EXPECT_LT(best, cost(measured));
  for (std::size_t i = 0; i < smoothed.size(); ++i)
    for (int axis = 0; axis < 3; ++axis)
      for (const double step : {-1e-4, 1e-4}) {
        Trajectory moved = smoothed;
        mrpt::poses::CPose3D& p = moved[i].pose;
        if (axis == 0) p.x(p.x() + step);
        if (axis == 1) p.y(p.y() + step);
        if (axis == 2) p.z(p.z() + step);
        EXPECT_GT(cost(moved), best) << i << " " << axis << " " << step;
      }
}
