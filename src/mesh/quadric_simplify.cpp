#include "vofusion/mesh/quadric_simplify.h"

#include <algorithm>
#include <stdexcept>

#include <meshoptimizer.h>

namespace vofusion {

namespace {

// meshoptimizer 0.18 locks a vertex only as part of "every border vertex" (meshopt_SimplifyLockBorder),
// which keeps a mesh's own ragged borders dense (rpy_first100: twice the faces for the same mean
// distance). It also locks any vertex that shares its position with an unreferenced vertex (two
// "wedges" that do not form a seam): one copy per locked vertex, after the mesh's own, locks just those.
std::vector<float> positionsLocking(const TriangleMesh& mesh, const std::vector<std::uint8_t>& locked) {
  std::vector<float> xyz;
  xyz.reserve(3 * mesh.vertices.size());
  for (const Eigen::Vector3f& v : mesh.vertices) xyz.insert(xyz.end(), {v.x(), v.y(), v.z()});
  for (std::size_t i = 0; i < locked.size(); ++i)
    if (locked[i]) xyz.insert(xyz.end(), {mesh.vertices[i].x(), mesh.vertices[i].y(), mesh.vertices[i].z()});
  return xyz;
}

// How many locked vertices `indices` references.
std::size_t lockedIn(const std::vector<unsigned>& indices, const std::vector<std::uint8_t>& locked) {
  std::vector<std::uint8_t> seen(locked.size(), 0);
  std::size_t found = 0;
  for (const unsigned v : indices)
    if (v < locked.size() && locked[v] && !seen[v]) seen[v] = 1, ++found;
  return found;
}

}  // namespace

bool simplifyByQuadrics(TriangleMesh& mesh, double max_error, std::size_t target_faces, std::vector<std::uint8_t>& locked) {
  const std::size_t n = mesh.vertices.size();
  if (mesh.faces.empty()) return true;
  if (!locked.empty() && locked.size() != n) throw std::invalid_argument("simplifyByQuadrics: one lock flag per vertex");
  // meshoptimizer asserts on a face naming a vertex past the end (Debian's build keeps its asserts): the
  // process aborted.
  checkFaceIndices(mesh);
  const std::vector<float> xyz = positionsLocking(mesh, locked);
  std::vector<unsigned> indices;
  indices.reserve(3 * mesh.faces.size());
  for (const auto& f : mesh.faces) indices.insert(indices.end(), {f[0], f[1], f[2]});
  // The error is relative to the mesh's extent; the mesh's own vertices give it, not the copies.
  const float scale = meshopt_simplifyScale(xyz.data(), n, 3 * sizeof(float));
  if (!(scale > 0)) return true;  // every vertex at one point: nothing to collapse
  // meshoptimizer asserts a target within the mesh's indices, and Debian's build keeps its asserts:
  // a budget above the mesh's faces (a small region) aborted the process.
  const std::size_t target_indices = std::min(3 * target_faces, indices.size());
  const auto collapse = [&](unsigned options) {
    std::vector<unsigned> kept(indices.size());
    kept.resize(meshopt_simplify(kept.data(), indices.data(), indices.size(), xyz.data(), xyz.size() / 3,
                                 3 * sizeof(float), target_indices, float(max_error / scale), options, nullptr));
    return kept;
  };
  const std::size_t locked_used = lockedIn(indices, locked);
  const auto keepsLocked = [&](const std::vector<unsigned>& kept) { return lockedIn(kept, locked) == locked_used; };
  std::vector<unsigned> kept = collapse(0);
  // A locked vertex's last face gone (its two neighbours collapsed into each other): once more with
  // every border vertex locked, as neighbours along a seam then are.
  if (!keepsLocked(kept)) kept = collapse(meshopt_SimplifyLockBorder);
  if (!keepsLocked(kept)) return false;

  std::vector<std::uint32_t> new_of(n, UINT32_MAX);
  TriangleMesh out;
  std::vector<std::uint8_t> out_locked;
  for (std::size_t i = 0; i < kept.size(); i += 3) {
    std::array<std::uint32_t, 3> face{};
    for (int k = 0; k < 3; ++k) {
      const unsigned old = kept[i + k];
      if (new_of[old] == UINT32_MAX) {
        new_of[old] = std::uint32_t(out.vertices.size());
        out.vertices.push_back(mesh.vertices[old]);
        if (!mesh.normals.empty()) out.normals.push_back(mesh.normals[old]);
        if (!mesh.colors.empty()) out.colors.push_back(mesh.colors[old]);
        if (!locked.empty()) out_locked.push_back(locked[old]);
      }
      face[k] = new_of[old];
    }
    out.faces.push_back(face);
  }
  mesh = std::move(out);
  locked = std::move(out_locked);
  return true;
}

}  // namespace vofusion
