// Ray casting the TSDF (KinectFusion §3.4): march each pixel's ray through the volume, skipping
// unallocated bricks whole and free space by the stored distance, stop at the first +/- zero crossing,
// refine it by trilinear interpolation and take the normal from the TSDF gradient.
#include <cmath>
#include <limits>

#include "vofusion/fusion/tsdf_volume.h"

namespace vofusion::fusion {

RaycastMaps TsdfVolume::raycast(const Eigen::Isometry3f& cam_to_world, const CameraIntrinsics& cam,
                                const cv::Mat* depth_hint, bool with_colour) const {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const int w = cam.width, h = cam.height;
  RaycastMaps maps;
  maps.vertices.create(h, w, CV_32FC3);
  maps.normals.create(h, w, CV_32FC3);
  maps.vertices.setTo(cv::Scalar::all(nan));
  maps.normals.setTo(cv::Scalar::all(nan));
  if (with_colour) maps.colours = cv::Mat::zeros(h, w, CV_8UC3);
  const bool use_hint = depth_hint && !depth_hint->empty() && depth_hint->size() == cv::Size(w, h);

  const float vs = params_.voxel_size, inv_vs = 1.f / vs, trunc = params_.truncation;
  const Eigen::Matrix3f R = cam_to_world.linear();
  const Eigen::Vector3f oq = cam_to_world.translation() * inv_vs;  // camera centre, voxel units
  const Eigen::Vector3f lo = (origin_ * kBrickEdge).cast<float>() - Eigen::Vector3f::Constant(0.5f);
  const Eigen::Vector3f hi = lo + Eigen::Vector3f::Constant(static_cast<float>(params_.volume_voxels));
  const float z_near = params_.min_depth, z_far = params_.max_depth + trunc;

#pragma omp parallel for schedule(dynamic, 4)
  for (int y = 0; y < h; ++y) {
    cv::Vec3f* vrow = maps.vertices.ptr<cv::Vec3f>(y);
    cv::Vec3f* nrow = maps.normals.ptr<cv::Vec3f>(y);
    const float* hrow = use_hint ? depth_hint->ptr<float>(y) : nullptr;
    for (int x = 0; x < w; ++x) {
      const Eigen::Vector3f ray_cam((x - cam.cx) / cam.fx, (y - cam.cy) / cam.fy, 1.f);
      const float len = ray_cam.norm();            // metres of ray per metre of depth
      const Eigen::Vector3f dq = R * ray_cam * inv_vs;  // voxel units per metre of depth
      // Clip the depth interval to the volume box.
      float z0 = z_near, z1 = z_far;
      for (int i = 0; i < 3; ++i) {
        if (std::fabs(dq[i]) < 1e-9f) {
          if (oq[i] < lo[i] || oq[i] > hi[i]) z1 = -1.f;
          continue;
        }
        float a = (lo[i] - oq[i]) / dq[i], b = (hi[i] - oq[i]) / dq[i];
        if (a > b) std::swap(a, b);
        z0 = std::max(z0, a);
        z1 = std::min(z1, b - 1e-3f);
      }
      if (z0 >= z1) continue;

      // Returns 1 on a hit (zs), 0 when the ray found no surface, -1 when need_free_start and the
      // first sample is not observed free space (the hint is not trustworthy here).
      float zs = 0.f;
      const auto march = [&](float z, float zend, bool need_free_start) -> int {
        float prev_f = nan, prev_z = 0.f;
        bool first = true;
        while (z < zend) {
          const Eigen::Vector3f q = oq + dq * z;
          const int ix = static_cast<int>(std::floor(q.x() + 0.5f)), iy = static_cast<int>(std::floor(q.y() + 0.5f)),
                    iz = static_cast<int>(std::floor(q.z() + 0.5f));
          const Brick* br = brickAt(ix >> 3, iy >> 3, iz >> 3);
          if (!br) {
            if (first && need_free_start) return -1;
            // Jump to where the ray leaves this brick.
            float exit = std::numeric_limits<float>::max();
            const int b[3] = {ix >> 3, iy >> 3, iz >> 3};
            for (int i = 0; i < 3; ++i) {
              if (std::fabs(dq[i]) < 1e-9f) continue;
              const float bound = dq[i] > 0 ? b[i] * 8 + 7.5f : b[i] * 8 - 0.5f;
              exit = std::min(exit, (bound - oq[i]) / dq[i]);
            }
            z = std::max(z + 1e-4f, exit + 1e-3f / dq.norm());
            prev_f = nan;
            first = false;
            continue;
          }
          const Voxel& v = br->voxels[Brick::index(ix & 7, iy & 7, iz & 7)];
          if (v.weight == 0) {
            if (first && need_free_start) return -1;
            prev_f = nan;
            first = false;
            z += vs / len;  // unobserved voxel next to observed ones: do not jump over the band
            continue;
          }
          const float f = v.tsdf * (1.f / kTsdfScale);
          if (f < 0.f) {
            if (first || std::isnan(prev_f)) return need_free_start && first ? -1 : 0;  // back face / unobserved
            // Nearest voxels bracket the surface; locate it on the trilinear field with half-voxel
            // steps so the crossing is interpolated between two close, continuous samples.
            float fa;
            if (trilinear(oq + dq * prev_z, fa) && fa > 0.f) {
              const float dz = 0.5f * vs / len, zlimit = z + 2.f * vs / len;
              for (float za = prev_z; za < zlimit; za += dz) {
                float fb;
                if (!trilinear(oq + dq * (za + dz), fb)) break;
                if (fb < 0.f) {
                  zs = za + dz * fa / (fa - fb);
                  return 1;
                }
                fa = fb;
              }
            }
            zs = prev_z + (z - prev_z) * prev_f / (prev_f - f);
            return 1;
          }
          prev_f = f;
          prev_z = z;
          first = false;
          z += std::max(vs, 0.8f * f * trunc) / len;
        }
        return 0;
      };

      int hit = 0;
      if (use_hint && hrow[x] > 0.f) {
        const float zh = hrow[x];
        hit = march(std::max(z0, zh - trunc), std::min(z1, zh + 2.f * trunc), true);
      }
      if (hit != 1) hit = march(z0, z1, false);
      if (hit != 1) continue;

      const Eigen::Vector3f q = oq + dq * zs;
      Eigen::Vector3f g;
      if (!gradient(q, g) || !(g.squaredNorm() > 0.f)) continue;
      g.normalize();
      const Eigen::Vector3f p = q * vs;
      vrow[x] = cv::Vec3f(p.x(), p.y(), p.z());
      nrow[x] = cv::Vec3f(g.x(), g.y(), g.z());
      if (with_colour) {
        const int ix = static_cast<int>(std::floor(q.x() + 0.5f)), iy = static_cast<int>(std::floor(q.y() + 0.5f)),
                  iz = static_cast<int>(std::floor(q.z() + 0.5f));
        if (const Brick* br = brickAt(ix >> 3, iy >> 3, iz >> 3)) {
          const Voxel& v = br->voxels[Brick::index(ix & 7, iy & 7, iz & 7)];
          maps.colours.ptr<cv::Vec3b>(y)[x] = cv::Vec3b(v.b, v.g, v.r);
        }
      }
    }
  }
  return maps;
}

}  // namespace vofusion::fusion
