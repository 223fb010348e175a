// Point-to-plane ICP with projective data association (KinectFusion §3.5). The 6x6 system is built
// around the current camera centre (rotation about it, then translation), which keeps its
// eigenvalues comparable between rotation and translation for the degeneracy test.
#include "vofusion/fusion/projective_icp.h"

#include <cmath>
#include <limits>

#include <Eigen/Dense>

#include "vofusion/core/parallel.h"

namespace vofusion::fusion {

namespace {

// Coarse levels run on one thread: their iterations take less than handing rows out to the pool.
constexpr std::size_t kParallelMinPixels = 30000;

struct Accum {
  double A[21] = {};  // upper triangle of J^T J
  double b[6] = {};
  double r2 = 0.0;
  double d2 = 0.0;  // squared distances of the inliers from the camera centre
  int n = 0;
  int valid = 0;  // pixels with a vertex and a normal
};

void addAccum(Accum& total, const Accum& a) {
  for (int i = 0; i < 21; ++i) total.A[i] += a.A[i];
  for (int i = 0; i < 6; ++i) total.b[i] += a.b[i];
  total.r2 += a.r2;
  total.d2 += a.d2;
  total.n += a.n;
  total.valid += a.valid;
}

}  // namespace

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

IcpResult projectiveIcp(const std::vector<DepthLevel>& frame, const std::vector<cv::Mat>& model_vertices,
                        const std::vector<cv::Mat>& model_normals, const Eigen::Isometry3d& model_pose,
                        const Eigen::Isometry3d& initial, const IcpParams& params) {
  IcpResult res;
  res.pose = initial;
  const int levels = static_cast<int>(std::min({frame.size(), model_vertices.size(), model_normals.size()}));
  const float max_d2 = params.max_distance * params.max_distance;
  const float min_cos = static_cast<float>(std::cos(params.max_angle * M_PI / 180.0));
  const Eigen::Isometry3f model_inv = model_pose.inverse().cast<float>();
  const Eigen::Matrix3f Rm = model_inv.linear();
  const Eigen::Vector3f tm = model_inv.translation();

  for (int l = levels - 1; l >= 0; --l) {
    const DepthLevel& lv = frame[l];
    const cv::Mat& mv = model_vertices[l];
    const cv::Mat& mn = model_normals[l];
    const float fx = lv.camera.fx, fy = lv.camera.fy, cx = lv.camera.cx, cy = lv.camera.cy;
    const int mw = mv.cols, mh = mv.rows;
    const int iters = l < static_cast<int>(params.iterations.size()) ? params.iterations[l] : params.iterations.back();
    for (int it = 0; it < iters; ++it) {
      const Eigen::Isometry3f T = res.pose.cast<float>();
      const Eigen::Matrix3f R = T.linear();
      const Eigen::Vector3f t = T.translation();
      // Rows in fixed chunks, summed in a fixed order: the same frame gives the same pose on every run.
      const Accum total = parallelReduce(
          0, lv.vertices.rows, Accum{},
          [&](int y, Accum& acc) {
            const cv::Vec3f* vrow = lv.vertices.ptr<cv::Vec3f>(y);
            const cv::Vec3f* nrow = lv.normals.ptr<cv::Vec3f>(y);
            for (int x = 0; x < lv.vertices.cols; ++x) {
              const cv::Vec3f& vc = vrow[x];
              const cv::Vec3f& nc = nrow[x];
              if (std::isnan(vc[0]) || std::isnan(nc[0])) continue;
              ++acc.valid;
              const Eigen::Vector3f vg = R * Eigen::Vector3f(vc[0], vc[1], vc[2]) + t;
              const Eigen::Vector3f pm = Rm * vg + tm;  // in the model camera
              if (pm.z() <= 0.f) continue;
              const float uf = fx * pm.x() / pm.z() + cx, vf = fy * pm.y() / pm.z() + cy;
              if (!(uf > -0.5f && vf > -0.5f && uf < mw - 0.5f && vf < mh - 0.5f)) continue;
              const int u = static_cast<int>(uf + 0.5f), v = static_cast<int>(vf + 0.5f);
              const cv::Vec3f& m = mv.ptr<cv::Vec3f>(v)[u];
              const cv::Vec3f& n = mn.ptr<cv::Vec3f>(v)[u];
              if (std::isnan(m[0]) || std::isnan(n[0])) continue;
              const Eigen::Vector3f vm(m[0], m[1], m[2]), nm(n[0], n[1], n[2]);
              const Eigen::Vector3f d = vg - vm;
              if (d.squaredNorm() > max_d2) continue;
              const Eigen::Vector3f ng = R * Eigen::Vector3f(nc[0], nc[1], nc[2]);
              if (ng.dot(nm) < min_cos) continue;
              const float r = nm.dot(d);
              const Eigen::Vector3f pc = vg - t;
              const Eigen::Vector3f rot = pc.cross(nm);
              const double J[6] = {rot.x(), rot.y(), rot.z(), nm.x(), nm.y(), nm.z()};
              int k = 0;
              for (int i = 0; i < 6; ++i) {
                for (int j = i; j < 6; ++j) acc.A[k++] += J[i] * J[j];
                acc.b[i] -= J[i] * r;
              }
              acc.r2 += static_cast<double>(r) * r;
              acc.d2 += pc.squaredNorm();
              ++acc.n;
            }
          },
          addAccum, 16, lv.vertices.total() >= kParallelMinPixels);
      const int valid = total.valid;
      Eigen::Matrix<double, 6, 6> A;
      Eigen::Matrix<double, 6, 1> b;
      int k = 0;
      for (int i = 0; i < 6; ++i) {
        for (int j = i; j < 6; ++j) A(i, j) = A(j, i) = total.A[k++];
        b[i] = total.b[i];
      }
      if (l == 0) {
        res.inliers = total.n;
        res.valid_pixels = valid;
        res.rms = total.n ? std::sqrt(total.r2 / total.n) : 0.0;
      }
      if (total.n < 6) {
        res.solved = false;
        if (l == 0) res.condition = 0.0;
        break;
      }
      // Scale the rotation block by the rms point distance from the camera centre: then a unit of
      // either part moves the points by about a metre, and eigenvalues compare across the two.
      const double scale = std::sqrt(std::max(1e-6, total.d2 / total.n));
      Eigen::Matrix<double, 6, 1> D;
      D << 1.0 / scale, 1.0 / scale, 1.0 / scale, 1.0, 1.0, 1.0;
      const Eigen::Matrix<double, 6, 6> As = D.asDiagonal() * A * D.asDiagonal();
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> es(As);
      const double emax = es.eigenvalues()[5];
      if (!(emax > 0.0) || !es.eigenvectors().allFinite()) {
        res.solved = false;
        break;
      }
      // Solve only in the well-constrained subspace; the rest of the step is zero.
      Eigen::Matrix<double, 6, 1> xs = Eigen::Matrix<double, 6, 1>::Zero();
      const Eigen::Matrix<double, 6, 1> bs = D.asDiagonal() * b;
      int degenerate = 0;
      for (int i = 0; i < 6; ++i) {
        const double e = es.eigenvalues()[i];
        if (e < params.degenerate_ratio * emax) {
          ++degenerate;
          continue;
        }
        const auto v = es.eigenvectors().col(i);
        xs += v * (v.dot(bs) / e);
      }
      if (l == 0) {
        res.condition = std::max(0.0, es.eigenvalues()[0]) / emax;
        res.degenerate_dims = degenerate;
      }
      const Eigen::Matrix<double, 6, 1> xi = D.asDiagonal() * xs;
      if (!xi.allFinite()) {
        res.solved = false;
        break;
      }
      res.solved = true;
      // Increment about the camera centre c: p -> R_inc (p - c) + c + tau.
      const Eigen::Vector3d w = xi.head<3>();
      const double angle = w.norm();
      const Eigen::Matrix3d Rinc =
          angle > 1e-12 ? Eigen::AngleAxisd(angle, w / angle).toRotationMatrix() : Eigen::Matrix3d::Identity();
      const Eigen::Vector3d c = res.pose.translation();
      Eigen::Isometry3d inc = Eigen::Isometry3d::Identity();
      inc.linear() = Rinc;
      inc.translation() = c - Rinc * c + xi.tail<3>();
      res.pose = inc * res.pose;
      // Re-orthonormalise against float drift.
      const Eigen::Quaterniond q(res.pose.linear());
      res.pose.linear() = q.normalized().toRotationMatrix();
      // Converged at this level: a step under 0.1 mm and 0.006 deg (1e-6 ran 11 % more ICP in mode
      // kinfu on fr1_xyz for the same ATE).
      if (xi.norm() < 1e-4) break;
    }
  }
  return res;
}

}  // namespace vofusion::fusion
