// TSDF integration, ray casting, volume shifting and marching cubes on analytic scenes.
#include <algorithm>
#include <functional>
#include <cmath>
#include <cstring>
#include <map>
#include <memory>
#include <random>
#include <set>
#include <sstream>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core/fast_math.hpp>  // cvFloor
#include <pcl/surface/marching_cubes.h>
#include <tbb/task_arena.h>

#include "support.h"
#include "vofusion/fusion/marching_cubes.h"
#include "vofusion/fusion/tsdf_volume.h"
#include "vofusion/mesh/mesh_io.h"
#include "vofusion/pipeline/mesh_by_region.h"

using namespace vofusion;
using namespace vofusion::fusion;

namespace {

// A camera at `eye` looking at `target` (world z up), camera-to-world.
Eigen::Isometry3f lookAt(const Eigen::Vector3f& eye, const Eigen::Vector3f& target) {
  const Eigen::Vector3f z = (target - eye).normalized();
  Eigen::Vector3f x = z.cross(Eigen::Vector3f::UnitZ());
  if (x.norm() < 1e-3f) x = Eigen::Vector3f::UnitX();
  x.normalize();
  const Eigen::Vector3f y = z.cross(x);
  Eigen::Isometry3f T = Eigen::Isometry3f::Identity();
  T.linear().col(0) = x;
  T.linear().col(1) = y;
  T.linear().col(2) = z;
  T.translation() = eye;
  return T;
}

CameraIntrinsics smallCam() { return CameraIntrinsics{}.scaled(0.5); }  // 320x240

// Depth (z in the camera) of a world sphere and/or the world plane z = plane_z, seen from T.
cv::Mat renderDepth(const CameraIntrinsics& c, const Eigen::Isometry3f& T, const Eigen::Vector3f* centre, float r,
                    const float* plane_z) {
  cv::Mat z(c.height, c.width, CV_32F, cv::Scalar(0));
  const Eigen::Vector3f o = T.translation();
  for (int v = 0; v < c.height; ++v)
    for (int u = 0; u < c.width; ++u) {
      const Eigen::Vector3f rc((u - c.cx) / c.fx, (v - c.cy) / c.fy, 1.f);
      const Eigen::Vector3f d = T.linear() * rc;  // per unit camera z
      float best = 1e9f;
      if (centre) {
        const Eigen::Vector3f oc = o - *centre;
        const float a = d.dot(d), b = 2 * d.dot(oc), cc = oc.dot(oc) - r * r, disc = b * b - 4 * a * cc;
        if (disc >= 0) {
          const float t = (-b - std::sqrt(disc)) / (2 * a);
          if (t > 0) best = std::min(best, t);
        }
      }
      if (plane_z && std::fabs(d.z()) > 1e-6f) {
        const float t = (*plane_z - o.z()) / d.z();
        if (t > 0) best = std::min(best, t);
      }
      if (best < 1e8f) z.at<float>(v, u) = best;
    }
  return z;
}

// The tests' sphere, in a small volume centred on it.
const Eigen::Vector3f kSphereCentre(0.03f, -0.02f, 1.0f);
constexpr float kSphereRadius = 0.3f;

TsdfParams smallParams() {
  TsdfParams p;
  p.volume_voxels = 256;
  p.voxel_size = 0.01f;
  p.truncation = 0.04f;
  p.mark_step = 2;
  return p;
}

// A sphere of radius r at centre fused from four cameras around it, 1.5 rad apart.
void fuseSphereFromFourSides(TsdfVolume& vol, const Eigen::Vector3f& centre, float r) {
  const CameraIntrinsics c = smallCam();
  for (int k = 0; k < 4; ++k) {
    const Eigen::Isometry3f T = lookAt(centre + Eigen::Vector3f(std::cos(k * 1.5f), std::sin(k * 1.5f), 0.2f), centre);
    vol.integrate(renderDepth(c, T, &centre, r, nullptr), cv::Mat(), c, T);
  }
}

}  // namespace

// A truncation band wider than two bricks (20 mm half-samples over 16 mm bricks): a wall lying in a
// brick's last voxel needs the next brick, which samples trunc / 2 apart stepped over.
TEST(Tsdf, AWideTruncationBandStepsOverNoBrick) {
  TsdfParams p;
  p.volume_voxels = 256;
  p.voxel_size = 0.002f;  // bricks of 16 mm
  p.truncation = 0.04f;
  p.mark_step = 1;
  const float wall = 0.6395f;  // in brick 39 (0.624-0.640 m), the zero crossing at brick 40's edge
  TsdfVolume vol(p, Eigen::Vector3f(0.f, 0.f, wall));
  const CameraIntrinsics c = smallCam();
  const Eigen::Isometry3f T = lookAt(Eigen::Vector3f::Zero(), Eigen::Vector3f(0.f, 0.f, 1.f));
  vol.integrate(renderDepth(c, T, nullptr, 0.f, &wall), cv::Mat(), c, T);
  const TriangleMesh m = vol.extractMesh();
  EXPECT_GT(m.faces.size(), 50000u) << "the wall's zero crossing needs both bricks";
  for (const auto& v : m.vertices) ASSERT_NEAR(v.z(), wall, p.voxel_size);
}

TEST(Tsdf, SphereMeshWithinOneVoxelClosedAndOutwardOriented) {
  const TsdfParams p = smallParams();
  const Eigen::Vector3f& centre = kSphereCentre;
  const float r = kSphereRadius;
  TsdfVolume vol(p, centre);
  const CameraIntrinsics c = smallCam();
  for (int k = 0; k < 12; ++k) {  // orbit around the sphere, above and below the equator
    const float a = k * float(M_PI) / 6.f, e = (k % 2 ? 0.5f : -0.5f);
    const Eigen::Vector3f eye = centre + 1.0f * Eigen::Vector3f(std::cos(a) * std::cos(e), std::sin(a) * std::cos(e), std::sin(e));
    const Eigen::Isometry3f T = lookAt(eye, centre);
    vol.integrate(renderDepth(c, T, &centre, r, nullptr), cv::Mat(), c, T);
  }
  // Only bricks near the surface exist.
  EXPECT_LT(vol.bricksInVolume(), 0.05 * std::pow(p.volume_voxels / 8, 3));
  const TriangleMesh m = vol.extractMesh();
  ASSERT_GT(m.faces.size(), 5000u);
  ASSERT_EQ(m.normals.size(), m.vertices.size());
  ASSERT_EQ(m.colors.size(), m.vertices.size());
  double worst = 0;
  for (const auto& v : m.vertices) worst = std::max(worst, double(std::fabs((v - centre).norm() - r)));
  EXPECT_LT(worst, p.voxel_size);
  // Shared vertices: no two vertices at the same place; a closed surface: every edge in 2 faces.
  std::set<std::tuple<long, long, long>> pos;
  for (const auto& v : m.vertices) pos.insert({std::lround(v.x() * 1e5), std::lround(v.y() * 1e5), std::lround(v.z() * 1e5)});
  EXPECT_EQ(pos.size(), m.vertices.size());
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> edges;
  int outward = 0;
  for (const auto& f : m.faces) {
    for (int k = 0; k < 3; ++k) ++edges[{std::min(f[k], f[(k + 1) % 3]), std::max(f[k], f[(k + 1) % 3])}];
    const Eigen::Vector3f n = (m.vertices[f[1]] - m.vertices[f[0]]).cross(m.vertices[f[2]] - m.vertices[f[0]]);
    outward += n.dot(m.vertices[f[0]] - centre) > 0;
  }
  int boundary = 0;
  for (const auto& [e, n] : edges) boundary += n != 2;
  EXPECT_LT(boundary, 0.01 * edges.size());
  EXPECT_GT(outward, 0.99 * m.faces.size());  // counter-clockwise seen from outside
  int good_normals = 0;
  for (std::size_t i = 0; i < m.vertices.size(); ++i)
    good_normals += m.normals[i].dot((m.vertices[i] - centre).normalized()) > 0.95f;
  EXPECT_GT(good_normals, 0.98 * m.vertices.size());
}

TEST(Tsdf, PlaneMeshWithinOneVoxelAndRaycastMatchesDepth) {
  const TsdfParams p = smallParams();
  const float plane_z = 0.0f;
  TsdfVolume vol(p, Eigen::Vector3f(0, 0, 0));
  const CameraIntrinsics c = smallCam();
  cv::Mat rgb(c.height, c.width, CV_8UC3, cv::Scalar(10, 100, 200));  // BGR
  for (int k = 0; k < 5; ++k) {
    const Eigen::Isometry3f T = lookAt(Eigen::Vector3f(-0.3f + 0.15f * k, 0.1f, 1.1f), Eigen::Vector3f(0.05f * k, 0, 0));
    vol.integrate(renderDepth(c, T, nullptr, 0, &plane_z), rgb, c, T);
  }
  const TriangleMesh m = vol.extractMesh();
  ASSERT_GT(m.faces.size(), 1000u);
  std::size_t up = 0;
  for (std::size_t i = 0; i < m.vertices.size(); ++i) {
    ASSERT_LT(std::fabs(m.vertices[i].z() - plane_z), p.voxel_size);
    up += m.normals[i].z() > 0.9f;  // towards the side the cameras saw
    ASSERT_EQ(m.colors[i][0], 200);
    ASSERT_EQ(m.colors[i][2], 10);
  }
  EXPECT_GT(up, 0.99 * m.vertices.size());  // a few flipped faces along the observed border
  // Ray cast from a new view: vertices on the plane where the depth says, normals +z.
  const Eigen::Isometry3f view = lookAt(Eigen::Vector3f(0.1f, -0.1f, 0.9f), Eigen::Vector3f(0, 0.05f, 0));
  const cv::Mat truth = renderDepth(c, view, nullptr, 0, &plane_z);
  const RaycastMaps maps = vol.raycast(view, c, nullptr, true);
  const cv::Mat hinted = vol.raycast(view, c, &truth).vertices;
  int hits = 0;
  for (int v = 0; v < c.height; v += 2)
    for (int u = 0; u < c.width; u += 2) {
      const cv::Vec3f pv = maps.vertices.at<cv::Vec3f>(v, u);
      if (std::isnan(pv[0])) continue;
      ++hits;
      const Eigen::Vector3f pw(pv[0], pv[1], pv[2]);
      const float z_cam = (view.inverse() * pw).z();
      ASSERT_NEAR(z_cam, truth.at<float>(v, u), p.voxel_size);
      ASSERT_GT(maps.normals.at<cv::Vec3f>(v, u)[2], 0.999f);
      ASSERT_EQ(maps.colours.at<cv::Vec3b>(v, u), cv::Vec3b(10, 100, 200));
      const cv::Vec3f ph = hinted.at<cv::Vec3f>(v, u);
      ASSERT_LT(cv::norm(ph - pv), 2 * p.voxel_size);  // both within a voxel of the truth (above)
    }
  EXPECT_GT(hits, 0.8 * c.width * c.height / 4);
}

// For tracking, a ray whose hint lies more than half the truncation behind the fused surface (its band
// starts behind it) still finds that surface: the same pixels and depths as with the exact hint.
TEST(Tsdf, AHintBehindTheSurfaceFindsTheSurfaceInFrontOfIt) {
  const TsdfParams p = smallParams();
  const float plane_z = 0.0f;
  TsdfVolume vol(p, Eigen::Vector3f(0, 0, 0));
  const CameraIntrinsics c = smallCam();
  const cv::Mat rgb(c.height, c.width, CV_8UC3, cv::Scalar(10, 100, 200));
  for (int k = 0; k < 5; ++k) {
    const Eigen::Isometry3f T = lookAt(Eigen::Vector3f(-0.3f + 0.15f * k, 0.1f, 1.1f), Eigen::Vector3f(0.05f * k, 0, 0));
    vol.integrate(renderDepth(c, T, nullptr, 0, &plane_z), rgb, c, T);
  }
  const Eigen::Isometry3f view = lookAt(Eigen::Vector3f(0.1f, -0.1f, 0.9f), Eigen::Vector3f(0, 0.05f, 0));
  const cv::Mat truth = renderDepth(c, view, nullptr, 0, &plane_z);
  for (const float behind : {0.6f, 1.0f, 1.5f}) {  // truncations behind the surface
    cv::Mat late_hint = truth + cv::Scalar(behind * p.truncation);
    late_hint.setTo(0.f, truth <= 0.f);  // no reading where the plane is not in view
    const RaycastMaps exact = vol.raycast(view, c, &truth, false, true);
    const RaycastMaps late = vol.raycast(view, c, &late_hint, false, true);
    int hits = 0, found = 0;
    for (int v = 0; v < c.height; ++v)
      for (int u = 0; u < c.width; ++u) {
        const float z = exact.depth.at<float>(v, u), z_late = late.depth.at<float>(v, u);
        if (!(z > 0.f)) continue;
        ++hits;
        if (!(z_late > 0.f)) continue;  // a few along the observed border, where no search finds the surface
        ++found;
        ASSERT_NEAR(z_late, z, 0.1f * p.voxel_size) << "pixel " << u << ", " << v << ", " << behind << " truncations";
        ASSERT_GT(late.normals.at<cv::Vec3f>(v, u)[2], 0.999f);
      }
    EXPECT_GT(hits, 0.8 * c.width * c.height);
    EXPECT_GT(found, 0.99 * hits) << behind << " truncations";
  }
}

// The ray cast marches several rays side by side: each pixel must come out as it does cast alone. A
// partly observed, coloured sphere, a hint with holes (0 and NaN) and with readings off the surface,
// both ray-cast modes, a view from inside the volume and one from outside it whose rays partly miss the
// volume; each column is cast again by a one-pixel-wide camera over the same rays.
TEST(Tsdf, RaysCastSideBySideGiveWhatEachGivesAlone) {
  const Eigen::Vector3f& centre = kSphereCentre;
  const TsdfParams params = smallParams();
  TsdfVolume vol(params, centre);
  const CameraIntrinsics c = smallCam();
  cv::Mat bgr(c.height, c.width, CV_8UC3);
  cv::RNG rng(5);
  rng.fill(bgr, cv::RNG::UNIFORM, 0, 256);
  for (int k = 0; k < 3; ++k) {  // three views from one side
    const Eigen::Isometry3f T = lookAt(centre + Eigen::Vector3f(std::cos(0.5f * k), std::sin(0.5f * k), 0.2f), centre);
    vol.integrate(renderDepth(c, T, &centre, kSphereRadius, nullptr), bgr, c, T);
  }
  // Rays that miss the volume's box (slabs) from the view, so that the outside view's test is not vacuous.
  const auto missesOfBox = [&](const Eigen::Isometry3f& view) {
    const Eigen::Vector3f lo = vol.minCorner(), hi = lo + Eigen::Vector3f::Constant(params.volume_voxels * params.voxel_size);
    int misses = 0;
    for (int v = 0; v < c.height; ++v)
      for (int u = 0; u < c.width; ++u) {
        const Eigen::Vector3f d = view.linear() * Eigen::Vector3f((u - c.cx) / c.fx, (v - c.cy) / c.fy, 1.f);
        float t0 = 0.f, t1 = 1e9f;
        for (int a = 0; a < 3; ++a) {
          const float ta = (lo[a] - view.translation()[a]) / d[a], tb = (hi[a] - view.translation()[a]) / d[a];
          t0 = std::max(t0, std::min(ta, tb)), t1 = std::min(t1, std::max(ta, tb));
        }
        misses += t0 > t1;
      }
    return misses;
  };
  const Eigen::Isometry3f inside = lookAt(centre + Eigen::Vector3f(0.9f, 0.5f, 0.1f), centre);
  const Eigen::Isometry3f outside = lookAt(centre + Eigen::Vector3f(2.2f, -0.3f, 0.1f), centre + Eigen::Vector3f(0.f, 0.9f, 0.f));
  ASSERT_EQ(missesOfBox(inside), 0);
  ASSERT_GT(missesOfBox(outside), 1000);
  for (const Eigen::Isometry3f& view : {inside, outside}) {
    cv::Mat hint = renderDepth(c, view, &centre, kSphereRadius, nullptr);
    for (int v = 0; v < hint.rows; ++v)
      for (int u = 0; u < hint.cols; ++u) {
        float& h = hint.at<float>(v, u);
        if ((u + 3 * v) % 7 == 0) h = 0.f;
        else if ((u + 5 * v) % 11 == 0) h = std::numeric_limits<float>::quiet_NaN();
        else if ((2 * u + v) % 13 == 0 && h > 0.f) h += 0.1f;  // a reading behind the surface
      }
    for (const bool hinted_only : {false, true}) {
      const RaycastMaps all = vol.raycast(view, c, &hint, true, hinted_only);
      ASSERT_EQ(all.colours.size(), all.vertices.size());
      int hits = 0;
      for (int u = 0; u < c.width; ++u) {
        CameraIntrinsics one = c;
        one.width = 1;
        one.cx = c.cx - u;  // the same rays: (0 - (cx - u)) is (u - cx) exactly
        const cv::Mat column = hint.col(u).clone();
        const RaycastMaps alone = vol.raycast(view, one, &column, true, hinted_only);
        for (int v = 0; v < c.height; ++v) {
          ASSERT_EQ(std::memcmp(&alone.vertices.at<cv::Vec3f>(v, 0), &all.vertices.at<cv::Vec3f>(v, u), sizeof(cv::Vec3f)), 0)
              << "pixel " << u << ", " << v << (hinted_only ? " (hinted only)" : "");
          ASSERT_EQ(std::memcmp(&alone.normals.at<cv::Vec3f>(v, 0), &all.normals.at<cv::Vec3f>(v, u), sizeof(cv::Vec3f)), 0);
          ASSERT_EQ(std::memcmp(&alone.depth.at<float>(v, 0), &all.depth.at<float>(v, u), sizeof(float)), 0);
          ASSERT_EQ(alone.colours.at<cv::Vec3b>(v, 0), all.colours.at<cv::Vec3b>(v, u));
          hits += !std::isnan(all.vertices.at<cv::Vec3f>(v, u)[0]);
        }
      }
      EXPECT_GT(hits, 1000) << "the sphere is in view: the comparison is not vacuous";
    }
  }
}

// The world model's keys hold bricks within kKeyReach of the world's origin on each axis: the volume
// follows a camera that goes past them no further (said once). It moved on, and its bricks were stored
// under the keys of bricks 2 kKeyReach away (another place's, silently replaced).
TEST(Tsdf, TheVolumeFollowsNoFurtherThanTheWorldModelsKeysReach) {
  const TsdfParams p = smallParams();
  TsdfVolume vol(p, Eigen::Vector3f::Zero());
  const float brick = kBrickEdge * p.voxel_size;
  const Eigen::Vector3i last = Eigen::Vector3i::Constant(p.volume_voxels / kBrickEdge - 1);
  for (const float x : {1.5f, -1.5f}) {
    vol.shiftTo(Eigen::Vector3f(x * float(WorldModel::kKeyReach) * brick, 0, 0));
    EXPECT_TRUE(WorldModel::keyHolds(vol.originBrick())) << vol.originBrick().transpose();
    EXPECT_TRUE(WorldModel::keyHolds(vol.originBrick() + last)) << vol.originBrick().transpose();
    // Saved there, it loads back (load() holds the origin to the same reach).
    std::stringstream saved;
    vol.save(saved);
    TsdfVolume back(p, Eigen::Vector3f::Zero());
    EXPECT_NO_THROW(back.load(saved));
    EXPECT_EQ(back.originBrick(), vol.originBrick());
  }
  const Eigen::Vector3i held = vol.originBrick();
  vol.shiftTo(Eigen::Vector3f(std::nanf(""), 0, 0));  // no place: the volume stays
  EXPECT_EQ(vol.originBrick(), held);
  // Nor does it start beyond them: placed there, its first shift stored the map under wrapped keys (a
  // start pose 60 km out at 6 mm voxels) and it never followed the camera again.
  for (const float x : {1.5f, -1.5f, std::nanf("")})
    EXPECT_THROW(TsdfVolume(p, Eigen::Vector3f(x * float(WorldModel::kKeyReach) * brick, 0, 0)), std::invalid_argument) << x;
  EXPECT_NO_THROW(TsdfVolume(p, Eigen::Vector3f(0.9f * float(WorldModel::kKeyReach) * brick, 0, 0)));
}

TEST(Tsdf, ShiftMovesBricksToWorldModelAndBackWithoutLoss) {
  const TsdfParams p = smallParams();
  const Eigen::Vector3f centre(0, 0, 1.0f);
  const float r = 0.3f;
  TsdfVolume vol(p, centre);
  fuseSphereFromFourSides(vol, centre, r);
  const TriangleMesh before = vol.extractMesh();
  const std::size_t bricks = vol.bricksInVolume();
  ASSERT_GT(bricks, 0u);
  EXPECT_FALSE(vol.shiftIfNeeded(centre + Eigen::Vector3f(0.1f, 0, 0), 0.3f));
  EXPECT_TRUE(vol.shiftIfNeeded(centre + Eigen::Vector3f(10.f, 0, 0), 0.3f));  // far away: all leave
  EXPECT_EQ(vol.bricksInVolume(), 0u);
  EXPECT_EQ(vol.bricksInWorldModel(), bricks);
  float sdf;
  EXPECT_FALSE(vol.sdfAt(centre + Eigen::Vector3f(r, 0, 0), sdf));  // no longer in the volume
  const TriangleMesh away = vol.extractMesh();
  EXPECT_EQ(away.vertices.size(), before.vertices.size());
  EXPECT_EQ(away.faces.size(), before.faces.size());
  // Half a volume away: part of the sphere stays, the rest is in the world model; same mesh.
  vol.shiftTo(centre + Eigen::Vector3f(0.3f + p.volume_voxels * p.voxel_size / 2, 0, 0));
  EXPECT_GT(vol.bricksInVolume(), 0u);
  EXPECT_GT(vol.bricksInWorldModel(), 0u);
  const TriangleMesh split = vol.extractMesh();
  EXPECT_EQ(split.faces.size(), before.faces.size());
  vol.shiftTo(centre);
  EXPECT_EQ(vol.bricksInWorldModel(), 0u);
  EXPECT_EQ(vol.bricksInVolume(), bricks);
  ASSERT_TRUE(vol.sdfAt(centre + Eigen::Vector3f(r, 0, 0), sdf));
  EXPECT_LT(std::fabs(sdf), p.voxel_size);
}

// A saved map that cannot be read whole (here cut in half, or a brick's bytes flipped) leaves the map as
// it was: the bricks read before the damage replaced it (a re-fusion that said it went on without the
// saved map kept part of it).
TEST(Tsdf, ALoadThatFailsLeavesTheMapAsItWas) {
  const TsdfParams p = smallParams();
  const Eigen::Vector3f centre(0, 0, 1.0f);
  const float r = 0.3f;
  TsdfVolume saved(p, centre);
  fuseSphereFromFourSides(saved, centre, r);
  const CameraIntrinsics c = smallCam();
  saved.shiftTo(centre + Eigen::Vector3f(0.3f + p.volume_voxels * p.voxel_size / 2, 0, 0));  // bricks in both
  ASSERT_GT(saved.bricksInVolume(), 0u);
  ASSERT_GT(saved.bricksInWorldModel(), 0u);
  std::stringstream whole;
  saved.save(whole);
  const std::string bytes = whole.str();

  TsdfVolume vol(p, Eigen::Vector3f(2.f, 0, 1.f));  // a map of its own: a plane
  const float wall = 1.2f;
  const Eigen::Isometry3f T = lookAt(Eigen::Vector3f(2.f, 0, 0), Eigen::Vector3f(2.f, 0, 1.f));
  vol.integrate(renderDepth(c, T, nullptr, 0.f, &wall), cv::Mat(), c, T);
  const TriangleMesh before = vol.extractMesh();
  const Eigen::Vector3i origin = vol.originBrick();
  ASSERT_GT(before.faces.size(), 100u);
  std::string flipped = bytes;
  flipped[bytes.size() - 100] ^= 0x5a;  // inside the last brick's compressed voxels
  for (const std::string& damaged : {bytes.substr(0, bytes.size() / 2), flipped}) {
    std::stringstream in(damaged);
    EXPECT_THROW(vol.load(in), std::runtime_error);
    EXPECT_EQ(vol.originBrick(), origin);
    const TriangleMesh after = vol.extractMesh();
    EXPECT_EQ(after.faces.size(), before.faces.size());
    EXPECT_EQ(after.vertices, before.vertices);
  }
  std::stringstream in(bytes);  // and a whole one loads
  vol.load(in);
  EXPECT_EQ(vol.bricksInVolume(), saved.bricksInVolume());
  EXPECT_EQ(vol.bricksInWorldModel(), saved.bricksInWorldModel());
}

// A truncation band wider than a reading's depth (0.5 m at a wall 0.35 m away) marks no brick behind
// the camera: the ray's samples mirrored through it allocated bricks that nothing updates.
TEST(Tsdf, ABandWiderThanTheDepthAllocatesNothingBehindTheCamera) {
  TsdfParams p;
  p.volume_voxels = 128;
  p.voxel_size = 0.05f;  // bricks of 0.4 m
  p.truncation = 0.5f;
  const float wall = 0.35f;
  TsdfVolume vol(p, Eigen::Vector3f(0.f, 0.f, 0.4f));
  const CameraIntrinsics c = smallCam();
  const Eigen::Isometry3f T = lookAt(Eigen::Vector3f::Zero(), Eigen::Vector3f(0.f, 0.f, 1.f));
  vol.integrate(renderDepth(c, T, nullptr, 0.f, &wall), cv::Mat(), c, T);
  ASSERT_GT(vol.bricksInVolume(), 0u);
  for (const BrickRef& b : vol.volumeBricks()) EXPECT_GE(b.coord.z(), 0) << "a brick behind the camera";
}

TEST(MarchingCubes, EmptyAndUnobservedGiveNoTriangles) {
  EXPECT_TRUE(marchingCubes({}, 0.01f).empty());
  Brick b;  // all weights 0: unobserved
  for (auto& v : b.voxels) v.tsdf = -100;
  b.voxels[0].tsdf = 100;
  EXPECT_TRUE(marchingCubes({{Eigen::Vector3i(0, 0, 0), &b}}, 0.01f).empty());
}

// A crossing between a painted voxel and one that saw only free space (weight, but black: never
// painted) takes the painted end's colour; it was blended toward black by the crossing's position.
TEST(MarchingCubes, AnEndNeverPaintedLendsNoBlack) {
  Brick b;
  for (int z = 0; z < kBrickEdge; ++z)
    for (int y = 0; y < kBrickEdge; ++y)
      for (int x = 0; x < kBrickEdge; ++x) {
        Voxel& v = b.voxels[Brick::index(x, y, z)];
        v.weight = 5;
        v.tsdf = x < 4 ? -8000 : 8000;  // a plane halfway between x = 3 and 4
        if (x == 3) v.r = 200, v.g = 20, v.b = 10;  // the surface's side painted, free space not
      }
  const TriangleMesh mesh = marchingCubes({{Eigen::Vector3i(0, 0, 0), &b}}, 0.01f);
  ASSERT_FALSE(mesh.empty());
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) {
    ASSERT_NEAR(mesh.vertices[i].x(), 0.035f, 1e-5f);
    EXPECT_EQ(mesh.colors[i], (std::array<std::uint8_t, 3>{200, 20, 10})) << "vertex " << i;
  }
}

// A crossing so near a voxel that its offset rounds away in float (|tsdf| 1 against -6553 at 19 m:
// 0.9 um against half an ulp of 0.95 um) is on that voxel: the crossings there are one vertex, and the
// faces between them, of zero area, are dropped (as for a voxel at exactly 0).
TEST(MarchingCubes, CrossingsThatRoundOntoAVoxelAreThatVoxelsVertex) {
  Brick b;  // one voxel just in front of a surface all around it: a tiny octahedron
  for (auto& v : b.voxels) v.weight = 1, v.tsdf = -6553;
  b.voxels[Brick::index(3, 3, 3)].tsdf = 1;
  const float vs = 0.006f;
  EXPECT_EQ(marchingCubes({{Eigen::Vector3i(0, 0, 0), &b}}, vs).faces.size(), 8u);  // resolved near the origin
  // At 19 m every crossing rounds onto the voxel: one vertex, and no face of zero area left.
  EXPECT_TRUE(marchingCubes({{Eigen::Vector3i(400, 400, 400), &b}}, vs).faces.empty());
  for (const int at : {0, 400}) {
    const TriangleMesh mesh = marchingCubes({{Eigen::Vector3i(at, at, at), &b}}, vs);
    for (const auto& f : mesh.faces) {
      const Eigen::Vector3f a = mesh.vertices[f[0]], c = mesh.vertices[f[1]], d = mesh.vertices[f[2]];
      EXPECT_GT((c - a).cross(d - a).norm(), 0.f) << "a face of zero area at brick " << at;
    }
  }
}

namespace {

// Bricks holding the truncated SDF of a sphere (weight 1, colour by height), no camera involved.
struct SphereBricks {
  std::vector<std::unique_ptr<Brick>> storage;
  std::vector<BrickRef> refs;
  SphereBricks(const Eigen::Vector3f& centre, float r, float voxel, float trunc) {
    const float brick = voxel * kBrickEdge;
    const Eigen::Vector3i lo = ((centre.array() - r - trunc) / brick).floor().cast<int>();
    const Eigen::Vector3i hi = ((centre.array() + r + trunc) / brick).floor().cast<int>();
    for (int bz = lo.z(); bz <= hi.z(); ++bz)
      for (int by = lo.y(); by <= hi.y(); ++by)
        for (int bx = lo.x(); bx <= hi.x(); ++bx) {
          auto b = std::make_unique<Brick>();
          b->coord = {bx, by, bz};
          bool near = false;
          for (int z = 0; z < kBrickEdge; ++z)
            for (int y = 0; y < kBrickEdge; ++y)
              for (int x = 0; x < kBrickEdge; ++x) {
                const Eigen::Vector3f p = (b->coord * kBrickEdge + Eigen::Vector3i(x, y, z)).cast<float>() * voxel;
                const float d = std::clamp(((p - centre).norm() - r) / trunc, -1.f, 1.f);
                Voxel& v = b->voxels[Brick::index(x, y, z)];
                // Never exactly 0: a crossing at a voxel would put vertices of several edges there.
                v.tsdf = std::int16_t(std::lround(d * kTsdfScale));
                if (v.tsdf == 0) v.tsdf = 1;
                v.weight = 1;
                v.r = v.g = v.b = std::uint8_t(std::clamp(128.f + 200.f * (p.z() - centre.z()), 0.f, 255.f));
                near |= std::fabs(d) < 0.99f;
              }
          if (!near) continue;
          refs.push_back({b->coord, b.get()});
          storage.push_back(std::move(b));
        }
  }
};

using Key = std::array<float, 3>;
Key keyOf(const Eigen::Vector3f& v) { return {v.x(), v.y(), v.z()}; }

// A face by its corners' exact positions, rotated so the smallest comes first (orientation kept).
std::array<Key, 3> faceKey(const TriangleMesh& m, const std::array<std::uint32_t, 3>& f) {
  std::array<Key, 3> k{keyOf(m.vertices[f[0]]), keyOf(m.vertices[f[1]]), keyOf(m.vertices[f[2]])};
  std::rotate(k.begin(), std::min_element(k.begin(), k.end()), k.end());
  return k;
}

}  // namespace

// A surface through voxels (their TSDF exactly 0: about 1 in 13 000 near a surface rounds there) gives
// one vertex on each such voxel and no zero-area face: every edge from it to the other side put a vertex
// on it, and faces between those copies had no area (a region's repair then refused its polygon soup).
// Region by region too: the same faces, none repeating a vertex.
namespace {
// 2x2x2 bricks (16 voxels a side) whose voxel g holds tsdf(g) (TSDF units, clamped), weight 1, grey.
struct FieldBricks {
  std::vector<std::unique_ptr<Brick>> storage;
  std::vector<BrickRef> refs;
  std::vector<Eigen::Vector3i> coords;
  explicit FieldBricks(const std::function<int(const Eigen::Vector3i&)>& tsdf) {
    for (int k = 0; k < 8; ++k) {
      auto b = std::make_unique<Brick>();
      b->coord = {k & 1, (k >> 1) & 1, (k >> 2) & 1};
      for (int z = 0; z < kBrickEdge; ++z)
        for (int y = 0; y < kBrickEdge; ++y)
          for (int x = 0; x < kBrickEdge; ++x) {
            Voxel& v = b->voxels[Brick::index(x, y, z)];
            v.tsdf = std::int16_t(std::clamp(tsdf(b->coord * kBrickEdge + Eigen::Vector3i(x, y, z)), -32767, 32767));
            v.weight = 1;
            v.r = v.g = v.b = 128;
          }
      coords.push_back(b->coord);
      refs.push_back({b->coord, b.get()});
      storage.push_back(std::move(b));
    }
  }
};
}  // namespace

TEST(MarchingCubes, ASurfaceThroughVoxelsGivesOneVertexThereAndNoFlatFaces) {
  const FieldBricks field([](const Eigen::Vector3i& g) { return (g.sum() - 12) * 1500; });  // 0 on x + y + z = 12
  const std::vector<BrickRef>& refs = field.refs;
  const auto expectNoFlatFaces = [](const TriangleMesh& m, const std::string& what) {
    for (const auto& f : m.faces) {
      ASSERT_TRUE(f[0] != f[1] && f[1] != f[2] && f[0] != f[2]) << what;
      const float area = (m.vertices[f[1]] - m.vertices[f[0]]).cross(m.vertices[f[2]] - m.vertices[f[0]]).norm();
      EXPECT_GT(area, 1e-12f) << what;
    }
  };
  const TriangleMesh whole = marchingCubes(refs, 0.01f);
  ASSERT_GT(whole.faces.size(), 100u);
  expectNoFlatFaces(whole, "whole");
  std::set<Key> positions;
  for (const auto& v : whole.vertices) EXPECT_TRUE(positions.insert(keyOf(v)).second) << v.transpose();
  std::multiset<std::array<Key, 3>> whole_faces, region_faces;
  for (const auto& f : whole.faces) whole_faces.insert(faceKey(whole, f));
  marchingCubesByRegion(refs, 0.01f, 1, 1, [&](RegionMesh& r) {
    expectNoFlatFaces(r.mesh, "region");
    for (const auto& f : r.mesh.faces) region_faces.insert(faceKey(r.mesh, f));
  });
  EXPECT_EQ(region_faces, whole_faces);
}

// A vertex on a voxel of a region's face is the seam's even when each region reaches it through an edge
// of its own along the face's normal (a saddle: negative across the face, positive along it), which
// neither flags: welded, the regions give the whole mesh's vertices (one more, unwelded, before).
TEST(MarchingCubes, AVertexOnARegionsFaceVoxelIsWelded) {
  const FieldBricks field([](const Eigen::Vector3i& g) {
    const Eigen::Vector3i d = g - Eigen::Vector3i(8, 4, 4);
    return (-d.x() * d.x() + d.y() * d.y() + d.z() * d.z()) * 1500;
  });
  const std::vector<BrickRef>& refs = field.refs;
  const std::vector<Eigen::Vector3i>& coords = field.coords;
  const TriangleMesh whole = marchingCubes(refs, 0.01f);
  ASSERT_GT(whole.faces.size(), 20u);
  const auto fetch = [&](const Eigen::Vector3i& c, Brick&) -> const Brick* {
    for (const BrickRef& r : refs)
      if (r.coord == c) return r.brick;
    return nullptr;
  };
  const TriangleMesh welded = marchingCubesStreamed(coords, fetch, 0.01f, 1, 1);
  EXPECT_EQ(welded.vertices.size(), whole.vertices.size());
  EXPECT_EQ(welded.faces.size(), whole.faces.size());
}

// Every cell on its own, straight from PCL's tables (Bourke's edgeTable/triTable) and the bricks' voxels,
// with none of marchingCubes' shared-vertex bookkeeping: its faces must be these, on the same vertices.
// Some voxels unobserved and some bricks missing, so cells next to unobserved voxels and to absent
// neighbour bricks are covered. The usable limit (32440) and the corner and edge order are PCL's
// convention copied on purpose: the check is the tables and the voxels, not the code under test.
TEST(MarchingCubes, EveryCellAsPclsTablesMakeIt) {
  const float voxel = 0.01f;
  SphereBricks sphere(Eigen::Vector3f(0.03f, -0.02f, 0.05f), 0.2f, voxel, 0.04f);
  std::map<std::array<int, 3>, const Brick*> at;
  std::vector<BrickRef> kept;
  for (std::size_t i = 0; i < sphere.refs.size(); ++i) {
    if (i % 11 == 5) continue;  // a missing brick
    Brick& b = *sphere.storage[i];
    for (int k = 0; k < kBrickVoxels; k += 37) b.voxels[(k * 7 + int(i)) % kBrickVoxels].weight = 0;
    kept.push_back(sphere.refs[i]);
    at[{b.coord.x(), b.coord.y(), b.coord.z()}] = &b;
  }
  const TriangleMesh mesh = marchingCubes(kept, voxel);
  ASSERT_GT(mesh.faces.size(), 3000u);

  const auto voxelAt = [&](const Eigen::Vector3i& g) -> const Voxel* {
    const Eigen::Vector3i c(g.x() >> 3, g.y() >> 3, g.z() >> 3);
    const auto it = at.find({c.x(), c.y(), c.z()});
    return it == at.end() ? nullptr : &it->second->voxels[Brick::index(g.x() & 7, g.y() & 7, g.z() & 7)];
  };
  const auto usable = [](const Voxel* v) { return v && v->weight >= 1 && std::abs(v->tsdf) < 32440; };
  const int corner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 0, 1}, {0, 0, 1}, {0, 1, 0}, {1, 1, 0}, {1, 1, 1}, {0, 1, 1}};
  const int edge[12][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 0}, {4, 5}, {5, 6}, {6, 7}, {7, 4}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};
  std::multiset<std::array<Key, 3>> expected;
  for (const BrickRef& b : kept)
    for (int z = 0; z < kBrickEdge; ++z)
      for (int y = 0; y < kBrickEdge; ++y)
        for (int x = 0; x < kBrickEdge; ++x) {
          const Eigen::Vector3i g0 = b.coord * kBrickEdge + Eigen::Vector3i(x, y, z);
          const Voxel* c[8];
          int cube = 0;
          bool ok = true;
          for (int k = 0; k < 8; ++k) {
            c[k] = voxelAt(g0 + Eigen::Vector3i(corner[k][0], corner[k][1], corner[k][2]));
            ok = ok && usable(c[k]);
            if (ok && c[k]->tsdf < 0) cube |= 1 << k;
          }
          if (!ok) continue;
          Key vertex[12];
          for (int e = 0; e < 12; ++e) {
            if (!(pcl::edgeTable[cube] & (1 << e))) continue;
            // From the edge's lower end, as the mesh's vertices are made.
            int lo = edge[e][0], hi = edge[e][1];
            if (corner[hi][0] + corner[hi][1] + corner[hi][2] < corner[lo][0] + corner[lo][1] + corner[lo][2]) std::swap(lo, hi);
            const int axis = corner[lo][0] != corner[hi][0] ? 0 : (corner[lo][1] != corner[hi][1] ? 1 : 2);
            const float fa = c[lo]->tsdf, fb = c[hi]->tsdf, t = fa / (fa - fb);
            const Eigen::Vector3i g = g0 + Eigen::Vector3i(corner[lo][0], corner[lo][1], corner[lo][2]);
            Eigen::Vector3f p(g.x() * voxel, g.y() * voxel, g.z() * voxel);
            p[axis] += t * voxel;
            vertex[e] = keyOf(p);
          }
          for (int k = 0; pcl::triTable[cube][k] != -1; k += 3) {
            std::array<Key, 3> f{vertex[pcl::triTable[cube][k]], vertex[pcl::triTable[cube][k + 1]],
                                 vertex[pcl::triTable[cube][k + 2]]};
            std::rotate(f.begin(), std::min_element(f.begin(), f.end()), f.end());
            expected.insert(f);
          }
        }
  std::multiset<std::array<Key, 3>> made;
  for (const auto& f : mesh.faces) made.insert(faceKey(mesh, f));
  EXPECT_EQ(made.size(), expected.size());
  EXPECT_TRUE(made == expected);
}

TEST(MarchingCubes, RegionByRegionGivesTheWholeWorldMeshAndClosedSeams) {
  // Centred off the origin and partly at negative brick coordinates: regions round down there too.
  const Eigen::Vector3f centre(-0.05f, 0.13f, 0.02f);
  const SphereBricks sphere(centre, 0.3f, 0.01f, 0.04f);
  const TriangleMesh whole = marchingCubes(sphere.refs, 0.01f);
  ASSERT_GT(whole.faces.size(), 5000u);

  std::multiset<std::array<Key, 3>> region_faces;
  std::map<Key, std::vector<std::uint8_t>> seam_flags;  // per position, its flag in each region having it
  int regions = 0;
  std::size_t last_ordinal = 0, of = 0;
  marchingCubesByRegion(sphere.refs, 0.01f, 1, 2, [&](RegionMesh& r) {
    if (regions > 0) {
      EXPECT_GT(r.ordinal, last_ordinal);  // in order, counting regions with bricks
    }
    EXPECT_LT(r.ordinal, r.regions);
    last_ordinal = r.ordinal, of = r.regions;
    ++regions;
    ASSERT_EQ(r.on_seam.size(), r.mesh.vertices.size());
    ASSERT_EQ(r.mesh.colors.size(), r.mesh.vertices.size());
    for (const auto& f : r.mesh.faces) region_faces.insert(faceKey(r.mesh, f));
    for (std::size_t v = 0; v < r.mesh.vertices.size(); ++v) seam_flags[keyOf(r.mesh.vertices[v])].push_back(r.on_seam[v]);
  });
  EXPECT_GT(regions, 20);
  EXPECT_GE(of, std::size_t(regions));

  // The same faces on the same (bit-identical) vertices, each exactly once.
  std::multiset<std::array<Key, 3>> whole_faces;
  for (const auto& f : whole.faces) whole_faces.insert(faceKey(whole, f));
  EXPECT_EQ(region_faces, whole_faces);
  std::set<Key> whole_vertices;
  for (const auto& v : whole.vertices) whole_vertices.insert(keyOf(v));
  EXPECT_EQ(seam_flags.size(), whole_vertices.size());
  // A vertex in several regions is flagged as a seam vertex in each (so none of them moves it).
  std::size_t shared = 0;
  for (const auto& [pos, flags] : seam_flags) {
    if (flags.size() < 2) continue;
    ++shared;
    for (std::uint8_t f : flags) EXPECT_EQ(f, 1) << pos[0] << " " << pos[1] << " " << pos[2];
  }
  EXPECT_GT(shared, 500u);

  // Welded by position the regions close up: on the closed sphere every edge has two faces.
  std::map<std::pair<Key, Key>, int> edges;
  for (const auto& f : region_faces)
    for (int k = 0; k < 3; ++k) ++edges[{std::min(f[k], f[(k + 1) % 3]), std::max(f[k], f[(k + 1) % 3])}];
  std::size_t open = 0;
  for (const auto& [e, n] : edges) open += n != 2;
  EXPECT_EQ(open, 0u);
}

// A map with no surface (a run stopped before any depth was fused) streams a raw mesh of nothing:
// a valid PLY of 0 vertices and 0 faces, not a "cannot write" error.
TEST(MarchingCubes, MeshByRegionOfNoRegionsWritesAnEmptyRawPly) {
  const std::string raw_path = testing::TempDir() + "/mesh_by_region_empty.ply";
  std::remove(raw_path.c_str());
  const RegionMeshResult r = meshByRegion([](const std::function<void(RegionMesh&)>&) {}, MeshCleanParams{}, raw_path);
  EXPECT_EQ(r.raw_faces, 0u);
  EXPECT_TRUE(r.mesh.faces.empty());
  const TriangleMesh back = readPly(raw_path);
  EXPECT_TRUE(back.vertices.empty());
  EXPECT_TRUE(back.faces.empty());
}

TEST(MarchingCubes, MeshByRegionSimplifiesWithClosedSeamsAndStreamsTheRawMesh) {
  const Eigen::Vector3f centre(-0.05f, 0.13f, 0.02f);
  const SphereBricks sphere(centre, 0.3f, 0.01f, 0.04f);
  const TriangleMesh whole = marchingCubes(sphere.refs, 0.01f);
  MeshCleanParams params;
  params.max_simplify_error = 0.003;
  const std::string raw_path = testing::TempDir() + "/mesh_by_region_raw.ply";
  std::map<int, std::size_t> told;  // per pass: regions reported
  std::size_t told_of = 0, regions_read_at_done = 0, welded_faces_told = 0;
  int done_calls = 0;
  const RegionMeshResult r = meshByRegion(
      [&](const std::function<void(RegionMesh&)>& sink) { marchingCubesByRegion(sphere.refs, 0.01f, 1, 2, sink); }, params,
      raw_path, [&](int pass, std::size_t done, std::size_t of) { told[pass] = done, told_of = of; },
      [&](std::size_t faces) { ++done_calls, regions_read_at_done = told[2], welded_faces_told = faces; });
  ASSERT_TRUE(r.report.success) << r.report.failure;
  EXPECT_EQ(done_calls, 1);  // once, after the last region was read (the source may be freed then)
  EXPECT_EQ(regions_read_at_done, told[2]);
  EXPECT_EQ(welded_faces_told, r.report.steps.front().faces_after);  // the regions' simplified faces, welded
  EXPECT_EQ(told.count(1), 1u);  // fragments judged: a first pass (min_component_faces is on by default)
  EXPECT_GE(told[2], r.regions);  // ordinal + 1 of the last region with faces
  EXPECT_LE(told[2], told_of);
  EXPECT_GT(r.regions, 20u);
  EXPECT_EQ(r.raw_faces, whole.faces.size());
  EXPECT_EQ(r.raw_vertices, whole.vertices.size());
  // Simplified region by region, yet one closed manifold sphere: the seams were kept and welded.
  EXPECT_TRUE(r.report.closed);
  EXPECT_TRUE(r.report.manifold);
  EXPECT_EQ(r.report.components_kept, 1u);
  EXPECT_LT(r.mesh.faces.size(), whole.faces.size() / 3);
  EXPECT_LT(r.report.simplification.distance.mean, 0.01);
  double worst = 0;
  for (const auto& v : r.mesh.vertices) worst = std::max(worst, double(std::fabs((v - centre).norm() - 0.3f)));
  EXPECT_LT(worst, 0.01 + params.max_simplify_error);
  // The streamed raw mesh is the whole-world marching-cubes mesh (faces by their corners' positions).
  const TriangleMesh raw = readPly(raw_path);
  ASSERT_EQ(raw.faces.size(), whole.faces.size());
  ASSERT_EQ(raw.vertices.size(), whole.vertices.size());
  std::multiset<std::array<Key, 3>> a, b;
  for (const auto& f : raw.faces) a.insert(faceKey(raw, f));
  for (const auto& f : whole.faces) b.insert(faceKey(whole, f));
  EXPECT_EQ(a, b);
  // With the whole mesh's normals: a seam vertex's over the faces of every region using it (each
  // region's own, over half its fan, shaded a line along every seam).
  std::map<Key, Eigen::Vector3f> normal_at;
  for (std::size_t v = 0; v < whole.vertices.size(); ++v) normal_at[keyOf(whole.vertices[v])] = whole.normals[v];
  ASSERT_EQ(raw.normals.size(), raw.vertices.size());
  std::size_t off = 0;
  for (std::size_t v = 0; v < raw.vertices.size(); ++v) off += raw.normals[v].dot(normal_at.at(keyOf(raw.vertices[v]))) < 0.9999f;
  EXPECT_EQ(off, 0u);
}

// target_faces is the whole mesh's budget, shared among the regions by their faces: region by region
// it was each region's, so every region below it was not simplified at all (the sphere kept nearly
// all its faces at half of them asked for).
TEST(MarchingCubes, MeshByRegionKeepsTheWholeMeshsFaceBudget) {
  const SphereBricks sphere(Eigen::Vector3f(-0.05f, 0.13f, 0.02f), 0.3f, 0.01f, 0.04f);
  const TriangleMesh whole = marchingCubes(sphere.refs, 0.01f);
  MeshCleanParams params;
  params.max_simplify_error = 0.05;  // loose: the budget is what stops
  params.target_faces = int(whole.faces.size() / 4);
  const RegionMeshResult r = meshByRegion(
      [&](const std::function<void(RegionMesh&)>& sink) { marchingCubesByRegion(sphere.refs, 0.01f, 1, 2, sink); }, params,
      "", {}, {});
  ASSERT_TRUE(r.report.success) << r.report.failure;
  ASSERT_GT(r.regions, 20u);
  EXPECT_LE(r.mesh.faces.size(), std::size_t(1.15 * params.target_faces));
  EXPECT_GE(r.mesh.faces.size(), std::size_t(0.8 * params.target_faces));
  EXPECT_TRUE(r.report.closed);
}

// The regions are simplified a batch at a time on every core, and welded in region order: the mesh is
// the one a single core gives, vertex for vertex.
TEST(MarchingCubes, MeshByRegionOnEveryCoreGivesTheSingleCoreMesh) {
  const SphereBricks sphere(Eigen::Vector3f(-0.05f, 0.13f, 0.02f), 0.3f, 0.01f, 0.04f);
  MeshCleanParams params;
  params.max_simplify_error = 0.003;
  // Kept from pass 1 (all at once, the largest first), and marched again (as they come, a few at a time).
  for (const std::size_t keep_bytes : {kKeptRawRegionBytes, std::size_t(0)}) {
    SCOPED_TRACE("keep_bytes " + std::to_string(keep_bytes));
    const auto mesh = [&] {
      return meshByRegion([&](const std::function<void(RegionMesh&)>& sink) { marchingCubesByRegion(sphere.refs, 0.01f, 1, 2, sink); },
                          params, "", nullptr, nullptr, {}, keep_bytes);
    };
    // Four threads, whatever the machine gives (on one CPU the default arena is one thread: the test
    // compared a single core with itself).
    RegionMeshResult parallel;
    tbb::task_arena four(4);
    four.execute([&] { parallel = mesh(); });
    RegionMeshResult single;
    tbb::task_arena one(1);
    one.execute([&] { single = mesh(); });
    ASSERT_GT(parallel.regions, 20u);
    ASSERT_EQ(parallel.mesh.faces.size(), single.mesh.faces.size());
    ASSERT_EQ(parallel.mesh.vertices.size(), single.mesh.vertices.size());
    EXPECT_TRUE(parallel.mesh.faces == single.mesh.faces);
    EXPECT_TRUE(parallel.mesh.vertices == single.mesh.vertices);
    EXPECT_EQ(parallel.report.simplification.faces_after, single.report.simplification.faces_after);
  }
}

// Fragments are judged whole across regions: a sphere that is only a few hundred faces in each region
// it crosses stays, while two small spheres go, one inside a region and one across a seam (as the
// whole-world cleanMesh would judge them).
TEST(MarchingCubes, MeshByRegionJudgesFragmentsWholeAcrossSeams) {
  const Eigen::Vector3f centre(-0.05f, 0.13f, 0.02f);
  const SphereBricks big(centre, 0.3f, 0.01f, 0.04f);
  // Regions of 2 bricks = 16 cm: x = 0.64 is a seam, [0.48, 0.64) x [0.32, 0.48) x [0, 0.16) one region.
  const SphereBricks across(Eigen::Vector3f(0.64f, 0.08f, 0.08f), 0.03f, 0.01f, 0.04f);
  const SphereBricks inside(Eigen::Vector3f(0.56f, 0.40f, 0.08f), 0.03f, 0.01f, 0.04f);
  std::vector<BrickRef> refs = big.refs;
  refs.insert(refs.end(), across.refs.begin(), across.refs.end());
  refs.insert(refs.end(), inside.refs.begin(), inside.refs.end());
  MeshCleanParams params;
  params.max_simplify_error = 0;
  params.max_hole_perimeter = 0;
  params.min_component_faces = 1000;  // the big sphere has more in all, but fewer in most regions
  params.min_component_area = 0;
  std::size_t small_region_parts = 0;
  marchingCubesByRegion(big.refs, 0.01f, 1, 2, [&](RegionMesh& r) { small_region_parts += r.mesh.faces.size() < 1000; });
  ASSERT_GT(small_region_parts, 10u);
  const RegionMeshResult r = meshByRegion(
      [&](const std::function<void(RegionMesh&)>& sink) { marchingCubesByRegion(refs, 0.01f, 1, 2, sink); }, params, "");
  ASSERT_TRUE(r.report.success) << r.report.failure;
  EXPECT_EQ(r.report.components_removed, 2u);
  EXPECT_EQ(r.report.components_kept, 1u);
  EXPECT_EQ(r.mesh.faces.size(), marchingCubes(big.refs, 0.01f).faces.size());
  for (const auto& v : r.mesh.vertices) ASSERT_LT(std::fabs((v - centre).norm() - 0.3f), 0.02f);
}

// A region read differently in pass 2 (a spilled brick lost between the passes) has seam vertices
// pass 1 never met: they count as on no seam, where a bare std::out_of_range ended the meshing.
TEST(MarchingCubes, MeshByRegionMeshesARegionThatChangedBetweenPasses) {
  const SphereBricks sphere(Eigen::Vector3f(-0.05f, 0.13f, 0.02f), 0.3f, 0.01f, 0.04f);
  int pass = 0;
  std::size_t moved = 0;
  const RegionMeshResult r = meshByRegion(
      [&](const std::function<void(RegionMesh&)>& sink) {
        ++pass;
        marchingCubesByRegion(sphere.refs, 0.01f, 1, 2, [&](RegionMesh& region) {
          if (pass == 2 && moved == 0)  // the first region with seam vertices
            for (std::size_t v = 0; v < region.mesh.vertices.size(); ++v)
              if (region.on_seam[v]) region.mesh.vertices[v].x() += 1e-4f, ++moved;
          sink(region);
        });
      },
      MeshCleanParams{}, "", {}, {}, {}, /*keep_bytes=*/0);  // marched again in pass 2, as a map too large to keep is
  ASSERT_EQ(pass, 2);  // fragments judged: min_component_faces is on by default
  ASSERT_GT(moved, 0u);
  EXPECT_TRUE(r.report.success) << r.report.failure;
  EXPECT_GT(r.mesh.faces.size(), 1000u);
}

// Pass 1's regions are kept for pass 2 when they fit, so the map is marched once; a map too large to
// keep is marched again, and either way the mesh is the same, bit for bit.
TEST(MarchingCubes, MeshByRegionMarchesOnceWhenItsRegionsFit) {
  const SphereBricks sphere(Eigen::Vector3f(-0.05f, 0.13f, 0.02f), 0.3f, 0.01f, 0.04f);
  MeshCleanParams params;
  params.max_simplify_error = 0.003;
  ASSERT_GT(params.min_component_faces, 0);  // pass 1 runs: fragments are judged
  std::size_t raw_bytes = 0;
  marchingCubesByRegion(sphere.refs, 0.01f, 1, 2, [&](RegionMesh& r) {
    raw_bytes += r.mesh.vertices.size() * (2 * sizeof(Eigen::Vector3f) + 3 + 1) + r.mesh.faces.size() * 12;
  });
  const auto mesh = [&](std::size_t keep_bytes, int& marched) {
    return meshByRegion(
        [&](const std::function<void(RegionMesh&)>& sink) {
          ++marched;
          marchingCubesByRegion(sphere.refs, 0.01f, 1, 2, sink);
        },
        params, "", {}, {}, {}, keep_bytes);
  };
  int once = 0, limit = 0, never = 0;
  const RegionMeshResult kept = mesh(kKeptRawRegionBytes, once);
  ASSERT_LT(raw_bytes, kKeptRawRegionBytes / 4);
  const RegionMeshResult over = mesh(raw_bytes / 2, limit);  // runs out half way (allocated >= used): nothing kept
  const RegionMeshResult again = mesh(0, never);
  EXPECT_EQ(once, 1);
  EXPECT_EQ(limit, 2);
  EXPECT_EQ(never, 2);
  ASSERT_GT(kept.regions, 20u);
  ASSERT_TRUE(kept.report.success) << kept.report.failure;
  for (const RegionMeshResult* r : {&over, &again}) {
    EXPECT_EQ(r->regions, kept.regions);
    EXPECT_EQ(r->raw_faces, kept.raw_faces);
    EXPECT_TRUE(r->mesh.faces == kept.mesh.faces);
    EXPECT_TRUE(r->mesh.vertices == kept.mesh.vertices);
    EXPECT_TRUE(r->mesh.colors == kept.mesh.colors);
    EXPECT_EQ(r->report.components_removed, kept.report.components_removed);
  }
}

// The ray cast's floor (OpenCV's cvFloor) must be the integer std::floor gives, or the ray cast's bytes
// change: voxel coordinates on both sides of zero, whole numbers and their neighbours, and floats too
// large to have a fraction.
TEST(Tsdf, CvFloorIsStdFloor) {
  std::vector<float> xs = {0.f, -0.f, 0.5f, -0.5f, 1.f, -1.f, 7.9999995f, -7.9999995f, 1e-30f, -1e-30f,
                           8388607.5f, -8388607.5f, 16777216.f, -16777216.f, 2e9f, -2e9f};
  for (int i = -300; i <= 300; ++i) {
    const float x = static_cast<float>(i);
    xs.push_back(x);
    xs.push_back(std::nextafter(x, -1e9f));
    xs.push_back(std::nextafter(x, 1e9f));
  }
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> any(-5000.f, 5000.f);
  for (int i = 0; i < 100000; ++i) xs.push_back(any(rng));
  for (const float x : xs) ASSERT_EQ(cvFloor(x), static_cast<int>(std::floor(x))) << "x = " << x;
}
