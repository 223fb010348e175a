// Mesh post-processing with CGAL PMP. All CGAL code of the project's mesh stage lives in this one
// unit (CGAL headers compile slowly).
#ifndef CGAL_EIGEN3_ENABLED
#define CGAL_EIGEN3_ENABLED 1  // Eigen sparse solvers for hole fairing and shape smoothing
#endif
#include "vofusion/mesh/mesh_clean.h"
#include "vofusion/core/parallel.h"
#include "vofusion/mesh/nearest_triangle.h"
#include "vofusion/mesh/quadric_simplify.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <set>
#include <type_traits>
#include <unordered_map>
#include <unordered_set>
#include <utility>

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/border.h>
#include <CGAL/Polygon_mesh_processing/compute_normal.h>
#include <CGAL/Polygon_mesh_processing/connected_components.h>
#include <CGAL/Polygon_mesh_processing/distance.h>
#include <CGAL/Polygon_mesh_processing/fair.h>
#include <CGAL/Polygon_mesh_processing/manifoldness.h>
#include <CGAL/Polygon_mesh_processing/measure.h>
#include <CGAL/Polygon_mesh_processing/orient_polygon_soup.h>
#include <CGAL/Polygon_mesh_processing/orientation.h>
#include <CGAL/Polygon_mesh_processing/polygon_soup_to_polygon_mesh.h>
#include <CGAL/Polygon_mesh_processing/repair.h>
#include <CGAL/Polygon_mesh_processing/repair_degeneracies.h>
#include <CGAL/Polygon_mesh_processing/repair_polygon_soup.h>
#include <CGAL/Polygon_mesh_processing/smooth_shape.h>
#include <CGAL/Polygon_mesh_processing/stitch_borders.h>
#include <CGAL/Polygon_mesh_processing/tangential_relaxation.h>
#include <CGAL/Polygon_mesh_processing/triangulate_hole.h>
#include <boost/container/small_vector.hpp>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Bounded_normal_change_placement.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/Edge_length_cost.h>
#include <CGAL/Surface_mesh_simplification/Policies/Edge_collapse/LindstromTurk_placement.h>
#include <CGAL/Surface_mesh_simplification/Edge_collapse_visitor_base.h>
#include <CGAL/Surface_mesh_simplification/edge_collapse.h>
#include <CGAL/boost/graph/helpers.h>

namespace PMP = CGAL::Polygon_mesh_processing;
namespace SMS = CGAL::Surface_mesh_simplification;

namespace vofusion {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;
using Mesh = CGAL::Surface_mesh<Point>;
using VD = Mesh::Vertex_index;
using FD = Mesh::Face_index;
using HD = Mesh::Halfedge_index;
using Rgb = std::array<std::uint8_t, 3>;

constexpr std::size_t kUnknownComponent = std::size_t(-1);

struct PointHash {
  std::size_t operator()(const Point& p) const {
    std::size_t h = 1469598103934665603ull;
    for (int i = 0; i < 3; ++i) {
      const double d = p[i];
      std::uint64_t b;
      std::memcpy(&b, &d, 8);
      h = (h ^ b) * 1099511628211ull;
    }
    return h;
  }
};

// Greedy welding of vertices closer than `dist`: each vertex maps to the first earlier
// representative within reach (hash grid with cell size `dist`, 27 neighbouring cells searched).
using Polygons = std::vector<boost::container::small_vector<std::size_t, 3>>;  // a soup's triangles, each in place

std::size_t weldSoup(std::vector<Point>& points, Polygons& polys, double dist) {
  struct CellHash {
    std::size_t operator()(const std::array<long long, 3>& c) const {
      return std::size_t(c[0] * 73856093ll ^ c[1] * 19349663ll ^ c[2] * 83492791ll);
    }
  };
  std::unordered_map<std::array<long long, 3>, std::vector<std::size_t>, CellHash> grid;
  std::vector<std::size_t> rep(points.size());
  const double d2 = dist * dist;
  std::size_t merged = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const std::array<long long, 3> c{(long long)std::floor(points[i].x() / dist), (long long)std::floor(points[i].y() / dist),
                                     (long long)std::floor(points[i].z() / dist)};
    rep[i] = i;
    for (int dx = -1; dx <= 1 && rep[i] == i; ++dx)
      for (int dy = -1; dy <= 1 && rep[i] == i; ++dy)
        for (int dz = -1; dz <= 1 && rep[i] == i; ++dz) {
          auto it = grid.find({c[0] + dx, c[1] + dy, c[2] + dz});
          if (it == grid.end()) continue;
          for (std::size_t j : it->second)
            if (CGAL::squared_distance(points[i], points[j]) <= d2) { rep[i] = j; break; }
        }
    if (rep[i] == i) grid[c].push_back(i);
    else ++merged;
  }
  for (auto& poly : polys)
    for (auto& v : poly) v = rep[v];
  return merged;  // welded points are left unreferenced; repair_polygon_soup drops them
}

// Vertices created by a step (hole patches) carry no colour yet: give each the mean colour of its
// coloured neighbours, layer by layer inwards from the patch border.
void propagateColours(Mesh& m, Mesh::Property_map<VD, Rgb> col, Mesh::Property_map<VD, bool> known) {
  for (bool changed = true; changed;) {
    changed = false;
    std::vector<std::pair<VD, Rgb>> layer;
    for (VD v : m.vertices()) {
      if (known[v]) continue;
      int sum[3] = {0, 0, 0}, n = 0;
      for (VD w : CGAL::vertices_around_target(m.halfedge(v), m))
        if (known[w]) {
          for (int k = 0; k < 3; ++k) sum[k] += col[w][k];
          ++n;
        }
      if (n) layer.push_back({v, Rgb{std::uint8_t(sum[0] / n), std::uint8_t(sum[1] / n), std::uint8_t(sum[2] / n)}});
    }
    for (const auto& [v, c] : layer) {
      col[v] = c;
      known[v] = true;
      changed = true;
    }
  }
}

// A vertex is non-manifold when the halfedges pointing at it form more than one umbrella.
// (PMP::is_non_manifold_vertex scans every halfedge of the mesh per call: quadratic over a mesh.)
std::size_t nonManifoldVertexCount(const Mesh& m) {
  std::vector<std::size_t> incoming(m.num_vertices(), 0);
  for (HD h : m.halfedges()) ++incoming[m.target(h)];
  std::size_t n = 0;
  for (VD v : m.vertices()) {
    std::size_t umbrella = 0, borders = 0;
    for (HD h : CGAL::halfedges_around_target(m.halfedge(v), m)) {
      ++umbrella;
      borders += m.is_border(h);
    }
    // Two border halfedges in one umbrella: two fans pinched at v.
    if (umbrella != incoming[v] || borders > 1) ++n;
  }
  return n;
}

std::size_t borderCycleCount(const Mesh& m) {
  std::vector<HD> cycles;
  PMP::extract_boundary_cycles(m, std::back_inserter(cycles));
  return cycles.size();
}

// Stops edge collapse (shortest edges first) at a face budget or once the shortest remaining edge
// reaches a length.
struct StopAtTarget {
  std::size_t target_edges = 0;  // 0: unused
  double min_sq_length = 0.0;    // m^2, 0: unused
  template <typename F, typename Profile>
  bool operator()(const F&, const Profile& profile, std::size_t, std::size_t current_edges) const {
    if (target_edges && current_edges <= target_edges) return true;
    return min_sq_length > 0 && CGAL::squared_distance(profile.p0(), profile.p1()) >= min_sq_length;
  }
};

// The colour of each position (the soup functions renumber points but keep their coordinates), as a
// sorted array: a third of a hash map's memory on the welded mesh, whose repair is a long run's peak.
// Positions are keyed by their bits, as PointHash keys them, and the first colour given for one wins,
// as a map's emplace.
class ColoursByPosition {
 public:
  ColoursByPosition(const std::vector<Point>& points, const std::vector<Rgb>& colours) {
    at_.reserve(std::min(points.size(), colours.size()));
    for (std::size_t i = 0; i < points.size() && i < colours.size(); ++i) at_.push_back({bitsOf(points[i]), colours[i]});
    std::stable_sort(at_.begin(), at_.end(), [](const Entry& a, const Entry& b) { return a.bits < b.bits; });
  }
  const Rgb* find(const Point& p) const {
    const Bits b = bitsOf(p);
    const auto it = std::lower_bound(at_.begin(), at_.end(), b, [](const Entry& e, const Bits& k) { return e.bits < k; });
    return it != at_.end() && it->bits == b ? &it->colour : nullptr;
  }

 private:
  using Bits = std::array<std::uint64_t, 3>;
  struct Entry {
    Bits bits;
    Rgb colour;
  };
  static Bits bitsOf(const Point& p) {
    Bits b;
    for (int i = 0; i < 3; ++i) {
      const double d = p[i];
      std::memcpy(&b[std::size_t(i)], &d, 8);
    }
    return b;
  }
  std::vector<Entry> at_;
};

// A triangle soup: distances are measured on soups, so any mesh (non-manifold too) can be compared.
struct Soup {
  std::vector<Point> points;
  std::vector<std::array<std::size_t, 3>> triangles;
};

Soup soupOf(const Mesh& m) {
  Soup s;
  s.points.reserve(m.num_vertices());
  for (std::size_t i = 0; i < m.num_vertices(); ++i) s.points.push_back(m.point(VD(i)));  // removed ones unreferenced
  for (FD f : m.faces()) {
    const HD h = m.halfedge(f);
    s.triangles.push_back({m.source(h).idx(), m.target(h).idx(), m.target(m.next(h)).idx()});
  }
  return s;
}

Soup soupOf(const TriangleMesh& m) {
  Soup s;
  for (const auto& v : m.vertices) s.points.emplace_back(v.x(), v.y(), v.z());
  checkFaceIndices(m);
  for (const auto& f : m.faces) s.triangles.push_back({f[0], f[1], f[2]});
  return s;
}

// `samples` points uniformly by area on the soup's faces, the same for the same soup: CGAL 5.5's
// sample_triangle_soup draws the point inside each face from the thread's default generator, not
// the seeded one, so its samples, and the distances reported, varied from run to run with the
// order TBB gave regions to threads (rpy_first100: max 6.2-7.3 mm).
std::vector<Eigen::Vector3d> samplesByArea(const Soup& soup, std::size_t samples) {
  std::vector<double> cumulative;
  cumulative.reserve(soup.triangles.size());
  double total = 0.0;
  std::size_t last_with_area = 0;  // where a pick rounded up to `total` lands
  for (const auto& t : soup.triangles) {
    const Point &a = soup.points[t[0]], &b = soup.points[t[1]], &c = soup.points[t[2]];
    const double area = std::sqrt(CGAL::squared_area(a, b, c));
    if (std::isfinite(area) && area > 0) total += area, last_with_area = cumulative.size();
    cumulative.push_back(total);
  }
  std::vector<Eigen::Vector3d> out;
  if (!(total > 0)) return out;
  out.reserve(samples);
  std::mt19937_64 rng(20240615u);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const auto at = [&](std::size_t i) { return Eigen::Vector3d(soup.points[i].x(), soup.points[i].y(), soup.points[i].z()); };
  for (std::size_t n = 0; n < samples; ++n) {
    const double pick = unit(rng) * total;
    const auto it = std::upper_bound(cumulative.begin(), cumulative.end(), pick);
    const std::size_t f = it == cumulative.end() ? last_with_area : std::size_t(it - cumulative.begin());
    const double s = std::sqrt(unit(rng)), r = unit(rng);  // uniform on the triangle
    const auto& t = soup.triangles[f];
    out.push_back((1.0 - s) * at(t[0]) + s * (1.0 - r) * at(t[1]) + s * r * at(t[2]));
  }
  return out;
}

// The points' indices in Morton order of 1 cm cells: queries in that order read the same grid cells and
// triangles one after another, where the samples' own (random) order missed the cache on most of them.
std::vector<std::uint32_t> spaceOrder(const std::vector<Eigen::Vector3d>& points) {
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::max());
  for (const auto& p : points) lo = lo.cwiseMin(p);
  const auto spread = [](std::uint64_t v) {  // 21 bits, two zeros between each
    v &= 0x1fffff;
    v = (v | v << 32) & 0x1f00000000ffffull;
    v = (v | v << 16) & 0x1f0000ff0000ffull;
    v = (v | v << 8) & 0x100f00f00f00f00full;
    v = (v | v << 4) & 0x10c30c30c30c30c3ull;
    v = (v | v << 2) & 0x1249249249249249ull;
    return v;
  };
  std::vector<std::pair<std::uint64_t, std::uint32_t>> keyed(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector3d q = (points[i] - lo) * 100.0;  // 1 cm cells; beyond 21 km a side the order only gets worse
    const auto cell = [&](int k) { return !(q[k] > 0) ? std::uint64_t(0) : std::uint64_t(std::min(q[k], double(0x1fffff))); };
    keyed[i] = {spread(cell(0)) | spread(cell(1)) << 1 | spread(cell(2)) << 2, std::uint32_t(i)};
  }
  std::sort(keyed.begin(), keyed.end());
  std::vector<std::uint32_t> order(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) order[i] = keyed[i].second;
  return order;
}

// Mean and max distance from points sampled uniformly by area on `from`'s faces to `to`'s surface.
MeshDistance distanceBetween(const Soup& from, const Soup& to, std::size_t samples) {
  MeshDistance d;
  if (from.triangles.empty() || to.triangles.empty() || samples == 0) return d;
  const std::vector<Eigen::Vector3d> points = samplesByArea(from, samples);
  std::vector<Eigen::Vector3d> to_points;
  to_points.reserve(to.points.size());
  for (const Point& q : to.points) to_points.emplace_back(q.x(), q.y(), q.z());
  const NearestTriangle surface(to_points, to.triangles);
  if (surface.empty()) return d;
  // Queried on every core (the last region's distance held the end's meshing on one), summed in
  // order: the same mean to the last bit as one core gives.
  std::vector<double> e(points.size());
  const std::vector<std::uint32_t> order = spaceOrder(points);
  parallelFor(0, int(points.size()), [&](int k) { e[order[k]] = surface.distance(points[order[k]]); }, 1024);
  double sum = 0.0;
  for (const double x : e) {
    sum += x;
    d.max = std::max(d.max, x);
  }
  d.samples = points.size();
  d.mean = points.empty() ? 0.0 : sum / double(points.size());
  return d;
}

// Gives the vertex that survives an edge collapse the mean colour of the edge's two ends, or, when
// one end is fixed (a seam vertex), that end's colour and fixedness (whichever vertex CGAL keeps).
struct BlendColoursOnCollapse : SMS::Edge_collapse_visitor_base<Mesh> {
  Mesh::Property_map<VD, Rgb> col;
  Mesh::Property_map<VD, bool> fixed;  // null map: no fixed vertices
  Rgb pending{};
  bool pending_fixed = false;
  BlendColoursOnCollapse(Mesh::Property_map<VD, Rgb> c, Mesh::Property_map<VD, bool> f) : col(c), fixed(f) {}
  template <typename Profile, typename Placement>
  void OnCollapsing(const Profile& prof, const Placement&) {
    const bool f0 = fixed && fixed[prof.v0()], f1 = fixed && fixed[prof.v1()];
    pending_fixed = f0 || f1;
    if (pending_fixed) pending = col[f0 ? prof.v0() : prof.v1()];
    else
      for (int k = 0; k < 3; ++k) pending[k] = std::uint8_t((int(col[prof.v0()][k]) + int(col[prof.v1()][k]) + 1) / 2);
  }
  template <typename Profile>
  void OnCollapsed(const Profile&, VD kept) {
    col[kept] = pending;
    if (fixed) fixed[kept] = pending_fixed;
  }
};

// A region's seam vertex stays where it is (the neighbouring region has it there too, and the two weld
// by position): an edge with one fixed end collapses onto that end, one with both is not collapsed.
template <class BasePlacement>
struct KeepFixedPlacement {
  BasePlacement base;
  Mesh::Property_map<VD, bool> fixed;
  template <typename Profile>
  boost::optional<typename Profile::Point> operator()(const Profile& profile) const {
    const bool f0 = fixed[profile.v0()], f1 = fixed[profile.v1()];
    if (f0 && f1) return boost::none;
    if (f0) return profile.p0();
    if (f1) return profile.p1();
    return base(profile);
  }
};

class Cleaner {
 public:
  // What the input is: any soup, or regions repaired each on its own and welded at their seams.
  enum class Input { Soup, WeldedRegions };
  static constexpr std::size_t kDistanceSamples = 100000;

  // What a run is asked for beside the parameters.
  struct Job {
    Input input = Input::Soup;
    TriangleMesh* unsimplified = nullptr;       // gets the mesh as simplification found it
    std::vector<std::uint8_t>* seam = nullptr;  // a region's seam flags: those vertices stay, no hole is filled
    std::size_t distance_samples = kDistanceSamples;  // of the simplification's distance
  };

  Cleaner(const MeshCleanParams& p, MeshCleanReport& r, const Job& job)
      : p_(p), r_(r), job_(job) {}

  void run(TriangleMesh& in) {
    has_colours_ = !in.colors.empty() && in.colors.size() == in.vertices.size();
    checkFaceIndices(in);
    step("repair", [&] { buildRepaired(in); });
    if (p_.min_component_faces > 0 || p_.min_component_area > 0) step("components", [&] { removeSmallComponents(); });
    // A region's holes may run into its neighbours: they are filled once the regions are welded.
    if (!job_.seam && p_.max_hole_perimeter > 0 && p_.max_hole_edges > 0) step("holes", [&] { fillHoles(); });
    const bool simplifying = p_.max_simplify_error > 0 || p_.target_faces > 0 || p_.target_edge_length > 0;
    Mesh before;  // the mesh as simplification found it: measured against, and `unsimplified`
    if (simplifying || job_.unsimplified) before = m_;
    if (simplifying) step("simplify", [&] { simplifyAndMeasure(before); });
    // A whole mesh's quadric collapse can fold three faces onto one edge, and the soup it is rebuilt from
    // cuts them off on corners of their own (the room's 562k raw faces: 276 pieces of 1-8 faces left on
    // the surface, 595 positions held twice). Those pieces are judged as the welded regions are (by area,
    // against half of min_component_faces raw faces), and the holes they leave filled.
    if (judgesCutOffs() && before.number_of_faces() > 0)
      step("cut-offs", [&] { removeCutOffs(PMP::area(before) / double(before.number_of_faces())); });
    if (!job_.seam && (p_.smooth_iterations > 0 || p_.relax_iterations > 0)) step("smooth", [&] { smooth(); });
    finish(m_);
    if (job_.unsimplified) {
      finish(before);
      *job_.unsimplified = toTriangleMesh(before);
    }
    r_.border_cycles_after = borderCycleCount(m_);
    {
      auto fcc = m_.add_property_map<FD, std::size_t>("f:cc_final", 0).first;
      r_.components_kept = m_.is_empty() ? 0 : PMP::connected_components(m_, fcc);
      m_.remove_property_map(fcc);
    }
    r_.closed = r_.border_cycles_after == 0 && m_.number_of_faces() > 0;  // points alone close nothing
    r_.manifold = nonManifoldVertexCount(m_) == 0;
    r_.area = m_.is_empty() ? 0.0 : PMP::area(m_);
    in = toTriangleMesh(m_);  // last but the seam flags: until here `in` is the caller's input (cleanMesh)
    if (job_.seam) {
      job_.seam->clear();
      for (VD v : m_.vertices()) job_.seam->push_back(fixed_[v]);
    }
  }

 private:
  template <typename F>
  void step(const char* name, F&& f) {
    MeshCleanStep s;
    s.name = name;
    if (!r_.steps.empty()) {
      s.vertices_before = m_.number_of_vertices();
      s.faces_before = m_.number_of_faces();
    }
    const auto t0 = std::chrono::steady_clock::now();
    f();
    s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    s.vertices_after = m_.number_of_vertices();
    s.faces_after = m_.number_of_faces();
    if (r_.steps.empty()) {
      s.vertices_before = input_vertices_;
      s.faces_before = input_faces_;
    }
    r_.steps.push_back(s);
  }

  void buildRepaired(const TriangleMesh& in) {
    input_vertices_ = in.vertices.size();
    input_faces_ = in.faces.size();
    // Welding by distance needs the soup.
    if (job_.input == Input::WeldedRegions && p_.repair && p_.weld_distance <= 0) buildFaceByFace(in);
    else buildFromSoup(in);
    if (!p_.repair) return;
    r_.border_edges_stitched += PMP::stitch_borders(m_);
    const std::size_t faces_before = m_.number_of_faces();
    PMP::remove_degenerate_faces(m_);  // zero-area triangles (collinear or coincident corners)
    m_.collect_garbage();
    r_.degenerate_faces_removed += faces_before - m_.number_of_faces();
    r_.non_manifold_vertices_split += splitNonManifoldVertices();
    PMP::remove_isolated_vertices(m_);
    m_.collect_garbage();
  }

  // Regions repaired each on their own and welded at their seams (meshByRegion) form a mesh but where
  // regions meet, so their faces go in one by one without a polygon soup: CGAL's soup orienter was
  // the welded repair's peak (loop scene at 640x480: 313 of 592 MB of heap, docs/mesh.md). A face the
  // mesh refuses repeats a corner or another face (dropped), or would make an edge or a vertex
  // non-manifold: it goes in on corners of its own, cut off as orient_polygon_soup cuts it off, and
  // stitch_borders joins it back where the mesh stays manifold (three corners rather than one: faces
  // and area nearer the soup repair's on the loop scene, docs/mesh.md).
  void buildFaceByFace(const TriangleMesh& in) {
    col_ = m_.add_property_map<VD, Rgb>("v:rgb", Rgb{128, 128, 128}).first;
    known_ = m_.add_property_map<VD, bool>("v:rgb_known", false).first;  // vertices made later take colours from these
    m_.reserve(Mesh::size_type(in.vertices.size()), Mesh::size_type(in.faces.size() * 3 / 2 + 3),
               Mesh::size_type(in.faces.size()));
    for (std::size_t i = 0; i < in.vertices.size(); ++i) {
      const Eigen::Vector3f& v = in.vertices[i];
      const VD d = m_.add_vertex(Point(v.x(), v.y(), v.z()));  // d.idx() == i
      if (has_colours_) col_[d] = in.colors[i];
      known_[d] = true;
    }
    std::set<std::array<std::uint32_t, 3>> cut_off;  // refused faces' corners, sorted: their repeats too are repeats
    for (const auto& f : in.faces) {
      const std::array<VD, 3> corners{VD(f[0]), VD(f[1]), VD(f[2])};
      if (corners[0] == corners[1] || corners[1] == corners[2] || corners[0] == corners[2]) {
        ++r_.degenerate_faces_removed;
        continue;
      }
      // Looked for first: a repeat the other way round would go in, closing a two-face pillow.
      if (hasFace(corners)) {
        ++r_.duplicate_faces_removed;
        continue;
      }
      if (m_.add_face(corners[0], corners[1], corners[2]) != Mesh::null_face()) continue;
      std::array<std::uint32_t, 3> sorted = f;
      std::sort(sorted.begin(), sorted.end());
      if (!cut_off.insert(sorted).second) ++r_.duplicate_faces_removed;
      else r_.non_manifold_vertices_split += addOnOwnCorners(corners);
    }
    PMP::remove_isolated_vertices(m_);  // corners no face kept
    m_.collect_garbage();
    // Stitching and the degeneracy repair need a valid polygon mesh: one fan of faces per vertex.
    r_.non_manifold_vertices_split += splitNonManifoldVertices();
  }

  // CGAL's split of vertices with more than one fan of faces, each copy in its vertex's colour and,
  // in a region, on the seam when its vertex is (so the welder joins it to the neighbour's).
  std::size_t splitNonManifoldVertices() {
    std::vector<std::vector<VD>> groups;  // a vertex, then its copies
    const std::size_t n =
        PMP::duplicate_non_manifold_vertices(m_, CGAL::parameters::output_iterator(std::back_inserter(groups)));
    for (const auto& g : groups)
      for (VD v : g) {
        col_[v] = col_[g.front()];
        known_[v] = known_[g.front()];
        if (job_.seam) fixed_[v] = fixed_[g.front()];
      }
    return n;
  }

  // A face on these corners already, in either orientation.
  bool hasFace(const std::array<VD, 3>& c) const {
    const HD h = m_.halfedge(c[0], c[1]);
    if (h == Mesh::null_halfedge()) return false;
    for (HD e : {h, m_.opposite(h)})
      if (!m_.is_border(e) && m_.target(m_.next(e)) == c[2]) return true;
    return false;
  }

  // Adds the face on corners of its own, cut off as the soup repair cuts it off; returns the copies.
  std::size_t addOnOwnCorners(std::array<VD, 3> c) {
    for (VD& v : c) {
      const Point at = m_.point(v);  // a copy: add_vertex may move the points
      const Rgb colour = col_[v];
      v = m_.add_vertex(at);
      col_[v] = colour;
      known_[v] = true;
    }
    m_.add_face(c[0], c[1], c[2]);
    return 3;
  }

  void buildFromSoup(const TriangleMesh& in) {
    std::vector<Point> pts;
    pts.reserve(in.vertices.size());
    for (const auto& v : in.vertices) pts.emplace_back(v.x(), v.y(), v.z());
    // Triangles held in place (no allocation each): the welded mesh's soup is a long run's peak.
    Polygons polys;
    polys.reserve(in.faces.size());
    for (const auto& f : in.faces) polys.push_back({f[0], f[1], f[2]});
    // Colours travel by position: the soup functions renumber points but keep their coordinates.
    static const std::vector<Rgb> kNoColours;
    const ColoursByPosition colour_at(pts, has_colours_ ? in.colors : kNoColours);
    std::unordered_set<Point, PointHash> fixed_at;  // seam vertices, by position too
    if (job_.seam)
      for (std::size_t i = 0; i < pts.size() && i < job_.seam->size(); ++i)
        if ((*job_.seam)[i]) fixed_at.insert(pts[i]);

    if (p_.repair) {
      if (p_.weld_distance > 0) r_.duplicate_vertices_merged += weldSoup(pts, polys, p_.weld_distance);
      r_.duplicate_vertices_merged += PMP::merge_duplicate_points_in_polygon_soup(pts, polys);
      // Faces that repeat a vertex (e.g. after welding) are degenerate.
      const std::size_t n_polys = polys.size();
      polys.erase(std::remove_if(polys.begin(), polys.end(),
                                 [](const auto& f) { return f[0] == f[1] || f[1] == f[2] || f[0] == f[2]; }),
                  polys.end());
      r_.degenerate_faces_removed += n_polys - polys.size();
      r_.duplicate_faces_removed += PMP::merge_duplicate_polygons_in_polygon_soup(pts, polys);
      PMP::repair_polygon_soup(pts, polys);  // drops isolated points and anything left invalid
      // Consistent orientation; points at non-manifold spots are duplicated so the result is manifold.
      const std::size_t before = pts.size();
      PMP::orient_polygon_soup(pts, polys);
      r_.non_manifold_vertices_split += pts.size() - before;
    } else if (!PMP::is_polygon_soup_a_polygon_mesh(polys)) {
      // The conversion's own check is compiled out in a release build, and it then drops the faces it
      // cannot place (three on one edge, a face turned against its neighbours) and says nothing.
      throw std::runtime_error("the mesh has non-manifold or inconsistently oriented faces: [mesh] repair = true mends them");
    }
    PMP::polygon_soup_to_polygon_mesh(pts, polys, m_);
    col_ = m_.add_property_map<VD, Rgb>("v:rgb", Rgb{128, 128, 128}).first;
    known_ = m_.add_property_map<VD, bool>("v:rgb_known", false).first;
    // Not repaired, the soup's points are the mesh's vertices in order: each keeps its own colour (copies
    // at one position, a colour seam, were all painted the first one's). Repaired, they went by position.
    const bool in_order = !p_.repair && has_colours_ && m_.number_of_vertices() == in.colors.size() &&
                          std::all_of(m_.vertices().begin(), m_.vertices().end(),
                                      [&](VD v) { return m_.point(v) == pts[v.idx()]; });
    for (VD v : m_.vertices()) {
      if (in_order) col_[v] = in.colors[v.idx()];
      else if (const Rgb* c = colour_at.find(m_.point(v))) col_[v] = *c;
      known_[v] = true;
    }
    if (job_.seam) {
      fixed_ = m_.add_property_map<VD, bool>("v:fixed_seam", false).first;
      for (VD v : m_.vertices()) fixed_[v] = fixed_at.count(m_.point(v)) > 0;
    }
    // Not repaired, points no face uses came along (the repair drops them): no surface, and a normal of
    // zero in the output.
    if (!p_.repair && PMP::remove_isolated_vertices(m_) > 0) m_.collect_garbage();
  }

  // Whether the cut-offs step runs: after a whole mesh's quadric collapse, fragments being judged.
  bool judgesCutOffs() const { return p_.max_simplify_error > 0 && !job_.seam && p_.min_component_faces > 0; }

  // Pieces the collapse split off a component (every piece of it but the largest) with less area than
  // half of min_component_faces raw faces; then the holes their removal opened are filled, no other (the
  // holes step judged those). A component the collapse left whole stays, however small: a 10 cm sphere
  // beside large faces fell under the mean face's area and went whole.
  void removeCutOffs(double mean_raw_face_area) {
    auto [origin, have_origin] = m_.property_map<VD, std::size_t>("v:origin");
    if (!have_origin) return;
    const double min_area = std::max(p_.min_component_area, 0.5 * p_.min_component_faces * mean_raw_face_area);
    auto fcc = m_.add_property_map<FD, std::size_t>("f:cc", 0).first;
    const std::size_t n = PMP::connected_components(m_, fcc);
    std::vector<double> area(n, 0.0);
    std::vector<std::size_t> from(n, kUnknownComponent);  // the component before the collapse
    for (FD f : m_.faces()) {
      area[fcc[f]] += PMP::face_area(f, m_);
      for (VD v : CGAL::vertices_around_face(m_.halfedge(f), m_))
        if (from[fcc[f]] == kUnknownComponent) from[fcc[f]] = origin[v];
    }
    std::unordered_map<std::size_t, std::size_t> largest;  // per component before: its largest piece now
    for (std::size_t c = 0; c < n; ++c)
      if (from[c] != kUnknownComponent) {
        const auto [it, added] = largest.emplace(from[c], c);
        if (!added && area[c] > area[it->second]) it->second = c;
      }
    std::vector<std::size_t> drop;
    std::vector<bool> dropped(n, false);
    for (std::size_t c = 0; c < n; ++c)
      if (from[c] != kUnknownComponent && largest.at(from[c]) != c && area[c] < min_area) drop.push_back(c), dropped[c] = true;
    std::unordered_set<Point, PointHash> corners;  // of the pieces dropped: where a hole may open
    for (FD f : m_.faces())
      if (dropped[fcc[f]])
        for (VD v : CGAL::vertices_around_face(m_.halfedge(f), m_)) corners.insert(m_.point(v));
    if (!drop.empty()) PMP::remove_connected_components(m_, drop, fcc);
    m_.remove_property_map(fcc);
    m_.remove_property_map(origin);
    PMP::remove_isolated_vertices(m_);
    m_.collect_garbage();
    r_.components_removed += drop.size();
    if (!corners.empty() && p_.max_hole_perimeter > 0 && p_.max_hole_edges > 0) fillHoles(&corners);
  }

  void removeSmallComponents() {
    auto fcc = m_.add_property_map<FD, std::size_t>("f:cc", 0).first;
    const std::size_t n = PMP::connected_components(m_, fcc);
    std::vector<std::size_t> faces(n, 0);
    std::vector<double> area(n, 0.0);
    std::vector<bool> on_seam(n, false);  // continues in another region: judged there, not here
    for (FD f : m_.faces()) {
      ++faces[fcc[f]];
      area[fcc[f]] += PMP::face_area(f, m_);
      if (job_.seam)
        for (VD v : CGAL::vertices_around_face(m_.halfedge(f), m_)) on_seam[fcc[f]] = on_seam[fcc[f]] || fixed_[v];
    }
    std::vector<std::size_t> drop;
    for (std::size_t c = 0; c < n; ++c)
      if (!on_seam[c] && ((p_.min_component_faces > 0 && faces[c] < std::size_t(p_.min_component_faces)) ||
                          (p_.min_component_area > 0 && area[c] < p_.min_component_area)))
        drop.push_back(c);
    if (!drop.empty()) PMP::remove_connected_components(m_, drop, fcc);
    m_.remove_property_map(fcc);
    PMP::remove_isolated_vertices(m_);
    m_.collect_garbage();
    r_.components_removed += drop.size();
  }

  // Per connected component: its border cycles and its area; `component` maps each face to its own.
  struct Pieces {
    std::vector<std::size_t> borders;
    std::vector<double> area;
  };
  Pieces piecesOf(const std::vector<HD>& cycles, Mesh::Property_map<FD, std::size_t> component) const {
    Pieces p;
    const std::size_t n = PMP::connected_components(m_, component);
    p.borders.assign(n, 0);
    p.area.assign(n, 0.0);
    for (FD f : m_.faces()) p.area[component[f]] += PMP::face_area(f, m_);
    for (HD start : cycles) ++p.borders[component[m_.face(m_.opposite(start))]];
    return p;
  }

  static constexpr std::size_t kFullSearchEdges = 200;
  // only_at: the border cycles through one of these positions only (the rest left as they are, uncounted).
  void fillHoles(const std::unordered_set<Point, PointHash>* only_at = nullptr) {
    std::vector<HD> cycles;
    PMP::extract_boundary_cycles(m_, std::back_inserter(cycles));
    if (only_at) {
      const auto touches = [&](HD start) {
        for (HD h : CGAL::halfedges_around_face(start, m_))
          if (only_at->count(m_.point(m_.target(h)))) return true;
        return false;
      };
      cycles.erase(std::remove_if(cycles.begin(), cycles.end(), [&](HD h) { return !touches(h); }), cycles.end());
    }
    auto component = m_.add_property_map<FD, std::size_t>("f:cc_holes", 0).first;
    const Pieces pieces = piecesOf(cycles, component);
    std::vector<std::pair<HD, std::size_t>> holes;  // border cycle, edges
    for (HD start : cycles) {
      double perimeter = 0.0;
      std::size_t edges = 0;
      HD h = start;
      do {
        perimeter += std::sqrt(CGAL::squared_distance(m_.point(m_.source(h)), m_.point(m_.target(h))));
        ++edges;
        h = m_.next(h);
      } while (h != start && edges <= std::size_t(p_.max_hole_edges));
      if (edges > std::size_t(p_.max_hole_edges) || perimeter > p_.max_hole_perimeter) {
        ++r_.holes_left;
        continue;
      }
      // A piece whose only border could enclose all of it (the largest area a curve of that length
      // encloses, a disc's) is bounded by it: an outline, not a hole. Filled, it became a second sheet
      // over the piece, facing the other way.
      const std::size_t c = component[m_.face(m_.opposite(start))];
      if (pieces.borders[c] == 1 && pieces.area[c] <= perimeter * perimeter / (4.0 * M_PI)) {
        ++r_.holes_left;
        continue;
      }
      holes.emplace_back(start, edges);
    }
    m_.remove_property_map(component);
    for (const auto& [start, edges] : holes) {
      std::vector<FD> new_faces;
      std::vector<VD> new_vertices;
      // CGAL's full search of the patch, not the one restricted to the 3D Delaunay triangulation of the
      // border: the restricted search gave different patches for the same mesh from run to run, on a
      // border with coincident corners (a vertex split where the mesh was non-manifold; loop scene, 300
      // frames: 2 of 3 pairs of runs differed in one hole; the full search: 4 runs byte-identical, the
      // holes step 0.39 -> 0.31 s). Why it varies was not found in CGAL's code. The full search costs
      // ~n^3/6 patch weights: above kFullSearchEdges (the default max_hole_edges) the restricted one.
      PMP::triangulate_and_refine_hole(m_, start, std::back_inserter(new_faces), std::back_inserter(new_vertices),
                                       CGAL::parameters::use_delaunay_triangulation(edges > kFullSearchEdges));
      if (p_.hole_fairing) fairPatch(new_vertices);
      if (new_faces.empty()) ++r_.holes_left;
      else ++r_.holes_filled;
    }
    propagateColours(m_, col_, known_);
  }

  // CGAL's fairing, as triangulate_refine_and_fair_hole runs it after refining (meshes byte-identical
  // on both shared sequences). It can fail or return non-finite points: on the loop scene with repair
  // off, 1 of 7594 patches came back with 7 NaN vertices. Such a patch stays flat, as refined.
  void fairPatch(const std::vector<VD>& patch) {
    if (patch.empty()) return;
    std::vector<Point> refined;
    for (VD v : patch) refined.push_back(m_.point(v));
    const bool faired = PMP::fair(m_, patch);
    const auto finite = [&](VD v) {
      const Point& q = m_.point(v);
      return std::isfinite(q.x()) && std::isfinite(q.y()) && std::isfinite(q.z());
    };
    if (faired && std::all_of(patch.begin(), patch.end(), finite)) return;
    for (std::size_t i = 0; i < patch.size(); ++i) m_.point(patch[i]) = refined[i];
    ++r_.holes_not_faired;
  }

  void simplifyAndMeasure(const Mesh& before) {
    const auto t0 = std::chrono::steady_clock::now();
    MeshSimplification& s = r_.simplification;
    s.ran = true;
    s.faces_before = m_.number_of_faces();
    simplify();
    s.faces_after = m_.number_of_faces();
    // Cheap enough to run every time (a fixed number of samples): the bound is measured, not assumed.
    if (s.faces_after < s.faces_before) s.distance = distanceBetween(soupOf(m_), soupOf(before), job_.distance_samples);
    s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }

  void simplify() {
    if (!CGAL::is_triangle_mesh(m_) || m_.is_empty()) return;
    if (p_.max_simplify_error > 0 && p_.target_edge_length > 0)
      throw std::invalid_argument("target_edge_length works only with max_simplify_error = 0 (shortest edges first)");
    if (p_.max_simplify_error > 0) {
      collapseByQuadrics();
      return;
    }
    StopAtTarget stop;
    if (p_.target_faces > 0 && m_.number_of_faces() > std::size_t(p_.target_faces))
      // Edges per face is nearly constant under collapse (3/2 on a closed surface).
      stop.target_edges = std::size_t(double(p_.target_faces) * m_.number_of_edges() / m_.number_of_faces());
    stop.min_sq_length = p_.target_edge_length * p_.target_edge_length;
    if (stop.target_edges == 0 && stop.min_sq_length == 0) return;
    // Shortest edges first, placed by Lindstrom-Turk, refusing collapses that flip normals. The
    // surviving vertex of a collapse keeps its colour. A region's seam vertices stay put.
    const auto collapse = [&](const auto& placement) {
      SMS::edge_collapse(m_, stop,
                         CGAL::parameters::get_cost(SMS::Edge_length_cost<Mesh>())
                             .get_placement(placement)
                             .visitor(BlendColoursOnCollapse(col_, fixed_)));
    };
    if (job_.seam)
      collapse(SMS::Bounded_normal_change_placement<KeepFixedPlacement<SMS::LindstromTurk_placement<Mesh>>>(
          KeepFixedPlacement<SMS::LindstromTurk_placement<Mesh>>{{}, fixed_}));
    else
      collapse(SMS::Bounded_normal_change_placement<SMS::LindstromTurk_placement<Mesh>>());
    m_.collect_garbage();
  }

  // Quadric collapse (quadric_simplify.h) on the mesh as a triangle list, rebuilt after: a collapse
  // may leave two faces on one triangle or pinch two fans at a vertex, so duplicates go and pinched
  // vertices are doubled where they are. Whole meshes only: simplifyRegion collapses a region, seams
  // locked, before its repair.
  void collapseByQuadrics() {
    m_.collect_garbage();
    // Each position's component before the collapse (a position in two: unknown), for the cut-offs step.
    std::unordered_map<Point, std::size_t, PointHash> component_at;
    if (judgesCutOffs()) {
      auto fcc = m_.add_property_map<FD, std::size_t>("f:cc_before", 0).first;
      PMP::connected_components(m_, fcc);
      for (FD f : m_.faces())
        for (VD v : CGAL::vertices_around_face(m_.halfedge(f), m_)) {
          const auto [it, added] = component_at.emplace(m_.point(v), fcc[f]);
          if (!added && it->second != fcc[f]) it->second = kUnknownComponent;
        }
      m_.remove_property_map(fcc);
    }
    std::vector<Point> points;
    TriangleMesh t;
    for (VD v : m_.vertices()) {
      const Point& q = m_.point(v);
      t.vertices.emplace_back(float(q.x()), float(q.y()), float(q.z()));
      t.colors.push_back(col_[v]);
    }
    for (FD f : m_.faces()) {
      const HD h = m_.halfedge(f);
      t.faces.push_back({std::uint32_t(m_.source(h).idx()), std::uint32_t(m_.target(h).idx()),
                         std::uint32_t(m_.target(m_.next(h)).idx())});
    }
    std::vector<std::uint8_t> no_locks;
    simplifyByQuadrics(t, p_.max_simplify_error, std::size_t(p_.target_faces), no_locks);
    for (const auto& v : t.vertices) points.emplace_back(v.x(), v.y(), v.z());
    std::vector<std::array<std::size_t, 3>> triangles;
    for (const auto& f : t.faces) triangles.push_back({f[0], f[1], f[2]});
    PMP::merge_duplicate_polygons_in_polygon_soup(points, triangles);
    const std::size_t before = points.size();
    PMP::orient_polygon_soup(points, triangles);  // doubled points go after the others, copies of one of them
    r_.non_manifold_vertices_split += points.size() - before;
    std::unordered_map<Point, std::size_t, PointHash> first_at;
    for (std::size_t i = 0; i < before; ++i) first_at.emplace(points[i], i);
    Mesh out;
    PMP::polygon_soup_to_polygon_mesh(points, triangles, out);
    auto col = out.add_property_map<VD, Rgb>("v:rgb", Rgb{128, 128, 128}).first;
    out.add_property_map<VD, bool>("v:rgb_known", true);
    for (VD v : out.vertices())  // the soup's points, in order
      col[v] = t.colors[v.idx() < before ? v.idx() : first_at.at(points[v.idx()])];
    if (!component_at.empty()) {
      auto origin = out.add_property_map<VD, std::size_t>("v:origin", kUnknownComponent).first;
      for (VD v : out.vertices())
        if (const auto it = component_at.find(points[v.idx()]); it != component_at.end()) origin[v] = it->second;
    }
    m_ = std::move(out);
    col_ = m_.property_map<VD, Rgb>("v:rgb").first;
    known_ = m_.property_map<VD, bool>("v:rgb_known").first;
  }

  void smooth() {
    auto fixed = m_.add_property_map<VD, bool>("v:fixed", false).first;
    for (HD h : m_.halfedges())
      if (m_.is_border(h)) fixed[m_.target(h)] = true;  // keep open borders where they are
    if (p_.smooth_iterations > 0)
      PMP::smooth_shape(m_, p_.smooth_time,
                        CGAL::parameters::number_of_iterations(p_.smooth_iterations).vertex_is_constrained_map(fixed));
    if (p_.relax_iterations > 0)
      PMP::tangential_relaxation(m_, CGAL::parameters::number_of_iterations(p_.relax_iterations).vertex_is_constrained_map(fixed));
    m_.remove_property_map(fixed);
  }

  void finish(Mesh& m) const {
    m.collect_garbage();  // indices are now 0..n-1
    if (job_.seam) return;    // a region is neither closed nor final
    if (p_.orient_closed_outward && !m.is_empty() && CGAL::is_closed(m)) PMP::orient(m);
  }

  // `m` is m_ or a copy of it (with the copied colour map).
  TriangleMesh toTriangleMesh(Mesh& m) const {
    TriangleMesh out;
    m.collect_garbage();
    const auto col = m.property_map<VD, Rgb>("v:rgb").first;
    out.vertices.reserve(m.number_of_vertices());
    for (VD v : m.vertices()) {
      const Point& p = m.point(v);
      out.vertices.emplace_back(float(p.x()), float(p.y()), float(p.z()));
      if (has_colours_) out.colors.push_back(col[v]);
    }
    for (FD f : m.faces()) {
      std::array<std::uint32_t, 3> tri{};
      int k = 0;
      for (VD v : CGAL::vertices_around_face(m.halfedge(f), m))
        if (k < 3) tri[k++] = std::uint32_t(v.idx());
      out.faces.push_back(tri);
    }
    if (p_.recompute_normals && !m.is_empty()) {
      // PMP::compute_vertex_normals' two steps, the second on every core: the face normals, then each
      // vertex's normal from them (only reads the mesh). The same normals; they were a third of the
      // welded mesh's cleaning time on one core (rpy_first100).
      auto fn = m.add_property_map<FD, Kernel::Vector_3>("f:n", CGAL::NULL_VECTOR).first;
      PMP::compute_face_normals(m, fn);
      out.normals.resize(out.vertices.size());  // vertex i is index i: the garbage is collected
      parallelFor(0, int(out.vertices.size()), [&](int i) {
        const Kernel::Vector_3 n = PMP::compute_vertex_normal(VD(i), m, PMP::parameters::face_normal_map(fn));
        out.normals[i] = Eigen::Vector3f(float(n.x()), float(n.y()), float(n.z()));
      }, 512);
      m.remove_property_map(fn);
    }
    return out;
  }

  const MeshCleanParams& p_;
  MeshCleanReport& r_;
  const Job job_;
  Mesh::Property_map<VD, bool> fixed_;
  Mesh m_;
  Mesh::Property_map<VD, Rgb> col_;
  Mesh::Property_map<VD, bool> known_;
  bool has_colours_ = false;
  std::size_t input_vertices_ = 0, input_faces_ = 0;
};

}  // namespace

namespace {

MeshCleanReport clean(TriangleMesh& mesh, const MeshCleanParams& params, TriangleMesh* unsimplified, Cleaner::Input input) {
  MeshCleanReport report;
  TriangleMesh before;
  try {
    // No copy of the input (the welded mesh's repair is a long run's peak): Cleaner only reads `mesh`
    // and replaces it at its very end, so on failure it is as it came.
    Cleaner::Job job;
    job.input = input;
    job.unsimplified = unsimplified ? &before : nullptr;
    Cleaner(params, report, job).run(mesh);
  } catch (const std::exception& e) {
    report.success = false;
    report.failure = e.what();
    return report;  // `unsimplified` untouched: the mesh as it came is `mesh` itself
  }
  if (unsimplified) *unsimplified = std::move(before);
  report.success = true;
  return report;
}

}  // namespace

MeshCleanReport cleanMesh(TriangleMesh& mesh, const MeshCleanParams& params, TriangleMesh* unsimplified) {
  return clean(mesh, params, unsimplified, Cleaner::Input::Soup);
}

MeshCleanReport cleanWeldedRegions(TriangleMesh& mesh, const MeshCleanParams& params) {
  return clean(mesh, params, nullptr, Cleaner::Input::WeldedRegions);
}

MeshCleanReport simplifyRegion(TriangleMesh& mesh, std::vector<std::uint8_t>& seam, const MeshCleanParams& params) {
  MeshCleanReport report;
  if (seam.size() != mesh.vertices.size()) throw std::invalid_argument("simplifyRegion: one seam flag per vertex");
  MeshCleanParams p = params;
  p.recompute_normals = false;  // normals come after welding
  // A region welds nothing by distance: a seam vertex merged onto a nearby inner one would leave its
  // place, and the neighbouring region's copy without a partner (a crack). The welded mesh is welded
  // once, with the distance asked for (cleanWeldedRegions).
  p.weld_distance = 0;
  TriangleMesh work;
  std::vector<std::uint8_t> work_seam;
  // Samples in proportion to the faces: spread over regions about as over the whole mesh.
  const std::size_t samples = std::max<std::size_t>(100, mesh.faces.size() / 8);
  const auto t0 = std::chrono::steady_clock::now();
  // Quadric collapse first, on marching cubes' own triangles: it needs no repair, and the repair
  // after it has a tenth of the faces (rpy_first100: repair 5.3 s of CPU before, docs/mesh.md).
  const bool quadrics = p.max_simplify_error > 0;
  try {
    // Copied in here: memory that runs out for a large region's copy costs that region (kept as it
    // came), as a CGAL failure does; it failed the whole mesh.
    work = mesh;
    work_seam = seam;
    if (quadrics) {
      if (!simplifyByQuadrics(work, p.max_simplify_error, std::size_t(p.target_faces), work_seam))
        throw std::runtime_error("simplification would move a seam vertex");
      p.max_simplify_error = 0;
      p.target_faces = 0;
    }
    Cleaner::Job job;
    job.seam = &work_seam;
    job.distance_samples = samples;
    Cleaner(p, report, job).run(work);
    if (quadrics) {
      MeshSimplification& s = report.simplification;
      s.ran = true;
      s.faces_before = mesh.faces.size();
      s.faces_after = work.faces.size();
      if (s.faces_after < s.faces_before) s.distance = distanceBetween(soupOf(work), soupOf(mesh), samples);
      s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    }
  } catch (const std::exception& e) {
    report.success = false;
    report.failure = e.what();
    return report;
  }
  mesh = std::move(work);
  seam = std::move(work_seam);
  report.success = true;
  return report;
}

MeshDistance meshDistance(const TriangleMesh& from, const TriangleMesh& to, std::size_t samples) {
  return distanceBetween(soupOf(from), soupOf(to), samples);
}

}  // namespace vofusion
