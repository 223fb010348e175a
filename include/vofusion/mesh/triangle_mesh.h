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

// Wavefront OBJ (text): "v x y z [r g b]" with colours in [0, 1] (the common extension MeshLab and
// Open3D read), "vn" normals when present, 1-based "f" lines. Written whole or not at all.
void writeObj(const std::string& path, const TriangleMesh& mesh);
// Binary STL: geometry only (STL has no vertex colours), a face normal per triangle.
void writeStl(const std::string& path, const TriangleMesh& mesh);

enum class MeshFormat { Ply, Obj, Stl };
// The format named by the path's extension (.ply, .obj, .stl, any case); InputError naming the file
// otherwise.
MeshFormat meshFormatOf(const std::string& path);
// Writes PLY, OBJ or STL by the extension of `path`.
void writeMesh(const std::string& path, const TriangleMesh& mesh);

}  // namespace vofusion
