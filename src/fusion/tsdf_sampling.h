// TsdfVolume's trilinear sampling, defined here (not in tsdf_volume.cpp) so that the ray caster,
// which samples the field ~7 times per ray, inlines it: as calls into another file they cost ~6 %
// of the ray cast (xyz_first300, back to back: 23.4-25.0 -> 22.0-22.8 ms per frame; same trajectory
// byte for byte). cell and trilinear are forced inline: GCC 12 left trilinear a call from marchStep;
// inlined there, the ray cast runs 22 % fewer instructions (callgrind, 12 frames of xyz_first300) and
// rpy_first100 takes 1-2 % less CPU (three pairs back to back), the same bytes.
// Included only by the fusion stage's own sources.
#pragma once

#include <cmath>

#include <opencv2/core/fast_math.hpp>  // cvFloor

#include "vofusion/fusion/tsdf_volume.h"

namespace vofusion::fusion {

// The 8 voxels of the cell holding q (voxel units) and q's position in it; false when one of them is
// outside the volume, in an unallocated brick or never observed.
__attribute__((always_inline)) inline bool TsdfVolume::cell(const Eigen::Vector3f& q, const Voxel* (&v)[8], float& a, float& b, float& c) const {
  // cvFloor: std::floor's integer for voxel coordinates (test Tsdf.CvFloorIsStdFloor), in a few
  // instructions where plain x86-64 has no roundss and std::floor is a 15-instruction sequence.
  const int x0 = cvFloor(q.x()), y0 = cvFloor(q.y()), z0 = cvFloor(q.z());
  a = q.x() - static_cast<float>(x0), b = q.y() - static_cast<float>(y0), c = q.z() - static_cast<float>(z0);
  if ((x0 & 7) != 7 && (y0 & 7) != 7 && (z0 & 7) != 7) {
    const Brick* br = brickAt(x0 >> 3, y0 >> 3, z0 >> 3);
    if (!br) return false;
    const Voxel* base = &br->voxels[Brick::index(x0 & 7, y0 & 7, z0 & 7)];
    constexpr int X = 1, Y = kBrickEdge, Z = kBrickEdge * kBrickEdge;
    v[0] = base; v[1] = base + X; v[2] = base + Y; v[3] = base + X + Y;
    v[4] = base + Z; v[5] = base + X + Z; v[6] = base + Y + Z; v[7] = base + X + Y + Z;
  } else {
    // Straddles a brick border: per axis the two voxel positions as (slot offset, index in brick).
    const int lo[3] = {x0 - origin_.x() * kBrickEdge, y0 - origin_.y() * kBrickEdge, z0 - origin_.z() * kBrickEdge};
    const int span = n_ * kBrickEdge;
    int slot_off[3][2], vox_off[3][2];
    constexpr int stride[3] = {1, kBrickEdge, kBrickEdge * kBrickEdge};
    for (int ax = 0; ax < 3; ++ax) {
      for (int k = 0; k < 2; ++k) {
        const int u = lo[ax] + k;  // voxel index relative to the volume's first voxel
        if (static_cast<unsigned>(u) >= static_cast<unsigned>(span)) return false;
        slot_off[ax][k] = cyclic_[ax][u >> 3];
        vox_off[ax][k] = stride[ax] * ((u + origin_[ax] * kBrickEdge) & 7);
      }
    }
    for (int i = 0; i < 8; ++i) {
      const int ix = i & 1, iy = (i >> 1) & 1, iz = (i >> 2) & 1;
      const Brick* br = slot_brick_[slot_off[0][ix] + slot_off[1][iy] + slot_off[2][iz]];
      if (!br) return false;
      v[i] = &br->voxels[vox_off[0][ix] + vox_off[1][iy] + vox_off[2][iz]];
    }
  }
  for (const Voxel* p : v)
    if (p->weight == 0) return false;
  return true;
}

__attribute__((always_inline)) inline bool TsdfVolume::trilinear(const Eigen::Vector3f& q, float& f) const {
  const Voxel* v[8];
  float a, b, c;
  if (!cell(q, v, a, b, c)) return false;
  const float c00 = v[0]->tsdf + a * (v[1]->tsdf - v[0]->tsdf);
  const float c10 = v[2]->tsdf + a * (v[3]->tsdf - v[2]->tsdf);
  const float c01 = v[4]->tsdf + a * (v[5]->tsdf - v[4]->tsdf);
  const float c11 = v[6]->tsdf + a * (v[7]->tsdf - v[6]->tsdf);
  const float c0 = c00 + b * (c10 - c00), c1 = c01 + b * (c11 - c01);
  f = (c0 + c * (c1 - c0)) * (1.f / kTsdfScale);
  return true;
}

inline bool TsdfVolume::cellGradient(const Eigen::Vector3f& q, Eigen::Vector3f& g) const {
  const Voxel* v[8];
  float a, b, c;
  if (!cell(q, v, a, b, c)) return false;
  float t[8];
  for (int i = 0; i < 8; ++i) t[i] = v[i]->tsdf;
  // Partial derivatives of the trilinear interpolant: per axis, the difference of the cell's two faces
  // interpolated bilinearly at q.
  const float dx00 = t[1] - t[0], dx10 = t[3] - t[2], dx01 = t[5] - t[4], dx11 = t[7] - t[6];
  const float dy00 = t[2] - t[0], dy10 = t[3] - t[1], dy01 = t[6] - t[4], dy11 = t[7] - t[5];
  const float dz00 = t[4] - t[0], dz10 = t[5] - t[1], dz01 = t[6] - t[2], dz11 = t[7] - t[3];
  g.x() = (1 - b) * (1 - c) * dx00 + b * (1 - c) * dx10 + (1 - b) * c * dx01 + b * c * dx11;
  g.y() = (1 - a) * (1 - c) * dy00 + a * (1 - c) * dy10 + (1 - a) * c * dy01 + a * c * dy11;
  g.z() = (1 - a) * (1 - b) * dz00 + a * (1 - b) * dz10 + (1 - a) * b * dz01 + a * b * dz11;
  return true;
}

}  // namespace vofusion::fusion
