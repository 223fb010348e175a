// Marching cubes over sparse TSDF bricks. Every grid edge belongs to the voxel at its lower end, so
// each surface crossing is computed once (pass 1, per brick, in parallel), numbered globally, and the
// triangles of each cell (pass 2) refer to those shared vertices.
#include "vofusion/fusion/marching_cubes.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <cstring>
#include <map>
#include <optional>
#include <unordered_map>
#include <unordered_set>

// Lorensen & Cline lookup tables (Bourke's edgeTable/triTable), as shipped by PCL.
#include <pcl/surface/marching_cubes.h>

#include "vofusion/core/parallel.h"

namespace vofusion::fusion {

Eigen::Vector3i regionOf(const Eigen::Vector3i& brick, int region_bricks) {
  const auto d = [region_bricks](int v) { return v >= 0 ? v / region_bricks : -((-v + region_bricks - 1) / region_bricks); };
  return {d(brick.x()), d(brick.y()), d(brick.z())};
}

namespace {

std::uint64_t brickKey(const Eigen::Vector3i& c) {
  const auto u = [](int v) { return static_cast<std::uint64_t>(static_cast<std::uint32_t>(v + (1 << 20)) & 0x1fffff); };
  return u(c.x()) | (u(c.y()) << 21) | (u(c.z()) << 42);
}

// Cube corners in PCL's order (its tables are written for it) and each cube edge's two corners, in
// PCL's edge numbering.
constexpr int kCorner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 0, 1}, {0, 0, 1}, {0, 1, 0}, {1, 1, 0}, {1, 1, 1}, {0, 1, 1}};
constexpr int kEdgeCorners[12][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 0}, {4, 5}, {5, 6}, {6, 7}, {7, 4}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};

struct BrickVertices {
  // Owned edges with a crossing, one bit per edge id (voxel index * 3 + axis), and per word of bits the
  // crossings before it: an edge's vertex is found by a popcount, not a search.
  static constexpr int kWords = kBrickVoxels * 3 / 64;
  std::array<std::uint64_t, kWords> edge_bits{};
  std::array<std::uint16_t, kWords> before{};
  std::vector<Eigen::Vector3f> points;  // in edge id order
  std::vector<std::array<std::uint8_t, 3>> colours;
  std::vector<std::uint8_t> seam;    // 1: also used by another region's cells (region meshing only)
  // Crossings exactly on a voxel (an end's TSDF is 0): the vertex (index in points) and that voxel.
  // Every edge from it to the other side has one there; extract() makes them one vertex.
  std::vector<std::pair<std::uint32_t, Eigen::Vector3i>> on_voxel;
  std::uint32_t base = 0;            // global index of the first vertex

  void addEdge(int id) { edge_bits[id >> 6] |= std::uint64_t(1) << (id & 63); }
  void countBefore() {
    std::uint16_t n = 0;
    for (int w = 0; w < kWords; ++w) {
      before[w] = n;
      n += std::uint16_t(__builtin_popcountll(edge_bits[w]));
    }
  }
  // The global index of the vertex on edge `id`, -1 when it has none.
  std::int64_t vertexOn(int id) const {
    const std::uint64_t bit = std::uint64_t(1) << (id & 63), word = edge_bits[id >> 6];
    if (!(word & bit)) return -1;
    return base + before[id >> 6] + std::uint32_t(__builtin_popcountll(word & (bit - 1)));
  }
};
static_assert(kBrickVoxels * 3 % 64 == 0, "edge bits fill whole words");

class Grid {
 public:
  Grid(const std::vector<BrickRef>& bricks) : bricks_(bricks) {
    map_.reserve(bricks.size() * 2);
    for (std::size_t i = 0; i < bricks.size(); ++i) map_[brickKey(bricks[i].coord)] = static_cast<int>(i);
  }
  int find(const Eigen::Vector3i& c) const {
    const auto it = map_.find(brickKey(c));
    return it == map_.end() ? -1 : it->second;
  }
  // Voxel at local coordinates of brick i that may spill into the +1 neighbours (0..8 per axis).
  const Voxel* voxel(const int nb[8], int x, int y, int z) const {
    const int which = (x >> 3) | ((y >> 3) << 1) | ((z >> 3) << 2);
    const int bi = nb[which];
    if (bi < 0) return nullptr;
    return &bricks_[bi].brick->voxels[Brick::index(x & 7, y & 7, z & 7)];
  }
  void neighbours(std::size_t i, int nb[8]) const {
    for (int k = 0; k < 8; ++k)
      nb[k] = k == 0 ? static_cast<int>(i) : find(bricks_[i].coord + Eigen::Vector3i(k & 1, (k >> 1) & 1, (k >> 2) & 1));
  }

 private:
  const std::vector<BrickRef>& bricks_;
  std::unordered_map<std::uint64_t, int> map_;
};

inline bool usable(const Voxel* v, int min_weight) {
  // Fully truncated values carry no surface position (occlusion boundaries, unobserved backs).
  return v && v->weight >= min_weight && std::abs(v->tsdf) < 32440;  // |tsdf| < 0.99
}



// Whether the crossing on the edge at voxel (x,y,z) of brick i along `axis` is one another region's
// cells also use: cells using that edge lie at the voxel minus 0 or 1 along each other axis, another
// region's when the voxel is on the region's low face there (or the brick is not one this pass owns).
struct SeamTest {
  const std::vector<BrickRef>& bricks;
  std::size_t owned;
  int region_bricks;

  std::uint8_t operator()(std::size_t i, int x, int y, int z, int axis) const {
    if (i >= owned) return 1;
    const int local[3] = {x, y, z};
    for (int k = 0; k < 3; ++k)
      if (k != axis && local[k] == 0 &&
          regionOf(bricks[i].coord - Eigen::Vector3i::Unit(k), region_bricks) != regionOf(bricks[i].coord, region_bricks))
        return 1;
    return 0;
  }
};

// Per voxel of a brick and its +1 neighbours (9 per axis, x fastest): 0 when unusable, else 1 on the
// positive side and 2 on the negative. Read once per voxel instead of once per cell corner (8 times):
// the cells without a crossing, most of a brick, are then skipped from this table alone.
constexpr int kSpan = kBrickEdge + 1;
using CornerStates = std::array<std::uint8_t, kSpan * kSpan * kSpan>;
// Each cube corner's offset in that table, in PCL's corner order (kCorner).
constexpr std::array<int, 8> cornerOffsets() {
  std::array<int, 8> o{};
  for (int k = 0; k < 8; ++k) o[k] = kCorner[k][0] + kSpan * (kCorner[k][1] + kSpan * kCorner[k][2]);
  return o;
}
constexpr std::array<int, 8> kCornerOffset = cornerOffsets();

// Each cube edge as the voxel it starts from (its lower corner, relative to the cell's first) and the
// axis it runs along: where its crossing's vertex is kept.
struct EdgeStart {
  int dx, dy, dz, axis;
};
constexpr std::array<EdgeStart, 12> edgeStarts() {
  std::array<EdgeStart, 12> s{};
  for (int e = 0; e < 12; ++e) {
    const int* a = kCorner[kEdgeCorners[e][0]];
    const int* b = kCorner[kEdgeCorners[e][1]];
    s[e] = {std::min(a[0], b[0]), std::min(a[1], b[1]), std::min(a[2], b[2]), a[0] != b[0] ? 0 : (a[1] != b[1] ? 1 : 2)};
  }
  return s;
}
constexpr std::array<EdgeStart, 12> kEdgeStart = edgeStarts();

void cornerStates(const Grid& grid, const int* nb, int min_weight, CornerStates& state) {
  std::size_t k = 0;
  for (int z = 0; z < kSpan; ++z)
    for (int y = 0; y < kSpan; ++y)
      for (int x = 0; x < kSpan; ++x, ++k) {
        const Voxel* v = grid.voxel(nb, x, y, z);
        state[k] = !usable(v, min_weight) ? 0 : (v->tsdf < 0 ? 2 : 1);
      }
}

// Pass 1, one brick: the vertices on the edges it owns (from each voxel along +x, +y, +z).
void edgeVertices(const Grid& grid, const int* nb, const CornerStates& state, std::size_t i, const Eigen::Vector3i& coord,
                  float voxel_size, const SeamTest* seam, BrickVertices& bv) {
  const Eigen::Vector3i o = coord * kBrickEdge;
  constexpr int kStep[3] = {1, kSpan, kSpan * kSpan};
  for (int z = 0; z < kBrickEdge; ++z)
    for (int y = 0; y < kBrickEdge; ++y)
      for (int x = 0; x < kBrickEdge; ++x) {
        const std::uint8_t* at = &state[x + kSpan * (y + kSpan * z)];
        if (!at[0]) continue;
        const Voxel* a = grid.voxel(nb, x, y, z);
        for (int axis = 0; axis < 3; ++axis) {
          // A crossing: both ends usable, on opposite sides.
          if (!at[kStep[axis]] || at[kStep[axis]] == at[0]) continue;
          const Voxel* b = grid.voxel(nb, x + (axis == 0), y + (axis == 1), z + (axis == 2));
          const float fa = a->tsdf, fb = b->tsdf;
          const float t = fa / (fa - fb);
          Eigen::Vector3f p((o.x() + x) * voxel_size, (o.y() + y) * voxel_size, (o.z() + z) * voxel_size);
          const float start = p[axis], end = float(o[axis] + (axis == 0 ? x : axis == 1 ? y : z) + 1) * voxel_size;
          p[axis] += t * voxel_size;
          // On a voxel: t is 0 or 1, or so near it that the offset rounds away in float (far from the
          // origin: 0.9 um is half an ulp at 19 m), which made vertices apart at one position.
          const bool at_a = t == 0.f || p[axis] == start;
          const bool at_b = !at_a && (t == 1.f || p[axis] == end || end - (1.f - t) * voxel_size == end);
          if (at_a || at_b) {  // the same arithmetic from every edge (and region) there
            Eigen::Vector3i g = o + Eigen::Vector3i(x, y, z);
            if (at_b) ++g[axis];
            p = Eigen::Vector3f(g.x() * voxel_size, g.y() * voxel_size, g.z() * voxel_size);
            bv.on_voxel.emplace_back(std::uint32_t(bv.points.size()), g);
          }
          bv.addEdge(Brick::index(x, y, z) * 3 + axis);
          if (seam) bv.seam.push_back((*seam)(i, x, y, z, axis));
          bv.points.push_back(p);
          const auto mix = [t](std::uint8_t u, std::uint8_t v) {
            return static_cast<std::uint8_t>(std::lround(u + t * (static_cast<float>(v) - u)));
          };
          // An end never painted (black: only free space seen there) has no colour to blend in.
          const bool a_painted = (a->r | a->g | a->b) != 0, b_painted = (b->r | b->g | b->b) != 0;
          const Voxel* ca = a_painted || !b_painted ? a : b;
          const Voxel* cb = b_painted || !a_painted ? b : a;
          bv.colours.push_back({mix(ca->r, cb->r), mix(ca->g, cb->g), mix(ca->b, cb->b)});
        }
      }
  bv.countBefore();
}

// The bricks' vertices one after another into the mesh (each brick's base index set).
void gatherVertices(std::vector<BrickVertices>& verts, TriangleMesh& mesh, std::vector<std::uint8_t>* seam) {
  std::uint32_t total = 0;
  for (auto& bv : verts) bv.base = total, total += static_cast<std::uint32_t>(bv.points.size());
  mesh.vertices.reserve(total);
  mesh.colors.reserve(total);
  for (const auto& bv : verts) {
    mesh.vertices.insert(mesh.vertices.end(), bv.points.begin(), bv.points.end());
    mesh.colors.insert(mesh.colors.end(), bv.colours.begin(), bv.colours.end());
    if (seam) seam->insert(seam->end(), bv.seam.begin(), bv.seam.end());
  }
}

// Pass 2, one brick: the triangles of every cell whose 8 corners are usable.
void cellFaces(const int* nb, const CornerStates& state, const std::vector<BrickVertices>& verts,
               std::vector<std::array<std::uint32_t, 3>>& faces) {
  auto vertexOf = [&](int cx, int cy, int cz, int axis) -> std::int64_t {
    const int which = (cx >> 3) | ((cy >> 3) << 1) | ((cz >> 3) << 2);
    const int bi = nb[which];
    if (bi < 0) return -1;
    return verts[bi].vertexOn(Brick::index(cx & 7, cy & 7, cz & 7) * 3 + axis);
  };
  for (int z = 0; z < kBrickEdge; ++z)
    for (int y = 0; y < kBrickEdge; ++y)
      for (int x = 0; x < kBrickEdge; ++x) {
        const std::uint8_t* at = &state[x + kSpan * (y + kSpan * z)];
        int cube = 0;
        bool ok = true;
        for (int k = 0; k < 8 && ok; ++k) {
          const std::uint8_t c = at[kCornerOffset[k]];
          ok = c != 0;
          if (c == 2) cube |= 1 << k;
        }
        if (!ok || pcl::edgeTable[cube] == 0) continue;
        std::int64_t ev[12];
        for (int e = 0; e < 12; ++e) {
          ev[e] = -1;
          if (!(pcl::edgeTable[cube] & (1 << e))) continue;
          const EdgeStart& start = kEdgeStart[e];
          ev[e] = vertexOf(x + start.dx, y + start.dy, z + start.dz, start.axis);
        }
        for (int k = 0; pcl::triTable[cube][k] != -1; k += 3) {
          const std::int64_t i0 = ev[pcl::triTable[cube][k]], i1 = ev[pcl::triTable[cube][k + 1]],
                             i2 = ev[pcl::triTable[cube][k + 2]];
          if (i0 < 0 || i1 < 0 || i2 < 0 || i0 == i1 || i1 == i2 || i0 == i2) continue;
          faces.push_back({static_cast<std::uint32_t>(i0), static_cast<std::uint32_t>(i1), static_cast<std::uint32_t>(i2)});
        }
      }
}

// The crossings on one voxel made one vertex (its seam flag any of theirs), and the faces that then
// repeat a vertex dropped: a voxel whose TSDF rounds to exactly 0 (about 1 in 13 000 near a surface)
// put a vertex on itself for every edge to the other side, and zero-area faces between them (which
// made a region mesh fail its repair as a polygon soup).
// Region meshing (`region` set): such a vertex is on the seam when any of the 8 cells with a corner on
// its voxel is another region's, which may use it through another edge (one it does not flag).
void mergeVoxelCrossings(const std::vector<BrickVertices>& verts, TriangleMesh& mesh, std::vector<std::uint8_t>* seam,
                         const std::optional<Eigen::Vector3i>& region, int region_bricks) {
  struct Hash {
    std::size_t operator()(const Eigen::Vector3i& g) const {
      return std::size_t((std::uint64_t(std::uint32_t(g.x())) * 0x9E3779B97F4A7C15ull) ^
                         (std::uint64_t(std::uint32_t(g.y())) * 0xC2B2AE3D27D4EB4Full) ^
                         (std::uint64_t(std::uint32_t(g.z())) * 0x165667B19E3779F9ull));
    }
  };
  const auto cellsOfAnotherRegion = [&](const Eigen::Vector3i& g) {
    for (int k = 0; k < 8; ++k) {
      const Eigen::Vector3i cell = g - Eigen::Vector3i(k & 1, (k >> 1) & 1, (k >> 2) & 1);
      static_assert(kBrickEdge == 8, "a cell's brick by shifting its voxel coordinates");
      const Eigen::Vector3i brick(cell.x() >> 3, cell.y() >> 3, cell.z() >> 3);
      if (regionOf(brick, region_bricks) != *region) return true;
    }
    return false;
  };
  std::unordered_map<Eigen::Vector3i, std::uint32_t, Hash> first;
  std::unordered_map<std::uint32_t, std::uint32_t> to;  // a copy -> the vertex it becomes
  for (const BrickVertices& bv : verts)
    for (const auto& [local, g] : bv.on_voxel) {
      const std::uint32_t v = bv.base + local;
      if (seam && region && cellsOfAnotherRegion(g)) (*seam)[v] = 1;
      const auto [it, fresh] = first.emplace(g, v);
      if (fresh) continue;
      to[v] = it->second;
      if (seam) (*seam)[it->second] |= (*seam)[v];
    }
  if (to.empty()) return;
  std::size_t n = 0;
  for (auto f : mesh.faces) {
    for (auto& v : f)
      if (const auto it = to.find(v); it != to.end()) v = it->second;
    if (f[0] != f[1] && f[1] != f[2] && f[0] != f[2]) mesh.faces[n++] = f;
  }
  mesh.faces.resize(n);
}

// Drop crossings no triangle uses (edges whose cells touch unobserved voxels).
void dropUnusedVertices(TriangleMesh& mesh, std::vector<std::uint8_t>* seam) {
  std::vector<std::uint32_t> remap(mesh.vertices.size(), UINT32_MAX);
  for (const auto& f : mesh.faces)
    for (std::uint32_t v : f) remap[v] = 0;
  std::uint32_t kept = 0;
  for (std::size_t v = 0; v < remap.size(); ++v) {
    if (remap[v] == UINT32_MAX) continue;
    remap[v] = kept;
    mesh.vertices[kept] = mesh.vertices[v];
    mesh.colors[kept] = mesh.colors[v];
    if (seam) (*seam)[kept] = (*seam)[v];
    ++kept;
  }
  mesh.vertices.resize(kept);
  mesh.colors.resize(kept);
  if (seam) seam->resize(kept);
  for (auto& f : mesh.faces)
    for (auto& v : f) v = remap[v];
}

// Marching cubes over the cells of bricks[0, owned); the later bricks only lend voxels and the
// vertices on edges they own. region_bricks > 0: `seam` flags the vertices that cells of another
// region also use (those of edges owned by a later brick, or on a face the region shares).
TriangleMesh extract(const std::vector<BrickRef>& bricks, std::size_t owned, float voxel_size, int min_weight,
                     int region_bricks, std::vector<std::uint8_t>* seam) {
  TriangleMesh mesh;
  if (bricks.empty()) return mesh;
  min_weight = std::max(1, min_weight);
  const Grid grid(bricks);
  std::vector<BrickVertices> verts(bricks.size());
  std::vector<std::array<int, 8>> nbs(bricks.size());
  std::vector<CornerStates> states(owned);  // the owned bricks', read again by pass 2
  const SeamTest seam_test{bricks, owned, region_bricks};
  parallelFor(0, static_cast<int>(bricks.size()), [&](int i) {
    grid.neighbours(i, nbs[i].data());
    CornerStates lent;
    CornerStates& state = std::size_t(i) < owned ? states[i] : lent;
    cornerStates(grid, nbs[i].data(), min_weight, state);
    edgeVertices(grid, nbs[i].data(), state, i, bricks[i].coord, voxel_size, seam ? &seam_test : nullptr, verts[i]);
  }, 8);
  gatherVertices(verts, mesh, seam);
  std::vector<std::vector<std::array<std::uint32_t, 3>>> faces(owned);
  parallelFor(0, static_cast<int>(owned), [&](int i) { cellFaces(nbs[i].data(), states[i], verts, faces[i]); }, 8);
  std::size_t nf = 0;
  for (const auto& f : faces) nf += f.size();
  mesh.faces.reserve(nf);
  for (const auto& f : faces) mesh.faces.insert(mesh.faces.end(), f.begin(), f.end());
  std::optional<Eigen::Vector3i> region;  // the owned bricks' (one region when meshing by region)
  if (seam && region_bricks > 0 && owned > 0) region = regionOf(bricks[0].coord, region_bricks);
  mergeVoxelCrossings(verts, mesh, seam, region, region_bricks);
  dropUnusedVertices(mesh, seam);
  computeVertexNormals(mesh);
  return mesh;
}

}  // namespace

TriangleMesh marchingCubes(const std::vector<BrickRef>& bricks, float voxel_size, int min_weight) {
  return extract(bricks, bricks.size(), voxel_size, min_weight, 0, nullptr);
}

void marchingCubesByRegion(const std::vector<BrickRef>& bricks, float voxel_size, int min_weight, int region_bricks,
                           const std::function<void(RegionMesh&)>& sink) {
  std::unordered_map<std::uint64_t, const Brick*> at;
  std::vector<Eigen::Vector3i> coords;
  at.reserve(bricks.size() * 2);
  for (const BrickRef& b : bricks) at[brickKey(b.coord)] = b.brick, coords.push_back(b.coord);
  marchingCubesStreamedByRegion(coords, [&](const Eigen::Vector3i& c, Brick&) { return at.at(brickKey(c)); },
                                voxel_size, min_weight, region_bricks, sink);
}

RegionMesh marchRegion(const Eigen::Vector3i& region, std::vector<Eigen::Vector3i> own,
                       const std::function<bool(const Eigen::Vector3i&)>& present, const BrickFetch& fetch,
                       float voxel_size, int min_weight, int region_bricks, std::vector<Brick>& scratch) {
  std::sort(own.begin(), own.end(), [](const Eigen::Vector3i& a, const Eigen::Vector3i& b) {
    return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3);
  });
  // Only this region's bricks and their +1 neighbours (whose voxels and edges its cells reach) are
  // fetched, and held, at a time.
  std::vector<Eigen::Vector3i> list = own;
  std::unordered_set<std::uint64_t> listed;
  for (const auto& c : own) listed.insert(brickKey(c));
  for (const auto& c : own)
    for (int k = 1; k < 8; ++k) {
      const Eigen::Vector3i n = c + Eigen::Vector3i(k & 1, (k >> 1) & 1, (k >> 2) & 1);
      if (present(n) && listed.insert(brickKey(n)).second) list.push_back(n);
    }
  if (scratch.size() < list.size()) scratch.resize(list.size());
  std::vector<BrickRef> refs(list.size());
  // On every core: a spilled brick is read and decompressed (the loop scene: a fifth of the first pass's
  // CPU, on one core while the other waited); fetches are safe side by side (WorldModel::read).
  parallelFor(0, int(list.size()), [&](int i) { refs[i] = {list[i], fetch(list[i], scratch[i])}; }, 16);
  RegionMesh r;
  r.region = region;
  r.mesh = extract(refs, own.size(), voxel_size, min_weight, region_bricks, &r.on_seam);
  return r;
}

void marchingCubesStreamedByRegion(const std::vector<Eigen::Vector3i>& coords, const BrickFetch& fetch, float voxel_size,
                                   int min_weight, int region_bricks, const std::function<void(RegionMesh&)>& sink) {
  if (region_bricks <= 0) throw std::invalid_argument("region_bricks must be positive");
  std::unordered_set<std::uint64_t> present;
  std::map<std::array<int, 3>, std::vector<Eigen::Vector3i>> regions;  // ordered: the same mesh every run
  present.reserve(coords.size() * 2);
  for (const auto& c : coords) {
    present.insert(brickKey(c));
    const Eigen::Vector3i r = regionOf(c, region_bricks);
    regions[{r.x(), r.y(), r.z()}].push_back(c);
  }
  const auto isPresent = [&](const Eigen::Vector3i& c) { return present.count(brickKey(c)) != 0; };
  std::size_t ordinal = 0;
  // Where bricks read from the world model go, kept from region to region: made per region, the
  // zeroed bricks of every listed brick were a tenth of meshing's page faults (rpy_first100).
  std::vector<Brick> scratch;
  for (auto& [region, own] : regions) {
    RegionMesh r = marchRegion(Eigen::Vector3i(region[0], region[1], region[2]), std::move(own), isPresent, fetch,
                               voxel_size, min_weight, region_bricks, scratch);
    r.ordinal = ordinal++;
    r.regions = regions.size();
    if (!r.mesh.empty()) sink(r);
  }
}

TriangleMesh marchingCubesStreamed(const std::vector<Eigen::Vector3i>& coords, const BrickFetch& fetch,
                                   float voxel_size, int min_weight, int region_bricks) {
  TriangleMesh mesh;
  SeamWelder welder;
  marchingCubesStreamedByRegion(coords, fetch, voxel_size, min_weight, std::max(1, region_bricks), [&](RegionMesh& r) {
    const TriangleMesh& part = r.mesh;
    const std::vector<std::uint32_t> to_mesh = welder.add(part, r.on_seam, [&](std::size_t v) {
      mesh.vertices.push_back(part.vertices[v]);
      mesh.colors.push_back(part.colors[v]);
    });
    for (const auto& f : part.faces) mesh.faces.push_back({to_mesh[f[0]], to_mesh[f[1]], to_mesh[f[2]]});
  });
  computeVertexNormals(mesh);
  return mesh;
}

}  // namespace vofusion::fusion
