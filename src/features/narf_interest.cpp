// NARF's interest image and interest points as pcl::NarfKeypoint computes them with its defaults
// (PCL 1.13: sparse interest image, non-maximum suppression, no polynomial refinement), on one
// thread with buffers reused across seeds. Operations keep PCL's order so the floats come out the same.
#include <algorithm>
#include <array>
#include <cmath>

#include <pcl/common/angles.h>
#include <pcl/common/eigen.h>

#include "vofusion/features/narf_fast.h"

namespace vofusion::narf {

namespace {
constexpr int kBins = 18;                    // angle_histogram_size: directions over 180 degrees
constexpr float kOptimalDistance = 0.25f;    // optimal_distance_to_high_surface_change, factor on the radius
constexpr float kMinSurfaceChange = 0.2f;    // min_surface_change_score
constexpr float kMinPointDistance = 0.25f;   // min_distance_between_interest_points, factor on support size
constexpr float kUnset = 2.0f;               // PCL's marker of a pixel whose interest is still to compute

// nkdGetScores: a surface change close by lowers the score (negative), one at the right distance
// raises its direction's histogram cell (positive).
inline void scores(float distance_factor, float change, float pixel_distance, float& negative, float& positive) {
  negative = 1.0f - 0.5f * change * std::max(1.0f - distance_factor / kOptimalDistance, 0.0f);
  negative = powf(negative, 2);
  positive = pixel_distance < 2.0 ? change : change * (1.0f - distance_factor);
}

// nkdGetDirectionAngle and the histogram cell of that angle, in the seed's viewer frame.
inline int directionCell(const Eigen::Vector3f& direction, const Eigen::Affine3f& rotation) {
  const Eigen::Vector3f rotated = rotation * direction;
  Eigen::Vector2f v(rotated[0], rotated[1]);
  v.normalize();
  const float angle = 0.5f * pcl::normAngle(2.0f * std::acos(v[0]));
  return std::min(kBins - 1, int(std::lrint(double(std::floor((angle + pcl::deg2rad(90.0f)) / pcl::deg2rad(180.0f) * kBins)))));
}

// The strongest change between two direction cells, weighted by their angle apart.
float angleChange(const std::array<float, kBins>& hist) {
  float change = 0.0f;
  for (int c1 = 0; c1 < kBins - 1; ++c1) {
    if (hist[c1] == 0.0f) continue;
    for (int c2 = c1 + 1; c2 < kBins; ++c2) {
      if (hist[c2] == 0.0f) continue;
      float diff = 2.0f * float(c2 - c1) / float(kBins);
      diff = diff <= 1.0f ? diff : 2.0f - diff;
      change = std::max(hist[c1] * hist[c2] * diff, change);
    }
  }
  return std::sqrt(change);
}

// The buffers of the sparse interest image, allocated once per image.
struct Workspace {
  std::vector<std::uint8_t> touched;
  std::vector<int> to_check, near;  // region of a seed; its pixels close enough to get a value from it
  std::array<std::vector<std::pair<int, float>>, kBins> relevant;  // (pixel, change) per direction cell
  std::vector<std::uint8_t> still_valid;
};

// calculateSparseInterestImage, one seed: grow the region within 1.5 support radii, histogram its
// surface changes by direction; if no pixel nearby can reach the minimum, zero them all, else compute
// the pixels within the overhead radius from a thinned list of the changes.
void seedInterest(const RangeImage& im, const Borders& b, float support_size, float min_interest, int index,
                  Workspace& ws, std::vector<float>& interest) {
  const int w = im.width, h = im.height;
  const float radius = 0.5f * support_size, radius_inv = 1.0f / radius, increased = 1.5f * radius,
              increased2 = increased * increased, overhead = increased - radius, overhead2 = overhead * overhead;
  const int x = index % w, y = index / w;
  const Eigen::Vector3f& point = im.points[index];
  Eigen::Affine3f rotation;
  pcl::getTransformationFromTwoUnitVectors(Eigen::Vector3f(0.0f, -1.0f, 0.0f), point.normalized(), rotation);

  ws.to_check.clear();
  ws.to_check.push_back(index);
  ws.near.clear();
  ws.touched[index] = 1;
  std::array<float, kBins> hist{};
  for (auto& r : ws.relevant) r.clear();
  for (std::size_t k = 0; k < ws.to_check.size(); ++k) {
    const int i2 = ws.to_check[k];
    if (!im.valid(i2) || (b.traits[i2] & (kShadow | kVeil))) continue;
    const int x2 = i2 % w, y2 = i2 / w;
    const float pixel_distance = float(std::max(std::abs(x2 - x), std::abs(y2 - y)));
    const Eigen::Vector3f& p2 = im.points[i2];
    const float dx = p2.x() - point.x(), dy = p2.y() - point.y(), dz = p2.z() - point.z();
    const float d2 = dx * dx + dy * dy + dz * dz;
    if (d2 <= overhead2) ws.near.push_back(i2);
    if (pixel_distance > 2.0f && d2 > increased2) continue;  // immediate neighbours always count
    for (int y3 = std::max(0, y2 - 1); y3 <= std::min(y2 + 1, h - 1); ++y3)
      for (int x3 = std::max(0, x2 - 1); x3 <= std::min(x2 + 1, w - 1); ++x3)
        if (!ws.touched[y3 * w + x3]) {
          ws.to_check.push_back(y3 * w + x3);
          ws.touched[y3 * w + x3] = 1;
        }
    const float change = b.change_score[i2];
    if (change < kMinSurfaceChange) continue;
    const int cell = directionCell(b.change_dir[i2], rotation);
    hist[cell] = std::max(hist[cell], change);
    ws.relevant[cell].emplace_back(i2, change);
  }
  for (int i : ws.to_check) ws.touched[i] = 0;

  if (angleChange(hist) < min_interest) {  // no pixel within the overhead radius can do better
    for (int i : ws.near) interest[i] = 0.0f;
    return;
  }
  // Thin each cell's changes: drop those close to a stronger one. PCL compares the distance (not
  // its square) with the squared limit; kept, since the keypoints must be PCL's.
  const float min_relevant2 = powf(0.25f * radius, 2);
  for (auto& rel : ws.relevant) {
    std::sort(rel.begin(), rel.end(), [](const auto& a, const auto& c) { return a.second > c.second; });
    ws.still_valid.assign(rel.size(), 1);
    for (int k1 = 0; k1 < int(rel.size()) - 1; ++k1) {
      if (!ws.still_valid[k1]) continue;
      for (int k2 = k1 + 1; k2 < int(rel.size()); ++k2)
        if (ws.still_valid[k2] && (im.points[rel[k1].first] - im.points[rel[k2].first]).norm() <= min_relevant2)
          ws.still_valid[k2] = 0;
    }
    std::size_t kept = 0;
    for (std::size_t k = 0; k < rel.size(); ++k)
      if (ws.still_valid[k]) rel[kept++] = rel[k];
    rel.resize(kept);
  }
  for (int i2 : ws.near) {
    if (interest[i2] <= 1.0f) continue;  // already computed by an earlier seed
    const int x2 = i2 % w, y2 = i2 / w;
    const Eigen::Vector3f& p2 = im.points[i2];
    float negative = 1.0f;
    for (int cell = 0; cell < kBins; ++cell) {
      hist[cell] = 0.0f;
      for (const auto& [i3, change] : ws.relevant[cell]) {
        const float pixel_distance = float(std::max(std::abs(i3 % w - x2), std::abs(i3 / w - y2)));
        const float distance = (im.points[i3] - p2).norm();
        float neg, pos;
        scores(radius_inv * distance, change, pixel_distance, neg, pos);
        hist[cell] = std::max(hist[cell], pos);
        negative = std::min(negative, neg);
      }
    }
    interest[i2] = negative * angleChange(hist);
  }
}
}  // namespace

std::vector<int> interestPoints(const RangeImage& im, const Borders& b, const KeypointParams& p,
                                std::vector<float>& interest) {
  const int w = im.width, h = im.height, size = w * h;
  interest.assign(size, 0.0f);
  for (int i = 0; i < size; ++i)
    if (im.valid(i) && !(b.traits[i] & (kShadow | kVeil))) interest[i] = kUnset;
  Workspace ws;
  ws.touched.assign(size, 0);
  // Seeds in raster order: each computes itself and its still unset neighbours, so later pixels
  // take the value the first seed near them gave (PCL's order, hence PCL's values).
  for (int i = 0; i < size; ++i)
    if (interest[i] > 1.0f) seedInterest(im, b, p.support_size, p.min_interest_value, i, ws, interest);

  // Local maxima above the minimum, strongest first, none within 0.25 support sizes of a stronger one.
  struct Candidate {
    float strength;
    int index;
  };
  std::vector<Candidate> candidates;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int i = y * w + x;
      const float v = interest[i];
      if (!im.valid(i) || v < p.min_interest_value) continue;
      bool is_max = true;
      for (int y2 = y - 1; y2 <= y + 1 && is_max; ++y2)
        for (int x2 = x - 1; x2 <= x + 1; ++x2)
          if (im.inImage(x2, y2) && interest[y2 * w + x2] > v) {
            is_max = false;
            break;
          }
      if (is_max) candidates.push_back({v, i});
    }
  std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& c) { return a.strength > c.strength; });
  const float min_d2 = powf(kMinPointDistance * p.support_size, 2);
  std::vector<int> kept;
  for (const Candidate& c : candidates) {
    if (p.max_points > 0 && int(kept.size()) >= p.max_points) break;
    bool too_close = false;
    for (int k : kept)
      if ((im.points[c.index] - im.points[k]).squaredNorm() < min_d2) {
        too_close = true;
        break;
      }
    if (!too_close) kept.push_back(c.index);
  }
  std::sort(kept.begin(), kept.end());  // raster order, as NarfKeypoint::compute lists them
  return kept;
}

}  // namespace vofusion::narf
