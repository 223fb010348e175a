#pragma once
// Synthetic meshes for the mesh and scene tests: an icosphere and a box room, coloured by position.
#include <array>
#include <cmath>
#include <map>
#include <utility>

#include "vofusion/core/triangle_mesh.h"

namespace vofusion::test {

// Colour as a smooth function of position, so a colour can be checked anywhere on the surface.
inline std::array<std::uint8_t, 3> colourAt(const Eigen::Vector3f& p) {
  const auto c = [](float v) { return std::uint8_t(std::lround(std::min(255.f, std::max(0.f, 127.5f + 100.f * v)))); };
  return {c(p.x()), c(p.y()), c(p.z())};
}

// Unit icosphere (radius r, centre c), subdivided `levels` times: 20 * 4^levels faces, closed,
// counter-clockwise seen from outside.
inline TriangleMesh icosphere(int levels, float r = 1.f, Eigen::Vector3f c = Eigen::Vector3f::Zero()) {
  TriangleMesh m;
  const float t = (1.f + std::sqrt(5.f)) / 2.f;
  m.vertices = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  for (auto& v : m.vertices) v.normalize();
  m.faces = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
             {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
             {3, 8, 9},  {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (int l = 0; l < levels; ++l) {
    std::map<std::pair<std::uint32_t, std::uint32_t>, std::uint32_t> mid;
    const auto midpoint = [&](std::uint32_t a, std::uint32_t b) {
      const auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      m.vertices.push_back((m.vertices[a] + m.vertices[b]).normalized());
      return mid[key] = std::uint32_t(m.vertices.size() - 1);
    };
    std::vector<std::array<std::uint32_t, 3>> faces;
    for (const auto& f : m.faces) {
      const std::uint32_t ab = midpoint(f[0], f[1]), bc = midpoint(f[1], f[2]), ca = midpoint(f[2], f[0]);
      faces.push_back({f[0], ab, ca});
      faces.push_back({f[1], bc, ab});
      faces.push_back({f[2], ca, bc});
      faces.push_back({ab, bc, ca});
    }
    m.faces = std::move(faces);
  }
  for (auto& v : m.vertices) {
    v = c + r * v;
    m.colors.push_back(colourAt(v));
  }
  return m;
}

// The inside of a box room [x0,x1]x[y0,y1]x[0,h] without a ceiling, each wall an n x n grid,
// faces pointing inwards (as a scan from inside sees them). Open at the top.
inline TriangleMesh boxRoom(float sx = 4.f, float sy = 3.f, float h = 2.5f, int n = 8) {
  TriangleMesh m;
  const auto addQuadGrid = [&](Eigen::Vector3f o, Eigen::Vector3f u, Eigen::Vector3f v) {
    const auto base = std::uint32_t(m.vertices.size());
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) {
        m.vertices.push_back(o + u * (float(i) / n) + v * (float(j) / n));
        m.colors.push_back(colourAt(m.vertices.back()));
      }
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const std::uint32_t a = base + j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
        m.faces.push_back({a, b, d});
        m.faces.push_back({a, d, c});
      }
  };
  const float x0 = -sx / 2, y0 = -sy / 2;
  addQuadGrid({x0, y0, 0}, {sx, 0, 0}, {0, sy, 0});            // floor, normal +z
  addQuadGrid({x0, y0, 0}, {0, 0, h}, {sx, 0, 0});             // wall y=y0, normal +y
  addQuadGrid({x0, -y0, 0}, {sx, 0, 0}, {0, 0, h});            // wall y=-y0, normal -y
  addQuadGrid({x0, y0, 0}, {0, sy, 0}, {0, 0, h});             // wall x=x0, normal +x
  addQuadGrid({-x0, y0, 0}, {0, 0, h}, {0, sy, 0});            // wall x=-x0, normal -x
  return m;  // walls share edge positions but not vertex indices: a welding/stitching case
}

}  // namespace vofusion::test
