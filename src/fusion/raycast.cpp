// Ray casting the TSDF (KinectFusion §3.4): march each pixel's ray through the volume, skipping
// unallocated bricks (and empty 4x4x4-brick blocks) whole and free space by the stored distance, stop at the first +/- zero crossing
// of the trilinearly interpolated field, refine it by regula falsi and take the normal from the TSDF
// gradient. Every sample is trilinear: nearest-voxel samples put the crossing up to half a voxel off,
// in rings that follow the marching phase (a systematic bias ICP then tracks as drift).
#include <cmath>
#include <limits>

#include "vofusion/fusion/tsdf_volume.h"

#include "vofusion/core/parallel.h"

#include "tsdf_sampling.h"

namespace vofusion::fusion {

namespace {
enum class March { Hit, Miss, Untrusted };
}

RaycastMaps TsdfVolume::raycast(const Eigen::Isometry3f& cam_to_world, const CameraIntrinsics& cam,
                                const cv::Mat* depth_hint, bool with_colour, bool hinted_only) const {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const int w = cam.width, h = cam.height;
  RaycastMaps maps;
  maps.vertices.create(h, w, CV_32FC3);
  maps.normals.create(h, w, CV_32FC3);
  maps.depth.create(h, w, CV_32FC1);
  if (with_colour) maps.colours = cv::Mat::zeros(h, w, CV_8UC3);
  const bool use_hint = depth_hint && !depth_hint->empty() && depth_hint->size() == cv::Size(w, h);

  const float vs = params_.voxel_size, inv_vs = 1.f / vs, trunc = params_.truncation;
  const Eigen::Matrix3f R = cam_to_world.linear();
  const Eigen::Vector3f oq = cam_to_world.translation() * inv_vs;  // camera centre, voxel units
  // Trilinear samples need the voxel and its +1 neighbours inside the volume.
  const Eigen::Vector3f lo = (origin_ * kBrickEdge).cast<float>();
  const Eigen::Vector3f hi = lo + Eigen::Vector3f::Constant(static_cast<float>(params_.volume_voxels - 1));
  const float z_near = params_.min_depth, z_far = params_.max_depth + trunc;

  parallelFor(0, h, [&](int y) {
    cv::Vec3f* vrow = maps.vertices.ptr<cv::Vec3f>(y);
    cv::Vec3f* nrow = maps.normals.ptr<cv::Vec3f>(y);
    const float* hrow = use_hint ? depth_hint->ptr<float>(y) : nullptr;
    float* zrow = maps.depth.ptr<float>(y);
    for (int x = 0; x < w; ++x) {
      vrow[x] = nrow[x] = cv::Vec3f(nan, nan, nan);
      zrow[x] = 0.f;
      if (hinted_only && !(use_hint && hrow[x] > 0.f)) continue;
      const Eigen::Vector3f ray_cam((x - cam.cx) / cam.fx, (y - cam.cy) / cam.fy, 1.f);
      const float len = ray_cam.norm();                // metres of ray per metre of depth
      const Eigen::Vector3f dq = R * ray_cam * inv_vs;  // voxel units per metre of depth
      const float min_step = 0.5f * vs / len;           // half a voxel along the ray, in depth
      const float inv_dq_norm = 1.f / dq.norm();
      const Eigen::Vector3f inv_dq = dq.cwiseInverse();
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

      // Hit: zs is the first +/- crossing in [z, zend]. Miss: none (or a back face / the ray starts
      // inside unobserved space). Untrusted: need_free_start and the first sample is not observed free
      // space, so a hint-based start cannot be relied on.
      float zs = 0.f;
      const auto march = [&](float z, float zend, bool need_free_start) -> March {
        float prev_f = 0.f, prev_z = 0.f;
        bool prev_ok = false, first = true;
        while (z < zend) {
          const Eigen::Vector3f q = oq + dq * z;
          const int ix = static_cast<int>(std::floor(q.x())), iy = static_cast<int>(std::floor(q.y())),
                    iz = static_cast<int>(std::floor(q.z()));
          if (!brickAt(ix >> 3, iy >> 3, iz >> 3)) {
            if (first && need_free_start) return March::Untrusted;
            // Jump to where the ray leaves this brick, or its whole 4x4x4-brick block when that is
            // empty (no surface inside unallocated bricks).
            const int b[3] = {ix >> 3, iy >> 3, iz >> 3};
            const bool block = !blockOccupied(b[0], b[1], b[2]);
            const int shift = block ? 5 : 3;
            const float edge = block ? 32.f : 8.f;
            const int c[3] = {ix >> shift, iy >> shift, iz >> shift};
            float exit = std::numeric_limits<float>::max();
            for (int i = 0; i < 3; ++i) {
              if (std::fabs(dq[i]) < 1e-9f) continue;
              const float bound = dq[i] > 0 ? c[i] * edge + edge : c[i] * edge;
              exit = std::min(exit, (bound - oq[i]) * inv_dq[i]);
            }
            // Go straight into the next brick: samples in this one have no data anyway.
            z = std::max(z + min_step, exit + 0.01f * inv_dq_norm);
            prev_ok = false;
            first = false;
            continue;
          }
          float f;
          if (!trilinear(q, f)) {  // next to unobserved voxels: creep, do not jump over the band
            if (first && need_free_start) return March::Untrusted;
            prev_ok = false;
            first = false;
            // A whole voxel: the observed band before any surface is several voxels deep, so the
            // first sample back in it still lands on its positive side.
            z += 2.f * min_step;
            continue;
          }
          if (f < 0.f) {
            if (!prev_ok) return first && need_free_start ? March::Untrusted : March::Miss;  // back face
            // Regula falsi on the bracket [prev_z (f > 0), z (f < 0)]. One step: over a bracket this
            // short the field is nearly linear (3 steps cost 6 % more CPU in mode kinfu, same ATE on fr1_xyz).
            float za = prev_z, fa = prev_f, zb = z, fb = f;
            constexpr int kRefineSteps = 1;
            for (int k = 0; k < kRefineSteps && zb - za > 0.05f * min_step; ++k) {
              const float zm = za + (zb - za) * fa / (fa - fb);
              float fm;
              if (!trilinear(oq + dq * zm, fm)) break;
              if (fm > 0.f) za = zm, fa = fm;
              else zb = zm, fb = fm;
            }
            zs = za + (zb - za) * fa / (fa - fb);
            return March::Hit;
          }
          prev_f = f;
          prev_z = z;
          prev_ok = true;
          first = false;
          // f * trunc is a projective (depth) distance to the surface; 0.8 of it rarely crosses it.
          z += std::max(min_step, 0.8f * f * trunc);
        }
        return March::Miss;
      };

      Eigen::Vector3f g;
      const auto normalAt = [&](const Eigen::Vector3f& q) { return cellGradient(q, g) && g.squaredNorm() > 0.f; };
      bool found = false, settled = false;
      if (use_hint && hrow[x] > 0.f) {
        const float zh = hrow[x];
        const March hinted = march(std::max(z0, zh - 0.5f * trunc), std::min(z1, zh + 2.f * trunc), true);
        found = hinted == March::Hit && normalAt(oq + dq * zs);
        // For tracking, a band that starts in observed free space and holds no surface settles the
        // ray: the model has nothing there for this reading to pair with. Searching such rays again
        // from min_depth (8 % of the rays, 1 in 17 finding a surface far in front of the reading)
        // took a third of the ray cast's samples. Without it, back to back: ray cast 20.4 -> 11.9 ms
        // per frame (synthetic room), frame loop +2/+5 % on xyz_first300, +11/+13 % on rpy_first100,
        // +12 % room, +2 % shake; ATE xyz 0.01194 -> 0.01193 m, rpy 0.01664 -> 0.01645, room
        // 0.0101 -> 0.0102, shake 0.0182 -> 0.0189, corridor and bare wall unchanged.
        settled = hinted_only && hinted == March::Miss;
      }
      // Whatever the hinted search could not settle, the full search decides; for tracking only up to
      // the hint's band (a surface farther behind the reading is hidden by it and would not pair).
      if (!found && !settled) {
        const float zend = hinted_only ? std::min(z1, hrow[x] + 2.f * trunc) : z1;
        found = march(z0, zend, false) == March::Hit && normalAt(oq + dq * zs);
      }
      if (!found) continue;

      const Eigen::Vector3f q = oq + dq * zs;
      g.normalize();
      const Eigen::Vector3f p = q * vs;
      vrow[x] = cv::Vec3f(p.x(), p.y(), p.z());
      zrow[x] = zs;
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
  }, 4);
  return maps;
}

}  // namespace vofusion::fusion
