// NARF's border extraction as pcl::RangeImageBorderExtractor (PCL 1.13) does it, on flat per-pixel
// arrays: local planes -> border scores in 4 directions -> propagation to neighbours -> shadow
// borders -> classification (obstacle / shadow / veil) -> border directions -> surface changes.
// Constants are PCL's defaults; operations keep PCL's order so that the floats come out the same.
// The per-pixel passes run on every core (each pixel reads only the previous passes' results); the
// shadow-border scan and the classification change values as they go and stay serial, as in PCL.
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include <pcl/common/angles.h>
#include <pcl/common/eigen.h>
#include <pcl/common/vector_average.h>

#include "vofusion/features/narf_fast.h"

#include "vofusion/core/parallel.h"

namespace vofusion::narf {

namespace {
constexpr int kRadiusBorders = 3;              // pixels, pixel_radius_borders
constexpr int kRadiusPlane = 2;                // pixels, pixel_radius_plane_extraction (step 1)
constexpr int kPlaneNeighbours = 9;            // (radius / step + 1)^2, as PCL derives it
constexpr int kRadiusBorderDirection = 2;      // pixels, pixel_radius_border_direction
constexpr int kRadiusCurvature = 2;            // pixels, pixel_radius_principal_curvature
constexpr float kMinBorderProbability = 0.8f;  // minimum_border_probability

// Left, right, top, bottom: PCL's order of the four border score images.
constexpr int kDx[4] = {-1, 1, 0, 0}, kDy[4] = {0, 0, -1, 1}, kOpposite[4] = {1, 0, 3, 2};
constexpr std::uint8_t kSide[4] = {kObstacleLeft, kObstacleRight, kObstacleTop, kObstacleBottom};

// pcl::squaredEuclideanDistance(p1, p2), same operand order.
inline float sqDist(const Eigen::Vector3f& p1, const Eigen::Vector3f& p2) {
  const float dx = p2.x() - p1.x(), dy = p2.y() - p1.y(), dz = p2.z() - p1.z();
  return dx * dx + dy * dy + dz * dz;
}

// PCL's LocalSurface, the parts later steps read (the "no jumps" plane of the closest neighbours).
struct Surface {
  Eigen::Vector3f normal, mean;
  float max_neighbour_dist2 = 0;  // m^2, of the 9th closest neighbour
  bool ok = false;
};

struct Neighbour {
  float distance;
  int index;
  bool operator<(const Neighbour& o) const { return distance < o.distance; }
};

// std::sort's order of (at most 25) neighbours by distance. Without equal distances that is the
// only ascending order, found here by counting the smaller ones (no branches); equal distances, rare,
// are left to std::sort itself, whose order among them the sums downstream depend on.
void sortByDistance(Neighbour* nb, int n) {
  float d[25];
  for (int i = 0; i < n; ++i) d[i] = nb[i].distance;
  int rank[25], equal = 0;
  for (int i = 0; i < n; ++i) {
    int r = 0;
    for (int j = 0; j < n; ++j) r += d[j] < d[i], equal += d[j] == d[i];
    rank[i] = r;
  }
  if (equal != n) {
    std::sort(nb, nb + n);
    return;
  }
  Neighbour sorted[25];
  for (int i = 0; i < n; ++i) sorted[rank[i]] = nb[i];
  std::copy(sorted, sorted + n, nb);
}

// RangeImage::getSurfaceInformation: the closest 9 of the 5x5 neighbours fix a distance; all within
// twice it define the plane. The neighbours are ordered as PCL's std::sort orders them, so they
// enter the running average in the same order.
Surface localSurface(const RangeImage& im, int x, int y) {
  std::array<Neighbour, (2 * kRadiusPlane + 1) * (2 * kRadiusPlane + 1)> nb;
  const Eigen::Vector3f& p = im.points[y * im.width + x];
  int n = 0;
  for (int y2 = y - kRadiusPlane; y2 <= y + kRadiusPlane; ++y2)
    for (int x2 = x - kRadiusPlane; x2 <= x + kRadiusPlane; ++x2)
      if (im.valid(x2, y2)) nb[n++] = {sqDist(p, im.points[y2 * im.width + x2]), y2 * im.width + x2};
  Surface s;
  sortByDistance(nb.data(), n);
  s.max_neighbour_dist2 = nb[std::min(n, kPlaneNeighbours) - 1].distance;
  const float max_dist2 = s.max_neighbour_dist2 * 4.0f;
  pcl::VectorAverage3f avg;
  for (int k = 0; k < n && nb[k].distance <= max_dist2; ++k) avg.add(im.points[nb[k].index]);
  if (avg.getNoOfSamples() < 3) return s;
  Eigen::Vector3f values, v2, v3;
  avg.doPCA(values, s.normal, v2, v3);
  const Eigen::Vector3f to_sensor = (Eigen::Vector3f::Zero() - p).normalized();  // sensor at the origin
  if (s.normal.dot(to_sensor) < 0.0f) s.normal *= -1.0f;
  s.mean = avg.getMean();
  s.ok = true;
  return s;
}

// RangeImage::get1dPointAverage: mean of the valid points among n steps from (x, y); range +inf if
// the first is a max-range point, -inf if none is usable.
struct Average {
  Eigen::Vector3f p = Eigen::Vector3f::Zero();
  float range = 0;
};
Average pointAverage(const RangeImage& im, int x, int y, int dx, int dy, int n) {
  Average a;
  float weight = 1.0f;
  if (!im.inImage(x, y)) {
    weight = 0.0f;
  } else if (!im.valid(y * im.width + x)) {
    a.range = RangeImage::kInf;
    return a;
  } else {
    a.p = im.points[y * im.width + x];
    a.range = im.range[y * im.width + x];
  }
  for (int step = 1; step < n; ++step) {
    x += dx, y += dy;
    if (!im.valid(x, y)) continue;
    a.p += im.points[y * im.width + x];
    a.range += im.range[y * im.width + x];
    weight += 1.0f;
  }
  if (weight <= 0.0f) {
    a.range = -RangeImage::kInf;
    return a;
  }
  const float f = 1.0f / weight;
  a.p *= f;
  a.range *= f;
  return a;
}

// RangeImageBorderExtractor::getNeighborDistanceChangeScore: how much farther (> 0) or nearer (< 0)
// the points in direction (dx, dy) are than the local plane's own neighbour spacing allows.
float distanceChangeScore(const RangeImage& im, const Surface& s, int x, int y, int dx, int dy, int radius) {
  const Average nb = pointAverage(im, x + dx, y + dy, dx, dy, radius);
  if (std::isinf(nb.range)) return nb.range < 0.0f ? 0.0f : 1.0f;
  const int i = y * im.width + x;
  const float d2 = sqDist(nb.p, im.points[i]);
  if (d2 <= s.max_neighbour_dist2) return 0.0f;
  const float score = 1.0f - std::sqrt(s.max_neighbour_dist2 / d2);
  return nb.range < im.range[i] ? -score : score;
}

// updatedScoreAccordingToNeighborValues: a score near the threshold gets a bonus from its 8 neighbours.
float propagatedScore(const RangeImage& im, const std::vector<float>& scores, int x, int y) {
  const float bonus = 0.5f, s = scores[y * im.width + x];
  if (s + bonus * (1.0f - s) < kMinBorderProbability) return s;
  float mean = 0.0f, weight = 0.0f;
  for (int y2 = y - 1; y2 <= y + 1; ++y2)
    for (int x2 = x - 1; x2 <= x + 1; ++x2) {
      if (!im.inImage(x2, y2) || (x2 == x && y2 == y)) continue;
      mean += scores[y2 * im.width + x2];
      weight += 1.0f;
    }
  mean /= weight;
  if (mean * s < 0.0f) return s;
  return s + bonus * mean * (1.0f - std::abs(s));
}

// changeScoreAccordingToShadowBorderValue: a border needs a shadow border (a strongly negative score
// of the other side) within 3 pixels, or a max-range neighbour; else its score drops to 0. Returns
// the shadow pixel or -1. Updates `scores` in place, as PCL does during its raster scan.
int shadowBorder(const RangeImage& im, int x, int y, int d, std::vector<float>& scores, const std::vector<float>& other) {
  float& score = scores[y * im.width + x];
  if (score < kMinBorderProbability) return -1;
  const int nx = x + kDx[d], ny = y + kDy[d];
  if (score == 1.0f && im.inImage(nx, ny) && im.range[ny * im.width + nx] == RangeImage::kInf)
    return ny * im.width + nx;
  int shadow = -1;
  float best = 0.0f;
  for (int k = 1; k <= kRadiusBorders; ++k) {
    const int x2 = x + k * kDx[d], y2 = y + k * kDy[d];
    if (!im.inImage(x2, y2)) continue;
    const float v = other[y2 * im.width + x2];
    if (v < best) shadow = y2 * im.width + x2, best = v;
  }
  if (shadow >= 0) {
    score *= std::max(0.9f, 1 - powf(1 + best, 3));
    if (score >= kMinBorderProbability) return shadow;
  }
  score = 0.0f;
  return -1;
}

// checkIfMaximum: the score is the largest between the pixel behind and the shadow border.
bool isMaximum(const RangeImage& im, int x, int y, int d, const std::vector<float>& scores, int shadow) {
  const float s = scores[y * im.width + x];
  if (im.inImage(x - kDx[d], y - kDy[d]) && scores[(y - kDy[d]) * im.width + x - kDx[d]] > s) return false;
  for (int k = 1; k <= kRadiusBorders; ++k) {
    const int x2 = x + k * kDx[d], y2 = y + k * kDy[d];
    if (!im.inImage(x2, y2)) continue;
    if (y2 * im.width + x2 == shadow) return true;
    if (scores[y2 * im.width + x2] > s) return false;
  }
  return true;
}

// get3dDirection: from the border point towards its obstacle side, on the local plane.
bool borderDirection(const RangeImage& im, const Surface& s, int x, int y, std::uint8_t traits, Eigen::Vector3f& dir) {
  int dx = 0, dy = 0;
  if (traits & kObstacleRight) ++dx;
  if (traits & kObstacleLeft) --dx;
  if (traits & kObstacleTop) --dy;
  if (traits & kObstacleBottom) ++dy;
  if (dx == 0 && dy == 0) return false;
  const int i = y * im.width + x;
  // RangeImagePlanar::calculate3DPoint of the neighbouring pixel at this pixel's range.
  const float ux = (float(x + dx) + 0.0f - im.cx) * im.fx_inv, uy = (float(y + dy) + 0.0f - im.cy) * im.fy_inv;
  Eigen::Vector3f nb;
  nb[2] = im.range[i] / std::sqrt(ux * ux + uy * uy + 1);
  nb[0] = ux * nb[2];
  nb[1] = uy * nb[2];
  if (s.ok) {  // onto the plane, along the viewing ray (sensor at the origin)
    const float lambda = s.normal.dot(s.mean) / s.normal.dot(nb);
    nb = lambda * nb;
  }
  dir = nb - im.points[i];
  dir.normalize();
  return true;
}

// calculateMainPrincipalCurvature: spread of the normals along 8 beams of 2 pixels, stopped at
// shadow / veil pixels; the magnitude is the root of the largest eigenvalue.
bool principalCurvature(const RangeImage& im, const std::vector<Surface>& surf, const std::vector<std::uint8_t>& traits,
                        int x, int y, float& magnitude, Eigen::Vector3f& direction) {
  magnitude = 0.0f;
  if (!surf[y * im.width + x].ok) return false;
  pcl::VectorAverage3f avg;
  bool beam_valid[9];
  for (int step = 1; step <= kRadiusCurvature; ++step) {
    int beam = 0;
    for (int y2 = y - step; y2 <= y + step; y2 += step)
      for (int x2 = x - step; x2 <= x + step; x2 += step) {
        bool& valid = beam_valid[beam++];
        if (step == 1)
          valid = !(x2 == x && y2 == y);
        else if (!valid)
          continue;
        if (!im.valid(x2, y2)) continue;
        const int i2 = y2 * im.width + x2;
        if (traits[i2] & (kVeil | kShadow)) {
          valid = false;
          continue;
        }
        if (surf[i2].ok) avg.add(surf[i2].normal);
      }
  }
  if (avg.getNoOfSamples() < 3) return false;
  // The eigenvalues exactly as doPCA's eigen33() gets them (roots of the scaled matrix); the
  // eigenvectors, most of its cost, only where the keypoint stage reads the direction.
  const Eigen::Matrix3f& cov = avg.getCovariance();
  float scale = cov.cwiseAbs().maxCoeff();
  if (scale <= std::numeric_limits<float>::min()) scale = 1.0f;
  Eigen::Vector3f values;
  pcl::computeRoots(Eigen::Matrix3f(cov / scale), values);
  values *= scale;
  magnitude = std::sqrt(values[2]);
  if (!std::isfinite(magnitude)) return false;
  if (magnitude >= kMinSurfaceChange) {
    Eigen::Vector3f v1, v2;
    avg.doPCA(values, v1, v2, direction);
  }
  return true;
}
}  // namespace

RangeImage::RangeImage(const cv::Mat& depth, const CameraIntrinsics& camera)
    : width(depth.cols), height(depth.rows), cx(float(camera.cx)), cy(float(camera.cy)),
      fx_inv(1.0f / float(camera.fx)), fy_inv(1.0f / float(camera.fy)) {
  CV_Assert(depth.type() == CV_32FC1);
  points.assign(std::size_t(width) * height, Eigen::Vector3f::Constant(std::nanf("")));
  range.assign(points.size(), kInf);
  for (int y = 0; y < height; ++y) {
    const float* d = depth.ptr<float>(y);
    for (int x = 0; x < width; ++x) {
      const float z = d[x];
      if (!(z > 0.0f) || !std::isfinite(z)) continue;
      Eigen::Vector3f& p = points[y * width + x];
      p = Eigen::Vector3f((float(x) - cx) * z * fx_inv, (float(y) - cy) * z * fy_inv, z);
      range[y * width + x] = p.norm();
    }
  }
}

namespace {
using Scores = std::array<std::vector<float>, 4>;

// Border scores per direction, then the neighbour bonus (computed from the unchanged scores).
Scores borderScores(const RangeImage& im, const std::vector<Surface>& surf) {
  const int w = im.width, h = im.height, size = w * h;
  Scores raw, score;
  for (int d = 0; d < 4; ++d) raw[d].assign(size, 0.0f), score[d].resize(size);
  parallelFor(0, h, [&](int y) {
    for (int x = 0; x < w; ++x)
      if (surf[y * w + x].ok)
        for (int d = 0; d < 4; ++d)
          raw[d][y * w + x] = distanceChangeScore(im, surf[y * w + x], x, y, kDx[d], kDy[d], kRadiusBorders);
  });
  parallelFor(0, h, [&](int y) {
    for (int d = 0; d < 4; ++d)
      for (int x = 0; x < w; ++x) score[d][y * w + x] = propagatedScore(im, raw[d], x, y);
  });
  return score;
}

// Shadow borders (one raster scan, the four directions in PCL's order, scores changed in place), then
// obstacle borders at the maxima, their shadow borders and the veil points in between.
std::vector<std::uint8_t> borderTraits(const RangeImage& im, Scores& score) {
  const int w = im.width, h = im.height, size = w * h;
  std::vector<std::array<int, 4>> shadow(size);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int d = 0; d < 4; ++d) shadow[y * w + x][d] = shadowBorder(im, x, y, d, score[d], score[kOpposite[d]]);
  std::vector<std::uint8_t> traits(size, 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int d = 0; d < 4; ++d) {
        const int i = y * w + x, s = shadow[i][d];
        if (s < 0 || !isMaximum(im, x, y, d, score[d], s)) continue;
        traits[i] |= kObstacle | kSide[d];
        traits[s] |= kShadow;
        const int step = kDx[d] + kDy[d] * w;
        for (int j = i + step; j != s; j += step) traits[j] |= kVeil;
      }
  return traits;
}

// Border directions, averaged over consistent neighbours (calculateBorderDirections); has_avg marks
// the pixels that have one.
std::vector<Eigen::Vector3f> borderDirections(const RangeImage& im, const std::vector<Surface>& surf,
                                              const std::vector<std::uint8_t>& traits, std::vector<std::uint8_t>& has_avg) {
  const int w = im.width, h = im.height, size = w * h;
  std::vector<Eigen::Vector3f> dir(size);
  std::vector<std::uint8_t> has_dir(size, 0);
  for (int i = 0; i < size; ++i)
    if (traits[i] & kObstacle) has_dir[i] = borderDirection(im, surf[i], i % w, i / w, traits[i], dir[i]);
  const int r = kRadiusBorderDirection, min_weight = r + 1;
  const float min_cos = std::cos(pcl::deg2rad(120.0f));
  std::vector<Eigen::Vector3f> avg_dir(size);
  has_avg.assign(size, 0);
  parallelFor(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      const int i = y * w + x;
      if (!has_dir[i]) continue;
      Eigen::Vector3f sum = dir[i];
      float weight = 1.0f;
      for (int y2 = std::max(0, y - r); y2 <= std::min(y + r, h - 1); ++y2)
        for (int x2 = std::max(0, x - r); x2 <= std::min(x + r, w - 1); ++x2) {
          const int i2 = y2 * w + x2;
          if (!has_dir[i2] || i2 == i) continue;
          if (dir[i2].dot(dir[i]) < min_cos) continue;  // opposite directions
          if (std::fabs(distanceChangeScore(im, surf[i], x, y, x2 - x, y2 - y, 1)) >= 0.95f * kMinBorderProbability)
            continue;  // a border in between
          sum += dir[i2];
          weight += 1.0f;
        }
      if (std::lrint(double(weight)) < min_weight) continue;
      avg_dir[i] = sum.normalized();
      has_avg[i] = 1;
    }
  });
  return avg_dir;
}
}  // namespace

Borders extractBorders(const RangeImage& im) {
  const int w = im.width, h = im.height, size = w * h;
  std::vector<Surface> surf(size);
  parallelFor(0, h, [&](int y) {
    for (int x = 0; x < w; ++x)
      if (im.valid(y * w + x)) surf[y * w + x] = localSurface(im, x, y);
  });
  Scores score = borderScores(im, surf);
  Borders b;
  b.traits = borderTraits(im, score);
  std::vector<std::uint8_t> has_avg;
  const std::vector<Eigen::Vector3f> avg_dir = borderDirections(im, surf, b.traits, has_avg);

  // Surface changes: 1 along the border direction on borders, else the main principal curvature.
  b.change_score.assign(size, 0.0f);
  b.change_dir.assign(size, Eigen::Vector3f::Zero());
  parallelFor(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      const int i = y * w + x;
      if (b.traits[i] & (kVeil | kShadow)) continue;
      if (has_avg[i]) {
        b.change_score[i] = 1.0f;
        b.change_dir[i] = avg_dir[i];
      } else if (!principalCurvature(im, surf, b.traits, x, y, b.change_score[i], b.change_dir[i])) {
        b.change_score[i] = 0.0f;
      }
    }
  });
  return b;
}

}  // namespace vofusion::narf
