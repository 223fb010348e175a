#pragma once
// An indexed triangle mesh (shared vertices), as marching cubes produces and CGAL post-processes.
// Its files (PLY, OBJ, STL) are the mesh stage's: vofusion/mesh/mesh_io.h.
#include <array>
#include <cstdint>
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

// Throws std::invalid_argument("a face references vertex V of N") for a face naming a vertex past the end.
void checkFaceIndices(const TriangleMesh& mesh);

// Area-weighted vertex normals, oriented like the faces (+z for a vertex of no face's area).
void computeVertexNormals(TriangleMesh& mesh);

}  // namespace vofusion
