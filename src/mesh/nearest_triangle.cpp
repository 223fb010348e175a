#include "vofusion/mesh/nearest_triangle.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

namespace vofusion {

Eigen::Vector3d closestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                       const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + ab * (d1 / (d1 - d3));
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + ac * (d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  const double denom = va + vb + vc;
  // Degenerate (a segment or a point), or a sliver whose rounding sent a point outside it here (a
  // barycentric weight below zero): the nearest of its edges' points.
  if (!(std::abs(denom) > 0) || va < 0 || vb < 0 || vc < 0) {
    Eigen::Vector3d best = a;
    for (const auto& [s, t] : {std::pair{a, b}, std::pair{b, c}, std::pair{c, a}}) {
      const Eigen::Vector3d st = t - s;
      const double len_sq = st.squaredNorm();
      const Eigen::Vector3d q = len_sq > 0 ? Eigen::Vector3d(s + st * std::clamp((p - s).dot(st) / len_sq, 0.0, 1.0)) : s;
      if ((q - p).squaredNorm() < (best - p).squaredNorm()) best = q;
    }
    return best;
  }
  return a + ab * (vb / denom) + ac * (vc / denom);
}

NearestTriangle::NearestTriangle(const std::vector<Eigen::Vector3d>& points,
                                 const std::vector<std::array<std::size_t, 3>>& triangles) {
  tris_.reserve(triangles.size());
  double edge_sum = 0.0;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::max()), hi = -lo;
  for (const auto& t : triangles) {
    for (const std::size_t i : t)
      if (i >= points.size()) throw std::invalid_argument("a triangle references point " + std::to_string(i));
    const std::array<Eigen::Vector3d, 3> v{points[t[0]], points[t[1]], points[t[2]]};
    if (!v[0].allFinite() || !v[1].allFinite() || !v[2].allFinite()) continue;  // nothing is nearest to it
    edge_sum += std::max({(v[1] - v[0]).norm(), (v[2] - v[1]).norm(), (v[0] - v[2]).norm()});
    for (const auto& x : v) lo = lo.cwiseMin(x), hi = hi.cwiseMax(x);
    tris_.push_back(v);
  }
  if (tris_.empty()) return;
  bounds_.reserve(tris_.size());
  for (const auto& v : tris_) {
    const Eigen::Vector3d centre = (v[0] + v[1] + v[2]) / 3.0;
    bounds_.push_back({centre, std::max({(v[0] - centre).norm(), (v[1] - centre).norm(), (v[2] - centre).norm()})});
  }
  origin_ = lo;
  const Eigen::Vector3d extent = hi - lo;
  cell_ = cellSize(extent, edge_sum / double(tris_.size()));
  // Long triangles among short ones are listed in every cell their box covers: a few hundred slivers
  // across a mesh of a million small faces asked for ~4e9 listings (16 GB, or the 2^32 refusal, which
  // failed the whole cleaning over its distance measurement). Larger cells then, at most 32 listings a
  // triangle on average: the search is exact at any cell size.
  const std::uint64_t budget = 32 * std::uint64_t(tris_.size()) + 1000000;
  while (!listTriangles(extent, budget)) cell_ *= 1.25;
}

double NearestTriangle::cellSize(const Eigen::Vector3d& extent, double mean_longest_edge) const {
  // Twice the mean longest edge: a triangle spans one or two cells a side, and a query near the
  // surface usually ends after its own cell and a few of its neighbours. A whole room's mesh, or a
  // flat one, would need too many such cells: then larger ones, at most eight cells per triangle.
  const auto cellsOf = [&](double cell) {
    double n = 1.0;
    for (int i = 0; i < 3; ++i) n *= std::floor(extent[i] / cell) + 1.0;
    return n;
  };
  double cell = std::max({2.0 * mean_longest_edge, extent.maxCoeff() * 1e-6, 1e-12});
  while (cellsOf(cell) > 8.0 * double(tris_.size()) + 64.0) cell *= 1.25;
  return cell;
}

bool NearestTriangle::listTriangles(const Eigen::Vector3d& extent, std::uint64_t budget) {
  for (int i = 0; i < 3; ++i) dims_[i] = std::int64_t(std::floor(extent[i] / cell_)) + 1;
  const auto index = [&](std::int64_t x, std::int64_t y, std::int64_t z) { return std::size_t((z * dims_[1] + y) * dims_[0] + x); };
  // The cells a triangle's bounding box covers, clamped to the grid: first and last per axis.
  const auto cellBox = [&](const std::array<Eigen::Vector3d, 3>& v) {
    const Cell a = cellOf(v[0].cwiseMin(v[1]).cwiseMin(v[2])), b = cellOf(v[0].cwiseMax(v[1]).cwiseMax(v[2]));
    std::pair<Cell, Cell> box;
    for (int i = 0; i < 3; ++i) box.first[i] = std::max<std::int64_t>(a[i], 0), box.second[i] = std::min(b[i], dims_[i] - 1);
    return box;
  };
  const auto forEachCell = [&](const std::pair<Cell, Cell>& box, const auto& visit) {
    const auto& [a, b] = box;
    for (std::int64_t z = a[2]; z <= b[2]; ++z)
      for (std::int64_t y = a[1]; y <= b[1]; ++y)
        for (std::int64_t x = a[0]; x <= b[0]; ++x) visit(index(x, y, z));
  };
  // Counting sort into cells: counts (stopped once over the budget), their running sum, then the ids.
  // More listings than 32-bit offsets hold (beyond ~130 million triangles) is refused.
  begin_.assign(std::size_t(dims_[0] * dims_[1] * dims_[2]) + 1, 0);
  std::uint64_t listings = 0;
  for (const auto& v : tris_) {
    const auto box = cellBox(v);
    const auto& [a, b] = box;
    listings += std::uint64_t(b[0] - a[0] + 1) * std::uint64_t(b[1] - a[1] + 1) * std::uint64_t(b[2] - a[2] + 1);
    if (listings > budget) return false;
    forEachCell(box, [&](std::size_t c) { ++begin_[c + 1]; });
  }
  if (listings > std::numeric_limits<std::uint32_t>::max())
    throw std::length_error("NearestTriangle: " + std::to_string(listings) + " cell listings, more than 2^32");
  for (std::size_t c = 1; c < begin_.size(); ++c) begin_[c] += begin_[c - 1];
  listed_.resize(begin_.back());
  std::vector<std::uint32_t> next(begin_.begin(), begin_.end() - 1);
  for (std::uint32_t id = 0; id < tris_.size(); ++id) forEachCell(cellBox(tris_[id]), [&](std::size_t c) { listed_[next[c]++] = id; });
  return true;
}

NearestTriangle::Cell NearestTriangle::cellOf(const Eigen::Vector3d& p) const {
  const Eigen::Vector3d q = (p - origin_) / cell_;
  // Far points clamp to far cells: still outside the grid, the search only starts further out.
  const auto index = [](double v) { return std::int64_t(std::floor(std::clamp(v, -1e15, 1e15))); };
  return {index(q.x()), index(q.y()), index(q.z())};
}

void NearestTriangle::searchCell(const Cell& c, const Eigen::Vector3d& p, Eigen::Vector3d& best, double& best_sq) const {
  const std::size_t i = std::size_t((c[2] * dims_[1] + c[1]) * dims_[0] + c[0]);
  if (begin_[i] == begin_[i + 1]) return;
  double box_sq = 0.0;  // from p to the cell's box
  for (int k = 0; k < 3; ++k) {
    const double lo = origin_[k] + double(c[k]) * cell_;
    const double gap = std::max({lo - p[k], p[k] - (lo + cell_), 0.0});
    box_sq += gap * gap;
  }
  if (box_sq >= best_sq) return;
  for (std::uint32_t k = begin_[i]; k < begin_[i + 1]; ++k) {
    const std::uint32_t id = listed_[k];
    // A lower bound of the distance, less a margin far above rounding (the bound's terms and the
    // closest point's coordinates are rounded to ~1e-16 of themselves): a triangle passed over could
    // only have tied or lost, so the point found is the one the exact test of every listed triangle finds.
    const Bound& s = bounds_[id];
    const double to_centre = (p - s.centre).norm();
    const double margin = 1e-9 * (to_centre + s.radius) + 1e-12 * p.cwiseAbs().maxCoeff();
    const double lower = to_centre - s.radius - margin;
    if (lower > 0 && lower * lower >= best_sq) continue;
    const auto& v = tris_[id];
    const Eigen::Vector3d q = closestPointOnTriangle(p, v[0], v[1], v[2]);
    const double d = (q - p).squaredNorm();
    if (d < best_sq) best_sq = d, best = q;
  }
}

Eigen::Vector3d NearestTriangle::closestPoint(const Eigen::Vector3d& p) const {
  if (!p.allFinite()) return Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  const Cell c = cellOf(p);
  Eigen::Vector3d best = Eigen::Vector3d::Zero();
  double best_sq = std::numeric_limits<double>::infinity();
  // Rings (cells at Chebyshev distance r from c) from the first that reaches the grid.
  std::int64_t r = 0;
  for (int i = 0; i < 3; ++i) r = std::max({r, -c[i], c[i] - (dims_[i] - 1)});
  for (;; ++r) {
    const std::int64_t x0 = std::max<std::int64_t>(c[0] - r, 0), x1 = std::min(c[0] + r, dims_[0] - 1);
    const std::int64_t y0 = std::max<std::int64_t>(c[1] - r, 0), y1 = std::min(c[1] + r, dims_[1] - 1);
    const std::int64_t z0 = std::max<std::int64_t>(c[2] - r, 0), z1 = std::min(c[2] + r, dims_[2] - 1);
    for (std::int64_t z = z0; z <= z1; ++z)
      for (std::int64_t y = y0; y <= y1; ++y) {
        if (std::abs(z - c[2]) == r || std::abs(y - c[1]) == r) {
          for (std::int64_t x = x0; x <= x1; ++x) searchCell({x, y, z}, p, best, best_sq);
        } else {  // inside the ring's y-z square: only its two x faces
          if (c[0] - r >= x0) searchCell({c[0] - r, y, z}, p, best, best_sq);
          if (r > 0 && c[0] + r <= x1) searchCell({c[0] + r, y, z}, p, best, best_sq);
        }
      }
    // Everything in the block of rings 0..r is searched: done when the whole grid is, or when
    // nothing outside the block can be nearer than the best found.
    bool whole = true;
    double outside = std::numeric_limits<double>::infinity();
    for (int i = 0; i < 3; ++i) {
      whole = whole && c[i] - r <= 0 && c[i] + r >= dims_[i] - 1;
      const double below = p[i] - (origin_[i] + double(c[i] - r) * cell_);
      const double above = origin_[i] + double(c[i] + r + 1) * cell_ - p[i];
      outside = std::min({outside, below, above});
    }
    if (whole || (best_sq < std::numeric_limits<double>::infinity() && best_sq <= outside * outside)) return best;
  }
}

}  // namespace vofusion
