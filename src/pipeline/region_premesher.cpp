#include "vofusion/pipeline/region_premesher.h"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <stdexcept>
#include <unordered_map>
#include <unordered_set>

#include <tbb/task_arena.h>

#include "vofusion/core/errors.h"
#include "vofusion/core/progress.h"
#include "vofusion/core/thread_name.h"

#include "union_find.h"

namespace vofusion {

namespace {

std::array<int, 3> keyOf(const Eigen::Vector3i& r) { return {r.x(), r.y(), r.z()}; }
Eigen::Vector3i vectorOf(const std::array<int, 3>& k) { return {k[0], k[1], k[2]}; }

// The 26 regions round a region (no allocation: called for every region a shift reaches).
std::array<std::array<int, 3>, 26> neighboursOf(const std::array<int, 3>& k) {
  std::array<std::array<int, 3>, 26> out;
  std::size_t n = 0;
  for (int dx = -1; dx <= 1; ++dx)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dz = -1; dz <= 1; ++dz)
        if (dx || dy || dz) out[n++] = {k[0] + dx, k[1] + dy, k[2] + dz};
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

void RegionPremesher::volumeShifted(const fusion::TsdfVolume& volume, const std::optional<Eigen::Vector3i>& old_origin) {
  try {
    followShift(volume, old_origin);
  } catch (const std::bad_alloc&) {
    // Meshing while tracking only saves time: without memory for its lists it stops, rather than fail
    // the fusion it was called from. What it made stays, and is taken only where its input matches.
    if (halt(true))
      printWarning("meshing while tracking: no memory to follow the volume: the rest of the mesh is made at the end");
  }
}

bool RegionPremesher::halt(bool out_of_memory) {
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    if (stopping_) return false;
    stopping_ = true;
    out_of_memory_ = out_of_memory;
    queue_.clear();
    queued_.clear();
  }
  wake_.notify_one();
  idle_.notify_all();
  return true;
}

void RegionPremesher::followShift(const fusion::TsdfVolume& volume, const std::optional<Eigen::Vector3i>& old_origin) {
  const int rb = params_.region_bricks;
  // After a load, the regions of the whole map: listed before the lock, which the fusion thread takes.
  std::set<Key> loaded;
  if (!old_origin)
    for (const Eigen::Vector3i& b : volume.worldModel().coords()) loaded.insert(keyOf(fusion::regionOf(b, rb)));
  const std::lock_guard<std::mutex> lock(mutex_);
  if (stopping_) return;
  // What was made of a map a load replaced would be stale, and work in flight would read freed bricks.
  if (!old_origin && world_)
    throw std::logic_error("RegionPremesher: a map was loaded after the volume had moved or another map was loaded");
  world_ = &volume.worldModel();
  voxel_size_ = volume.params().voxel_size;
  box_bricks_ = volume.bricksPerSide();
  origin_ = volume.originBrick();
  // Calls f for each region the box of bricks [o, o + n) reaches (from the region holding brick o - 1
  // to the one holding o + n - 1, those whose range meets the box).
  const auto forRegionsReached = [&](const Eigen::Vector3i& o, const auto& f) {
    const Eigen::Vector3i first = fusion::regionOf(o - Eigen::Vector3i::Ones(), rb);
    const Eigen::Vector3i last = fusion::regionOf(o + Eigen::Vector3i::Constant(box_bricks_ - 1), rb);
    for (int x = first.x(); x <= last.x(); ++x)
      for (int y = first.y(); y <= last.y(); ++y)
        for (int z = first.z(); z <= last.z(); ++z)
          if (const Key k{x, y, z}; reaches(k, o)) f(k);
  };
  // Regions the volume reaches now may change: what was made of them is stale, and so are their
  // neighbours' judgements made with their pieces.
  forRegionsReached(origin_, [&](const Key& k) {
    ++generation_[k];
    pieces_.erase(k);
    empty_.erase(k);
    done_.erase(k);
    for (const Key& n : neighboursOf(k)) done_.erase(n);
  });
  // Regions it reached before and does not now are final until it comes back; after a load, every
  // region of the map it does not reach.
  bool queued = false;
  const auto queueIfFinal = [&](const Key& k) {
    // Once in the queue at most: a box swinging over a boundary left the same regions again and again.
    if (reaches(k, origin_) || !queued_.insert(k).second) return;
    queue_.push_back(k);
    queued = true;
  };
  if (old_origin) forRegionsReached(*old_origin, queueIfFinal);
  for (const Key& k : loaded) queueIfFinal(k);
  if (queued) wake_.notify_one();
}

void RegionPremesher::waitIdle() {
  std::unique_lock<std::mutex> lock(mutex_);
  idle_.wait(lock, [&] { return stopping_ || (queue_.empty() && !in_hand_); });
}

void RegionPremesher::stop() {
  halt(false);  // already halted for want of memory: it stays so
  if (thread_.joinable()) thread_.join();
  // What only the thread needed, before the end's meshing (the run's peak) begins.
  pieces_.clear();
  empty_.clear();
  generation_.clear();
  scratch_ = {};
}

void RegionPremesher::run() {
  // Only what the frame loop leaves of the two cores: the lowest priority, and marching cubes'
  // parallel loops kept on this thread (a one-slot arena) instead of the pool the frame loop uses.
  nameThisThread("vof-premesh");
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
      queued_.erase(region);
      in_hand_ = true;
    }
    try {
      alone.execute([&] {
        summarise(region);
        // The region, or a neighbour waiting for it, may be ready to simplify.
        simplifyIfReady(region);
        for (const Key& n : neighboursOf(region)) simplifyIfReady(n);
      });
    } catch (...) {
      // The end meshes such a region (and its neighbours, which waited for it) and reports what is
      // wrong there (a spilled brick that does not read back comes as never observed, no failure).
      if (failed_.fetch_add(1) == 0) warnOfFailure(std::current_exception());
    }
    const std::lock_guard<std::mutex> lock(mutex_);
    in_hand_ = false;
    if (queue_.empty()) idle_.notify_all();
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
  std::vector<Eigen::Vector3i> own;
  std::unordered_set<std::uint64_t> reach;  // own and +1 bricks: one scan of the world model
  for (const Eigen::Vector3i& c : world->coordsInBox(lo, rb + 1)) {
    reach.insert(fusion::WorldModel::key(c));
    if (((c - lo).array() < rb).all()) own.push_back(c);
  }
  if (own.empty()) return {};
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
    // Summarised already (what is made of a region goes when the volume reaches it again).
    if (stopping_ || !finalNow(region) || pieces_.count(region) || empty_.count(region)) return;
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
  else pieces_[region] = std::make_shared<const SeamPieces>(std::move(p));
}

// The region is marched again here rather than kept from summarise(): regions wait for their
// neighbours while others are marched, and holding their raw meshes (~4 MB a region of the long walk)
// would cost more memory than marching again costs time.
void RegionPremesher::simplifyIfReady(const Key& region) {
  const int rb = params_.region_bricks;
  std::vector<std::uint64_t> generations;  // the region's and its neighbours': what the judgement rests on
  std::vector<std::shared_ptr<const SeamPieces>> neighbours;
  std::vector<Key> unknown;  // final neighbours neither summarised nor known empty
  const fusion::WorldModel* world;
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    if (stopping_ || !pieces_.count(region) || done_.count(region)) return;
    for (const Key& n : neighboursOf(region)) {
      if (!finalNow(n)) return;
      if (const auto it = pieces_.find(n); it != pieces_.end()) neighbours.push_back(it->second);
      else if (!empty_.count(n)) unknown.push_back(n);
    }
    generations = generationsAround(region);
    world = world_;
  }
  if (!unknown.empty()) {
    // One scan of the world model for the block round the region, outside the lock the fusion thread
    // takes at a shift. A final neighbour without bricks was never reached (none can come while it
    // is final); one with bricks is to be summarised yet: wait for it.
    std::set<Key> with_bricks;
    for (const Eigen::Vector3i& b : world->coordsInBox((vectorOf(region) - Eigen::Vector3i::Ones()) * rb, 3 * rb))
      with_bricks.insert(keyOf(fusion::regionOf(b, rb)));
    const std::lock_guard<std::mutex> lock(mutex_);
    if (generationsAround(region) != generations) return;  // the scan may be of bricks since taken back
    for (const Key& n : unknown) {
      if (with_bricks.count(n) || !finalNow(n)) return;  // to be summarised, or reached again meanwhile
      empty_.insert(n);
    }
  }
  bool ok = false;
  fusion::RegionMesh r = march(region, ok);
  if (!ok || r.mesh.faces.empty()) return;
  const RegionComponents c = componentsOf(r.mesh);
  std::vector<std::uint8_t> drop;
  if (!judge(r, c, neighbours, drop)) return;
  dropComponents(r, c.of_vertex, drop);
  PremeshedRegion done;
  done.input_hash = regionInputHash(r);
  done.report = simplifyRegion(r.mesh, r.on_seam, region_params_);
  // A region that failed (no memory, say) is left to the end, which reports it if it fails there too.
  if (!done.report.success) return;
  done.mesh = std::move(r.mesh);
  done.on_seam = std::move(r.on_seam);
  const std::lock_guard<std::mutex> lock(mutex_);
  // The volume came back to it or to a neighbour meanwhile: judged with pieces that are gone. Kept, it
  // would also stop the redo (done_ is what simplifyIfReady skips).
  if (generationsAround(region) != generations) return;
  done_[region] = std::move(done);
  ++meshed_;
}

std::vector<std::uint64_t> RegionPremesher::generationsAround(const Key& region) const {
  const auto of = [&](const Key& k) {  // without an entry for a region never reached
    const auto it = generation_.find(k);
    return it == generation_.end() ? std::uint64_t(0) : it->second;
  };
  std::vector<std::uint64_t> g{of(region)};
  for (const Key& n : neighboursOf(region)) g.push_back(of(n));
  return g;
}

bool RegionPremesher::judge(const fusion::RegionMesh& r, const RegionComponents& c,
                            const std::vector<std::shared_ptr<const SeamPieces>>& neighbours,
                            std::vector<std::uint8_t>& drop) const {
  const int min_faces = params_.min_component_faces;
  const double min_area = params_.min_component_area;
  drop.assign(c.faces.size(), 0);
  if (min_faces <= 0 && min_area <= 0) return true;
  // Pieces: this region's components, then each neighbour's; joined where they share a seam vertex.
  std::vector<std::size_t> base{0};
  base.push_back(c.faces.size());
  for (const auto& n : neighbours) base.push_back(base.back() + n->faces.size());
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
  const std::uint64_t span = std::uint64_t(params_.region_bricks) * fusion::kBrickEdge;
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

PremeshedLookup RegionPremesher::lookup() {
  if (thread_.joinable()) throw std::logic_error("RegionPremesher::lookup before stop()");
  // Hashed only for a region made during the run: most regions of a short run have none. The thread
  // has ended; the lock keeps two meshings from erasing at once.
  return [this](const fusion::RegionMesh& r) -> std::optional<PremeshedRegion> {
    const std::lock_guard<std::mutex> lock(mutex_);
    const auto it = done_.find(keyOf(r.region));
    if (it == done_.end() || it->second.input_hash != regionInputHash(r)) return std::nullopt;
    return std::move(done_.extract(it).mapped());
  };
}

void RegionPremesher::discard() {
  if (thread_.joinable()) throw std::logic_error("RegionPremesher::discard before stop()");
  const std::lock_guard<std::mutex> lock(mutex_);
  done_.clear();
}

std::size_t RegionPremesher::regionsHeld() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  return done_.size();
}

std::size_t RegionPremesher::regionsFailed() const { return failed_.load(); }

bool RegionPremesher::stoppedWithoutMemory() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  return out_of_memory_;
}

void RegionPremesher::warnOfFailure(const std::exception_ptr& failure) noexcept {
  try {  // the message is built with memory too: without it, the count says it
    try {
      std::rethrow_exception(failure);
    } catch (const std::exception& e) {
      printWarning("meshing while tracking: a region failed (" + oneLineMessage(e) + "): it and its neighbours are meshed at the end");
    } catch (...) {
      printWarning("meshing while tracking: a region failed (unknown error): it and its neighbours are meshed at the end");
    }
  } catch (...) {
  }
}

std::size_t RegionPremesher::regionsMeshed() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  return meshed_;
}

}  // namespace vofusion
