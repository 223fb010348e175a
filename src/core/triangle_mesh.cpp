#include "vofusion/core/triangle_mesh.h"

#include <stdexcept>
#include <string>

#include <Eigen/Geometry>

namespace vofusion {

void checkFaceIndices(const TriangleMesh& mesh) {
  for (const auto& f : mesh.faces)
    for (const std::uint32_t v : f)
      if (v >= mesh.vertices.size())
        throw std::invalid_argument("a face references vertex " + std::to_string(v) + " of " + std::to_string(mesh.vertices.size()));
}

void computeVertexNormals(TriangleMesh& mesh) {
  mesh.normals.assign(mesh.vertices.size(), Eigen::Vector3f::Zero());
  for (const auto& f : mesh.faces) {
    const Eigen::Vector3f n = (mesh.vertices[f[1]] - mesh.vertices[f[0]]).cross(mesh.vertices[f[2]] - mesh.vertices[f[0]]);
    for (int k = 0; k < 3; ++k) mesh.normals[f[k]] += n;
  }
  for (auto& n : mesh.normals) {
    const float len = n.norm();
    n = len > 0.f ? Eigen::Vector3f(n / len) : Eigen::Vector3f(0.f, 0.f, 1.f);
  }
}

}  // namespace vofusion
