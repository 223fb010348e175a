// Point-to-plane ICP with projective data association (KinectFusion §3.5). The 6x6 system is built
// around the current camera centre (rotation about it, then translation), which keeps its
// eigenvalues comparable between rotation and translation for the degeneracy test.
#include "vofusion/registration/projective_icp.h"

#include <cmath>
#include <limits>

#include <Eigen/Dense>
#include <tbb/parallel_invoke.h>

#include "vofusion/core/parallel.h"
#include "vofusion/registration/icp_association.h"
#include "vofusion/registration/normal_equations.h"

namespace vofusion::fusion {

namespace {

// Coarse levels run on one thread: their iterations take less than handing rows out to the pool.
constexpr std::size_t kParallelMinPixels = 30000;

// A level's sums: its rows' (icp_association.h).
using Accum = IcpRowSums;

void addAccum(Accum& total, const Accum& a) { total += a; }

// Projective association of one level's pixels with the model and the point-to-plane normal equations
// about the camera centre (truncation > 0 also sums the truncated squared residuals).
Accum accumulate(const DepthLevel& lv, const cv::Mat& mv, const cv::Mat& mn, const Eigen::Isometry3f& model_inv,
                 const Eigen::Isometry3f& T, const IcpParams& params, float truncation) {
  const IcpAssociator associator(mv, mn, lv.camera, model_inv, T, params.max_distance, params.max_angle, truncation);
  // Rows in fixed chunks, summed in a fixed order: the same frame gives the same pose on every run.
  return parallelReduce(
      0, lv.vertices.rows, Accum{},
      [&](int y, Accum& acc) {
        acc += associator.sumRow(lv.vertices.ptr<cv::Vec3f>(y), lv.normals.ptr<cv::Vec3f>(y), lv.vertices.cols);
      },
      addAccum, 16, lv.vertices.total() >= kParallelMinPixels);
}

}  // namespace

// Every valid point of a block, also across an occlusion edge (downsampleDepth keeps a band around
// the nearest): keeping the band here was measured and did not carry over (loop seed 5 +3.7 mm, shake
// seed 3 +2.1 mm; bench/results/2026-12-05-pyramid-block-band.md); for the frame's pyramid alone it won
// nowhere (rpy +0.21 mm, the rest within 0.03; 2026-12-07-fifteenth-session.md).
void downsampleMaps(const cv::Mat& vertices, const cv::Mat& normals, cv::Mat& vertices_out, cv::Mat& normals_out) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const int w = vertices.cols / 2, h = vertices.rows / 2;
  vertices_out.create(h, w, CV_32FC3);
  normals_out.create(h, w, CV_32FC3);
  parallelFor(0, h, [&](int y) {
    cv::Vec3f* vo = vertices_out.ptr<cv::Vec3f>(y);
    cv::Vec3f* no = normals_out.ptr<cv::Vec3f>(y);
    for (int x = 0; x < w; ++x) {
      cv::Vec3f vs(0, 0, 0), ns(0, 0, 0);
      int n = 0;
      for (int k = 0; k < 4; ++k) {
        const int yy = 2 * y + (k >> 1), xx = 2 * x + (k & 1);
        const cv::Vec3f& v = vertices.ptr<cv::Vec3f>(yy)[xx];
        const cv::Vec3f& nn = normals.ptr<cv::Vec3f>(yy)[xx];
        if (std::isnan(v[0]) || std::isnan(nn[0])) continue;
        vs += v;
        ns += nn;
        ++n;
      }
      const float len = n ? std::sqrt(ns.dot(ns)) : 0.f;
      if (n == 0 || !(len > 0.f)) {
        vo[x] = no[x] = cv::Vec3f(nan, nan, nan);
      } else {
        vo[x] = vs * (1.f / n);
        no[x] = ns * (1.f / len);
      }
    }
  }, 1, vertices.total() >= kParallelMinPixels);
}

namespace {

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d S;
  S << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return S;
}

// Adds the point matches' whitened, Cauchy-weighted residuals T p - q to the system about the camera
// centre c (parameters: rotation about c, then translation); returns the matches within 3 sigmas.
int addPointMatches(const PointMatches& pm, const Eigen::Isometry3d& T, Eigen::Matrix<double, 6, 6>& A,
                    Eigen::Matrix<double, 6, 1>& b) {
  const Eigen::Vector3d c = T.translation();
  int close = 0;
  for (std::size_t i = 0; i < pm.camera_points.size(); ++i) {
    const Eigen::Vector3d p = T * pm.camera_points[i];
    const Eigen::Vector3d e = p - pm.world_points[i];
    const Eigen::Matrix3d& W = pm.information[i];
    const double m2 = e.dot(W * e);  // squared Mahalanobis length
    if (m2 < 9.0) ++close;
    const double w = pm.cauchy > 0 ? 1.0 / (1.0 + m2 / (pm.cauchy * pm.cauchy)) : 1.0;
    Eigen::Matrix<double, 3, 6> J;
    J << -skew(p - c), Eigen::Matrix3d::Identity();
    A += w * J.transpose() * W * J;
    b -= w * J.transpose() * (W * e);
  }
  return close;
}

// Adds the pose prior: rotation residual log(R R_prior^T) (world frame, Jacobian I in the rotation
// part) and camera-centre residual (Jacobian I in the translation part).
void addPosePrior(const PosePrior& pp, const Eigen::Isometry3d& T, Eigen::Matrix<double, 6, 6>& A,
                  Eigen::Matrix<double, 6, 1>& b) {
  if (pp.sigma_rotation > 0) {
    const Eigen::AngleAxisd d(T.linear() * pp.pose.linear().transpose());
    const Eigen::Vector3d e = d.angle() * d.axis();
    const double w = 1.0 / (pp.sigma_rotation * pp.sigma_rotation);
    A.topLeftCorner<3, 3>() += w * Eigen::Matrix3d::Identity();
    b.head<3>() -= w * e;
  }
  if (pp.sigma_translation > 0) {
    const Eigen::Vector3d e = T.translation() - pp.pose.translation();
    const double w = 1.0 / (pp.sigma_translation * pp.sigma_translation);
    A.bottomRightCorner<3, 3>() += w * Eigen::Matrix3d::Identity();
    b.tail<3>() -= w * e;
  }
}

// What a term (information A, right-hand side b; rotation first) says about the rotation whatever the
// translation: the Schur complement A_rr - A_rt A_tt^-1 A_tr, and b_r - A_rt A_tt^-1 b_t. Nothing
// when the translation block cannot be inverted.
void keepRotationOnly(Eigen::Matrix<double, 6, 6>& A, Eigen::Matrix<double, 6, 1>& b) {
  const Eigen::LDLT<Eigen::Matrix3d> tt(A.bottomRightCorner<3, 3>());
  const Eigen::Matrix3d Art = A.topRightCorner<3, 3>();
  Eigen::Matrix<double, 6, 6> As = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 1> bs = Eigen::Matrix<double, 6, 1>::Zero();
  if (tt.info() == Eigen::Success && tt.isPositive() && A.bottomRightCorner<3, 3>().trace() > 0) {
    As.topLeftCorner<3, 3>() = A.topLeftCorner<3, 3>() - Art * tt.solve(Art.transpose());
    bs.head<3>() = b.head<3>() - Art * tt.solve(b.tail<3>());
  }
  A = As;
  b = bs;
}

}  // namespace

AlignmentScore scoreAlignment(const DepthLevel& frame, const cv::Mat& model_vertices, const cv::Mat& model_normals,
                              const Eigen::Isometry3d& model_pose, const Eigen::Isometry3d& pose,
                              const IcpParams& params, double truncation) {
  const Accum a = accumulate(frame, model_vertices, model_normals, model_pose.inverse().cast<float>(), pose.cast<float>(),
                             params, float(truncation));
  AlignmentScore s;
  s.inliers = a.n;
  s.valid = a.valid;
  // Over the pixels that see the model: leaving the model's view is no evidence against a pose
  // (sliding along a wall moves pixels out of it while the geometry cannot tell).
  s.in_view = a.in_view;
  s.cost = a.in_view ? (a.r2_truncated + double(a.in_view - a.n) * truncation * truncation) / a.in_view
                     : truncation * truncation;
  return s;
}

namespace {
using Mat6 = Eigen::Matrix<double, 6, 6>;
using Vec6 = Eigen::Matrix<double, 6, 1>;

// The scaled ICP system's strong directions (eigenvalue at least degenerate_ratio of the largest):
// their information As and projector Ps; the weak ones get no step, or the step to the weak anchor.
struct StrongDirections {
  Mat6 As = Mat6::Zero(), Ps = Mat6::Zero();
  int degenerate = 0;
};

// Mode joint's weak directions of ICP, decided once per call at its first iteration with 6 inliers
// (the finest level's first, whatever its count, if none before) and kept (why:
// JointTerms in the header). Each is a unit vector in that iteration's scaled coordinates with the
// share of its step solved as strong: 0 under half of degenerate_ratio, 1 from twice it (not kept),
// log-linear between (half and half at the ratio).
struct WeakDirection {
  Vec6 v;
  double strong_share;
};
struct WeakDirections {
  bool decided = false;
  std::vector<WeakDirection> directions;
  int belowRatio() const {  // weak more than strong: under degenerate_ratio
    int n = 0;
    for (const WeakDirection& d : directions) n += d.strong_share < 0.5;
    return n;
  }
};

void decideWeakDirections(const Eigen::SelfAdjointEigenSolver<Mat6>& es, double emax, double ratio, WeakDirections& weak) {
  weak.decided = true;
  for (int i = 0; i < 6 && ratio > 0; ++i) {
    const double q = es.eigenvalues()[i] / (ratio * emax);
    if (q >= 2.0) continue;
    weak.directions.push_back({es.eigenvectors().col(i), q < 0.5 ? 0.0 : 0.5 * (std::log2(q) + 1.0)});
  }
}

// ICP's system M (scaled) without the weak directions whose strong share is at most `max_share`
// (0: the wholly weak ones left out; 1: the partly weak ones too).
StrongDirections strongBeside(const Mat6& M, const WeakDirections& weak, double max_share) {
  StrongDirections sd;
  sd.Ps = Mat6::Identity();
  for (const WeakDirection& d : weak.directions)
    if (d.strong_share <= max_share) {
      sd.Ps -= d.v * d.v.transpose();
      ++sd.degenerate;
    }
  sd.As = sd.Ps * M * sd.Ps;
  return sd;
}

// One level's fixed inputs to each Gauss-Newton iteration.
struct IcpLevel {
  const DepthLevel& frame;
  const cv::Mat &model_vertices, &model_normals;
  const Eigen::Isometry3f& model_inv;
  const IcpParams& params;
  const JointTerms& joint;
  int level;
  double icp_weight;
  bool have_points, have_photo;
  WeakDirections* weak;  // mode joint, shared by all levels of the frame
};

// With the other terms (matches, motion model, photometric term, weak anchor): the scaled step xs.
// False when the combined system cannot be decomposed.
bool jointStep(const IcpLevel& L, const PhotometricSums& ps, const StrongDirections& sd, const Vec6& D,
               const Vec6& b_icp, IcpResult& res, Vec6& xs) {
  Mat6 At = Mat6::Zero();
  Vec6 bt = Vec6::Zero();
  if (L.have_points) {
    const int close = addPointMatches(*L.joint.matches, res.pose, At, bt);
    if (L.level == 0) res.point_inliers = close;
  }
  if (L.joint.motion) addPosePrior(*L.joint.motion, res.pose, At, bt);
  if (L.have_photo) {
    Mat6 Ap = ps.A;
    Vec6 bp = ps.b;
    if (L.joint.photometric->rotation_only) keepRotationOnly(Ap, bp);
    At += Ap;
    bt += bp;
  }
  // Strong subspace: ICP, the matches, the motion model and the photometric term together.
  const Mat6 Ss = sd.As + sd.Ps * D.asDiagonal() * At * D.asDiagonal() * sd.Ps;
  const Vec6 bb = sd.Ps * (b_icp + D.asDiagonal() * bt);
  const Eigen::SelfAdjointEigenSolver<Mat6> ej(Ss);
  if (!ej.eigenvectors().allFinite()) return false;
  for (int i = 0; i < 6; ++i) {
    const double e = ej.eigenvalues()[i];
    if (e > 1e-9 * ej.eigenvalues()[5]) xs += ej.eigenvectors().col(i) * (ej.eigenvectors().col(i).dot(bb) / e);
  }
  // Weak subspace: the step that brings the pose to the anchor (rotation about the camera
  // centre, then the centre), in the scaled coordinates.
  if (L.joint.weak_anchor && sd.degenerate > 0) {
    const Eigen::AngleAxisd dr(L.joint.weak_anchor->linear() * res.pose.linear().transpose());
    Vec6 delta;
    delta << dr.angle() * dr.axis(), L.joint.weak_anchor->translation() - res.pose.translation();
    const Vec6 delta_s = delta.cwiseQuotient(D);
    xs += (Mat6::Identity() - sd.Ps) * delta_s;
  }
  return true;
}

// jointStep with ICP's weak directions as decided for the frame (WeakDirections): the step with the
// partly weak directions solved and the one with them left to the anchor, mixed by the product of
// their shares (one such direction: continuous; two at once can still jump as one leaves the band).
bool jointStepBesideWeak(const IcpLevel& L, const PhotometricSums& ps, const Mat6& M, const Vec6& D, const Vec6& b_icp,
                         IcpResult& res, Vec6& xs) {
  double strong_share = 1.0;
  for (const WeakDirection& d : L.weak->directions)
    if (d.strong_share > 0) strong_share *= d.strong_share;
  const StrongDirections with_partly = strongBeside(M, *L.weak, 0.0);
  if (strong_share == 1.0) return jointStep(L, ps, with_partly, D, b_icp, res, xs);
  const StrongDirections without_partly = strongBeside(M, *L.weak, 1.0);
  Vec6 xs_strong = Vec6::Zero(), xs_weak = Vec6::Zero();
  if (!jointStep(L, ps, with_partly, D, b_icp, res, xs_strong) || !jointStep(L, ps, without_partly, D, b_icp, res, xs_weak))
    return false;
  xs += xs_weak + strong_share * (xs_strong - xs_weak);
  return true;
}

// The pose moved by the increment xi about its camera centre c: p -> R_inc (p - c) + c + tau.
Eigen::Isometry3d stepAboutCentre(const Eigen::Isometry3d& pose, const Vec6& xi) {
  const Eigen::Vector3d w = xi.head<3>();
  const double angle = w.norm();
  const Eigen::Matrix3d Rinc = angle > 1e-12 ? Eigen::AngleAxisd(angle, w / angle).toRotationMatrix() : Eigen::Matrix3d::Identity();
  const Eigen::Vector3d c = pose.translation();
  Eigen::Isometry3d inc = Eigen::Isometry3d::Identity();
  inc.linear() = Rinc;
  inc.translation() = c - Rinc * c + xi.tail<3>();
  Eigen::Isometry3d moved = inc * pose;
  // Re-orthonormalise against float drift.
  const Eigen::Quaterniond q(moved.linear());
  moved.linear() = q.normalized().toRotationMatrix();
  return moved;
}

// ICP's and the photometric term's sums at the current pose, side by side: below kParallelMinPixels
// each runs on one thread, and while ICP runs nothing else of the pipeline does.
Accum accumulateTerms(const IcpLevel& L, const Eigen::Isometry3d& pose, PhotometricSums& ps) {
  Accum total;
  const auto icpSums = [&] {
    total = accumulate(L.frame, L.model_vertices, L.model_normals, L.model_inv, pose.cast<float>(), L.params, 0.f);
  };
  const PhotometricTerms* photo = L.joint.photometric;
  const auto photoSums = [&] {
    ps = accumulatePhotometric(photo->levels[L.level], pose, photo->params, double(1 << (2 * L.level)), photo->colour_motion);
  };
  if (L.have_photo) tbb::parallel_invoke(icpSums, photoSums);
  else icpSums();
  return total;
}

// ICP alone's step, in the scaled coordinates of es: the Gauss-Newton solution over the directions
// whose eigenvalue is at least degenerate_ratio of the largest; the others (a plane's slide) stay 0.
Vec6 stepOverWellPosed(const Eigen::SelfAdjointEigenSolver<Mat6>& es, double emax, const Vec6& b_scaled,
                       double degenerate_ratio, int& degenerate) {
  Vec6 xs = Vec6::Zero();
  degenerate = 0;
  for (int i = 0; i < 6; ++i) {
    const double e = es.eigenvalues()[i];
    // Floored as the joint step's is: icp_degenerate_ratio 0 (in range) divided by a plane's zero eigenvalues.
    if (e >= std::max(degenerate_ratio, 1e-9) * emax) xs += es.eigenvectors().col(i) * (es.eigenvectors().col(i).dot(b_scaled) / e);
    else ++degenerate;
  }
  return xs;
}

// One Gauss-Newton iteration at a level; false when the level stops (converged or unsolvable).
bool icpIteration(const IcpLevel& L, IcpResult& res) {
  PhotometricSums ps;
  const Accum total = accumulateTerms(L, res.pose, ps);
  Mat6 A;
  Vec6 b;
  total.eq.unpack(L.icp_weight, A, b);
  if (L.level == 0) {
    res.inliers = total.n;
    res.valid_pixels = total.valid;
    res.in_view = total.in_view;
    res.rms = total.n ? std::sqrt(total.r2 / total.n) : 0.0;
  }
  if (total.n < 6 && !L.have_points && !L.joint.motion && !L.have_photo) {
    res.solved = false;
    if (L.level == 0) res.condition = 0.0;
    return false;
  }
  // Scale the rotation block by the rms point distance from the camera centre: then a unit of
  // either part moves the points by about a metre, and eigenvalues compare across the two.
  const double scale = std::sqrt(std::max(1e-6, total.n ? total.d2 / total.n : 1.0));
  Vec6 D;
  D << 1.0 / scale, 1.0 / scale, 1.0 / scale, 1.0, 1.0, 1.0;
  const Mat6 M = D.asDiagonal() * A * D.asDiagonal();
  const Eigen::SelfAdjointEigenSolver<Mat6> es(M);
  const double emax = es.eigenvalues()[5];
  const bool other_terms = L.have_points || L.joint.motion || L.joint.weak_anchor || L.have_photo;
  if (!(emax > 0.0) || !es.eigenvectors().allFinite()) {
    res.solved = false;
    return false;
  }
  if (L.level == 0) res.condition = std::max(0.0, es.eigenvalues()[0]) / emax;
  const Vec6 b_icp = D.asDiagonal() * b;
  Vec6 xs = Vec6::Zero();
  if (!other_terms) {
    int degenerate = 0;
    xs = stepOverWellPosed(es, emax, b_icp, L.params.degenerate_ratio, degenerate);
    if (L.level == 0) res.degenerate_dims = degenerate;
  } else {
    // Not on fewer than 6 points on a coarse level the guess left nearly empty: their system has rank
    // below 6 by count alone, and 6 - n directions would stay with the prior for the whole frame. The
    // finest level decides whatever its count (undecided, the anchor would hold no direction).
    if (!L.weak->decided && (total.n >= 6 || L.level == 0)) decideWeakDirections(es, emax, L.params.degenerate_ratio, *L.weak);
    if (L.level == 0) res.degenerate_dims = L.weak->belowRatio();
    if (!jointStepBesideWeak(L, ps, M, D, b_icp, res, xs)) {
      res.solved = false;
      return false;
    }
  }
  const Vec6 xi = D.asDiagonal() * xs;
  if (!xi.allFinite()) {
    res.solved = false;
    return false;
  }
  res.solved = true;
  res.pose = stepAboutCentre(res.pose, xi);
  // Converged at this level: a step under 0.1 mm and 0.006 deg (1e-6 ran 11 % more ICP in mode
  // kinfu on fr1_xyz for the same ATE).
  return !(xi.norm() < 1e-4);
}
}  // namespace

IcpResult projectiveIcp(const std::vector<DepthLevel>& frame, const std::vector<cv::Mat>& model_vertices,
                        const std::vector<cv::Mat>& model_normals, const Eigen::Isometry3d& model_pose,
                        const Eigen::Isometry3d& initial, const IcpParams& params, const JointTerms& joint) {
  IcpResult res;
  res.pose = initial;
  const int levels = static_cast<int>(std::min({frame.size(), model_vertices.size(), model_normals.size()}));
  const Eigen::Isometry3f model_inv = model_pose.inverse().cast<float>();
  const bool have_points = joint.matches && !joint.matches->camera_points.empty();
  WeakDirections weak;
  for (int l = levels - 1; l >= 0; --l) {
    const int iters = l < static_cast<int>(params.iterations.size()) ? params.iterations[l] : params.iterations.back();
    // A pixel of level l averages 4^l finest-level readings.
    const double icp_weight =
        params.point_to_plane_sigma > 0 ? double(1 << (2 * l)) / (params.point_to_plane_sigma * params.point_to_plane_sigma) : 1.0;
    const bool have_photo = joint.photometric && l < static_cast<int>(joint.photometric->levels.size());
    const IcpLevel L{frame[l], model_vertices[l], model_normals[l], model_inv, params, joint, l, icp_weight, have_points, have_photo, &weak};
    for (int it = 0; it < iters; ++it)
      if (!icpIteration(L, res)) break;
  }
  return res;
}

}  // namespace vofusion::fusion
