#include "vofusion/fusion/world_model.h"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "vofusion/core/deflate.h"
#include "vofusion/core/parallel.h"

namespace vofusion::fusion {

namespace {
constexpr std::size_t kVoxelBytes = sizeof(Brick::voxels);
constexpr std::size_t kBrickBytes = sizeof(Brick);

Eigen::Vector3i decode(std::uint64_t k) {
  const auto d = [](std::uint64_t v) { return static_cast<int>(v & 0x1fffff) - (1 << 20); };
  return {d(k), d(k >> 21), d(k >> 42)};
}

double since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}
}  // namespace

std::vector<std::uint8_t> compressBrick(const Brick& b) { return zlibCompress(b.voxels, kVoxelBytes); }

bool decompressBrick(const std::uint8_t* data, std::size_t size, Brick& b) {
  return zlibUncompress(data, size, b.voxels, kVoxelBytes);
}

std::uint64_t WorldModel::key(const Eigen::Vector3i& c) {
  const auto u = [](int v) { return static_cast<std::uint64_t>(static_cast<std::uint32_t>(v + (1 << 20)) & 0x1fffff); };
  return u(c.x()) | (u(c.y()) << 21) | (u(c.z()) << 42);
}

WorldModel::WorldModel(std::size_t cache_bytes, std::string spill_dir)
    : cache_bytes_(cache_bytes), spill_(std::move(spill_dir), "the world model's spill file") {}

WorldModel::~WorldModel() = default;

void WorldModel::erase(std::uint64_t k) {
  if (auto it = ram_.find(k); it != ram_.end()) {
    lru_.erase(it->second.lru);
    stats_.ram_bytes -= kBrickBytes;
    ram_.erase(it);
  }
  if (const auto record = disk_.find(k)) {
    spill_.release(*record);
    disk_.erase(k);
  }
}

void WorldModel::cache(std::unique_ptr<Brick> brick) {
  const std::uint64_t k = key(brick->coord);
  erase(k);  // a brick already stored there is replaced
  lru_.push_front(k);
  ram_[k] = {std::move(brick), lru_.begin()};
  stats_.ram_bytes += kBrickBytes;
}

void WorldModel::put(std::unique_ptr<Brick> brick) {
  std::vector<std::unique_ptr<Brick>> one;
  one.push_back(std::move(brick));
  putAll(std::move(one));
}

void WorldModel::putAll(std::vector<std::unique_ptr<Brick>> bricks) {
  const std::lock_guard<std::shared_mutex> lock(mutex_);
  std::size_t due = 0;
  for (std::size_t i = 0; i < bricks.size(); ++i) {
    const std::uint64_t k = key(bricks[i]->coord);
    try {
      // A brick handed over again while due, or one replacing a brick on disk (whose place it frees):
      // what is due goes to disk first, so places are taken and freed in the order of one put at a time.
      const auto cached = ram_.find(k);
      if ((cached != ram_.end() && cached->second.due) || disk_.find(k)) spillDue(due);
      cache(std::move(bricks[i]));
      markDue(due);
      if (due >= kBatchBricks) spillDue(due);
    } catch (...) {
      // No memory, say: the rest stay cached, over the cache's limit.
      for (std::size_t j = i; j < bricks.size(); ++j)
        if (bricks[j]) cache(std::move(bricks[j]));  // null: stored already
      throw;
    }
  }
  spillDue(due);
}

// Puts go to the front of lru_ and spills take the back, so the bricks beyond the cache after each put
// are the same, in the same order, as when each put spilled at once.
void WorldModel::markDue(std::size_t& due) {
  while (stats_.ram_bytes - due * kBrickBytes > cache_bytes_ && due < lru_.size()) {
    auto it = lru_.end();
    std::advance(it, -std::ptrdiff_t(due + 1));
    ram_.find(*it)->second.due = true;
    ++due;
  }
}

// Compressed on every core (a volume shift spills ~1300 bricks on the loop scene: a fifth of its
// re-fusion's CPU on one core) and appended in order, so the spill file is the same. Each brick leaves
// the cache once its record is on disk, as one at a time did.
void WorldModel::spillDue(std::size_t& due) {
  if (due == 0) return;
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<std::uint64_t> keys;
  try {
    keys.reserve(due);
    auto back = lru_.end();
    while (keys.size() < due) keys.push_back(*--back);  // oldest first
    // Records' buffers made here and filled on the workers: what a worker allocates stays in its own
    // heap (bricks made on them lifted the loop scene's peak RSS by 45 MiB).
    std::vector<std::vector<std::uint8_t>> bytes(due, std::vector<std::uint8_t>(zlibCompressBound(kVoxelBytes)));
    parallelForEvery(0, int(due), [&](int i) {
      const Brick& b = *ram_.find(keys[i])->second.brick;
      bytes[i].resize(zlibCompressInto(b.voxels, kVoxelBytes, bytes[i].data(), bytes[i].size()));
    }, 8);
    for (std::size_t i = 0; i < keys.size(); ++i) {
      const std::optional<SpillFile::Record> record = spill_.append(bytes[i]);
      if (!record) {
        // The spill file cannot be written (disk full; SpillFile warns): what is not on disk stays
        // in RAM, and so does every brick handed over from now on, beyond the cache's limit.
        for (std::size_t j = i; j < keys.size(); ++j) ram_.find(keys[j])->second.due = false;
        cache_bytes_ = std::numeric_limits<std::size_t>::max();
        due = 0;
        stats_.spill_seconds += since(t0);
        return;
      }
      disk_.set(keys[i], *record);
      ram_.erase(keys[i]);
      lru_.pop_back();
      stats_.ram_bytes -= kBrickBytes;
      ++stats_.spilled;
    }
  } catch (...) {
    for (std::uint64_t k : keys)
      if (const auto it = ram_.find(k); it != ram_.end()) it->second.due = false;  // back to plain cached
    due = 0;
    throw;
  }
  stats_.spill_seconds += since(t0);
  due = 0;
}

void WorldModel::readRecord(std::uint64_t k, SpillFile::Record r, Brick& out) const {
  const auto t0 = std::chrono::steady_clock::now();
  try {
    const std::vector<std::uint8_t> bytes = spill_.read(r);
    if (!decompressBrick(bytes.data(), bytes.size(), out)) return lose(k, "damaged record", out);
  } catch (const SpillFile::ReadError& e) {  // pread failed, or the file is short (not memory: that goes on up)
    return lose(k, e.cause, out);
  }
  reloaded_.fetch_add(1, std::memory_order_relaxed);
  reload_nanoseconds_.fetch_add(
      std::uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - t0).count()),
      std::memory_order_relaxed);
}

void WorldModel::lose(std::uint64_t k, const std::string& why, Brick& out) const {
  std::fill(std::begin(out.voxels), std::end(out.voxels), Voxel{});
  spill_.lost(k, spill_.folder() + ": cannot read a brick back from the world model's spill file (" + why +
                     "): such bricks are lost from the map (summary.json: fusion.world_model.bricks_lost), the run goes on");
}

std::unique_ptr<Brick> WorldModel::take(const Eigen::Vector3i& c) {
  std::vector<std::unique_ptr<Brick>> one = takeAll({c});
  return std::move(one.front());
}

std::vector<std::unique_ptr<Brick>> WorldModel::takeAll(const std::vector<Eigen::Vector3i>& coords) {
  const std::lock_guard<std::shared_mutex> lock(mutex_);
  std::vector<std::unique_ptr<Brick>> out(coords.size());
  // Bricks on disk are read and decompressed on every core first; their places are released after,
  // in the order given, as taking them one by one releases them (the file's free places are the same).
  std::vector<std::pair<std::size_t, SpillFile::Record>> on_disk;
  std::vector<std::uint8_t> repeat(coords.size(), 0);  // a coordinate given before: null, as a second take gives
  {
    std::unordered_map<std::uint64_t, std::size_t> first;
    for (std::size_t i = 0; i < coords.size(); ++i) {
      const std::uint64_t k = key(coords[i]);
      if (!first.emplace(k, i).second) repeat[i] = 1;
      else if (ram_.count(k) == 0)
        if (const auto record = disk_.find(k)) on_disk.emplace_back(i, *record);
    }
  }
  for (const auto& [i, record] : on_disk) out[i] = std::make_unique<Brick>();  // here, not on the workers (above)
  parallelForEvery(0, int(on_disk.size()), [&](int j) {
    const auto& [i, record] = on_disk[j];
    readRecord(key(coords[i]), record, *out[i]);
  }, 8);
  for (std::size_t i = 0; i < coords.size(); ++i) {
    if (repeat[i]) continue;
    const std::uint64_t k = key(coords[i]);
    if (auto it = ram_.find(k); it != ram_.end()) {
      out[i] = std::move(it->second.brick);
      erase(k);
    } else if (const auto record = disk_.find(k); out[i] && record) {
      spill_.release(*record);
      disk_.erase(k);
    }
    if (out[i]) out[i]->coord = coords[i];
  }
  return out;
}

bool WorldModel::read(const Eigen::Vector3i& c, Brick& out) const {
  const std::shared_lock lock(mutex_);
  const std::uint64_t k = key(c);
  if (const auto it = ram_.find(k); it != ram_.end()) std::memcpy(out.voxels, it->second.brick->voxels, kVoxelBytes);
  else if (const auto record = disk_.find(k)) readRecord(k, *record, out);
  else return false;
  out.coord = c;
  return true;
}

bool WorldModel::readCompressed(const Eigen::Vector3i& c, std::vector<std::uint8_t>& out) const {
  const std::shared_lock lock(mutex_);
  const std::uint64_t k = key(c);
  if (const auto it = ram_.find(k); it != ram_.end()) {
    out = compressBrick(*it->second.brick);
    return true;
  }
  const auto record = disk_.find(k);
  if (!record) return false;
  // Inflated once to check it (a fraction of compressing it again): a damaged record is found now, not
  // sealed into a checkpoint that fails only when resumed.
  Brick check;
  try {
    out = spill_.read(*record);  // spilled as compressBrick makes it
    if (decompressBrick(out.data(), out.size(), check)) return true;
    lose(k, "damaged record", check);
  } catch (const SpillFile::ReadError& e) {
    lose(k, e.cause, check);
  }
  out = compressBrick(check);
  return true;
}

template <class F>
void WorldModel::forEachKey(F&& f) const {
  for (const auto& [k, e] : ram_) f(k);
  disk_.forEachKey(f);
}

std::vector<Eigen::Vector3i> WorldModel::coordsInBox(const Eigen::Vector3i& lo, int n) const {
  const std::shared_lock lock(mutex_);
  std::vector<Eigen::Vector3i> out;
  const auto inBox = [&](std::uint64_t k) {
    const Eigen::Vector3i c = decode(k);
    return ((c - lo).array() >= 0).all() && ((c - lo).array() < n).all();
  };
  const auto take = [&](std::uint64_t k) { out.push_back(decode(k)); };
  for (const auto& [k, e] : ram_)
    if (inBox(k)) take(k);
  // On disk, one key range per row of the box (keys order bricks by z, then y, then x; the box cut to
  // the keys' reach): a volume shift and each region the premesher takes ask this, and walking every
  // brick of a long run's map (1-3 M) cost milliseconds each time. The same bricks in the same order as
  // the walk, which stays for boxes with more rows than the map has bricks.
  const Eigen::Vector3i first = lo.cwiseMax(Eigen::Vector3i::Constant(-kKeyReach)),
                        last = (lo + Eigen::Vector3i::Constant(n - 1)).cwiseMin(Eigen::Vector3i::Constant(kKeyReach - 1));
  if (n <= 0 || (first.array() > last.array()).any()) return out;
  const std::size_t row_count = std::size_t(last.y() - first.y() + 1) * std::size_t(last.z() - first.z() + 1);
  if (row_count > disk_.size()) {
    disk_.forEachKey([&](std::uint64_t k) {
      if (inBox(k)) take(k);
    });
    return out;
  }
  std::vector<std::pair<std::uint64_t, std::uint64_t>> rows;
  rows.reserve(row_count);
  for (int z = first.z(); z <= last.z(); ++z)
    for (int y = first.y(); y <= last.y(); ++y) rows.emplace_back(key({first.x(), y, z}), key({last.x(), y, z}));
  disk_.forEachKeyIn(rows, inBox, take);
  return out;
}

std::size_t WorldModel::size() const {
  const std::shared_lock lock(mutex_);
  return ram_.size() + disk_.size();
}

bool WorldModel::contains(const Eigen::Vector3i& c) const {
  const std::shared_lock lock(mutex_);
  return ram_.count(key(c)) != 0 || disk_.find(key(c)).has_value();
}

std::vector<Eigen::Vector3i> WorldModel::coords() const {
  const std::shared_lock lock(mutex_);
  std::vector<Eigen::Vector3i> out;
  out.reserve(ram_.size() + disk_.size());
  forEachKey([&](std::uint64_t k) { out.push_back(decode(k)); });
  return out;
}

WorldModelStats WorldModel::stats() const {
  const std::shared_lock lock(mutex_);
  WorldModelStats s = stats_;
  s.bricks = ram_.size() + disk_.size();
  s.bricks_in_ram = lru_.size();
  // cache: map node + bucket ~64, list node ~24; a free place of the spill file: two tree nodes ~96
  s.index_bytes = disk_.bytes() + lru_.size() * 88 + spill_.freePlaces() * 96;
  s.spill_file_bytes = spill_.bytes();
  s.spill_free_bytes = spill_.freeBytes();
  s.spill_error = spill_.failure();
  s.reloaded = reloaded_.load(std::memory_order_relaxed);
  s.lost = spill_.lostCount();
  s.spill_seconds += 1e-9 * double(reload_nanoseconds_.load(std::memory_order_relaxed));
  return s;
}

}  // namespace vofusion::fusion
