// Closed-form rigid fits (Umeyama), the paper's Algorithm 1 and the robust variant, against known
// transforms with noise and outliers.
#include <random>

#include <Eigen/Dense>

#include "support.h"
#include "vofusion/core/depth_noise.h"
#include "vofusion/registration/rigid_motion.h"

using namespace vofusion;

namespace {
Eigen::Isometry3d knownMotion() {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(0.12, Eigen::Vector3d(0.3, -1.0, 0.4).normalized()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(0.05, -0.03, 0.08);
  return T;
}
// Points spread like a Kinect view (x, y in +-1 m, z in 1..3 m); dst = T src (+ noise, + outliers).
void makeCorrespondences(int n, double noise, double outlier_ratio, Points3& src, Points3& dst, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1), z(1, 3);
  std::normal_distribution<double> g(0, noise);
  const Eigen::Isometry3d T = knownMotion();
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d p(u(rng), u(rng), z(rng));
    src.push_back(p);
    if (i < outlier_ratio * n) dst.push_back(Eigen::Vector3d(u(rng), u(rng), z(rng)));  // wrong match
    else dst.push_back(T * p + Eigen::Vector3d(g(rng), g(rng), g(rng)));
  }
}
double rotationErrorDeg(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle() * 180.0 / M_PI;
}
}  // namespace

TEST(RigidMotion, UmeyamaExactWithoutNoise) {
  Points3 s, d;
  makeCorrespondences(20, 0.0, 0.0, s, d, 1);
  const Eigen::Isometry3d T = umeyamaRigid(s, d);
  EXPECT_LT((T.translation() - knownMotion().translation()).norm(), 1e-9);
  EXPECT_LT(rotationErrorDeg(T, knownMotion()), 1e-7);
}

TEST(RigidMotion, PaperAlgorithmWithNoise) {
  Points3 s, d;
  makeCorrespondences(200, 0.003, 0.0, s, d, 2);
  PaperFitOptions o;
  const RigidFit f = fitPaper(s, d, o);
  ASSERT_TRUE(f.ok) << f.failure;
  // Best of 100 minimal-ish samples: within a few mm / a few tenths of a degree.
  EXPECT_LT((f.T.translation() - knownMotion().translation()).norm(), 0.01);
  EXPECT_LT(rotationErrorDeg(f.T, knownMotion()), 0.5);
  EXPECT_NEAR(f.rms_all, 0.003 * std::sqrt(3.0), 0.004);
}

TEST(RigidMotion, RobustRejectsThirtyPercentOutliers) {
  Points3 s, d;
  makeCorrespondences(300, 0.002, 0.3, s, d, 3);
  RobustFitOptions o;
  const RigidFit f = fitRobust(s, d, o);
  ASSERT_TRUE(f.ok) << f.failure;
  EXPECT_LT((f.T.translation() - knownMotion().translation()).norm(), 0.003);
  EXPECT_LT(rotationErrorDeg(f.T, knownMotion()), 0.15);
  // The 90 outliers are (almost all) excluded, the 210 true matches (almost all) kept.
  EXPECT_GT(f.inliers.size(), 195u);
  EXPECT_LT(f.inliers.size(), 215u);
  // Covariance: symmetric positive definite, translation sigma in the mm range.
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> es(f.covariance);
  EXPECT_GT(es.eigenvalues().minCoeff(), 0.0);
  EXPECT_LT(std::sqrt(f.covariance(0, 0)), 0.005);
  EXPECT_GT(std::sqrt(f.covariance(0, 0)), 1e-5);
}

TEST(RigidMotion, PaperAlgorithmIsHurtByOutliersRobustIsNot) {
  // Why the robust variant exists: least RMS over all correspondences lets outliers pull the fit.
  Points3 s, d;
  makeCorrespondences(200, 0.002, 0.3, s, d, 4);
  const RigidFit p = fitPaper(s, d, PaperFitOptions{});
  const RigidFit r = fitRobust(s, d, RobustFitOptions{});
  ASSERT_TRUE(p.ok && r.ok);
  const double ep = (p.T.translation() - knownMotion().translation()).norm();
  const double er = (r.T.translation() - knownMotion().translation()).norm();
  EXPECT_LT(er, ep);
}

// The paper's fit reports its covariance over its inliers, as its options say: with the outliers in,
// their residuals scaled the spread by ~30x (chi^2 / dof ~1000 times too large).
TEST(RigidMotion, PaperCovarianceIsTheInliers) {
  Points3 s, d;
  makeCorrespondences(300, 0.002, 0.3, s, d, 3);
  const RigidFit p = fitPaper(s, d, PaperFitOptions{});
  ASSERT_TRUE(p.ok) << p.failure;
  ASSERT_GE(p.inliers.size(), 150u);
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> es(p.covariance);
  EXPECT_GT(es.eigenvalues().minCoeff(), 0.0);
  EXPECT_LT(std::sqrt(p.covariance(0, 0)), 0.005);
  EXPECT_GT(std::sqrt(p.covariance(0, 0)), 1e-5);
}

TEST(RigidMotion, CollinearPointsAreDegenerate) {
  Points3 s, d;
  for (int i = 0; i < 30; ++i) s.emplace_back(0.1 * i, 0.05 * i, 2.0), d.push_back(knownMotion() * s.back());
  EXPECT_LT(secondaryExtent(s), 1e-9);
  const RigidFit f = fitRobust(s, d, RobustFitOptions{});
  EXPECT_FALSE(f.ok);  // no non-collinear minimal sample exists
}

TEST(RigidMotion, TooFewCorrespondencesFail) {
  Points3 s{{0, 0, 1}, {1, 0, 1}}, d = s;
  EXPECT_FALSE(fitRobust(s, d, {}).ok);
  EXPECT_FALSE(fitPaper(s, d, {}).ok);
}

// Correspondences far enough out that their squares overflow a double (a damaged reading) give no fit,
// never a NaN or infinite motion with ok set: the odometry and the loop verifier pass a fit's motion
// on without checking it. (Measured: up to 1e150 m the fits succeed, from 1e155 m on they fail.)
TEST(RigidMotion, OverflowingPointsGiveNoFitRatherThanANonFiniteOne) {
  Points3 s, d;
  makeCorrespondences(40, 0.0, 0.0, s, d, 3);
  for (const double scale : {1e150, 1e160, 1e300}) {
    Points3 ss = s, ds = d;
    for (Points3* points : {&ss, &ds})
      for (Eigen::Vector3d& p : *points) p *= scale;
    for (const RigidFit& f : {fitRobust(ss, ds, RobustFitOptions{}), fitPaper(ss, ds, PaperFitOptions{})}) {
      if (f.ok) {
        EXPECT_TRUE(f.T.matrix().allFinite()) << scale;
        EXPECT_TRUE(f.covariance.allFinite()) << scale;
      } else {
        EXPECT_FALSE(f.failure.empty()) << scale;
      }
    }
  }
}

// Kinect-like noise (large along the viewing ray, small across it, growing with depth): whitening the
// residuals by that model (ray_noise) recovers the motion better than isotropic weights, on average
// (measured: 1.40 vs 1.55 mm mean point displacement over 30 draws).
TEST(RigidMotion, RayNoiseWeightingBeatsIsotropicOnAxialNoise) {
  const Eigen::Isometry3d T = knownMotion();
  double err_iso = 0, err_ray = 0;
  for (std::uint32_t seed = 10; seed < 40; ++seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1, 1), z(0.8, 3.5);
    std::normal_distribution<double> g(0, 1);
    auto noisy = [&](const Eigen::Vector3d& p) {
      const double axial = 0.0012 + 0.0019 * (p.z() - 0.4) * (p.z() - 0.4), lateral = p.z() / 525.0;
      const Eigen::Vector3d ray = p.normalized();
      Eigen::Vector3d e(g(rng), g(rng), g(rng));
      e = lateral * (e - e.dot(ray) * ray) + axial * g(rng) * ray;
      return Eigen::Vector3d(p + e);
    };
    Points3 s, d;
    for (int i = 0; i < 80; ++i) {
      const Eigen::Vector3d p(u(rng), u(rng), z(rng));
      s.push_back(noisy(p));
      d.push_back(noisy(T * p));
    }
    for (bool ray : {false, true}) {
      RobustFitOptions o;
      o.inlier_threshold = 0.05;  // no outliers here: every point is an inlier
      o.ray_noise = ray;
      o.cauchy = 0;  // plain least squares: the weighting alone is compared (a kernel costs a little
                     // efficiency on noise that is exactly Gaussian, as here)
      o.gauss_newton_iterations = 10;
      const RigidFit f = fitRobust(s, d, o);
      ASSERT_TRUE(f.ok) << f.failure;
      // Pose error as the mean displacement of the scene points (translation and rotation together).
      double e = 0;
      for (const auto& p : s) e += (f.T * p - T * p).norm();
      (ray ? err_ray : err_iso) += e / s.size();
    }
  }
  EXPECT_LT(err_ray, 0.95 * err_iso) << "ray " << err_ray / 30 << " m, isotropic " << err_iso / 30 << " m";
}

// Half the 3000 matches wrong: a first RANSAC hypothesis with an outlier in its sample has almost no
// inliers, and the draws it asks for (log(0.001) / log(1 - 1e-9)) overflowed an int, which ended the
// loop after one hypothesis.
TEST(RigidMotion, RobustSurvivesAHopelessFirstHypothesis) {
  Points3 s, d;
  makeCorrespondences(3000, 0.002, 0.5, s, d, 5);
  for (std::uint32_t seed = 1; seed <= 8; ++seed) {
    RobustFitOptions o;
    o.seed = seed;
    const RigidFit f = fitRobust(s, d, o);
    ASSERT_TRUE(f.ok) << "seed " << seed << ": " << f.failure;
    EXPECT_GT(f.inliers.size(), 1400u) << "seed " << seed;
    EXPECT_LT((f.T.translation() - knownMotion().translation()).norm(), 0.003) << "seed " << seed;
  }
}

// Matches whose depth came from another surface a few mm away pass the inlier threshold and pull a
// plain least-squares refinement; the Cauchy kernel lets them pull much less.
TEST(RigidMotion, CauchyKernelResistsInliersWithWrongDepth) {
  const Eigen::Isometry3d T = knownMotion();
  double err_plain = 0, err_cauchy = 0;
  for (std::uint32_t seed = 50; seed < 70; ++seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1, 1), z(0.8, 2.0), shift(0.004, 0.009);
    std::normal_distribution<double> g(0, 0.001);
    Points3 s, d;
    for (int i = 0; i < 150; ++i) {
      const Eigen::Vector3d p(u(rng), u(rng), z(rng));
      s.push_back(p);
      Eigen::Vector3d q = T * p + Eigen::Vector3d(g(rng), g(rng), g(rng));
      if (i % 4 == 0) q += shift(rng) * q.normalized();  // a quarter read a surface behind the point
      d.push_back(q);
    }
    for (double c : {0.0, 1.0}) {
      RobustFitOptions o;
      o.cauchy = c;
      const RigidFit f = fitRobust(s, d, o);
      ASSERT_TRUE(f.ok) << f.failure;
      double e = 0;
      for (const auto& p : s) e += (f.T * p - T * p).norm();
      (c > 0 ? err_cauchy : err_plain) += e / s.size();
    }
  }
  EXPECT_LT(err_cauchy, 0.7 * err_plain) << "cauchy " << err_cauchy / 20 << " m, plain " << err_plain / 20 << " m";
}

// Gauss-Newton's Jacobian is written in closed form: its covariance (H^-1 chi^2 / dof at the solution)
// must be the one a central-difference Jacobian of the same whitened residuals gives, in the same
// (x y z yaw pitch roll) parameters, with the Cauchy kernel's weights as the last pass left them; and
// without the kernel the solution is a minimum (no step of either Jacobian lowers it).
TEST(RigidMotion, GaussNewtonCovarianceMatchesNumericDifferentiation) {
  Points3 s, d;
  makeCorrespondences(150, 0.004, 0.0, s, d, 7);
  Eigen::Isometry3d T0 = knownMotion();
  T0.translation() += Eigen::Vector3d(0.01, -0.02, 0.005);
  // MRPT's convention, as the fit's parameters: R = Rz(yaw) Ry(pitch) Rx(roll).
  const auto pose = [](const Eigen::Matrix<double, 6, 1>& p) {
    Eigen::Isometry3d P = Eigen::Isometry3d::Identity();
    P.linear() = (Eigen::AngleAxisd(p[3], Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(p[4], Eigen::Vector3d::UnitY()) *
                  Eigen::AngleAxisd(p[5], Eigen::Vector3d::UnitX())).toRotationMatrix();
    P.translation() = p.head<3>();
    return P;
  };
  // The whitening the fit uses: both points' Kinect ray noise, the source's turned by the initial guess.
  std::vector<Eigen::Matrix3d> w;
  for (std::size_t k = 0; k < s.size(); ++k) {
    const Eigen::Matrix3d C = T0.linear() * rayCovariance(s[k]) * T0.linear().transpose() + rayCovariance(d[k]);
    w.push_back(Eigen::Matrix3d(C.llt().matrixL()).inverse());
  }
  for (const double cauchy : {0.0, 1.0}) {
    SCOPED_TRACE(cauchy);
    Eigen::Matrix<double, 6, 6> cov;
    const Eigen::Isometry3d T = refineGaussNewton(s, d, {}, T0, 8, &cov, true, cauchy);
    const Eigen::Matrix3d R = T.linear();
    Eigen::Matrix<double, 6, 1> p;
    p.head<3>() = T.translation();
    p[4] = std::atan2(-R(2, 0), std::hypot(R(0, 0), R(1, 0)));
    p[3] = std::atan2(R(1, 0), R(0, 0));
    p[5] = std::atan2(R(2, 1), R(2, 2));
    ASSERT_LT((pose(p).matrix() - T.matrix()).norm(), 1e-12);
    // The kernel's weights at the solution, held fixed as the fit holds them.
    std::vector<double> sw(s.size(), 1.0);
    if (cauchy > 0)
      for (std::size_t k = 0; k < s.size(); ++k) {
        const double e = (w[k] * (T * s[k] - d[k])).norm() / cauchy;
        sw[k] = 1.0 / std::sqrt(1.0 + e * e);
      }
    const auto residuals = [&](const Eigen::Matrix<double, 6, 1>& q) {
      Eigen::VectorXd r(3 * s.size());
      for (std::size_t k = 0; k < s.size(); ++k) r.segment<3>(3 * k) = sw[k] * (w[k] * (pose(q) * s[k] - d[k]));
      return r;
    };
    Eigen::MatrixXd J(3 * s.size(), 6);
    for (int j = 0; j < 6; ++j) {
      Eigen::Matrix<double, 6, 1> q = p;
      const double h = 1e-6;
      q[j] += h;
      const Eigen::VectorXd rp = residuals(q);
      q[j] -= 2 * h;
      J.col(j) = (rp - residuals(q)) / (2 * h);
    }
    const Eigen::VectorXd r = residuals(p);
    const Eigen::Matrix<double, 6, 6> H = J.transpose() * J;
    const Eigen::Matrix<double, 6, 6> numeric = H.inverse() * (r.squaredNorm() / (3.0 * double(s.size()) - 6.0));
    EXPECT_LT((cov - numeric).norm(), 1e-5 * numeric.norm()) << cov << "\n\n" << numeric;
    // Without the kernel the gradient vanishes at the solution against the Hessian's scale (with it,
    // reweighting leaves the last step's weights a pass behind).
    if (cauchy == 0) {
      EXPECT_LT((J.transpose() * r).norm(), 1e-6 * H.norm());
    }
    // Still the known motion, within the noise.
    EXPECT_LT((T.translation() - knownMotion().translation()).norm(), 0.003);
    EXPECT_LT(rotationErrorDeg(T, knownMotion()), 0.15);
  }
}
