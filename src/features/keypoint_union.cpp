#include "vofusion/features/keypoint_union.h"

#include <cmath>
#include <unordered_map>

namespace vofusion {

std::vector<cv::KeyPoint> mergeKeypoints(const std::vector<cv::KeyPoint>& a, const std::vector<cv::KeyPoint>& b,
                                         float radius) {
  std::vector<cv::KeyPoint> out = a;
  if (radius <= 0.f) {
    out.insert(out.end(), b.begin(), b.end());
    return out;
  }
  // Grid hash with cells of `radius`: a neighbour lies in the 3x3 cells around a point.
  auto cell = [radius](float v) { return static_cast<long>(std::floor(v / radius)); };
  auto key = [](long cx, long cy) { return long((static_cast<unsigned long>(cx) << 32) ^ (cy & 0xffffffffL)); };
  std::unordered_multimap<long, cv::Point2f> grid;
  grid.reserve(a.size() * 2);
  for (const auto& k : a) grid.emplace(key(cell(k.pt.x), cell(k.pt.y)), k.pt);
  const float r2 = radius * radius;
  for (const auto& k : b) {
    const long cx = cell(k.pt.x), cy = cell(k.pt.y);
    bool dup = false;
    for (long dy = -1; dy <= 1 && !dup; ++dy)
      for (long dx = -1; dx <= 1 && !dup; ++dx) {
        auto range = grid.equal_range(key(cx + dx, cy + dy));
        for (auto it = range.first; it != range.second; ++it) {
          const cv::Point2f d = it->second - k.pt;
          if (d.dot(d) <= r2) { dup = true; break; }
        }
      }
    if (!dup) out.push_back(k);
  }
  return out;
}

}  // namespace vofusion
