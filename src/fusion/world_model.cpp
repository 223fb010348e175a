#include "vofusion/fusion/world_model.h"

#include <chrono>
#include <cstring>
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

void WorldModel::put(std::unique_ptr<Brick> brick) {
  std::vector<std::unique_ptr<Brick>> one;
  one.push_back(std::move(brick));
  putAll(std::move(one));
}

void WorldModel::putAll(std::vector<std::unique_ptr<Brick>> bricks) {
  const std::lock_guard<std::shared_mutex> lock(mutex_);
  Evicted due;
  for (auto& brick : bricks) {
    const std::uint64_t k = key(brick->coord);
    // A brick handed over again, or one replacing a brick stored on disk (whose place it frees): what
    // is due goes to disk first, so places are taken and freed in the order of one put at a time.
    if (due.keys.count(k) != 0 || disk_.find(k)) spill(due);
    erase(k);  // a brick already stored there is replaced
    lru_.push_front(k);
    ram_[k] = {std::move(brick), lru_.begin()};
    stats_.ram_bytes += kBrickBytes;
    // The least recently handed over beyond the cache: the same bricks, in the same order, as
    // spilling after each put (puts go to the front, evictions take the back).
    while (stats_.ram_bytes > cache_bytes_ && !lru_.empty()) {
      const std::uint64_t old = lru_.back();
      auto it = ram_.find(old);
      due.keys.insert(old);
      due.bricks.emplace_back(old, std::move(it->second.brick));
      ram_.erase(it);
      lru_.pop_back();
      stats_.ram_bytes -= kBrickBytes;
    }
  }
  spill(due);
}

// Compressed on every core (a volume shift spills ~1300 bricks on the loop scene: a fifth of its
// re-fusion's CPU on one core) and appended in order, so the spill file is the same.
void WorldModel::spill(Evicted& due) {
  if (due.bricks.empty()) return;
  const auto t0 = std::chrono::steady_clock::now();
  auto& out = due.bricks;
  // Buffers made here, filled on the workers (nothing allocated there: heap kept per thread).
  std::vector<std::vector<std::uint8_t>> bytes(out.size(), std::vector<std::uint8_t>(zlibCompressBound(kVoxelBytes)));
  std::size_t spilled = 0;
  try {
    parallelFor(0, int(out.size()), [&](int i) {
      bytes[i].resize(zlibCompressInto(out[i].second->voxels, kVoxelBytes, bytes[i].data(), bytes[i].size()));
    }, 8);
    for (; spilled < out.size(); ++spilled) disk_.set(out[spilled].first, spill_.append(bytes[spilled]));
  } catch (...) {
    // What did not reach the disk (no memory, disk full) goes back to the cache where it was, the oldest last.
    for (std::size_t i = out.size(); i-- > spilled;) {
      lru_.push_back(out[i].first);
      ram_[out[i].first] = {std::move(out[i].second), std::prev(lru_.end())};
      stats_.ram_bytes += kBrickBytes;
    }
    stats_.spilled += spilled;
    due = {};
    throw;
  }
  stats_.spilled += out.size();
  stats_.spill_seconds += since(t0);
  due = {};
}

void WorldModel::readRecord(SpillFile::Record r, Brick& out) const {
  const auto t0 = std::chrono::steady_clock::now();
  const std::vector<std::uint8_t> bytes = spill_.read(r);
  if (!decompressBrick(bytes.data(), bytes.size(), out)) throw std::runtime_error("corrupt record in the world model's spill file");
  reloaded_.fetch_add(1, std::memory_order_relaxed);
  reload_nanoseconds_.fetch_add(
      std::uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - t0).count()),
      std::memory_order_relaxed);
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
  for (std::size_t i = 0; i < coords.size(); ++i) {
    const std::uint64_t k = key(coords[i]);
    if (ram_.count(k) == 0)
      if (const auto record = disk_.find(k)) on_disk.emplace_back(i, *record);
  }
  for (const auto& [i, record] : on_disk) out[i] = std::make_unique<Brick>();  // here, not on the workers
  parallelFor(0, int(on_disk.size()), [&](int j) { readRecord(on_disk[j].second, *out[on_disk[j].first]); }, 8);
  for (std::size_t i = 0; i < coords.size(); ++i) {
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
  else if (const auto record = disk_.find(k)) readRecord(*record, out);
  else return false;
  out.coord = c;
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
  forEachKey([&](std::uint64_t k) {
    const Eigen::Vector3i c = decode(k);
    if (((c - lo).array() >= 0).all() && ((c - lo).array() < n).all()) out.push_back(c);
  });
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
  s.reloaded = reloaded_.load(std::memory_order_relaxed);
  s.spill_seconds += 1e-9 * double(reload_nanoseconds_.load(std::memory_order_relaxed));
  return s;
}

}  // namespace vofusion::fusion
