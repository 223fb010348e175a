#include "vofusion/fusion/tsdf_volume.h"

#include "vofusion/core/progress.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <istream>
#include <ostream>
#include <stdexcept>
#include <unordered_set>
#include <utility>
#include <vector>

#include "vofusion/core/parallel.h"
#include "vofusion/fusion/marching_cubes.h"
#include "vofusion/fusion/voxel_projection.h"
#include "vofusion/fusion/voxel_update.h"

#include "tsdf_sampling.h"

namespace vofusion::fusion {

namespace {
inline int modPos(int a, int n) {
  const int m = a % n;
  return m < 0 ? m + n : m;
}
}  // namespace

namespace {
std::size_t slotCount(const TsdfParams& p) {
  if (p.volume_voxels < kBrickEdge || p.volume_voxels % kBrickEdge != 0)
    throw std::invalid_argument("TSDF volume_voxels must be a positive multiple of 8");
  const auto n = static_cast<std::size_t>(p.volume_voxels / kBrickEdge);
  return n * n * n;
}
}  // namespace

TsdfVolume::TsdfVolume(const TsdfParams& params, const Eigen::Vector3f& centre)
    : params_(params), bricks_(slotCount(params)) {
  if (!(params_.voxel_size > 0.f) || !(params_.truncation > 0.f))
    throw std::invalid_argument("TSDF voxel_size and truncation must be positive");
  params_.max_weight = std::clamp(params_.max_weight, 1, 255);
  n_ = params_.volume_voxels / kBrickEdge;
  slots_.assign(static_cast<std::size_t>(n_) * n_ * n_, -1);
  marks_.assign(slots_.size(), 0);
  // Within the world model's keys, as shiftTo keeps it: placed beyond them, the first shift stored the
  // map's bricks under wrapped keys (tens of km away) and the volume never followed the camera again.
  for (int i = 0; i < 3; ++i) {
    const long o = centredOrigin(centre[i]);
    if (o < reachLo() || o > reachHi())
      throw std::invalid_argument("TsdfVolume: a start at (" + std::to_string(centre.x()) + ", " + std::to_string(centre.y()) +
                                  ", " + std::to_string(centre.z()) + ") m is beyond the map's reach (" + reachText() + ")");
    origin_[i] = static_cast<int>(o);
  }
  slot_brick_.assign(slots_.size(), nullptr);
  if (n_ % 4 == 0) block_count_.assign(slots_.size() / 64, 0);
  updateCyclicTables();
  world_ = std::make_unique<WorldModel>(static_cast<std::size_t>(std::max(0, params_.world_cache_mib)) << 20,
                                        params_.work_dir);
}

void TsdfVolume::updateCyclicTables() {
  int stride = 1;
  for (int a = 0; a < 3; ++a) {
    cyclic_[a].resize(n_);
    for (int i = 0; i < n_; ++i) cyclic_[a][i] = stride * modPos(origin_[a] + i, n_);
    stride *= n_;
  }
  if (n_ % 4 != 0) return;
  const int m = n_ / 4;
  stride = 1;
  for (int a = 0; a < 3; ++a) {
    block_cyclic_[a].resize(n_);
    for (int i = 0; i < n_; ++i) block_cyclic_[a][i] = stride * (modPos(origin_[a] + i, n_) / 4);
    stride *= m;
  }
}

int TsdfVolume::blockOfSlot(int slot) const {
  const int m = n_ / 4;
  const int sx = slot % n_, sy = (slot / n_) % n_, sz = slot / (n_ * n_);
  return sx / 4 + m * (sy / 4 + m * (sz / 4));
}

void TsdfVolume::setSlot(int slot, std::int32_t id) {
  if (!block_count_.empty() && (slots_[slot] < 0) != (id < 0)) {
    if (id < 0) --block_count_[blockOfSlot(slot)];
    else ++block_count_[blockOfSlot(slot)];
  }
  slots_[slot] = id;
  slot_brick_[slot] = id < 0 ? nullptr : &bricks_[id];
}

void TsdfVolume::removeBrick(int slot) {
  const std::int32_t id = slots_[slot];
  setSlot(slot, -1);
  if (bricks_.remove(id) < 0) return;
  // The arena's last brick now has id `id`: repoint its slot (every brick in the arena is inside the volume).
  const Eigen::Vector3i& c = bricks_[id].coord;
  setSlot(slotOf(c.x(), c.y(), c.z()), id);
}

Eigen::Vector3f TsdfVolume::minCorner() const {
  return (origin_ * kBrickEdge).cast<float>() * params_.voxel_size;
}

Eigen::Vector3f TsdfVolume::centre() const {
  return minCorner() + Eigen::Vector3f::Constant(0.5f * (params_.volume_voxels - 1) * params_.voxel_size);
}

std::size_t TsdfVolume::bricksInVolume() const {
  return static_cast<std::size_t>(std::count_if(slots_.begin(), slots_.end(), [](std::int32_t id) { return id >= 0; }));
}

std::size_t TsdfVolume::memoryBytes() const {
  const WorldModelStats world = world_->stats();
  return bricks_.size() * sizeof(Brick) +
         slots_.size() * (sizeof(std::int32_t) + sizeof(void*) + 1) + world.ram_bytes + world.index_bytes;
}

std::size_t TsdfVolume::integrate(const cv::Mat& depth, const cv::Mat& bgr, const CameraIntrinsics& cam,
                                  const Eigen::Isometry3f& cam_to_world) {
  CV_Assert(depth.type() == CV_32FC1);
  markTouchedBricks(depth, cam, cam_to_world);
  return updateVoxels(allocateTouchedBricks(), depth, bgr, cam, cam_to_world);
}

// 1. Bricks touched by the truncation band [z - trunc, z + trunc] of (a subsample of) the readings.
void TsdfVolume::markTouchedBricks(const cv::Mat& depth, const CameraIntrinsics& cam, const Eigen::Isometry3f& cam_to_world) {
  const float vs = params_.voxel_size, trunc = params_.truncation;
  const float zmin = params_.min_depth, zmax = params_.max_depth;
  const float fx = cam.fx, fy = cam.fy, cx = cam.cx, cy = cam.cy;
  const Eigen::Matrix3f R = cam_to_world.linear();
  const Eigen::Vector3f t = cam_to_world.translation();
  const float inv_brick = 1.f / (kBrickEdge * vs);
  const int w = depth.cols, h = depth.rows;
  // Sampled readings must lie closer than half a brick apart even at the far end of the range.
  const int step = std::max(1, std::min(params_.mark_step,
                                        static_cast<int>(0.5f * kBrickEdge * vs * std::min(fx, fy) / zmax)));
  // Along each ray, samples of the band no further apart than half a brick, so that a band spanning
  // several bricks steps over none of them (trunc / 2 apart, 5 samples, at the defaults).
  const int band_steps = std::max(2, static_cast<int>(std::ceil(trunc / (0.5f * kBrickEdge * vs))));
  const float band_step = trunc / band_steps;
  std::fill(marks_.begin(), marks_.end(), 0);
  parallelFor(0, (h + step - 1) / step, [&](int row_index) {
    const int y = row_index * step;
    const float* row = depth.ptr<float>(y);
    for (int x = 0; x < w; x += step) {
      const float z = row[x];
      if (!(z >= zmin && z <= zmax)) continue;
      const Eigen::Vector3f ray((x - cx) / fx, (y - cy) / fy, 1.f);
      for (int k = -band_steps; k <= band_steps; ++k) {
        // Not behind the camera (a band wider than the reading's depth): no voxel there is updated by
        // this frame, and the ray mirrored through the camera allocated bricks nobody fills.
        if (z + k * band_step <= 0.f) continue;
        const Eigen::Vector3f p = (R * (ray * (z + k * band_step)) + t) * inv_brick;
        const int s = slotOf(cvFloor(p.x()), cvFloor(p.y()), cvFloor(p.z()));  // = std::floor (tsdf_sampling.h)
        // Many rows mark the same brick: a relaxed atomic store (all write the same 1).
        if (s >= 0) __atomic_store_n(&marks_[s], std::uint8_t{1}, __ATOMIC_RELAXED);
      }
    }
  });
}

// 2. Allocate the touched bricks that are new (serial: the pool grows); returns the touched bricks' ids.
std::vector<std::int32_t> TsdfVolume::allocateTouchedBricks() {
  std::vector<std::int32_t> touched;
  for (std::size_t s = 0; s < marks_.size(); ++s) {
    if (!marks_[s]) continue;
    if (slots_[s] < 0) {
      const int sx = static_cast<int>(s % n_), sy = static_cast<int>((s / n_) % n_), sz = static_cast<int>(s / (n_ * n_));
      const int bx = origin_.x() + modPos(sx - origin_.x(), n_);
      const int by = origin_.y() + modPos(sy - origin_.y(), n_);
      const int bz = origin_.z() + modPos(sz - origin_.z(), n_);
      setSlot(static_cast<int>(s), bricks_.add(Eigen::Vector3i(bx, by, bz)));
    }
    touched.push_back(slots_[s]);
  }
  return touched;
}

// 3. Update the voxels of those bricks: projective signed distance, weighted running average.
std::size_t TsdfVolume::updateVoxels(const std::vector<std::int32_t>& touched, const cv::Mat& depth, const cv::Mat& bgr,
                                     const CameraIntrinsics& cam, const Eigen::Isometry3f& cam_to_world) {
  const bool colour = !bgr.empty() && bgr.type() == CV_8UC3 && bgr.size() == depth.size();
  const float vs = params_.voxel_size, trunc = params_.truncation;
  const float zmin = params_.min_depth, zmax = params_.max_depth;
  const Eigen::Matrix3f R = cam_to_world.linear();
  const Eigen::Vector3f t = cam_to_world.translation();
  const Eigen::Matrix3f Rt = R.transpose();
  const Eigen::Vector3f tc = -Rt * t;
  const Eigen::Vector3f dx = Rt.col(0) * vs, dy = Rt.col(1) * vs, dz = Rt.col(2) * vs;
  std::atomic<std::size_t> updated{0};
  const cv::Mat depth_c = depth.isContinuous() ? depth : depth.clone();
  const cv::Mat bgr_c = colour && !bgr.isContinuous() ? bgr.clone() : bgr;
  // Bilinear depth only where the 4 neighbours spread less than half the truncation (voxel_projection.h).
  const VoxelProjector projector(depth_c, cam, zmin, zmax, 0.5f * trunc);
  const VoxelUpdater updater(trunc, params_.max_weight, colour ? bgr_c.ptr<cv::Vec3b>() : nullptr);
  parallelFor(0, static_cast<int>(touched.size()), [&](int i) {
    Brick& b = bricks_[touched[i]];
    std::size_t brick_updates = 0;
    const Eigen::Vector3f p0 = Rt * ((b.coord * kBrickEdge).cast<float>() * vs) + tc;
    VoxelRowSamples row;
    for (int z = 0; z < kBrickEdge; ++z) {
      for (int y = 0; y < kBrickEdge; ++y) {
        projector.sampleRow(p0 + dy * static_cast<float>(y) + dz * static_cast<float>(z), dx, row);
        brick_updates += updater.updateRow(row, &b.voxels[Brick::index(0, y, z)]);
      }
    }
    updated.fetch_add(brick_updates, std::memory_order_relaxed);
  }, 16);
  return updated.load();
}

bool TsdfVolume::sdfAt(const Eigen::Vector3f& p, float& sdf_m) const {
  float f;
  if (!trilinear(p / params_.voxel_size, f)) return false;
  sdf_m = f * params_.truncation;
  return true;
}

long TsdfVolume::centredOrigin(float metres) const {
  const float q = metres / (kBrickEdge * params_.voxel_size);
  if (!std::isfinite(q)) return reachHi() + 1;
  return std::fabs(q) < 1e12f ? std::lround(q) - n_ / 2 : (q > 0 ? reachHi() + 1 : reachLo() - 1);
}

std::string TsdfVolume::reachText() const {
  const double brick = kBrickEdge * params_.voxel_size;
  return std::to_string(int(WorldModel::kKeyReach * brick / 1000)) + " km from the world's origin on each axis";
}

void TsdfVolume::shiftTo(const Eigen::Vector3f& point) {
  Eigen::Vector3i o;
  // Past the world model's reach the volume stops following, said once, rather than store bricks
  // under another's key.
  for (int i = 0; i < 3; ++i) {
    if (!std::isfinite(point[i])) {  // no place to follow: stay
      o[i] = origin_[i];
      continue;
    }
    const long wanted = centredOrigin(point[i]);
    if ((wanted < reachLo() || wanted > reachHi()) && !reach_warned_) {
      printWarning("the camera left the map's reach (" + reachText() + "): the volume follows it no further");
      reach_warned_ = true;
    }
    o[i] = static_cast<int>(std::clamp(wanted, reachLo(), reachHi()));
  }
  if (o == origin_) return;
  const auto inside = [&](const Eigen::Vector3i& c) {
    return ((c - o).array() >= 0).all() && ((c - o).array() < n_).all();
  };
  // Bricks leaving the volume go to the world model, a batch at a time (its compression on every core;
  // the batch bounds what is held beside the map when the whole volume leaves)...
  constexpr std::size_t kBatch = WorldModel::kBatchBricks;
  std::vector<std::unique_ptr<Brick>> leaving;
  for (std::size_t s = 0; s < slots_.size(); ++s) {
    const std::int32_t id = slots_[s];
    if (id < 0 || inside(bricks_[id].coord)) continue;
    leaving.push_back(std::make_unique<Brick>(bricks_[id]));
    removeBrick(static_cast<int>(s));
    if (leaving.size() == kBatch) world_->putAll(std::exchange(leaving, {}));
  }
  world_->putAll(std::move(leaving));
  origin_ = o;
  updateCyclicTables();
  // ...and world-model bricks the volume now covers come back (camera revisiting a place).
  const std::vector<Eigen::Vector3i> back = world_->coordsInBox(origin_, n_);
  for (std::size_t first = 0; first < back.size(); first += kBatch) {
    const std::vector<Eigen::Vector3i> batch(back.begin() + std::ptrdiff_t(first),
                                             back.begin() + std::ptrdiff_t(std::min(back.size(), first + kBatch)));
    std::vector<std::unique_ptr<Brick>> taken = world_->takeAll(batch);
    for (std::size_t i = 0; i < batch.size(); ++i) {
      setSlot(slotOf(batch[i].x(), batch[i].y(), batch[i].z()), bricks_.add(*taken[i]));
      taken[i].reset();
    }
  }
  bricks_.releaseUnusedPages();
}

bool TsdfVolume::shiftIfNeeded(const Eigen::Vector3f& point, float threshold) {
  if ((point - centre()).norm() <= threshold) return false;
  const Eigen::Vector3i before = origin_;
  shiftTo(point);
  return origin_ != before;
}

std::vector<BrickRef> TsdfVolume::volumeBricks() const {
  std::vector<BrickRef> out;
  for (std::int32_t id : slots_)
    if (id >= 0) out.push_back({bricks_[id].coord, &bricks_[id]});
  return out;
}

std::vector<Eigen::Vector3i> TsdfVolume::allCoords() const {
  std::vector<Eigen::Vector3i> coords = world_->coords();
  for (std::int32_t id : slots_)
    if (id >= 0) coords.push_back(bricks_[id].coord);
  return coords;
}

BrickFetch TsdfVolume::fetcher() const {
  return [this](const Eigen::Vector3i& c, Brick& scratch) -> const Brick* {
    if (const Brick* b = brickAt(c.x(), c.y(), c.z())) return b;
    if (!world_->read(c, scratch)) throw std::logic_error("TSDF brick missing from the world model");
    return &scratch;
  };
}

TriangleMesh TsdfVolume::extractMesh() const {
  return marchingCubesStreamed(allCoords(), fetcher(), params_.voxel_size, 1);
}

void TsdfVolume::extractMeshByRegion(int region_bricks, const std::function<void(RegionMesh&)>& sink) const {
  marchingCubesStreamedByRegion(allCoords(), fetcher(), params_.voxel_size, 1, region_bricks, sink);
}

// Map file body (after the caller's header): "VFTSDF1\n", int32 volume_voxels, float voxel_size,
// float truncation, int32 origin[3], uint64 brick count, per brick int32 coord[3] + uint32 length +
// zlib bytes of its voxels, then "END\n".
namespace {
constexpr char kMagic[8] = {'V', 'F', 'T', 'S', 'D', 'F', '1', '\n'};
template <typename T>
void put(std::ostream& os, const T& v) {
  os.write(reinterpret_cast<const char*>(&v), sizeof(T));
}
template <typename T>
T get(std::istream& is, const char* what) {
  T v{};
  if (!is.read(reinterpret_cast<char*>(&v), sizeof(T))) throw std::runtime_error(std::string("truncated (") + what + ")");
  return v;
}
}  // namespace

void TsdfVolume::save(std::ostream& os) const {
  os.write(kMagic, sizeof(kMagic));
  put<std::int32_t>(os, params_.volume_voxels);
  put<float>(os, params_.voxel_size);
  put<float>(os, params_.truncation);
  for (int i = 0; i < 3; ++i) put<std::int32_t>(os, origin_[i]);
  const std::vector<Eigen::Vector3i> world = world_->coords();
  const std::vector<BrickRef> vol = volumeBricks();
  put<std::uint64_t>(os, world.size() + vol.size());
  const auto write = [&](const Eigen::Vector3i& coord, const std::vector<std::uint8_t>& z) {
    for (int i = 0; i < 3; ++i) put<std::int32_t>(os, coord[i]);
    put<std::uint32_t>(os, static_cast<std::uint32_t>(z.size()));
    os.write(reinterpret_cast<const char*>(z.data()), static_cast<std::streamsize>(z.size()));
  };
  // Compression is most of a save's time (a checkpoint stops the frame loop): the volume's bricks are
  // compressed on every core, then written in order; the world model's too (those in its RAM cache
  // compressed, those on disk read as stored and inflated to check), a bounded batch at a time.
  std::vector<std::vector<std::uint8_t>> packed(vol.size());
  parallelFor(0, int(vol.size()), [&](int i) { packed[std::size_t(i)] = compressBrick(*vol[std::size_t(i)].brick); }, 16);
  for (std::size_t i = 0; i < vol.size(); ++i) write(vol[i].brick->coord, packed[i]);
  constexpr std::size_t kBatch = 512;  // ~2 MiB of compressed bricks in flight
  packed.assign(std::min(kBatch, world.size()), {});
  for (std::size_t first = 0; first < world.size(); first += kBatch) {
    const std::size_t n = std::min(kBatch, world.size() - first);
    parallelForEvery(0, int(n), [&](int i) {
      if (!world_->readCompressed(world[first + std::size_t(i)], packed[std::size_t(i)]))
        throw std::logic_error("TsdfVolume::save: a brick left the world model while saving");
    }, 16);
    for (std::size_t i = 0; i < n; ++i) write(world[first + i], packed[i]);
  }
  os.write("END\n", 4);
  if (!os) throw std::runtime_error("write failed (disk full?)");
}

namespace {
// The map file's header, whose settings must be these `params`; returns the saved volume origin.
Eigen::Vector3i readMapHeader(std::istream& is, const TsdfParams& params, int volume_bricks) {
  char magic[sizeof(kMagic)];
  if (!is.read(magic, sizeof(magic)) || std::memcmp(magic, kMagic, sizeof(kMagic)) != 0)
    throw std::runtime_error("not a vofusion TSDF map");
  const auto vv = get<std::int32_t>(is, "header");
  const auto vs = get<float>(is, "header");
  const auto tr = get<float>(is, "header");
  if (vv != params.volume_voxels || vs != params.voxel_size || tr != params.truncation)
    throw std::runtime_error("saved with volume_voxels " + std::to_string(vv) + ", voxel_size " + std::to_string(vs) +
                             ", truncation " + std::to_string(tr) + ": the [kinfu] settings differ");
  Eigen::Vector3i o;
  for (int i = 0; i < 3; ++i) o[i] = get<std::int32_t>(is, "header");
  // Checked, as the zlib checksums cover only the voxels: a flipped byte here would place bricks
  // elsewhere, or overflow the volume's indices.
  if (!WorldModel::keyHolds(o) || !WorldModel::keyHolds(o + Eigen::Vector3i::Constant(volume_bricks)))
    throw std::runtime_error("corrupt header (volume origin out of range)");
  return o;
}

using PackedBricks = std::vector<std::pair<Eigen::Vector3i, std::vector<std::uint8_t>>>;

// The map file's bricks, each checked, up to its end marker: those outside the volume at `origin` go
// into `world` (spilled as it fills), those inside are returned compressed.
PackedBricks readMapBricks(std::istream& is, const Eigen::Vector3i& origin, int volume_bricks, WorldModel& world) {
  const auto inVolume = [&](const Eigen::Vector3i& c) {
    return ((c - origin).array() >= 0).all() && ((c - origin).array() < volume_bricks).all();
  };
  const auto count = get<std::uint64_t>(is, "brick count");
  PackedBricks in_volume;
  std::unordered_set<std::uint64_t> in_volume_keys;
  std::vector<std::uint8_t> bytes;
  auto scratch = std::make_unique<Brick>();
  for (std::uint64_t i = 0; i < count; ++i) {
    Eigen::Vector3i c;
    for (int k = 0; k < 3; ++k) c[k] = get<std::int32_t>(is, "brick");
    if (!WorldModel::keyHolds(c)) throw std::runtime_error("corrupt brick record (coordinates out of range)");
    const auto len = get<std::uint32_t>(is, "brick");
    if (len == 0 || len > 4 * sizeof(Brick)) throw std::runtime_error("corrupt brick record");
    bytes.resize(len);
    if (!is.read(reinterpret_cast<char*>(bytes.data()), len)) throw std::runtime_error("truncated (brick data)");
    if (inVolume(c)) {
      if (!decompressBrick(bytes.data(), len, *scratch)) throw std::runtime_error("corrupt brick data");
      if (!in_volume_keys.insert(WorldModel::key(c)).second) throw std::runtime_error("brick stored twice");
      in_volume.emplace_back(c, bytes);
    } else {
      auto b = std::make_unique<Brick>();
      if (!decompressBrick(bytes.data(), len, *b)) throw std::runtime_error("corrupt brick data");
      b->coord = c;
      if (world.contains(c)) throw std::runtime_error("brick stored twice");
      world.put(std::move(b));
    }
  }
  char end[4];
  if (!is.read(end, 4) || std::memcmp(end, "END\n", 4) != 0) throw std::runtime_error("truncated (no end marker)");
  return in_volume;
}
}  // namespace

void TsdfVolume::load(std::istream& is) {
  // The whole file is read before the map changes: a bad one leaves the map as it was (a re-fusion
  // that could not take a saved map, and said it fused the frames again without it, kept the part read
  // before the damage). Bricks beyond the volume go to a world model of their own (spilled as it fills);
  // those in it wait compressed (checked whole), and are decompressed into the volume's arena once the
  // file is read: staged whole, they sat on glibc's heap, which keeps freed memory for the frame loop.
  const Eigen::Vector3i o = readMapHeader(is, params_, n_);
  auto world = std::make_unique<WorldModel>(static_cast<std::size_t>(std::max(0, params_.world_cache_mib)) << 20,
                                            params_.work_dir);
  PackedBricks in_volume = readMapBricks(is, o, n_, *world);
  // Read whole: the map becomes the file's, at the saved origin.
  for (std::size_t s = 0; s < slots_.size(); ++s)
    if (slots_[s] >= 0) setSlot(static_cast<int>(s), -1);
  bricks_.clear();
  world_ = std::move(world);
  origin_ = o;
  updateCyclicTables();
  auto scratch = std::make_unique<Brick>();
  for (auto& [c, packed] : in_volume) {
    decompressBrick(packed.data(), packed.size(), *scratch);  // checked on reading
    scratch->coord = c;
    setSlot(slotOf(c.x(), c.y(), c.z()), bricks_.add(*scratch));
    std::vector<std::uint8_t>().swap(packed);
  }
}

}  // namespace vofusion::fusion
