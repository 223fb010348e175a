// CGAL mesh post-processing on synthetic meshes with known defects.
#include <Eigen/Dense>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>

#include <random>
#include <set>

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <mrpt/config/CConfigFileMemory.h>

#include <nlohmann/json.hpp>

#include "support.h"
#include "test_mesh_fixtures.h"
#include "vofusion/core/allocation_limit.h"
#include "vofusion/mesh/mesh_clean.h"
#include "vofusion/mesh/mesh_io.h"
#include "vofusion/mesh/nearest_triangle.h"
#include "vofusion/mesh/quadric_simplify.h"

using namespace vofusion;
using test::colourAt;
using test::icosphere;

namespace {

double triangleArea(const TriangleMesh& m, const std::array<std::uint32_t, 3>& f) {
  return 0.5 * double((m.vertices[f[1]] - m.vertices[f[0]]).cross(m.vertices[f[2]] - m.vertices[f[0]]).norm());
}

double totalArea(const TriangleMesh& m) {
  double a = 0;
  for (const auto& f : m.faces) a += triangleArea(m, f);
  return a;
}

// Signed volume (divergence theorem): positive when faces are oriented outward.
double signedVolume(const TriangleMesh& m) {
  double v = 0;
  for (const auto& f : m.faces)
    v += double(m.vertices[f[0]].dot(m.vertices[f[1]].cross(m.vertices[f[2]]))) / 6.0;
  return v;
}

// Every undirected edge used by exactly two faces, in opposite directions: closed and consistently oriented.
bool closedAndOriented(const TriangleMesh& m) {
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> directed;
  for (const auto& f : m.faces)
    for (int k = 0; k < 3; ++k) ++directed[{f[k], f[(k + 1) % 3]}];
  for (const auto& [e, n] : directed) {
    if (n != 1) return false;
    auto it = directed.find({e.second, e.first});
    if (it == directed.end() || it->second != 1) return false;
  }
  return !m.faces.empty();
}

// Each face with its own three vertex copies: a "polygon soup" as naive marching cubes writes it.
TriangleMesh explode(const TriangleMesh& m) {
  TriangleMesh s;
  for (const auto& f : m.faces) {
    const auto base = std::uint32_t(s.vertices.size());
    for (auto i : f) {
      s.vertices.push_back(m.vertices[i]);
      s.colors.push_back(m.colors[i]);
    }
    s.faces.push_back({base, base + 1, base + 2});
  }
  return s;
}

// Colours coloured by position (colourAt): vertices on the unit sphere keep theirs exactly, the others
// (a hole's patch) take their border's, within 20. Returns how many are not on the sphere.
std::size_t expectColoursKeptAndBlended(const TriangleMesh& m) {
  EXPECT_EQ(m.colors.size(), m.vertices.size());
  std::size_t patch_vertices = 0;
  for (std::size_t i = 0; i < m.vertices.size() && i < m.colors.size(); ++i) {
    const auto expected = colourAt(m.vertices[i]);
    const bool original = std::abs(m.vertices[i].norm() - 1.f) < 1e-6f;
    for (int k = 0; k < 3; ++k) {
      if (original) EXPECT_EQ(m.colors[i][k], expected[k]);
      else EXPECT_NEAR(m.colors[i][k], expected[k], 20);
    }
    patch_vertices += !original;
  }
  return patch_vertices;
}

MeshCleanParams testParams() {
  MeshCleanParams p;
  p.min_component_faces = 30;  // the 20-face fragment goes
  p.max_hole_perimeter = 2.0;  // m: the punched cap (~1.3 m around) is filled
  p.max_hole_edges = 100;
  p.max_simplify_error = 0;    // the checks below count the repaired faces and vertices
  return p;
}

}  // namespace

TEST(MeshClean, RepairsSphereWithHoleFragmentDegeneratesAndDuplicates) {
  const TriangleMesh ref = icosphere(3);  // 1280 faces, r = 1
  TriangleMesh m = ref;
  // Punch a hole: drop the cap z > 0.97 (a ring of radius ~0.24 m).
  std::size_t cap_faces = 0;
  m.faces.erase(std::remove_if(m.faces.begin(), m.faces.end(),
                               [&](const auto& f) {
                                 const bool cap = (m.vertices[f[0]] + m.vertices[f[1]] + m.vertices[f[2]]).z() / 3 > 0.97f;
                                 cap_faces += cap;
                                 return cap;
                               }),
                m.faces.end());
  ASSERT_GT(cap_faces, 5u);
  m = explode(m);  // every vertex duplicated
  // A floating fragment: a small closed sphere 4 m away.
  const TriangleMesh frag = icosphere(0, 0.1f, {4, 0, 0});
  const auto off = std::uint32_t(m.vertices.size());
  m.vertices.insert(m.vertices.end(), frag.vertices.begin(), frag.vertices.end());
  m.colors.insert(m.colors.end(), frag.colors.begin(), frag.colors.end());
  for (auto f : frag.faces) m.faces.push_back({f[0] + off, f[1] + off, f[2] + off});
  // Degenerate faces: a repeated vertex, and a zero-area sliver glued onto the sphere (collinear corners).
  m.faces.push_back({0, 0, 1});
  m.vertices.push_back((m.vertices[m.faces[5][0]] + m.vertices[m.faces[5][1]]) / 2);
  m.colors.push_back({0, 0, 0});
  m.faces.push_back({m.faces[5][0], m.faces[5][1], std::uint32_t(m.vertices.size() - 1)});
  // An exactly collinear (zero-area) triangle.
  const auto c0 = std::uint32_t(m.vertices.size());
  for (float x : {0.f, 0.25f, 0.5f}) {
    m.vertices.push_back({x, 0, 0});
    m.colors.push_back({0, 0, 0});
  }
  m.faces.push_back({c0, c0 + 1, c0 + 2});
  // A duplicated face.
  m.faces.push_back(m.faces[10]);

  const MeshCleanReport r = cleanMesh(m, testParams());
  ASSERT_TRUE(r.success) << r.failure;
  EXPECT_GE(r.duplicate_vertices_merged, ref.vertices.size());  // the soup had ~6 copies per vertex
  EXPECT_GE(r.degenerate_faces_removed, 2u);
  EXPECT_GE(r.duplicate_faces_removed, 1u);
  EXPECT_GE(r.components_removed, 1u);
  EXPECT_EQ(r.components_kept, 1u);
  EXPECT_EQ(r.holes_filled, 1u);
  EXPECT_EQ(r.holes_left, 0u);
  EXPECT_TRUE(r.closed);
  EXPECT_TRUE(r.manifold);
  EXPECT_EQ(r.border_cycles_after, 0u);
  ASSERT_EQ(r.steps.size(), 3u);
  EXPECT_EQ(r.steps[0].name, "repair");
  EXPECT_EQ(r.steps[2].name, "holes");
  EXPECT_GT(r.steps[2].faces_after, r.steps[2].faces_before);

  // The result: a closed, consistently outward-oriented sphere with no degenerate triangle.
  EXPECT_TRUE(closedAndOriented(m));
  for (const auto& f : m.faces) {
    EXPECT_TRUE(f[0] != f[1] && f[1] != f[2] && f[0] != f[2]);
    EXPECT_GT(triangleArea(m, f), 1e-8);
  }
  for (const auto& v : m.vertices) EXPECT_LT(v.norm(), 1.01f) << "fragment vertex left: " << v.transpose();
  const double ref_area = totalArea(ref), ref_vol = signedVolume(ref);
  EXPECT_NEAR(totalArea(m), ref_area, 0.02 * ref_area);
  EXPECT_NEAR(signedVolume(m), ref_vol, 0.03 * ref_vol);
  EXPECT_NEAR(r.area, totalArea(m), 1e-3 * ref_area);
  // Fresh unit normals pointing outward.
  ASSERT_EQ(m.normals.size(), m.vertices.size());
  for (std::size_t i = 0; i < m.vertices.size(); ++i) EXPECT_GT(m.normals[i].dot(m.vertices[i].normalized()), 0.9f);

  // Colours: original vertices keep theirs exactly; patch vertices get the colour of their surroundings.
  EXPECT_GT(expectColoursKeptAndBlended(m), 0u);  // the patch was refined
}

// cleanMesh works on the mesh itself (no copy: the welded mesh's repair is a long run's peak), and a
// failure leaves it as it came: at the start (a bad face), and after the repair, fragments and holes
// (simplification refuses an edge-length target beside a quadric error).
TEST(MeshClean, AFailureLeavesTheMeshAsItCame) {
  TriangleMesh m = explode(icosphere(2));  // a soup: the repair has work to do
  for (std::size_t i = 0; i < m.vertices.size(); ++i) m.colors.push_back({std::uint8_t(i), 7, 9});
  m.normals.assign(m.vertices.size(), Eigen::Vector3f::UnitZ());
  const TriangleMesh in = m;
  MeshCleanParams late = testParams();
  late.max_simplify_error = 0.001;
  late.target_edge_length = 0.01;
  const MeshCleanReport r = cleanMesh(m, late);
  EXPECT_FALSE(r.success);
  EXPECT_NE(r.failure.find("target_edge_length"), std::string::npos) << r.failure;
  EXPECT_EQ(m.vertices, in.vertices);
  EXPECT_EQ(m.faces, in.faces);
  EXPECT_EQ(m.colors, in.colors);
  EXPECT_EQ(m.normals, in.normals);
  m.faces.push_back({0, 1, std::uint32_t(m.vertices.size() + 7)});
  const TriangleMesh bad = m;
  const MeshCleanReport early = cleanMesh(m, testParams());
  EXPECT_FALSE(early.success);
  EXPECT_NE(early.failure.find("references vertex"), std::string::npos) << early.failure;
  EXPECT_EQ(m.faces, bad.faces);
  EXPECT_EQ(m.vertices, bad.vertices);
}

TEST(MeshClean, LargeOpeningsStayOpenSmallHolesClose) {
  TriangleMesh m = test::boxRoom(4, 3, 2.5, 8);  // walls meet along shared positions, not indices
  const double ref_area = totalArea(m);
  // A small hole in the floor: drop the two triangles of one grid cell (0.5 x 0.375 m).
  m.faces.erase(m.faces.begin() + 2 * (3 * 8 + 3), m.faces.begin() + 2 * (3 * 8 + 3) + 2);
  MeshCleanParams p;
  p.max_hole_perimeter = 2.0;
  const MeshCleanReport r = cleanMesh(m, p);
  ASSERT_TRUE(r.success) << r.failure;
  EXPECT_GT(r.border_edges_stitched + r.duplicate_vertices_merged, 0u);
  EXPECT_EQ(r.holes_filled, 1u);
  EXPECT_EQ(r.holes_left, 1u);           // the missing ceiling (14 m around) is no hole to fill
  EXPECT_EQ(r.border_cycles_after, 1u);
  EXPECT_FALSE(r.closed);
  EXPECT_TRUE(r.manifold);
  EXPECT_EQ(r.components_kept, 1u);      // the five walls were stitched into one surface
  EXPECT_NEAR(totalArea(m), ref_area, 0.01 * ref_area);
}

// A room scanned all round (closed once its small holes are filled) keeps its faces towards the room,
// where the cameras were: marching cubes faces the free space it saw, and orienting the closed result
// outward (CGAL decides at the highest vertex: the ceiling) turned the room inside out.
TEST(MeshClean, AClosedRoomKeepsItsFacesTowardsTheRoom) {
  const int n = 8;
  TriangleMesh m = test::boxRoom(4, 3, 2.5, n);  // floor first, every face towards the inside
  const auto floor_vertices = std::uint32_t((n + 1) * (n + 1)), base = std::uint32_t(m.vertices.size());
  for (std::uint32_t i = 0; i < floor_vertices; ++i) {  // the ceiling: the floor lifted, facing down
    m.vertices.push_back({m.vertices[i].x(), m.vertices[i].y(), 2.5f});
    m.colors.push_back(m.colors[i]);
  }
  for (int f = 0; f < 2 * n * n; ++f) {
    const auto t = m.faces[std::size_t(f)];
    m.faces.push_back({t[0] + base, t[2] + base, t[1] + base});
  }
  const MeshCleanReport r = cleanMesh(m, MeshCleanParams{});
  ASSERT_TRUE(r.success) << r.failure;
  ASSERT_TRUE(r.closed);
  double floor_up = 0, ceiling_up = 0;
  for (const auto& f : m.faces) {
    const Eigen::Vector3f a = m.vertices[f[0]], b = m.vertices[f[1]], c = m.vertices[f[2]];
    const float nz = (b - a).cross(c - a).z(), z = (a.z() + b.z() + c.z()) / 3;
    if (z < 0.01f) floor_up += nz;
    if (z > 2.49f) ceiling_up += nz;
  }
  EXPECT_GT(floor_up, 0.0) << "the floor faces down: the room was turned inside out";
  EXPECT_LT(ceiling_up, 0.0);
}

// A small piece on its own (kept: more faces than min_component_faces) has one border, its outline, which
// is no hole: filling it laid a second sheet over the piece, facing the other way (a closed "pillow").
TEST(MeshClean, ASmallPiecesOutlineIsNoHole) {
  TriangleMesh m;
  const int n = 10;  // a 5 x 5 cm square of 200 faces: perimeter 0.2 m, within max_hole_perimeter
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) m.vertices.push_back({0.005f * i, 0.005f * j, 1.f});
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const auto a = std::uint32_t(j * (n + 1) + i), b = a + 1, c = a + n + 1, d = c + 1;
      m.faces.push_back({a, b, d});
      m.faces.push_back({a, d, c});
    }
  const double area = totalArea(m);
  MeshCleanParams p;
  p.max_simplify_error = 0;
  ASSERT_LT(0.2, p.max_hole_perimeter);
  ASSERT_LT(std::size_t(p.min_component_faces), m.faces.size());
  const MeshCleanReport r = cleanMesh(m, p);
  ASSERT_TRUE(r.success) << r.failure;
  EXPECT_EQ(r.holes_filled, 0u);
  EXPECT_EQ(r.holes_left, 1u);
  EXPECT_FALSE(r.closed);
  EXPECT_NEAR(totalArea(m), area, 1e-6);
}

TEST(MeshClean, NonManifoldVertexIsSplit) {
  // Two tetrahedra touching at one vertex (a bow-tie vertex).
  TriangleMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {-1, 0, 0}, {0, -1, 0}, {0, 0, -1}};
  m.faces = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}, {0, 5, 4}, {0, 4, 6}, {0, 6, 5}, {4, 5, 6}};
  MeshCleanParams p;
  p.min_component_faces = 0;
  const MeshCleanReport r = cleanMesh(m, p);
  ASSERT_TRUE(r.success) << r.failure;
  EXPECT_EQ(r.non_manifold_vertices_split, 1u);
  EXPECT_EQ(m.vertices.size(), 8u);
  EXPECT_EQ(m.faces.size(), 8u);
  EXPECT_TRUE(r.manifold);
  EXPECT_TRUE(r.closed);
  EXPECT_EQ(r.components_kept, 2u);
  EXPECT_TRUE(m.colors.empty());  // none given, none invented
}

// A fault where regions meet; `fills_a_hole`: the repair patches a hole with vertices of its own.
struct SeamFault {
  std::string name;
  TriangleMesh mesh;
  bool fills_a_hole = false;
};

// The faults a welded mesh can have where regions meet, each beside a sound surface.
std::vector<SeamFault> seamFaults() {
  std::vector<SeamFault> out;
  TriangleMesh bowtie;  // two tetrahedra touching at one vertex
  bowtie.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {-1, 0, 0}, {0, -1, 0}, {0, 0, -1}};
  for (const auto& v : bowtie.vertices) bowtie.colors.push_back(colourAt(v));
  bowtie.faces = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}, {0, 5, 4}, {0, 4, 6}, {0, 6, 5}, {4, 5, 6}};
  out.push_back({"two tetrahedra on one vertex", bowtie});
  TriangleMesh sphere = icosphere(3);
  const std::array<std::uint32_t, 3> f = sphere.faces[40];
  std::vector<std::array<std::uint32_t, 3>> faults = {f, {f[0], f[2], f[1]}, {f[0], f[0], f[1]}};  // repeats both ways, a repeated corner
  const auto fin = std::uint32_t(sphere.vertices.size());  // a third face on an edge, twice
  sphere.vertices.push_back(1.2f * sphere.vertices[f[0]]);
  sphere.colors.push_back(colourAt(sphere.vertices.back()));
  faults.push_back({f[0], f[1], fin});
  faults.push_back({f[1], fin, f[0]});
  TriangleMesh after = sphere, before = sphere;
  after.faces.insert(after.faces.end(), faults.begin(), faults.end());
  out.push_back({"sphere, then repeats, a repeated fin and a repeated corner", after});
  before.faces.insert(before.faces.begin(), faults.begin(), faults.end());
  out.push_back({"the same faults before the sphere", before});
  TriangleMesh open = icosphere(3);  // a hole, a cap to fill with new vertices, a flap on a border vertex
  open.faces.erase(std::remove_if(open.faces.begin(), open.faces.end(),
                                  [&](const auto& t) { return (open.vertices[t[0]] + open.vertices[t[1]] + open.vertices[t[2]]).z() / 3 > 0.97f; }),
                   open.faces.end());
  const std::array<std::uint32_t, 3> g = open.faces[7];
  open.faces.erase(open.faces.begin() + 7);
  const auto tip = std::uint32_t(open.vertices.size());
  open.vertices.push_back(1.5f * open.vertices[g[0]]);
  open.vertices.push_back(1.5f * open.vertices[g[0]] + Eigen::Vector3f(0.1f, 0, 0));
  for (std::size_t i = tip; i < open.vertices.size(); ++i) open.colors.push_back(colourAt(open.vertices[i]));
  open.faces.push_back({g[0], tip, tip + 1});
  out.push_back({"sphere with a hole, a cap to fill and a flap on its border", open, true});
  return out;
}

// Regions welded at their seams are repaired face by face (no polygon soup, a fraction of the
// memory): on each fault where regions meet it must give what CGAL's soup repair gives.
TEST(MeshClean, WeldedRegionsRepairAsTheSoupRepairDoes) {
  for (const SeamFault& fault : seamFaults()) {
    SCOPED_TRACE(fault.name);
    const TriangleMesh& in = fault.mesh;
    for (int min_faces : {0, 30}) {
      MeshCleanParams p = testParams();
      p.min_component_faces = min_faces;
      TriangleMesh soup = in, welded = in;
      const MeshCleanReport a = cleanMesh(soup, p), b = cleanWeldedRegions(welded, p);
      ASSERT_TRUE(a.success) << a.failure;
      ASSERT_TRUE(b.success) << b.failure;
      EXPECT_EQ(b.closed, a.closed);
      EXPECT_TRUE(b.manifold);
      EXPECT_EQ(b.components_kept, a.components_kept);
      EXPECT_EQ(b.border_cycles_after, a.border_cycles_after);
      EXPECT_EQ(b.holes_filled, a.holes_filled);
      EXPECT_EQ(b.duplicate_faces_removed, a.duplicate_faces_removed);
      EXPECT_EQ(b.degenerate_faces_removed, a.degenerate_faces_removed);
      EXPECT_EQ(welded.faces.size(), soup.faces.size());
      EXPECT_EQ(welded.vertices.size(), soup.vertices.size());
      EXPECT_NEAR(totalArea(welded), totalArea(soup), 1e-6 * totalArea(soup));
      EXPECT_NEAR(signedVolume(welded), signedVolume(soup), 1e-6 * std::abs(signedVolume(soup)) + 1e-9);
      const std::size_t patch_vertices = expectColoursKeptAndBlended(welded);
      if (fault.fills_a_hole) {
        EXPECT_GT(a.holes_filled, 0u);  // the flap's tips are off the sphere too: patch_vertices alone cannot tell
        EXPECT_GT(patch_vertices, 0u);
      }
    }
  }
}

TEST(MeshClean, SimplifiesToFaceBudgetKeepingShapeAndColours) {
  TriangleMesh m = icosphere(4);  // 5120 faces
  const double ref_vol = signedVolume(m);
  MeshCleanParams p;
  p.max_simplify_error = 0;  // shortest edges first
  p.target_faces = 1000;
  const MeshCleanReport r = cleanMesh(m, p);
  ASSERT_TRUE(r.success) << r.failure;
  EXPECT_LE(m.faces.size(), 1050u);
  EXPECT_GE(m.faces.size(), 900u);
  EXPECT_TRUE(closedAndOriented(m));
  EXPECT_NEAR(signedVolume(m), ref_vol, 0.03 * ref_vol);
  for (std::size_t i = 0; i < m.vertices.size(); ++i)
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(m.colors[i][k], colourAt(m.vertices[i])[k], 12);
}

// A face budget above the mesh's own faces (a small region, a small PLY) leaves the mesh as the error
// bound does: meshoptimizer asserts target <= faces, and Debian's build keeps its asserts (SIGABRT).
TEST(MeshClean, AFaceBudgetLargerThanTheMeshIsNoAbort) {
  TriangleMesh m = icosphere(1);  // 80 faces
  MeshCleanParams p;
  p.max_simplify_error = 0.003;
  p.target_faces = 1000;
  const MeshCleanReport r = cleanMesh(m, p);
  ASSERT_TRUE(r.success) << r.failure;
  EXPECT_EQ(m.faces.size(), 80u);  // a coarse sphere: every collapse moves it by more than 3 mm
  EXPECT_TRUE(closedAndOriented(m));
}

// A region left unsimplified while the rest succeeded shows in summary.json (it was written into
// `failure`, which only a failed report writes: nowhere).
TEST(MeshClean, AWarningOfASucceededReportIsWritten) {
  MeshCleanReport r;
  r.success = true;
  r.warning = "1 region(s) left unsimplified: would move a seam vertex";
  const nlohmann::json j = nlohmann::json::parse(r.toJson());
  EXPECT_TRUE(j.at("success").get<bool>());
  EXPECT_EQ(j.at("warning"), r.warning);
  EXPECT_FALSE(j.contains("failure"));
}

// Without the repair, a mesh the half-edge structure cannot hold (three faces on one edge) is a
// failure that says so, and the mesh is left as given: its third face used to vanish, reported a success.
namespace {
// No repair and no step that changes the surface: the mesh taken as it is given.
MeshCleanParams withoutRepair() {
  MeshCleanParams p;
  p.repair = false;
  p.min_component_faces = 0;
  p.min_component_area = 0;
  p.max_hole_perimeter = 0;
  p.max_simplify_error = 0;
  p.target_edge_length = 0;
  return p;
}
}  // namespace

TEST(MeshClean, WithoutRepairANonManifoldMeshIsAFailureNotALoss) {
  TriangleMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}};
  m.faces = {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}};  // edge 0-1 shared by three faces
  const MeshCleanParams p = withoutRepair();
  const MeshCleanReport r = cleanMesh(m, p);
  EXPECT_FALSE(r.success);
  EXPECT_NE(r.failure.find("repair = true"), std::string::npos) << r.failure;
  EXPECT_EQ(m.faces.size(), 3u);
}

// Without the repair, vertices at one position keep their own colours (a colour seam: each side its
// own copy); colours were looked up by position, the first at a place painting every copy there.
TEST(MeshClean, WithoutRepairCopiesAtOnePositionKeepTheirColours) {
  TriangleMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 0, 0}, {0, 0, 0}, {1, -1, 0}};
  const std::array<std::uint8_t, 3> red{200, 0, 0}, blue{0, 0, 200};
  m.colors = {red, red, red, blue, blue, blue};
  m.faces = {{0, 1, 2}, {3, 4, 5}};  // two faces meeting along an edge, each with its own corners there
  const MeshCleanParams p = withoutRepair();
  const MeshCleanReport r = cleanMesh(m, p);
  ASSERT_TRUE(r.success) << r.failure;
  ASSERT_EQ(m.faces.size(), 2u);
  for (const auto& f : m.faces) {
    const auto colour = m.colors[f[0]];
    for (std::uint32_t v : f) EXPECT_EQ(m.colors[v], colour) << "a face's corners in two colours";
  }
  EXPECT_NE(m.colors[m.faces[0][0]], m.colors[m.faces[1][0]]);
  // A point no face uses is no surface: left out, as the repair leaves it out (it came out with a
  // normal of zero).
  m.vertices.push_back({5, 5, 5});
  m.colors.push_back(red);
  ASSERT_TRUE(cleanMesh(m, p).success);
  EXPECT_EQ(m.vertices.size(), 6u);
  ASSERT_EQ(m.normals.size(), m.vertices.size());
  for (const auto& n : m.normals) EXPECT_GT(n.norm(), 0.5f);
  // Points alone close nothing (it said closed, as a mesh without borders).
  TriangleMesh points;
  points.vertices = {{0, 0, 0}, {1, 0, 0}};
  const MeshCleanReport alone = cleanMesh(points, p);
  EXPECT_FALSE(alone.closed);
}

TEST(MeshClean, SimplifiesToEdgeLength) {
  TriangleMesh m = icosphere(4);  // edges ~0.08 m
  MeshCleanParams p;
  p.max_simplify_error = 0;  // shortest edges first
  p.target_edge_length = 0.2;
  const MeshCleanReport r = cleanMesh(m, p);
  ASSERT_TRUE(r.success) << r.failure;
  EXPECT_LT(m.faces.size(), 1500u);
  EXPECT_TRUE(closedAndOriented(m));
}

// A finely tessellated plane (1 m square, 5 mm steps) beside a sphere (r = 0.3 m, 20480 faces).
TriangleMesh planeAndSphere() {
  TriangleMesh m = icosphere(5, 0.3f, {0, 0, 0.5f});
  const int n = 200;
  const auto base = std::uint32_t(m.vertices.size());
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      m.vertices.emplace_back(-0.5f + float(i) / n, -0.5f + float(j) / n, 0.f);
      m.colors.push_back(colourAt(m.vertices.back()));
    }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const std::uint32_t a = base + j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      m.faces.push_back({a, b, d});
      m.faces.push_back({a, d, c});
    }
  return m;
}

// meshoptimizer's error is a collapse's area-weighted RMS distance to the merged faces' planes, not a
// bound on each of them: on this sphere the largest distance is 1.6-1.8x the target, the mean 0.26-0.30x.
TEST(MeshClean, QuadricSimplificationStaysNearItsErrorTarget) {
  const TriangleMesh ref = planeAndSphere();
  for (const double bound : {0.001, 0.004}) {
    TriangleMesh m = ref, full;
    MeshCleanParams p;
    p.max_simplify_error = bound;
    const MeshCleanReport r = cleanMesh(m, p, &full);
    ASSERT_TRUE(r.success) << r.failure;
    ASSERT_TRUE(r.simplification.ran);
    EXPECT_EQ(r.simplification.faces_before, ref.faces.size());
    EXPECT_EQ(r.simplification.faces_after, m.faces.size());
    EXPECT_EQ(full.faces.size(), ref.faces.size());  // the unsimplified mesh, as asked
    EXPECT_LT(m.faces.size(), ref.faces.size() / 10) << bound;  // the plane collapses to a few faces
    // Measured both ways (simplified -> original, original -> simplified), independently of the report.
    const MeshDistance there = meshDistance(m, ref), back = meshDistance(ref, m);
    EXPECT_LE(there.mean, 0.5 * bound) << bound;
    EXPECT_LE(back.mean, 0.5 * bound) << bound;
    EXPECT_LE(there.max, 2 * bound) << bound;
    EXPECT_LE(back.max, 2 * bound) << bound;
    EXPECT_LE(r.simplification.distance.max, 2 * bound);
    EXPECT_NEAR(r.simplification.distance.mean, there.mean, 0.2 * there.mean + 1e-6);
    EXPECT_GT(r.simplification.distance.samples, 10000u);
    // The sphere is curved: it keeps more of its faces with the tighter bound, and stays round.
    std::size_t sphere_vertices = 0;
    for (std::size_t i = 0; i < m.vertices.size(); ++i) {
      if (m.vertices[i].z() < 0.15f) continue;
      ++sphere_vertices;
      EXPECT_NEAR((m.vertices[i] - Eigen::Vector3f(0, 0, 0.5f)).norm(), 0.3f, 1e-6);  // vertices are kept, not moved
      for (int k = 0; k < 3; ++k) EXPECT_NEAR(m.colors[i][k], colourAt(m.vertices[i])[k], 12);
    }
    EXPECT_GT(sphere_vertices, bound < 0.002 ? 1000u : 100u) << bound;
  }
}

// A region's seam: its vertices on one border are locked and stay, bit for bit, so the neighbouring
// region welds to them; its other borders are not, and collapse along themselves.
TEST(MeshClean, QuadricSimplificationKeepsLockedVerticesOnly) {
  const int n = 40;
  TriangleMesh m;
  std::vector<std::uint8_t> locked;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      m.vertices.emplace_back(float(i) / n, float(j) / n, 0.f);
      m.colors.push_back({std::uint8_t(i), std::uint8_t(j), 0});
      locked.push_back(i == n);  // the right border is the seam
    }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const std::uint32_t a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      m.faces.push_back({a, b, d});
      m.faces.push_back({a, d, c});
    }
  const TriangleMesh before = m;
  ASSERT_TRUE(simplifyByQuadrics(m, 0.001, 0, locked));
  ASSERT_EQ(locked.size(), m.vertices.size());
  std::size_t seam = 0, left_border = 0;
  for (std::size_t v = 0; v < m.vertices.size(); ++v) {
    const Eigen::Vector3f& p = m.vertices[v];
    seam += locked[v] != 0;
    EXPECT_EQ(locked[v] != 0, p.x() == 1.f) << v;
    left_border += p.x() == 0.f;
    // Kept vertices keep their position and colour.
    EXPECT_EQ(m.colors[v][0], std::uint8_t(std::lround(p.x() * n)));
    EXPECT_EQ(m.colors[v][1], std::uint8_t(std::lround(p.y() * n)));
  }
  EXPECT_EQ(seam, std::size_t(n + 1));
  EXPECT_LE(left_border, 4u);  // the unlocked border collapsed along itself, to its corners
  EXPECT_LT(m.faces.size(), before.faces.size() / 10);
  EXPECT_NEAR(meshDistance(before, m).max, 0.0, 1e-6);  // a plane stays the plane
}

// Known answers: every point of a unit sphere is 0.1 from a sphere of radius 0.9 (the queries start
// from the last one's answer; a start that is not the nearest must not stick).
TEST(MeshClean, MeshDistanceIsTheDistanceToTheNearestSurface) {
  const TriangleMesh outer = icosphere(4), inner = icosphere(6, 0.9f);
  const MeshDistance d = meshDistance(outer, inner, 20000);
  EXPECT_EQ(d.samples, 20000u);
  // Both are flat-faced: a point mid-face on the outer one lies up to ~1 mm inside its radius, the
  // inner one's faces a few hundredths of a millimetre inside theirs.
  EXPECT_NEAR(d.mean, 0.1, 0.001);
  EXPECT_LT(d.max, 0.1 + 0.0002);
  // The same samples every time: CGAL 5.5's soup sampler drew from its default generator, which the
  // first call advanced, so a second call measured other points.
  const MeshDistance again = meshDistance(outer, inner, 20000);
  EXPECT_EQ(again.mean, d.mean);
  EXPECT_EQ(again.max, d.max);
}

// The grid search against CGAL's AABB tree: a fine sphere (marching cubes' small triangles), one
// large triangle across it, a degenerate segment and point; queries on, near, inside and far from it.
TEST(MeshClean, NearestTriangleFindsWhatCgalsAabbTreeFinds) {
  const TriangleMesh sphere = icosphere(4, 0.5f, Eigen::Vector3f(0.1f, -0.2f, 1.0f));
  std::vector<Eigen::Vector3d> points;
  for (const auto& v : sphere.vertices) points.push_back(v.cast<double>());
  std::vector<std::array<std::size_t, 3>> tris;
  for (const auto& f : sphere.faces) tris.push_back({f[0], f[1], f[2]});
  const std::size_t n = points.size();
  points.insert(points.end(), {{-2.0, 0.3, 0.4}, {2.5, 0.1, 1.9}, {0.2, 1.7, 0.8},    // large
                               {0.9, 0.9, 0.9}, {1.0, 1.1, 0.7},                        // segment
                               {-0.7, -0.9, 1.3}});                                     // point
  tris.push_back({n, n + 1, n + 2});
  tris.push_back({n + 3, n + 4, n + 4});
  tris.push_back({n + 5, n + 5, n + 5});
  const NearestTriangle grid(points, tris);

  using K = CGAL::Exact_predicates_inexact_constructions_kernel;
  std::vector<K::Triangle_3> cgal;
  const auto pt = [&](std::size_t i) { return K::Point_3(points[i].x(), points[i].y(), points[i].z()); };
  for (const auto& t : tris) cgal.emplace_back(pt(t[0]), pt(t[1]), pt(t[2]));
  using Primitive = CGAL::AABB_triangle_primitive<K, std::vector<K::Triangle_3>::const_iterator>;
  CGAL::AABB_tree<CGAL::AABB_traits<K, Primitive>> tree(cgal.cbegin(), cgal.cend());

  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::vector<Eigen::Vector3d> queries;
  for (int i = 0; i < 3000; ++i) {
    const Eigen::Vector3d on = points[std::size_t(rng() % n)];
    queries.push_back(on + 0.002 * Eigen::Vector3d(unit(rng), unit(rng), unit(rng)));  // near the surface
    queries.push_back(Eigen::Vector3d(0.1, -0.2, 1.0) + 3.0 * Eigen::Vector3d(unit(rng), unit(rng), unit(rng)));
  }
  queries.push_back({0.1, -0.2, 1.0});  // the centre, 0.5 m from the sphere
  queries.push_back({40.0, -30.0, 25.0});
  queries.push_back({0.95, 1.0, 0.8});
  std::size_t far = 0;
  for (const Eigen::Vector3d& q : queries) {
    const double expected = std::sqrt(tree.squared_distance(K::Point_3(q.x(), q.y(), q.z())));
    far += expected > 0.05;
    ASSERT_NEAR(grid.distance(q), expected, 1e-12) << "at " << q.transpose();
  }
  EXPECT_GT(far, 1000u);  // most of the box's queries are many cells from any triangle
  // The bounding spheres pass over triangles without changing what is found: the squared distance is
  // the smallest of every triangle's, to the last bit, here and with everything 10 km away (rounding
  // grows with the coordinates, the triangles stay small).
  const Eigen::Vector3d far_away(1e4, -2e4, 3e3);
  std::vector<Eigen::Vector3d> moved;
  for (const auto& v : points) moved.push_back(v + far_away);
  const NearestTriangle moved_grid(moved, tris);
  for (std::size_t i = 0; i < queries.size(); i += 3)
    for (const auto* set : {&points, &moved}) {
      const NearestTriangle& g = set == &points ? grid : moved_grid;
      const Eigen::Vector3d q = queries[i] + (set == &points ? Eigen::Vector3d::Zero() : far_away);
      double brute = std::numeric_limits<double>::infinity();
      for (const auto& t : tris)
        brute = std::min(brute, (closestPointOnTriangle(q, (*set)[t[0]], (*set)[t[1]], (*set)[t[2]]) - q).squaredNorm());
      ASSERT_EQ((g.closestPoint(q) - q).squaredNorm(), brute) << "at " << q.transpose();
    }
  EXPECT_TRUE(NearestTriangle({}, {}).empty());
}

// A few hundred long slivers across 200 000 small faces: at the small faces' cells every sliver was
// listed in all ~470 000 of them (560 MB here; a million faces gave ~4e9 listings, refused, and the
// cleaning failed over its distance measurement). The cells grow instead, and what is found is the same.
TEST(MeshClean, NearestTriangleTakesLongSliversAmongSmallFaces) {
  std::vector<Eigen::Vector3d> points;
  std::vector<std::array<std::size_t, 3>> tris;
  const int side = 317;  // 2 x 316^2 ~ 200 000 triangles on the unit square at z = 0
  for (int y = 0; y < side; ++y)
    for (int x = 0; x < side; ++x) points.emplace_back(x / double(side - 1), y / double(side - 1), 0.0);
  for (int y = 0; y + 1 < side; ++y)
    for (int x = 0; x + 1 < side; ++x) {
      const std::size_t a = std::size_t(y * side + x);
      tris.push_back({a, a + 1, a + side + 1});
      tris.push_back({a, a + side + 1, a + side});
    }
  for (int k = 0; k < 300; ++k) {  // across the unit cube, each a little turned
    const double t = k / 300.0;
    const std::size_t n = points.size();
    points.insert(points.end(), {{0.0, t, 0.0}, {1.0, 1.0 - t, 1.0}, {1.0, 1.0 - t + 0.001, 1.0}});
    tris.push_back({n, n + 1, n + 2});
  }
  std::optional<NearestTriangle> grid;
  {
    const ScopedAllocationLimit limit(std::size_t(256) << 20, std::size_t(256) << 20);
    ASSERT_NO_THROW(grid.emplace(points, tris));
  }
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> unit(-0.2, 1.2);
  for (int i = 0; i < 50; ++i) {
    const Eigen::Vector3d q(unit(rng), unit(rng), unit(rng));
    double brute = std::numeric_limits<double>::infinity();
    for (const auto& t : tris) brute = std::min(brute, (closestPointOnTriangle(q, points[t[0]], points[t[1]], points[t[2]]) - q).squaredNorm());
    ASSERT_EQ((grid->closestPoint(q) - q).squaredNorm(), brute) << "at " << q.transpose();
  }
}

TEST(MeshClean, FaceBudgetStillStopsErrorBoundedSimplification) {
  MeshCleanParams p;
  p.max_simplify_error = 0.5;  // m, on a unit sphere: far below 500 faces on its own
  TriangleMesh bound_only = icosphere(4);
  ASSERT_TRUE(cleanMesh(bound_only, p).success);
  ASSERT_LT(bound_only.faces.size(), 400u);
  p.target_faces = 500;  // whichever comes first: here the budget
  TriangleMesh m = icosphere(4);
  const MeshCleanReport r = cleanMesh(m, p);
  ASSERT_TRUE(r.success) << r.failure;
  EXPECT_LE(m.faces.size(), 550u);
  EXPECT_GE(m.faces.size(), 450u);
  EXPECT_TRUE(closedAndOriented(m));
}

TEST(MeshClean, EdgeLengthTargetNeedsLengthOrder) {
  mrpt::config::CConfigFileMemory ini;
  ini.write("mesh", "max_simplify_error", 0.006);
  ini.write("mesh", "target_edge_length", 0.02);
  MeshCleanParams p;
  try {
    p.loadFromConfigFile(ini, "mesh");
    ADD_FAILURE() << "no error";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("target_edge_length"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("max_simplify_error = 0"), std::string::npos) << e.what();
  }
  ini.write("mesh", "max_simplify_error", 0.0);
  p.loadFromConfigFile(ini, "mesh");
  EXPECT_DOUBLE_EQ(p.target_edge_length, 0.02);
}

TEST(MeshClean, SmoothingReducesNoise) {
  TriangleMesh m = icosphere(3);
  // Deterministic radial noise of +-3 %.
  for (std::size_t i = 0; i < m.vertices.size(); ++i) m.vertices[i] *= 1.f + 0.03f * std::sin(float(i) * 12.9898f) ;
  const auto radialSpread = [](const TriangleMesh& mm) {
    double s = 0, s2 = 0;
    for (const auto& v : mm.vertices) { s += v.norm(); s2 += v.squaredNorm(); }
    const double n = double(mm.vertices.size());
    return std::sqrt(std::max(0.0, s2 / n - (s / n) * (s / n)));
  };
  const double before = radialSpread(m);
  MeshCleanParams p;
  p.max_simplify_error = 0;  // smoothing alone
  p.smooth_iterations = 3;
  p.smooth_time = 1e-3;
  p.relax_iterations = 2;
  const MeshCleanReport r = cleanMesh(m, p);
  ASSERT_TRUE(r.success) << r.failure;
  EXPECT_LT(radialSpread(m), 0.5 * before);
  EXPECT_TRUE(closedAndOriented(m));
  EXPECT_EQ(r.steps.back().name, "smooth");
}

TEST(MeshClean, ParamsRoundTripThroughIni) {
  MeshCleanParams a;
  a.repair = false;
  a.weld_distance = 0.001;
  a.min_component_faces = 7;
  a.min_component_area = 0.25;
  a.max_hole_perimeter = 0.7;
  a.max_hole_edges = 33;
  a.hole_fairing = false;
  a.max_simplify_error = 0;
  a.target_faces = 1234;
  a.target_edge_length = 0.02;
  a.smooth_iterations = 4;
  a.smooth_time = 2e-4;
  a.relax_iterations = 5;
  a.orient_closed_outward = true;  // not the default: the round trip must carry it
  a.recompute_normals = false;
  mrpt::config::CConfigFileMemory ini;
  a.saveToConfigFile(ini, "mesh");
  MeshCleanParams b;
  b.loadFromConfigFile(ini, "mesh");
  EXPECT_EQ(b.repair, a.repair);
  EXPECT_DOUBLE_EQ(b.weld_distance, a.weld_distance);
  EXPECT_EQ(b.min_component_faces, a.min_component_faces);
  EXPECT_DOUBLE_EQ(b.min_component_area, a.min_component_area);
  EXPECT_DOUBLE_EQ(b.max_hole_perimeter, a.max_hole_perimeter);
  EXPECT_EQ(b.max_hole_edges, a.max_hole_edges);
  EXPECT_EQ(b.hole_fairing, a.hole_fairing);
  EXPECT_DOUBLE_EQ(b.max_simplify_error, a.max_simplify_error);
  EXPECT_EQ(b.target_faces, a.target_faces);
  EXPECT_DOUBLE_EQ(b.target_edge_length, a.target_edge_length);
  EXPECT_EQ(b.smooth_iterations, a.smooth_iterations);
  EXPECT_DOUBLE_EQ(b.smooth_time, a.smooth_time);
  EXPECT_EQ(b.relax_iterations, a.relax_iterations);
  EXPECT_EQ(b.orient_closed_outward, a.orient_closed_outward);
  EXPECT_EQ(b.recompute_normals, a.recompute_normals);
}

TEST(MeshClean, ReportJsonHasSteps) {
  TriangleMesh m = icosphere(1);
  const std::string j = cleanMesh(m, MeshCleanParams()).toJson();
  EXPECT_EQ(j.front(), '{');
  EXPECT_EQ(j.back(), '}');
  EXPECT_NE(j.find("\"success\": true"), std::string::npos) << j;
  EXPECT_NE(j.find("\"name\": \"repair\""), std::string::npos) << j;
  EXPECT_NE(j.find("\"closed\": true"), std::string::npos) << j;
}

TEST(MeshClean, SharedIniDocumentsEveryKeyWithItsDefault) {
  mrpt::config::CConfigFileMemory shipped;
  {
    std::ifstream f(test::shareDir() + "/mesh.ini");
    ASSERT_TRUE(f.good());
    shipped.setContent(std::string(std::istreambuf_iterator<char>(f), {}));
  }
  const MeshCleanParams defaults;
  mrpt::config::CConfigFileMemory dumped;
  defaults.saveToConfigFile(dumped, "mesh");
  std::vector<std::string> want, have;
  dumped.getAllKeys("mesh", want);
  shipped.getAllKeys("mesh", have);
  std::sort(want.begin(), want.end());
  std::sort(have.begin(), have.end());
  EXPECT_EQ(have, want);
  // As text: read as numbers, "true" and "false" were both 0 and a switch shipped wrong passed.
  for (const auto& k : want) EXPECT_EQ(shipped.read_string("mesh", k, "?"), dumped.read_string("mesh", k, "!")) << k;
}

namespace {
std::string fileText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}
}  // namespace

// A whole mesh's quadric collapse folds three faces onto an edge here and there; the soup it is rebuilt
// from cuts them off on corners of their own, and nothing joined them back: the synthetic room's whole
// mesh (8 frames at 320x240) kept 199 components and 196 border cycles, nearly all pieces of a few
// faces lying on the surface. They are judged as the welded regions are (by area), their holes filled.
// Only what the collapse cut off goes: a small closed part beside large faces (a 20 cm sphere on a 10 m
// floor of 128 faces) fell under the mean face's area and was removed whole (a review's case).
TEST(MeshClean, TheCollapsesCutOffsAreTheOnlyPiecesJudgedAfterIt) {
  TriangleMesh m = icosphere(4, 0.1f, Eigen::Vector3f(0.f, 0.f, 1.f));
  const std::size_t sphere_faces = m.faces.size();
  const int n = 8;
  const std::uint32_t base = std::uint32_t(m.vertices.size());
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) m.vertices.emplace_back(10.f * i / n - 5.f, 10.f * j / n - 5.f, 0.f);
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const std::uint32_t a = base + j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      m.faces.push_back({a, b, d});
      m.faces.push_back({a, d, c});
    }
  m.colors.assign(m.vertices.size(), {128, 128, 128});
  const MeshCleanReport r = cleanMesh(m, MeshCleanParams());
  ASSERT_TRUE(r.success) << r.failure;
  EXPECT_EQ(r.components_kept, 2u);
  EXPECT_EQ(r.components_removed, 0u);
  EXPECT_GT(m.faces.size(), sphere_faces / 20);  // the sphere, simplified, beside the floor
}

TEST(MeshCleanApp, AWholeMeshKeepsNoPiecesTheCollapseCutOff) {
  const std::string dir = test::tempDir("mesh_app_cut_offs");
  std::string log;
  ASSERT_EQ(test::run(test::app("rgbd-simulate") + " --out " + dir + "/s --frames 8 --size 320x240 2>&1", &log), 0) << log;
  std::ofstream(dir + "/whole.ini") << "[mesh]\nregion_bricks = 0\n[output]\nwrite_rawlog = false\n";
  ASSERT_EQ(test::run(test::app("vofusion") + " " + dir + "/s --out " + dir + "/o --config " + dir + "/whole.ini 2>&1", &log), 0)
      << log;
  std::ifstream in(dir + "/o/summary.json");
  const nlohmann::json clean = nlohmann::json::parse(in).at("mesh_clean");
  EXPECT_LE(clean.at("components_kept").get<int>(), 10) << clean.dump();
  EXPECT_LE(clean.at("border_cycles_after").get<int>(), 30) << clean.dump();
  EXPECT_EQ(clean.at("steps").back().at("name"), "cut-offs");
}

TEST(MeshCleanApp, CleansAPlyAndWritesAReport) {
  const std::string dir = test::tempDir("mesh_app");
  TriangleMesh m = icosphere(2, 0.2f);
  m.faces.erase(m.faces.begin());  // a one-triangle hole, ~0.19 m around: within the default bound
  writePly(dir + "/in.ply", m);
  std::ofstream(dir + "/keep.ini") << "[mesh]\nmax_simplify_error = 0\n";  // the face count below is the filled sphere's
  std::string out;
  ASSERT_EQ(test::run(test::app("vofusion-mesh") + " " + dir + "/in.ply " + dir + "/out.ply --config " + dir +
                          "/keep.ini --report " + dir + "/r.json --scene " + dir + "/s.3Dscene --png " + dir + "/m.png",
                      &out),
            0)
      << out;
  EXPECT_GT(std::filesystem::file_size(dir + "/s.3Dscene"), 1000u);
  EXPECT_GT(std::filesystem::file_size(dir + "/m.png"), 1000u);
  const TriangleMesh r = readPly(dir + "/out.ply");
  EXPECT_EQ(r.faces.size(), icosphere(2).faces.size());
  EXPECT_TRUE(closedAndOriented(r));
  EXPECT_EQ(r.colors.size(), r.vertices.size());
  std::ifstream j(dir + "/r.json");
  const std::string json((std::istreambuf_iterator<char>(j)), {});
  EXPECT_NE(json.find("\"holes_filled\": 1"), std::string::npos) << json;

  // Usage and input errors: exit 2 with a one-line message naming the file.
  EXPECT_EQ(test::run(test::app("vofusion-mesh") + " " + dir + "/in.ply", &out), 2);
  EXPECT_EQ(test::run(test::app("vofusion-mesh") + " " + dir + "/missing.ply " + dir + "/o.ply", &out), 2);
  EXPECT_NE(out.find("missing.ply: "), std::string::npos) << out;
  std::ofstream(dir + "/bad.ini") << "[mesh]\nmax_hole_perimetre = 1\n";
  EXPECT_EQ(test::run(test::app("vofusion-mesh") + " " + dir + "/in.ply " + dir + "/o.ply --config " + dir + "/bad.ini",
                      &out),
            2);
  EXPECT_NE(out.find("max_hole_perimetre"), std::string::npos) << out;
  // The other sections of a vofusion config are checked as vofusion checks them (before: only [mesh]).
  std::ofstream(dir + "/typo.ini") << "[mesh]\nmin_component_faces = 10\n[kinfu]\nvoxel_sise = 0.01\n";
  EXPECT_EQ(test::run(test::app("vofusion-mesh") + " " + dir + "/in.ply " + dir + "/o.ply --config " + dir + "/typo.ini",
                      &out),
            2);
  EXPECT_EQ(out, "vofusion-mesh: error: " + dir + "/typo.ini: unknown key 'voxel_sise' in section [kinfu]\n");
  // A point cloud has nothing to clean: one line, nothing written (before: an empty mesh, exit 0).
  TriangleMesh cloud = m;
  cloud.faces.clear();
  writePly(dir + "/cloud.ply", cloud);
  EXPECT_EQ(test::run(test::app("vofusion-mesh") + " " + dir + "/cloud.ply " + dir + "/o.ply", &out), 2);
  EXPECT_EQ(out, "vofusion-mesh: error: " + dir + "/cloud.ply: holds no faces (a point cloud?): nothing to clean\n");
  EXPECT_FALSE(std::filesystem::exists(dir + "/o.ply"));
  // Nor is it a surface to measure a distance to (it gave "mean 0 m, max 0 m", a perfect match).
  EXPECT_EQ(test::run(test::app("vofusion-mesh") + " " + dir + "/in.ply " + dir + "/o.ply --distance-to " + dir + "/cloud.ply",
                      &out),
            2);
  EXPECT_EQ(out, "vofusion-mesh: error: " + dir + "/cloud.ply: holds no faces (a point cloud?): no surface to measure "
                 "the distance to\n");
  EXPECT_FALSE(std::filesystem::exists(dir + "/o.ply"));
  // A camera path with nothing to draw it in was read and left unused.
  EXPECT_EQ(test::run(test::app("vofusion-mesh") + " " + dir + "/in.ply " + dir + "/o.ply --trajectory " + dir + "/t.txt", &out), 2);
  EXPECT_EQ(out, "vofusion-mesh: error: usage: --trajectory is drawn in --png or --scene: give one of them\n");
  // A vofusion-grab config's sensor section is not this app's to check, nor rawlog-grabber's key.
  std::ofstream(dir + "/grab.ini")
      << "[mesh]\nmin_component_faces = 10\nrawlog-grabber-ignore = true\n[OPENNI2]\ndriver = COpenNI2Sensor\n";
  EXPECT_EQ(test::run(test::app("vofusion-mesh") + " " + dir + "/in.ply " + dir + "/o.ply --config " + dir + "/grab.ini",
                      &out),
            0)
      << out;
  // Every face in fragments: the (empty) mesh is written, and a warning says why it is empty.
  TriangleMesh one = m;
  one.faces.resize(1);
  writePly(dir + "/one.ply", one);
  EXPECT_EQ(test::run(test::app("vofusion-mesh") + " " + dir + "/one.ply " + dir + "/o.ply", &out), 0) << out;
  EXPECT_EQ(out.rfind("warning: " + dir + "/one.ply: no face is left (fragments below [mesh] min_component_faces / " +
                          "min_component_area, degenerate or duplicate faces); " + dir + "/o.ply is empty\n", 0),
            0u) << out;
  // Cleaned in place to nothing: the input stays (it was replaced by the empty mesh, exit 0).
  const std::string one_before = fileText(dir + "/one.ply");
  EXPECT_EQ(test::run(test::app("vofusion-mesh") + " " + dir + "/one.ply " + dir + "/one.ply", &out), 2) << out;
  EXPECT_NE(out.find(dir + "/one.ply: no face is left"), std::string::npos) << out;
  EXPECT_NE(out.find("the input is kept"), std::string::npos) << out;
  EXPECT_EQ(fileText(dir + "/one.ply"), one_before);
  // Measured from nothing, the distance is none (it said mean 0, max 0: a perfect match).
  EXPECT_EQ(test::run(test::app("vofusion-mesh") + " " + dir + "/one.ply " + dir + "/o.ply --distance-to " + dir + "/in.ply",
                      &out),
            0)
      << out;
  EXPECT_NE(out.find("distance to " + dir + "/in.ply: none (the result has no face to measure from)"), std::string::npos)
      << out;
  // The outputs go into place together: one that cannot be written (a scene in a folder that is not
  // there) leaves the mesh already at out.ply as it was, and the error names the file asked for.
  // The report goes with them (it said success beside the earlier out.ply).
  std::ofstream(dir + "/r.json") << "an earlier report\n";
  const std::string before = fileText(dir + "/out.ply");
  EXPECT_EQ(test::run(test::app("vofusion-mesh") + " " + dir + "/in.ply " + dir + "/out.ply --report " + dir +
                          "/r.json --scene " + dir + "/no_such_folder/s.3Dscene",
                      &out),
            2)
      << out;
  EXPECT_EQ(out.rfind("vofusion-mesh: error: " + dir + "/no_such_folder/s.3Dscene: ", 0), 0u) << out;
  EXPECT_EQ(fileText(dir + "/out.ply"), before);
  EXPECT_EQ(fileText(dir + "/r.json"), "an earlier report\n");
  for (const auto& e : std::filesystem::directory_iterator(dir))
    EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << "left behind: " << e.path();
}

TEST(MeshClean, EmptyAndInvalidMeshes) {
  TriangleMesh empty;
  const MeshCleanReport r = cleanMesh(empty, MeshCleanParams());
  EXPECT_TRUE(r.success) << r.failure;
  EXPECT_TRUE(empty.faces.empty());
  EXPECT_FALSE(r.closed);

  TriangleMesh bad = icosphere(1);
  bad.faces.push_back({0, 1, 9999});
  const TriangleMesh before = bad;
  const MeshCleanReport rb = cleanMesh(bad, MeshCleanParams());
  EXPECT_FALSE(rb.success);
  EXPECT_NE(rb.failure.find("9999"), std::string::npos) << rb.failure;
  EXPECT_EQ(bad.faces, before.faces);  // left as given
}

TEST(MeshClean, ReportJsonWritesNonFiniteFiguresAsNull) {
  MeshCleanReport r;
  r.success = true;
  r.area = std::nan("");
  EXPECT_NE(r.toJson().find("\"area\": null"), std::string::npos) << r.toJson();
}

namespace {

// A flat sheet z = 0 over [x0, x1] x [0, 1] as a grid of `n` x `n` cells (columns at `xs` when given),
// its vertices at x == seam_x flagged as a seam: one region of a plane meshed region by region.
struct SheetRegion {
  TriangleMesh mesh;
  std::vector<std::uint8_t> seam;
};
SheetRegion sheetRegion(std::vector<float> xs, int n, float seam_x) {
  SheetRegion r;
  for (int j = 0; j <= n; ++j)
    for (const float x : xs) {
      r.mesh.vertices.emplace_back(x, float(j) / float(n), 0.f);
      r.mesh.colors.push_back({100, 100, 100});
      r.seam.push_back(x == seam_x);
    }
  const auto at = [&](std::size_t i, int j) { return std::uint32_t(std::size_t(j) * xs.size() + i); };
  for (int j = 0; j < n; ++j)
    for (std::size_t i = 0; i + 1 < xs.size(); ++i) {
      r.mesh.faces.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      r.mesh.faces.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  return r;
}
std::vector<float> columns(float x0, float x1, int n) {
  std::vector<float> xs;
  for (int i = 0; i <= n; ++i) xs.push_back(i == n ? x1 : x0 + (x1 - x0) * float(i) / float(n));
  return xs;
}
std::set<std::array<float, 3>> seamPoints(const SheetRegion& r) {
  std::set<std::array<float, 3>> p;
  for (std::size_t i = 0; i < r.seam.size(); ++i)
    if (r.seam[i]) p.insert({r.mesh.vertices[i].x(), r.mesh.vertices[i].y(), r.mesh.vertices[i].z()});
  return p;
}

}  // namespace

// Two regions of one plane simplified by edge length (CGAL's collapse) keep every seam vertex where
// it was, so they weld: Lindstrom-Turk placed collapsed seam vertices anywhere along the border, each
// region its own way (an open crack along every seam).
TEST(MeshClean, RegionsSimplifiedByEdgeLengthKeepTheirSeams) {
  SheetRegion a = sheetRegion(columns(0.f, 1.f, 20), 20, 1.f), b = sheetRegion(columns(1.f, 2.f, 20), 20, 1.f);
  const auto seam_before = seamPoints(a);
  ASSERT_EQ(seam_before.size(), 21u);
  ASSERT_EQ(seamPoints(b), seam_before);
  MeshCleanParams p;
  p.max_simplify_error = 0;
  p.target_edge_length = 0.2;
  p.min_component_faces = 0;
  for (SheetRegion* r : {&a, &b}) {
    const std::size_t faces = r->mesh.faces.size();
    const MeshCleanReport report = simplifyRegion(r->mesh, r->seam, p);
    ASSERT_TRUE(report.success) << report.failure;
    EXPECT_LT(r->mesh.faces.size(), faces / 2) << "simplified";
  }
  EXPECT_EQ(seamPoints(a), seam_before);
  EXPECT_EQ(seamPoints(b), seam_before);
}

// weld_distance merges nothing inside a region: a seam vertex merged onto an inner one 5 mm away left
// the seam (its neighbour's copy without a partner). The welded mesh is welded with the distance.
TEST(MeshClean, ARegionsSeamIsNotWeldedAwayByDistance) {
  std::vector<float> xs = columns(0.f, 1.f, 40);
  xs[39] = 0.995f;  // the last inner column 5 mm from the seam
  SheetRegion a = sheetRegion(xs, 40, 1.f);
  const auto seam_before = seamPoints(a);
  MeshCleanParams p;
  p.max_simplify_error = 0;
  p.weld_distance = 0.01;
  p.min_component_faces = 0;
  const MeshCleanReport report = simplifyRegion(a.mesh, a.seam, p);
  ASSERT_TRUE(report.success) << report.failure;
  EXPECT_EQ(seamPoints(a), seam_before);
}

// Memory that runs out for a region's copy costs that region (kept as marching cubes made it, the
// failure reported), as a CGAL failure does: the copy was made outside the catch, and failed the mesh.
TEST(MeshClean, ARegionThatCannotBeCopiedIsKeptAsItCame) {
  SheetRegion a = sheetRegion(columns(0.f, 1.f, 40), 40, 1.f);
  const TriangleMesh before = a.mesh;
  MeshCleanParams p;
  p.min_component_faces = 0;
  MeshCleanReport report;
  {
    const ScopedAllocationLimit limit(std::size_t(8) << 10, std::size_t(64) << 10);  // less than its 20 KB of vertices
    ASSERT_NO_THROW(report = simplifyRegion(a.mesh, a.seam, p));
  }
  EXPECT_FALSE(report.success);
  EXPECT_FALSE(report.failure.empty());
  EXPECT_EQ(a.mesh.vertices, before.vertices);
  EXPECT_EQ(a.mesh.faces, before.faces);
}

// A face naming a vertex past the end is refused before meshoptimizer reads it (it asserts, and Debian's
// build keeps its asserts: the process aborted), the mesh untouched. A region went to the quadric
// collapse before the repair's own check.
TEST(MeshClean, TheQuadricCollapseRefusesAFacePastItsVertices) {
  TriangleMesh m = icosphere(2);
  m.faces[5][1] = std::uint32_t(m.vertices.size());
  const TriangleMesh before = m;
  std::vector<std::uint8_t> locked;
  try {
    simplifyByQuadrics(m, 0.01, 0, locked);
    ADD_FAILURE() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_EQ(std::string(e.what()), "a face references vertex " + std::to_string(before.vertices.size()) + " of " +
                                         std::to_string(before.vertices.size()));
  }
  EXPECT_EQ(m.faces, before.faces);
}
