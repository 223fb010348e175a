#pragma once
// Exact nearest-surface distances to a mesh of small triangles (marching cubes' own), from a uniform
// grid over the mesh's box: each triangle is listed in the cells its bounding box overlaps, and a
// query searches rings of cells round its point, skipping cells farther than the best found, until no
// unsearched cell can hold anything nearer. It measures simplification
// (mesh_clean.cpp), where CGAL's AABB tree took a quarter of meshing's CPU (rpy_first100) building and
// descending a tree for each region; test_mesh_clean checks it against that tree.
#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace vofusion {

class NearestTriangle {
 public:
  // Triangles as indices into `points`; both are copied. Cells are twice the mean longest edge, or
  // larger where the box would otherwise hold more than eight cells per triangle, or the triangles be
  // listed in more than 32 cells each on average (long ones among short ones). Throws std::length_error
  // beyond 2^32 listings in all (~130 million triangles).
  NearestTriangle(const std::vector<Eigen::Vector3d>& points, const std::vector<std::array<std::size_t, 3>>& triangles);

  bool empty() const { return tris_.empty(); }
  // The nearest point of the surface to p (undefined when empty(); NaN when p is not finite). Exact
  // for any p within 1e15 cells of the mesh.
  Eigen::Vector3d closestPoint(const Eigen::Vector3d& p) const;
  double distance(const Eigen::Vector3d& p) const { return (closestPoint(p) - p).norm(); }

 private:
  using Cell = std::array<std::int64_t, 3>;
  Cell cellOf(const Eigen::Vector3d& p) const;
  // The grid's first cell edge for triangles spanning `extent` from origin_.
  double cellSize(const Eigen::Vector3d& extent, double mean_longest_edge) const;
  // Each triangle listed in the cells its box covers (dims_, begin_, listed_) at cell_; false, the grid
  // left unmade, when that takes more than `budget` listings.
  bool listTriangles(const Eigen::Vector3d& extent, std::uint64_t budget);
  // Tests the triangles listed in cell c (inside the grid) against p unless the cell's box is
  // farther than `best_sq`, keeping the nearest point in `best` (squared distance `best_sq`).
  void searchCell(const Cell& c, const Eigen::Vector3d& p, Eigen::Vector3d& best, double& best_sq) const;

  std::vector<std::array<Eigen::Vector3d, 3>> tris_;
  // Per triangle, a sphere holding it (centre, radius): most of a cell's triangles are farther than the
  // best point found so far by more than their size, and are passed over without the exact test.
  struct Bound {
    Eigen::Vector3d centre;
    double radius;
  };
  std::vector<Bound> bounds_;
  double cell_ = 1.0;
  Eigen::Vector3d origin_ = Eigen::Vector3d::Zero();
  Cell dims_{};                        // cells per axis
  std::vector<std::uint32_t> begin_;   // per cell (x fastest), and one past the last: its range in listed_
  std::vector<std::uint32_t> listed_;  // triangle ids, cell by cell
};

// The point of triangle abc nearest to p (Ericson, Real-Time Collision Detection, 5.1.5).
Eigen::Vector3d closestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                       const Eigen::Vector3d& c);

}  // namespace vofusion
