#pragma once
// Union-find over 0..n-1, the smaller index as root (mesh_by_region.cpp's fragments across regions,
// region_premesher.cpp's across a region's neighbours). Private to src/pipeline/.
#include <algorithm>
#include <cstdint>
#include <vector>

namespace vofusion {

class UnionFind {
 public:
  std::uint32_t add() {
    parent_.push_back(std::uint32_t(parent_.size()));
    return parent_.back();
  }
  void reset(std::size_t n) {
    parent_.resize(n);
    for (std::uint32_t i = 0; i < n; ++i) parent_[i] = i;
  }
  std::uint32_t find(std::uint32_t v) {
    while (parent_[v] != v) v = parent_[v] = parent_[parent_[v]];
    return v;
  }
  void unite(std::uint32_t a, std::uint32_t b) {
    a = find(a), b = find(b);
    if (a != b) parent_[std::max(a, b)] = std::min(a, b);
  }
  std::size_t size() const { return parent_.size(); }

 private:
  std::vector<std::uint32_t> parent_;
};

}  // namespace vofusion
