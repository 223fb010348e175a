#include "vofusion/pipeline/mesh_by_region.h"

#include <chrono>
#include <cstdio>
#include <cstring>
#include <deque>
#include <fstream>
#include <algorithm>
#include <cmath>
#include <atomic>
#include <exception>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <unordered_map>

#include <tbb/task_arena.h>
#include <tbb/task_group.h>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/errors.h"

#include "union_find.h"

namespace vofusion {

namespace {

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
      // A seam vertex's normal from the faces of every region using it (each region's own covers
      // part of its fan): summed here, written over the first region's by finish().
      if (!(r.on_seam[f[0]] || r.on_seam[f[1]] || r.on_seam[f[2]])) continue;
      const Eigen::Vector3f n = (m.vertices[f[1]] - m.vertices[f[0]]).cross(m.vertices[f[2]] - m.vertices[f[0]]);
      for (std::uint32_t i : f)
        if (r.on_seam[i]) seam_normals_.try_emplace(index[i], Eigen::Vector3f::Zero()).first->second += n;
    }
    faces_ += m.faces.size();
  }
  std::size_t vertices() const { return welder_.vertices(); }
  std::size_t faces() const { return faces_; }
  void finish() {
    v_.close();
    f_.close();
    if (!v_ || !f_) throw InputError(path_, "cannot write");  // a side file cut short (disk full)
    writeSeamNormals();
    std::ofstream out(path_, std::ios::binary);
    out << "ply\nformat binary_little_endian 1.0\ncomment written by vofusion\nelement vertex " << vertices()
        << "\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\n"
           "property uchar red\nproperty uchar green\nproperty uchar blue\nelement face "
        << faces_ << "\nproperty list uchar int vertex_indices\nend_header\n";
    for (const std::string& side : {path_ + ".vertices", path_ + ".faces"}) {
      std::ifstream in(side, std::ios::binary);
      if (!in) throw InputError(path_, "cannot write (its side file " + side + " cannot be read back)");
      // Copying an empty file (a map with no surface) sets out's failbit: nothing to copy, no failure.
      if (in.peek() != std::ifstream::traits_type::eof()) out << in.rdbuf();
      in.close();
      std::remove(side.c_str());
    }
    out.close();
    if (!out) throw InputError(path_, "cannot write");
    syncFileToDisk(path_);  // staged: its rename into the output folder follows its bytes to the disk
  }

 private:
  static constexpr std::streamoff kVertexBytes = 27, kNormalAt = 12;  // x y z, nx ny nz, r g b
  // Each seam vertex's normal over all its faces, as computeVertexNormals makes it for the whole mesh.
  void writeSeamNormals() {
    if (seam_normals_.empty()) return;
    // In file order: one pass forward over the side file, not a seek back and forth per vertex.
    std::vector<std::pair<std::uint32_t, Eigen::Vector3f>> sums(seam_normals_.begin(), seam_normals_.end());
    std::sort(sums.begin(), sums.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    seam_normals_.clear();
    std::fstream v(path_ + ".vertices", std::ios::binary | std::ios::in | std::ios::out);
    for (const auto& [index, sum] : sums) {
      const float len = sum.norm();
      const Eigen::Vector3f n = len > 0.f ? Eigen::Vector3f(sum / len) : Eigen::Vector3f(0.f, 0.f, 1.f);
      v.seekp(std::streamoff(index) * kVertexBytes + kNormalAt);
      v.write(reinterpret_cast<const char*>(n.data()), 12);
    }
    v.close();
    if (!v) throw InputError(path_, "cannot write (its seam vertices' normals)");
  }

  std::string path_;
  std::ofstream v_, f_;
  fusion::SeamWelder welder_;
  std::unordered_map<std::uint32_t, Eigen::Vector3f> seam_normals_;
  std::size_t faces_ = 0;
};


// Connected components of the raw mesh across regions, with their faces and area: cleanMesh judges
// fragments on the raw mesh, so must the regions. Inside a region components are found locally;
// only those touching a seam are joined across regions, through their seam vertices (bit-identical
// in the regions sharing them). Memory follows the seams, not the whole mesh: a union-find over
// every raw vertex was the mesh stage's peak (loop scene: 6 M raw vertices, ~280 MiB).
class RawComponents {
 public:
  RawComponents(int min_faces, double min_area) : min_faces_(min_faces), min_area_(min_area) {}

  // Pass 1, every region in order.
  void add(const fusion::RegionMesh& r) {
    const Local l = local(r, true);
    for (std::size_t c = 0; c < l.faces.size(); ++c) {
      total_faces_ += l.faces[c];
      total_area_ += l.area[c];
      if (l.seam_slot[c] < 0) {
        local_small_ += l.faces[c] > 0 && small(l.faces[c], l.area[c]);
        continue;
      }
      const auto g = std::uint32_t(l.seam_slot[c]);  // tallied on one seam vertex, summed per component in judge()
      faces_[g] += l.faces[c];
      area_[g] += l.area[c];
    }
  }
  // Mean area of a raw face (after pass 1).
  double meanFaceArea() const { return total_faces_ ? total_area_ / double(total_faces_) : 0.0; }
  // Marks the components that touch seams and are smaller than either bound; returns how many
  // components are small in all.
  std::size_t judge() {
    std::vector<std::uint64_t> faces(seams_.size(), 0);
    std::vector<double> area(seams_.size(), 0.0);
    for (std::uint32_t v = 0; v < seams_.size(); ++v) faces[seams_.find(v)] += faces_[v], area[seams_.find(v)] += area_[v];
    small_.assign(seams_.size(), 0);
    std::size_t n = local_small_;
    for (std::uint32_t v = 0; v < seams_.size(); ++v)
      if (seams_.find(v) == v && faces[v] > 0 && small(faces[v], area[v])) small_[v] = 1, ++n;
    faces_ = {};
    area_ = {};
    return n;
  }
  // Pass 2: drops the region's faces of small components.
  void filter(fusion::RegionMesh& r) {
    const Local l = local(r, false);
    std::vector<std::uint8_t> drop(l.faces.size());
    for (std::size_t c = 0; c < drop.size(); ++c)
      drop[c] = l.seam_slot[c] < 0 ? small(l.faces[c], l.area[c]) : small_[seams_.find(std::uint32_t(l.seam_slot[c]))];
    dropComponents(r, l.of_vertex, drop);
  }

 private:
  struct Local {
    std::vector<std::uint32_t> of_vertex;  // vertex -> component (dense)
    std::vector<std::uint64_t> faces;
    std::vector<double> area;
    std::vector<std::int64_t> seam_slot;   // per component: one of its seam vertices' slot, -1 when none
  };

  bool small(std::uint64_t faces, double area) const { return smallFragment(faces, area, min_faces_, min_area_); }

  // The region's components; in pass 1 (`first`) its seam vertices get slots and each component's
  // seam vertices are joined, in pass 2 they are looked up.
  Local local(const fusion::RegionMesh& r, bool first) {
    const TriangleMesh& m = r.mesh;
    RegionComponents rc = componentsOf(m);
    Local l{std::move(rc.of_vertex), std::move(rc.faces), std::move(rc.area), {}};
    l.seam_slot.assign(l.faces.size(), -1);
    for (std::uint32_t v = 0; v < m.vertices.size(); ++v) {
      if (!r.on_seam[v]) continue;
      const std::array<float, 3> key = fusion::exactPosition(m.vertices[v]);
      std::uint32_t slot;
      if (first) {
        const auto [it, fresh] = slot_of_.emplace(key, std::uint32_t(seams_.size()));
        if (fresh) seams_.add(), faces_.push_back(0), area_.push_back(0.0);
        slot = it->second;
      } else {
        // Not met in pass 1: the region read differently this time (a spilled brick lost between the
        // passes). Its component is judged as if the vertex were on no seam.
        const auto it = slot_of_.find(key);
        if (it == slot_of_.end()) continue;
        slot = it->second;
      }
      std::int64_t& s = l.seam_slot[l.of_vertex[v]];
      if (s < 0) s = slot;
      else if (first) seams_.unite(std::uint32_t(s), slot);
    }
    return l;
  }

  int min_faces_;
  double min_area_;
  std::unordered_map<std::array<float, 3>, std::uint32_t, fusion::ExactPositionHash> slot_of_;  // seam vertex -> slot
  UnionFind seams_;                      // over slots: components joined across regions
  std::vector<std::uint64_t> faces_;     // per slot, pass 1
  std::vector<double> area_;
  std::vector<std::uint8_t> small_;      // per root slot, after judge()
  std::size_t local_small_ = 0;          // small components touching no seam
  std::uint64_t total_faces_ = 0;        // pass 1, all regions
  double total_area_ = 0.0;
};

// The repair's counts of `from` added to `to`'s: most of the repair is the regions', the welded mesh's
// own repair only joins them (summary.json's mesh_clean counts both, as meshing the whole mesh at once does).
void addRepairs(MeshCleanReport& to, const MeshCleanReport& from) {
  to.duplicate_vertices_merged += from.duplicate_vertices_merged;
  to.degenerate_faces_removed += from.degenerate_faces_removed;
  to.duplicate_faces_removed += from.duplicate_faces_removed;
  to.border_edges_stitched += from.border_edges_stitched;
  to.non_manifold_vertices_split += from.non_manifold_vertices_split;
}

// Pass 2's running sums: each region, once simplified, welded into the merged mesh in region order.
struct RegionMerge {
  RegionMerge(TriangleMesh& m, MeshSimplification& s) : merged(m), simp(s) {}
  TriangleMesh& merged;
  MeshSimplification& simp;
  fusion::SeamWelder welder;
  double distance_sum = 0.0;
  std::size_t failed = 0;
  std::string failure;
  MeshCleanReport repairs;  // the regions' repair counts, summed

  void add(fusion::RegionMesh& r, const MeshCleanReport& rr) {
    if (!rr.success) ++failed, failure = rr.failure;  // the region stays as marching cubes made it
    addRepairs(repairs, rr);
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
  }
};

// The rest on the welded mesh: components are judged whole (those inside one region already were, on
// raw faces), holes filled across seams; no second simplification.
// mean_raw_face_area: pass 1's (0 when it did not run).
void cleanWelded(RegionMeshResult& out, const MeshCleanParams& params, double mean_raw_face_area,
                 const MeshCleanStep& step, const RegionMerge& merge) {
  MeshCleanParams rest = params;
  rest.max_simplify_error = 0;
  rest.target_faces = 0;
  rest.target_edge_length = 0;
  rest.min_component_faces = 0;  // judged on the raw mesh in pass 1...
  rest.min_component_area = params.min_component_area;
  // ...but a region's repair can cut a sliver off a kept component where it meets a seam (the
  // sliver's other side, in the next region, was a few degenerate or non-manifold faces): pieces
  // with less area than half of min_component_faces raw faces (mean raw face area) go too. Area,
  // not faces: the welded mesh is simplified.
  if (mean_raw_face_area > 0 && params.min_component_faces > 0)
    rest.min_component_area = std::max(rest.min_component_area, 0.5 * params.min_component_faces * mean_raw_face_area);
  const MeshSimplification regional = out.report.simplification;
  const std::size_t removed = out.report.components_removed;
  if (!out.mesh.empty()) out.report = cleanWeldedRegions(out.mesh, rest);
  else out.report.success = true;
  // Failed: the welded mesh as it came, whose regions' normals were left behind at the welding.
  if (!out.report.success && params.recompute_normals) computeVertexNormals(out.mesh);
  out.report.simplification = regional;
  out.report.components_removed += removed;
  addRepairs(out.report, merge.repairs);
  out.report.steps.insert(out.report.steps.begin(), step);
  // Said beside the welded mesh's own outcome (a failure there keeps its message), in summary.json.
  if (merge.failed) out.report.warning = std::to_string(merge.failed) + " region(s) left unsimplified: " + merge.failure;
}

}  // namespace

RegionComponents componentsOf(const TriangleMesh& m) {
  UnionFind uf;
  uf.reset(m.vertices.size());
  for (const auto& f : m.faces) uf.unite(f[0], f[1]), uf.unite(f[1], f[2]);
  RegionComponents out;
  out.of_vertex.assign(m.vertices.size(), 0);
  std::vector<std::int64_t> comp_of_root(m.vertices.size(), -1);
  for (std::uint32_t v = 0; v < m.vertices.size(); ++v) {
    std::int64_t& c = comp_of_root[uf.find(v)];
    if (c < 0) c = std::int64_t(out.faces.size()), out.faces.push_back(0), out.area.push_back(0.0);
    out.of_vertex[v] = std::uint32_t(c);
  }
  for (const auto& f : m.faces) {
    const Eigen::Vector3f& a = m.vertices[f[0]];
    const std::uint32_t c = out.of_vertex[f[0]];
    ++out.faces[c];
    out.area[c] += 0.5 * double((m.vertices[f[1]] - a).cross(m.vertices[f[2]] - a).norm());
  }
  return out;
}

bool smallFragment(std::uint64_t faces, double area, int min_faces, double min_area) {
  return (min_faces > 0 && faces < std::uint64_t(min_faces)) || (min_area > 0 && area < min_area);
}

void dropComponents(fusion::RegionMesh& r, const std::vector<std::uint32_t>& component_of_vertex,
                    const std::vector<std::uint8_t>& drop) {
  auto& f = r.mesh.faces;
  f.erase(std::remove_if(f.begin(), f.end(), [&](const auto& t) { return drop[component_of_vertex[t[0]]] != 0; }), f.end());
}

MeshCleanParams regionSimplifyParams(const MeshCleanParams& params) {
  MeshCleanParams p = params;
  if (params.min_component_faces > 0 || params.min_component_area > 0) {  // judged on the raw mesh before
    p.min_component_faces = 0;
    p.min_component_area = 0;
  }
  return p;
}

std::uint64_t regionInputHash(const fusion::RegionMesh& r) {
  std::uint64_t h = 0xcbf29ce484222325ull;  // FNV-1a, 64 bits
  const auto mix = [&h](const void* data, std::size_t n) {
    const auto* b = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 0x100000001b3ull;
  };
  const auto mixSized = [&](const auto& v) {
    const std::uint64_t n = v.size();
    mix(&n, sizeof n);
    if (n) mix(v.data(), n * sizeof(v[0]));
  };
  mix(r.region.data(), 3 * sizeof(int));
  mixSized(r.mesh.vertices);
  mixSized(r.mesh.normals);
  mixSized(r.mesh.colors);
  mixSized(r.mesh.faces);
  mixSized(r.on_seam);
  return h;
}

// Simplifies regions on every core as they come and hands them to `weld` in region order. Streamed
// regions (marched now) are taken as they come, at most two per core unsimplified; only those count,
// so a large region on one core does not hold up the smaller ones behind it on the other: waiting for
// the oldest in order left a core idle for seconds (xyz_first300: 4.3 s for its largest region, with
// four regions in flight). Regions already in memory (kept from pass 1) are queued without a limit
// (waiting costs no memory), and each task takes the largest waiting when it starts: the last one left
// on one core is then a small one (rpy_first100's largest, a quarter of its faces, came ninth of fourteen).
class OrderedRegionSimplifier {
 public:
  using Weld = std::function<void(fusion::RegionMesh&, const MeshCleanReport&)>;
  OrderedRegionSimplifier(const MeshCleanParams& params, Weld weld, bool all_in_memory)
      : params_(params), weld_(std::move(weld)), largest_first_(all_in_memory),
        limit_(all_in_memory ? std::numeric_limits<std::size_t>::max()
                             : 2 * std::size_t(std::max(1, tbb::this_task_arena::max_concurrency()))) {}
  ~OrderedRegionSimplifier() {
    // No task outlives the regions it reads; after a failure, those not started yet are not run.
    for (auto& t : tasks_) t->group.cancel();
    for (auto& t : tasks_) t->group.wait();
  }

  // Queues r for simplifying (to `target_faces`, its share of the mesh's budget); meanwhile welds what
  // is ready, and waits while `limit_` regions are unsimplified.
  void add(fusion::RegionMesh r, int target_faces) {
    queue_.push_back(std::make_unique<Item>());
    Item& item = *queue_.back();
    item.region = std::move(r);
    item.params = params_;
    item.params.target_faces = target_faces;
    {
      std::lock_guard<std::mutex> lk(waiting_m_);
      waiting_.push_back(&item);
    }
    // One task per region added; each simplifies the next region waiting when it starts.
    tasks_.push_back(std::make_unique<Task>());
    Task& task = *tasks_.back();
    task.group.run([this, &task] {
      simplify(takeNext());
      task.finished.store(true, std::memory_order_release);
    });
    weldReady();
    while (unsimplified() >= limit_) {
      // The newest unfinished task: this thread simplifies waiting regions while it waits (TBB), and
      // returns as soon as that task is done, not when the slowest is.
      for (auto it = tasks_.rbegin(); it != tasks_.rend(); ++it)
        if (!(*it)->finished.load(std::memory_order_acquire)) {
          (*it)->group.wait();
          break;
        }
      weldReady();
    }
  }
  // A region simplified already (during the run): welded in its turn like the others.
  void addDone(fusion::RegionMesh r, MeshCleanReport report) {
    queue_.push_back(std::make_unique<Item>());
    Item& item = *queue_.back();
    item.region = std::move(r);
    item.report = std::move(report);
    item.done.store(true, std::memory_order_release);
    weldReady();
  }
  // Waits for every region and welds the rest; rethrows what a region's simplification threw.
  void finish() {
    for (auto& t : tasks_) {  // each task simplifies one region: once all are done, so are the regions
      t->group.wait();
      weldReady();
    }
  }

 private:
  struct Item {
    fusion::RegionMesh region;
    MeshCleanParams params;
    MeshCleanReport report;
    std::exception_ptr error;
    std::atomic<bool> done{false};  // simplified (or failed): no task reads it any more
  };
  struct Task {
    tbb::task_group group;
    std::atomic<bool> finished{false};
  };
  // The first of the largest, or the oldest.
  Item& takeNext() {
    std::lock_guard<std::mutex> lk(waiting_m_);
    const auto largest = [](const Item* a, const Item* b) { return a->region.mesh.faces.size() < b->region.mesh.faces.size(); };
    const auto it = largest_first_ ? std::max_element(waiting_.begin(), waiting_.end(), largest) : waiting_.begin();
    Item& item = **it;
    waiting_.erase(it);
    return item;
  }
  static void simplify(Item& item) {
    try {
      item.report = simplifyRegion(item.region.mesh, item.region.on_seam, item.params);
    } catch (...) {
      item.error = std::current_exception();
    }
    item.done.store(true, std::memory_order_release);
  }
  std::size_t unsimplified() const {
    return std::size_t(std::count_if(queue_.begin(), queue_.end(),
                                     [](const auto& i) { return !i->done.load(std::memory_order_acquire); }));
  }
  void weldReady() {
    while (!queue_.empty() && queue_.front()->done.load(std::memory_order_acquire)) {
      std::unique_ptr<Item> item = std::move(queue_.front());
      queue_.pop_front();
      if (item->error) std::rethrow_exception(item->error);
      weld_(item->region, item->report);
    }
  }

  const MeshCleanParams& params_;
  Weld weld_;
  const bool largest_first_;
  const std::size_t limit_;  // regions added but not simplified yet, at most (add() waits)
  std::deque<std::unique_ptr<Item>> queue_;  // region order; the front is welded next
  std::mutex waiting_m_;
  std::vector<Item*> waiting_;               // added, not taken by a task yet
  std::deque<std::unique_ptr<Task>> tasks_;  // one per region added, all kept to the end (small)
};

// The whole mesh's face budget (target_faces) shared among the regions by their raw faces.
class FaceBudget {
 public:
  explicit FaceBudget(int target_faces) : target_(target_faces) {}
  bool active() const { return target_ > 0; }
  void add(const fusion::RegionMesh& r) {
    if (raw_faces_of_.size() <= r.ordinal) raw_faces_of_.resize(r.ordinal + 1, 0);
    raw_faces_of_[r.ordinal] = r.mesh.faces.size();
    raw_faces_total_ += r.mesh.faces.size();
  }
  // A region's share, at least 1 (0 would mean no budget). Locked seam vertices may keep a region
  // above its share.
  int shareOf(const fusion::RegionMesh& r) const {
    if (!active() || raw_faces_total_ == 0 || r.ordinal >= raw_faces_of_.size()) return target_;
    const double share = std::ceil(double(target_) * double(raw_faces_of_[r.ordinal]) / double(raw_faces_total_));
    return std::max(1, int(share));
  }

 private:
  int target_;
  std::vector<std::size_t> raw_faces_of_;  // by region ordinal
  std::size_t raw_faces_total_ = 0;
};

namespace {
// Pass 1's regions, kept for pass 2 while all of them fit in `limit` bytes: then pass 2 does not march
// them again. A larger raw mesh is marched twice, and none is kept.
class KeptRegions {
 public:
  explicit KeptRegions(std::size_t limit) : limit_(limit) {}
  void keep(fusion::RegionMesh& r) {
    if (dropped()) return;
    bytes_ += bytesOf(r);
    if (dropped()) regions_ = {};
    else regions_.push_back(std::move(r));
  }
  // Whether pass 2 takes its regions from here: pass 1 kept every region it made (and made some).
  bool complete() const { return !dropped() && !regions_.empty(); }
  // Pass 2's source: the kept regions (handed over, each once) when complete, else `marched`.
  RegionSource secondPass(const RegionSource& marched) {
    if (!complete()) return marched;
    return [this](const std::function<void(fusion::RegionMesh&)>& sink) {
      for (fusion::RegionMesh& r : regions_) {
        fusion::RegionMesh handed = std::move(r);
        sink(handed);
      }
      regions_ = {};
    };
  }

 private:
  static std::size_t bytesOf(const fusion::RegionMesh& r) {  // as allocated, not as used
    const TriangleMesh& m = r.mesh;
    return m.vertices.capacity() * sizeof(m.vertices[0]) + m.normals.capacity() * sizeof(m.normals[0]) +
           m.colors.capacity() * sizeof(m.colors[0]) + m.faces.capacity() * sizeof(m.faces[0]) + r.on_seam.capacity();
  }
  std::size_t limit_;
  std::vector<fusion::RegionMesh> regions_;
  std::size_t bytes_ = 0;  // of the regions met so far, kept or not
  bool dropped() const { return bytes_ > limit_; }  // the limit ran out: none is kept
};

// Pass 1 of meshByRegion (marching cubes only): each region's raw components into `fragments` (when
// fragments are judged) and its faces into the budget, the region itself into `kept`; returns the
// number of regions (0 if none).
std::size_t firstPass(const RegionSource& regions, RawComponents* fragments, FaceBudget& budget, KeptRegions& kept,
                      const std::function<void(int, const fusion::RegionMesh&)>& told) {
  std::size_t region_count = 0;
  regions([&](fusion::RegionMesh& r) {
    if (fragments) fragments->add(r);
    budget.add(r);
    told(1, r);
    region_count = r.regions;
    kept.keep(r);
  });
  return region_count;
}

// The "regions" step's figures once every region is welded: the simplification's mean distance over
// all regions' samples, the merged mesh's size, and the time (marching cubes, repair and simplification
// interleaved, so the simplification's seconds are the step's).
void closeRegionsStep(RegionMeshResult& out, const RegionMerge& merge, MeshCleanStep& step, double seconds) {
  MeshSimplification& simp = out.report.simplification;
  if (simp.distance.samples) simp.distance.mean = merge.distance_sum / double(simp.distance.samples);
  step.faces_after = out.mesh.faces.size();
  step.vertices_after = out.mesh.vertices.size();
  step.seconds = seconds;
  simp.seconds = seconds;
}
}  // namespace

RegionMeshResult meshByRegion(const RegionSource& regions, const MeshCleanParams& params, const std::string& raw_ply,
                              const MeshProgress& progress, const std::function<void(std::size_t)>& regions_done,
                              const PremeshedLookup& premeshed, std::size_t keep_bytes) {
  const auto told = [&](int pass, const fusion::RegionMesh& r) {
    if (progress) progress(pass, r.ordinal + 1, r.regions);
  };
  RegionMeshResult out;
  std::unique_ptr<PlyStream> raw;
  if (!raw_ply.empty()) raw = std::make_unique<PlyStream>(raw_ply);
  fusion::SeamWelder raw_count;
  RegionMerge merge(out.mesh, out.report.simplification);
  MeshCleanStep step{"regions"};
  const auto t0 = std::chrono::steady_clock::now();
  // Pass 1 (marching cubes only): which fragments are too small, judged whole across seams, and each
  // region's faces, which share a face budget (target_faces is the whole mesh's, not each region's).
  const MeshCleanParams region_params = regionSimplifyParams(params);
  std::unique_ptr<RawComponents> fragments;
  if (params.min_component_faces > 0 || params.min_component_area > 0)
    fragments = std::make_unique<RawComponents>(params.min_component_faces, params.min_component_area);
  FaceBudget budget(params.target_faces);
  KeptRegions kept(keep_bytes);
  if (fragments || budget.active()) {
    const std::size_t region_count = firstPass(regions, fragments.get(), budget, kept, told);
    if (fragments) out.report.components_removed = fragments->judge();
    // Pass 2 shows from its start, not from its first welded region (seconds later when that is large).
    if (progress && region_count) progress(2, 0, region_count);
  }
  // Pass 2: the same regions again (kept from pass 1, or marched again), each simplified on a task while
  // the next ones come (CGAL works on the region's own mesh), and welded in region order, so the mesh is
  // the one a single core gives.
  const bool all_kept = kept.complete();  // false without pass 1
  OrderedRegionSimplifier simplifier(region_params, [&](fusion::RegionMesh& r, const MeshCleanReport& report) {
    merge.add(r, report);
    told(2, r);
  }, all_kept);
  const RegionSource second = kept.secondPass(regions);
  second([&](fusion::RegionMesh& r) {
    ++out.regions;
    if (raw) raw->add(r);
    else raw_count.add(r.mesh, r.on_seam, [](std::size_t) {});
    out.raw_faces += r.mesh.faces.size();
    step.faces_before += r.mesh.faces.size();
    if (fragments) fragments->filter(r);
    if (premeshed && !budget.active())  // a budget's shares are known only now (RunSession starts no premesher then)
      if (std::optional<PremeshedRegion> done = premeshed(r)) {
        r.mesh = std::move(done->mesh);
        r.on_seam = std::move(done->on_seam);
        ++out.regions_premeshed;
        simplifier.addDone(std::move(r), std::move(done->report));
        return;
      }
    const int share = budget.shareOf(r);
    simplifier.add(std::move(r), share);
  });
  simplifier.finish();
  TriangleMesh& merged = out.mesh;
  if (merged.colors.size() != merged.vertices.size()) merged.colors.clear();
  closeRegionsStep(out, merge, step, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  out.raw_vertices = raw_count.vertices();
  if (raw) {
    raw->finish();
    out.raw_vertices = raw->vertices();
    raw.reset();
  }
  step.vertices_before = out.raw_vertices;
  if (regions_done) regions_done(out.mesh.faces.size());
  // The welded mesh's repair can be the run's peak (CGAL's mesh beside the merged one): the seam
  // indexes of both passes go first, and the merged mesh's spare capacity.
  const double mean_raw_face_area = fragments ? fragments->meanFaceArea() : 0.0;
  fragments.reset();
  raw_count = fusion::SeamWelder();
  merge.welder = fusion::SeamWelder();
  merged.vertices.shrink_to_fit();
  merged.colors.shrink_to_fit();
  merged.faces.shrink_to_fit();
  cleanWelded(out, params, mean_raw_face_area, step, merge);
  return out;
}

}  // namespace vofusion
