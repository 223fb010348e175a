#include "vofusion/pipeline/mesh_by_region.h"

#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <algorithm>
#include <memory>
#include <unordered_map>

#include "vofusion/core/errors.h"

namespace vofusion {

namespace {

struct PositionHash {
  std::size_t operator()(const std::array<float, 3>& p) const {
    std::size_t h = 1469598103934665603ull;
    for (float f : p) {
      std::uint32_t b;
      std::memcpy(&b, &f, 4);
      h = (h ^ b) * 1099511628211ull;
    }
    return h;
  }
};

// Appends region meshes into one, giving seam vertices (bit-identical in the regions sharing them)
// one index. Only seam vertices are remembered, not the whole mesh.
class Welder {
 public:
  // Global index of each of the part's vertices; new vertices are handed to `emit`.
  template <typename Emit>
  std::vector<std::uint32_t> add(const TriangleMesh& part, const std::vector<std::uint8_t>& seam, Emit&& emit) {
    std::vector<std::uint32_t> index(part.vertices.size());
    for (std::size_t v = 0; v < part.vertices.size(); ++v) {
      if (seam[v]) {
        const std::array<float, 3> key{part.vertices[v].x(), part.vertices[v].y(), part.vertices[v].z()};
        const auto [it, fresh] = seam_index_.emplace(key, next_);
        index[v] = it->second;
        if (!fresh) continue;
      } else {
        index[v] = next_;
      }
      ++next_;
      emit(v);
    }
    return index;
  }
  std::uint32_t vertices() const { return next_; }

 private:
  std::unordered_map<std::array<float, 3>, std::uint32_t, PositionHash> seam_index_;
  std::uint32_t next_ = 0;
};

// Binary PLY written as the regions come: vertex and face records go to two side files, joined
// under the header (whose counts are known only at the end) by finish().
class PlyStream {
 public:
  explicit PlyStream(const std::string& path)
      : path_(path), v_(path + ".vertices", std::ios::binary), f_(path + ".faces", std::ios::binary) {
    if (!v_ || !f_) throw InputError(path, "cannot write");
  }
  void add(const fusion::RegionMesh& r) {
    const TriangleMesh& m = r.mesh;
    const std::vector<std::uint32_t> index = welder_.add(m, r.on_seam, [&](std::size_t v) {
      v_.write(reinterpret_cast<const char*>(m.vertices[v].data()), 12);
      v_.write(reinterpret_cast<const char*>(m.normals[v].data()), 12);
      v_.write(reinterpret_cast<const char*>(m.colors[v].data()), 3);
    });
    for (const auto& f : m.faces) {
      const char three = 3;
      f_.write(&three, 1);
      for (std::uint32_t i : f) {
        const std::int32_t g = std::int32_t(index[i]);
        f_.write(reinterpret_cast<const char*>(&g), 4);
      }
    }
    faces_ += m.faces.size();
  }
  std::size_t vertices() const { return welder_.vertices(); }
  std::size_t faces() const { return faces_; }
  void finish() {
    v_.close();
    f_.close();
    std::ofstream out(path_, std::ios::binary);
    out << "ply\nformat binary_little_endian 1.0\ncomment written by vofusion\nelement vertex " << vertices()
        << "\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\n"
           "property uchar red\nproperty uchar green\nproperty uchar blue\nelement face "
        << faces_ << "\nproperty list uchar int vertex_indices\nend_header\n";
    for (const std::string& side : {path_ + ".vertices", path_ + ".faces"}) {
      std::ifstream in(side, std::ios::binary);
      out << in.rdbuf();
      in.close();
      std::remove(side.c_str());
    }
    if (!out.flush()) throw InputError(path_, "cannot write");
  }

 private:
  std::string path_;
  std::ofstream v_, f_;
  Welder welder_;
  std::size_t faces_ = 0;
};

// Connected components of the raw mesh across regions (union-find over welded vertex ids), with
// their faces and area: cleanMesh judges fragments on the raw mesh, so must the regions.
class RawComponents {
 public:
  void add(const fusion::RegionMesh& r) {
    const std::vector<std::uint32_t> id = ids_.add(r.mesh, r.on_seam, [&](std::size_t) {
      parent_.push_back(std::uint32_t(parent_.size()));
      faces_.push_back(0);
      area_.push_back(0.f);
    });
    for (const auto& f : r.mesh.faces) {
      unite(id[f[0]], id[f[1]]);
      unite(id[f[1]], id[f[2]]);
      const Eigen::Vector3f& a = r.mesh.vertices[f[0]];
      ++faces_[id[f[0]]];  // tallied on a vertex, summed per component in judge()
      area_[id[f[0]]] += 0.5f * (r.mesh.vertices[f[1]] - a).cross(r.mesh.vertices[f[2]] - a).norm();
    }
  }
  // Marks the components smaller than either bound; returns how many.
  std::size_t judge(int min_faces, double min_area) {
    std::vector<std::uint64_t> faces(parent_.size(), 0);
    std::vector<double> area(parent_.size(), 0.0);
    for (std::uint32_t v = 0; v < parent_.size(); ++v) faces[find(v)] += faces_[v], area[find(v)] += area_[v];
    small_.assign(parent_.size(), 0);
    std::size_t n = 0;
    for (std::uint32_t v = 0; v < parent_.size(); ++v)
      if (find(v) == v && faces[v] > 0 &&
          ((min_faces > 0 && faces[v] < std::uint64_t(min_faces)) || (min_area > 0 && area[v] < min_area)))
        small_[v] = 1, ++n;
    return n;
  }
  // Drops the region's faces of small components (the same region, in the same order, as add()).
  void filter(fusion::RegionMesh& r) {
    const std::vector<std::uint32_t> id = ids2_.add(r.mesh, r.on_seam, [](std::size_t) {});
    auto& f = r.mesh.faces;
    f.erase(std::remove_if(f.begin(), f.end(), [&](const auto& t) { return small_[find(id[t[0]])] != 0; }), f.end());
  }

 private:
  std::uint32_t find(std::uint32_t v) {
    while (parent_[v] != v) v = parent_[v] = parent_[parent_[v]];
    return v;
  }
  void unite(std::uint32_t a, std::uint32_t b) {
    a = find(a), b = find(b);
    if (a != b) parent_[std::max(a, b)] = std::min(a, b);
  }
  Welder ids_, ids2_;
  std::vector<std::uint32_t> parent_, faces_;
  std::vector<float> area_;
  std::vector<std::uint8_t> small_;
};

}  // namespace

RegionMeshResult meshByRegion(const RegionSource& regions, const MeshCleanParams& params, const std::string& raw_ply) {
  RegionMeshResult out;
  std::unique_ptr<PlyStream> raw;
  if (!raw_ply.empty()) raw = std::make_unique<PlyStream>(raw_ply);
  Welder welder, raw_count;
  TriangleMesh& merged = out.mesh;
  MeshSimplification& simp = out.report.simplification;
  MeshCleanStep step{"regions"};
  double distance_sum = 0.0;
  std::size_t failed = 0;
  std::string failure;
  const auto t0 = std::chrono::steady_clock::now();
  // Pass 1 (marching cubes only): which fragments are too small, judged whole across seams.
  MeshCleanParams region_params = params;
  std::unique_ptr<RawComponents> fragments;
  if (params.min_component_faces > 0 || params.min_component_area > 0) {
    fragments = std::make_unique<RawComponents>();
    regions([&](fusion::RegionMesh& r) { fragments->add(r); });
    out.report.components_removed = fragments->judge(params.min_component_faces, params.min_component_area);
    region_params.min_component_faces = 0;
    region_params.min_component_area = 0;
  }
  // Pass 2: the same regions again, simplified one at a time.
  regions([&](fusion::RegionMesh& r) {
    ++out.regions;
    if (raw) raw->add(r);
    else raw_count.add(r.mesh, r.on_seam, [](std::size_t) {});
    out.raw_faces += r.mesh.faces.size();
    step.faces_before += r.mesh.faces.size();
    if (fragments) fragments->filter(r);
    const MeshCleanReport rr = simplifyRegion(r.mesh, r.on_seam, region_params);
    if (!rr.success) ++failed, failure = rr.failure;  // the region stays as marching cubes made it
    const MeshSimplification& s = rr.simplification;
    if (s.ran) {
      simp.ran = true;
      simp.faces_before += s.faces_before;
      simp.faces_after += s.faces_after;
      simp.distance.samples += s.distance.samples;
      distance_sum += s.distance.mean * double(s.distance.samples);
      simp.distance.max = std::max(simp.distance.max, s.distance.max);
    }
    const std::vector<std::uint32_t> index = welder.add(r.mesh, r.on_seam, [&](std::size_t v) {
      merged.vertices.push_back(r.mesh.vertices[v]);
      if (!r.mesh.colors.empty()) merged.colors.push_back(r.mesh.colors[v]);
    });
    for (const auto& f : r.mesh.faces) merged.faces.push_back({index[f[0]], index[f[1]], index[f[2]]});
  });
  if (merged.colors.size() != merged.vertices.size()) merged.colors.clear();
  if (simp.distance.samples) simp.distance.mean = distance_sum / double(simp.distance.samples);
  step.faces_after = merged.faces.size();
  step.vertices_after = merged.vertices.size();
  step.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  simp.seconds = step.seconds;  // marching cubes, repair and simplification are interleaved
  out.raw_vertices = raw_count.vertices();
  if (raw) {
    raw->finish();
    out.raw_vertices = raw->vertices();
  }
  step.vertices_before = out.raw_vertices;

  // The rest on the welded mesh: components are judged whole (those inside one region already
  // were, on raw faces), holes filled across seams; no second simplification.
  MeshCleanParams rest = params;
  rest.max_simplify_error = 0;
  rest.target_faces = 0;
  rest.target_edge_length = 0;
  rest.min_component_faces = 0;  // judged on the raw mesh in pass 1
  rest.min_component_area = 0;
  const MeshSimplification regional = simp;
  const std::size_t removed = out.report.components_removed;
  if (!merged.empty()) out.report = cleanMesh(merged, rest);
  else out.report.success = true;
  out.report.simplification = regional;
  out.report.components_removed += removed;
  out.report.steps.insert(out.report.steps.begin(), step);
  if (failed) {
    out.report.failure = std::to_string(failed) + " region(s) left unsimplified: " + failure;
  }
  return out;
}

}  // namespace vofusion
