#include "vofusion/pipeline/region_premesher.h"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <unordered_map>
#include <unordered_set>

#include <tbb/task_arena.h>

#include "union_find.h"

namespace vofusion {

namespace {

using Key = RegionPremesher::Key;

Key keyOf(const Eigen::Vector3i& r) { return {r.x(), r.y(), r.z()}; }
Eigen::Vector3i vectorOf(const Key& k) { return {k[0], k[1], k[2]}; }

int floorDiv(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

// The 26 regions round a region.
std::vector<Key> neighboursOf(const Key& k) {
  std::vector<Key> out;
  for (int dx = -1; dx <= 1; ++dx)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dz = -1; dz <= 1; ++dz)
        if (dx || dy || dz) out.push_back({k[0] + dx, k[1] + dy, k[2] + dz});
  return out;
}

// A brick the volume took back while its region was read: the region is not final after all.
struct BrickTakenBack {};


}  // namespace

RegionPremesher::RegionPremesher(const MeshCleanParams& params)
    : params_(params), region_params_(regionSimplifyParams(params)) {
  if (params.region_bricks <= 0) throw std::invalid_argument("RegionPremesher: region_bricks must be positive");
  thread_ = std::thread([this] { run(); });
}

RegionPremesher::~RegionPremesher() { stop(); }

// A region's mesh reads the bricks [R rb, R rb + rb] on each axis (its own and the +1 ones its cells
// reach): it can change while that range meets the volume's box, and cannot once it does not.
bool RegionPremesher::reaches(const Key& region, const Eigen::Vector3i& origin) const {
  const int rb = params_.region_bricks;
  for (int i = 0; i < 3; ++i)
    if (region[i] * rb + rb < origin[i] || region[i] * rb > origin[i] + box_bricks_ - 1) return false;
  return true;
}

bool RegionPremesher::finalNow(const Key& region) const { return box_bricks_ > 0 && !reaches(region, origin_); }

void RegionPremesher::volumeShifted(const fusion::TsdfVolume& volume, const Eigen::Vector3i& old_origin) {
  const int rb = params_.region_bricks;
  const std::lock_guard<std::mutex> lock(mutex_);
  if (stopping_) return;
  world_ = &volume.worldModel();
  voxel_size_ = volume.params().voxel_size;
  box_bricks_ = volume.bricksPerSide();
  origin_ = volume.originBrick();
  // Regions the volume reaches now may change: what was made of them is stale.
  Eigen::Vector3i first, last;
  for (int i = 0; i < 3; ++i) first[i] = floorDiv(origin_[i] - 1, rb), last[i] = floorDiv(origin_[i] + box_bricks_ - 1, rb);
  for (int x = first.x(); x <= last.x(); ++x)
    for (int y = first.y(); y <= last.y(); ++y)
      for (int z = first.z(); z <= last.z(); ++z) {
        const Key k{x, y, z};
        if (!reaches(k, origin_)) continue;
        ++generation_[k];
        pieces_.erase(k);
        empty_.erase(k);
        done_.erase(k);
      }
  // Regions it reached before and does not now are final until it comes back.
  for (int i = 0; i < 3; ++i) first[i] = floorDiv(old_origin[i] - 1, rb), last[i] = floorDiv(old_origin[i] + box_bricks_ - 1, rb);
  bool queued = false;
  for (int x = first.x(); x <= last.x(); ++x)
    for (int y = first.y(); y <= last.y(); ++y)
      for (int z = first.z(); z <= last.z(); ++z) {
        const Key k{x, y, z};
        if (!reaches(k, old_origin) || reaches(k, origin_)) continue;
        queue_.push_back(k);
        queued = true;
      }
  if (queued) wake_.notify_one();
}

void RegionPremesher::stop() {
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
    queue_.clear();
  }
  wake_.notify_one();
  if (thread_.joinable()) thread_.join();
}

void RegionPremesher::run() {
  // Only what the frame loop leaves of the two cores: the lowest priority, and marching cubes'
  // parallel loops kept on this thread (a one-slot arena) instead of the pool the frame loop uses.
  setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), 19);
  tbb::task_arena alone(1);
  for (;;) {
    Key region;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
      if (stopping_) return;
      region = queue_.front();
      queue_.pop_front();
    }
    try {
      alone.execute([&] {
        summarise(region);
        // The region, or a neighbour waiting for it, may be ready to simplify.
        simplifyIfReady(region);
        for (const Key& n : neighboursOf(region)) simplifyIfReady(n);
      });
    } catch (const std::exception&) {
      // A spilled brick that does not read back (or no memory): the end meshes this region and
      // reports what is wrong with it there.
    }
  }
}

fusion::RegionMesh RegionPremesher::march(const Key& region, bool& ok) {
  const fusion::WorldModel* world;
  float voxel_size;
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    world = world_;
    voxel_size = voxel_size_;
  }
  const int rb = params_.region_bricks;
  const Eigen::Vector3i lo = vectorOf(region) * rb;
  ok = true;
  const std::vector<Eigen::Vector3i> own = world->coordsInBox(lo, rb);
  if (own.empty()) return {};
  std::unordered_set<std::uint64_t> reach;
  for (const Eigen::Vector3i& c : world->coordsInBox(lo, rb + 1)) reach.insert(fusion::WorldModel::key(c));
  const fusion::BrickFetch fetch = [&](const Eigen::Vector3i& c, fusion::Brick& scratch) -> const fusion::Brick* {
    if (!world->read(c, scratch)) throw BrickTakenBack{};
    return &scratch;
  };
  const auto present = [&](const Eigen::Vector3i& c) { return reach.count(fusion::WorldModel::key(c)) != 0; };
  try {
    // min_weight 1, as TsdfVolume::extractMeshByRegion marches at the end.
    return fusion::marchRegion(vectorOf(region), own, present, fetch, voxel_size, 1, rb, scratch_);
  } catch (const BrickTakenBack&) {
    ok = false;  // queued again when the volume leaves it again
    return {};
  }
}

void RegionPremesher::summarise(const Key& region) {
  std::uint64_t generation;
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    if (stopping_ || !finalNow(region)) return;
    generation = generation_[region];
  }
  bool ok = false;
  const fusion::RegionMesh r = march(region, ok);
  if (!ok) return;
  SeamPieces p;
  if (!r.mesh.faces.empty()) {
    const RegionComponents c = componentsOf(r.mesh);
    std::vector<std::int64_t> piece(c.faces.size(), -1);  // component -> its index in p
    for (std::uint32_t v = 0; v < r.on_seam.size(); ++v) {
      if (!r.on_seam[v]) continue;
      std::int64_t& i = piece[c.of_vertex[v]];
      if (i < 0) i = std::int64_t(p.faces.size()), p.faces.push_back(c.faces[c.of_vertex[v]]), p.area.push_back(c.area[c.of_vertex[v]]);
      p.seam_vertices.push_back({fusion::exactPosition(r.mesh.vertices[v]), std::uint32_t(i)});
    }
  }
  const std::lock_guard<std::mutex> lock(mutex_);
  if (generation_[region] != generation) return;  // the volume came back meanwhile
  if (r.mesh.faces.empty()) empty_.insert(region);
  else pieces_[region] = std::move(p);
}

void RegionPremesher::simplifyIfReady(const Key& region) {
  std::uint64_t generation;
  std::vector<SeamPieces> neighbours;  // copies: the map may change while this one works
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    if (stopping_ || !pieces_.count(region) || done_.count(region)) return;
    for (const Key& n : neighboursOf(region)) {
      if (!finalNow(n)) return;
      if (const auto it = pieces_.find(n); it != pieces_.end()) neighbours.push_back(it->second);
      else if (empty_.count(n)) continue;
      // Never reached by the volume (no bricks, and none can come while it is final), or summarised
      // yet to be.
      else if (world_->coordsInBox(vectorOf(n) * params_.region_bricks, params_.region_bricks).empty()) empty_.insert(n);
      else return;
    }
    generation = generation_[region];
  }
  bool ok = false;
  fusion::RegionMesh r = march(region, ok);
  if (!ok || r.mesh.faces.empty()) return;
  const RegionComponents c = componentsOf(r.mesh);
  std::vector<const SeamPieces*> around;
  for (const SeamPieces& n : neighbours) around.push_back(&n);
  std::vector<std::uint8_t> drop;
  if (!judge(region, r, c, around, drop)) return;
  dropComponents(r, c, drop);
  PremeshedRegion done;
  done.input_hash = regionInputHash(r);
  try {
    done.report = simplifyRegion(r.mesh, r.on_seam, region_params_);
  } catch (const std::exception&) {
    return;  // the end simplifies it, and reports what failed
  }
  done.mesh = std::move(r.mesh);
  done.on_seam = std::move(r.on_seam);
  const std::lock_guard<std::mutex> lock(mutex_);
  if (generation_[region] != generation) return;
  done_[region] = std::move(done);
  ++meshed_;
}

bool RegionPremesher::judge(const Key&, const fusion::RegionMesh& r, const RegionComponents& c,
                            const std::vector<const SeamPieces*>& neighbours, std::vector<std::uint8_t>& drop) const {
  const int min_faces = params_.min_component_faces;
  const double min_area = params_.min_component_area;
  drop.assign(c.faces.size(), 0);
  if (min_faces <= 0 && min_area <= 0) return true;
  // Pieces: this region's components, then each neighbour's; joined where they share a seam vertex.
  std::vector<std::size_t> base{0};
  base.push_back(c.faces.size());
  for (const SeamPieces* n : neighbours) base.push_back(base.back() + n->faces.size());
  UnionFind joins;
  joins.reset(base.back());
  std::unordered_map<std::array<float, 3>, std::uint32_t, fusion::ExactPositionHash> first_at;
  const auto meet = [&](const std::array<float, 3>& at, std::uint32_t piece) {
    const auto [it, fresh] = first_at.emplace(at, piece);
    if (!fresh) joins.unite(it->second, piece);
  };
  std::vector<std::uint8_t> on_seam(c.faces.size(), 0);
  for (std::uint32_t v = 0; v < r.on_seam.size(); ++v)
    if (r.on_seam[v]) on_seam[c.of_vertex[v]] = 1, meet(fusion::exactPosition(r.mesh.vertices[v]), c.of_vertex[v]);
  for (std::size_t k = 0; k < neighbours.size(); ++k)
    for (const auto& [at, i] : neighbours[k]->seam_vertices) meet(at, std::uint32_t(base[k + 1] + i));
  std::vector<std::uint64_t> faces(base.back(), 0);
  std::vector<double> area(base.back(), 0.0);
  for (std::uint32_t p = 0; p < base.back(); ++p) {
    const std::size_t k = std::size_t(std::upper_bound(base.begin(), base.end(), p) - base.begin()) - 1;
    const std::uint32_t root = joins.find(p);
    faces[root] += k == 0 ? c.faces[p] : neighbours[k - 1]->faces[p - base[k]];
    area[root] += k == 0 ? c.area[p] : neighbours[k - 1]->area[p - base[k]];
  }
  // A fragment judged on this region and its neighbours is judged whole: a component reaching past
  // them spans a whole region (region_bricks * 8 cells, one face at least in each), more faces than
  // min_component_faces. An area bound has no such guarantee: a component it would call small is left
  // to the end.
  const std::uint64_t span = std::uint64_t(params_.region_bricks) * 8;
  for (std::uint32_t comp = 0; comp < c.faces.size(); ++comp) {
    if (!on_seam[comp]) {
      drop[comp] = smallFragment(c.faces[comp], c.area[comp], min_faces, min_area);
      continue;
    }
    const std::uint32_t root = joins.find(comp);
    if (!smallFragment(faces[root], area[root], min_faces, min_area)) continue;  // partial sums: kept whole too
    if (min_area > 0 || min_faces <= 0 || std::uint64_t(min_faces) > span) return false;
    drop[comp] = 1;
  }
  return true;
}

PremeshedLookup RegionPremesher::lookup() const {
  return [this](const Eigen::Vector3i& region, std::uint64_t input_hash) -> const PremeshedRegion* {
    const std::lock_guard<std::mutex> lock(mutex_);
    const auto it = done_.find(keyOf(region));
    return it != done_.end() && it->second.input_hash == input_hash ? &it->second : nullptr;
  };
}

std::size_t RegionPremesher::regionsMeshed() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  return meshed_;
}

}  // namespace vofusion
