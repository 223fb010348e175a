#pragma once
// An indexed triangle mesh (shared vertices), as marching cubes produces and CGAL post-processes.
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace vofusion {

struct TriangleMesh {
  std::vector<Eigen::Vector3f> vertices;               // metres, world frame
  std::vector<Eigen::Vector3f> normals;                // unit, per vertex (empty or vertices.size())
  std::vector<std::array<std::uint8_t, 3>> colors;     // RGB per vertex (empty or vertices.size())
  std::vector<std::array<std::uint32_t, 3>> faces;     // counter-clockwise seen from outside

  bool empty() const { return faces.empty(); }
};

// Binary little-endian PLY (vertex x y z [nx ny nz] [red green blue], face vertex_indices);
// written whole or not at all. readPly also accepts ASCII PLY; throws InputError on bad files.
void writePly(const std::string& path, const TriangleMesh& mesh);
TriangleMesh readPly(const std::string& path);

}  // namespace vofusion
