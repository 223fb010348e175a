#include "vofusion/fusion/world_model.h"

#include <fcntl.h>
#include <unistd.h>
#include <zlib.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>

#include "vofusion/core/errors.h"

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

std::vector<std::uint8_t> compressBrick(const Brick& b) {
  uLongf len = compressBound(kVoxelBytes);
  std::vector<std::uint8_t> out(len);
  if (compress2(out.data(), &len, reinterpret_cast<const Bytef*>(b.voxels), kVoxelBytes, 1) != Z_OK)
    throw std::runtime_error("zlib: cannot compress a TSDF brick");
  out.resize(len);
  return out;
}

bool decompressBrick(const std::uint8_t* data, std::size_t size, Brick& b) {
  uLongf len = kVoxelBytes;
  return uncompress(reinterpret_cast<Bytef*>(b.voxels), &len, data, size) == Z_OK && len == kVoxelBytes;
}

std::uint64_t WorldModel::key(const Eigen::Vector3i& c) {
  const auto u = [](int v) { return static_cast<std::uint64_t>(static_cast<std::uint32_t>(v + (1 << 20)) & 0x1fffff); };
  return u(c.x()) | (u(c.y()) << 21) | (u(c.z()) << 42);
}

WorldModel::WorldModel(std::size_t cache_bytes, std::string spill_dir)
    : cache_bytes_(cache_bytes), spill_dir_(std::move(spill_dir)) {}

WorldModel::~WorldModel() {
  if (fd_ >= 0) ::close(fd_);
}

void WorldModel::openSpill() {
  namespace fs = std::filesystem;
  const fs::path dir = spill_dir_.empty() || spill_dir_ == "auto" ? fs::temp_directory_path() : fs::path(spill_dir_);
  std::error_code ec;
  fs::create_directories(dir, ec);
  std::string name = (dir / "vofusion-world-XXXXXX").string();
  fd_ = ::mkstemp(name.data());
  if (fd_ < 0) throw InputError(dir.string(), std::string("cannot create the world model's spill file: ") + std::strerror(errno));
  ::unlink(name.c_str());  // gone with the process, whatever happens to it
}

void WorldModel::put(std::unique_ptr<Brick> brick) {
  const std::uint64_t k = key(brick->coord);
  auto it = index_.find(k);
  if (it != index_.end()) {
    if (it->second.ram) {
      lru_.erase(it->second.lru);
      stats_.ram_bytes -= kBrickBytes;
    }
    index_.erase(it);
  }
  lru_.push_front(k);
  Entry& e = index_[k];
  e.ram = std::move(brick);
  e.lru = lru_.begin();
  stats_.ram_bytes += kBrickBytes;
  evict();
}

void WorldModel::evict() {
  while (stats_.ram_bytes > cache_bytes_ && !lru_.empty()) {
    const auto t0 = std::chrono::steady_clock::now();
    if (fd_ < 0) openSpill();
    const std::uint64_t k = lru_.back();
    Entry& e = index_.at(k);
    const std::vector<std::uint8_t> bytes = compressBrick(*e.ram);
    std::size_t done = 0;
    while (done < bytes.size()) {
      const ssize_t w = ::pwrite(fd_, bytes.data() + done, bytes.size() - done, static_cast<off_t>(end_ + done));
      if (w < 0 && errno == EINTR) continue;
      if (w <= 0) throw InputError(spill_dir_.empty() ? "spill file" : spill_dir_,
                                   std::string("cannot write the world model's spill file: ") + std::strerror(errno));
      done += static_cast<std::size_t>(w);
    }
    e.offset = end_;
    e.length = static_cast<std::uint32_t>(bytes.size());
    end_ += bytes.size();
    e.ram.reset();
    lru_.pop_back();
    stats_.ram_bytes -= kBrickBytes;
    ++stats_.spilled;
    stats_.spill_seconds += since(t0);
  }
}

void WorldModel::readRecord(const Entry& e, Brick& out) const {
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<std::uint8_t> bytes(e.length);
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t r = ::pread(fd_, bytes.data() + done, bytes.size() - done, static_cast<off_t>(e.offset + done));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) throw std::runtime_error(std::string("cannot read the world model's spill file: ") + std::strerror(errno));
    done += static_cast<std::size_t>(r);
  }
  if (!decompressBrick(bytes.data(), bytes.size(), out)) throw std::runtime_error("corrupt record in the world model's spill file");
  ++stats_.reloaded;
  stats_.spill_seconds += since(t0);
}

std::unique_ptr<Brick> WorldModel::take(const Eigen::Vector3i& c) {
  auto it = index_.find(key(c));
  if (it == index_.end()) return nullptr;
  std::unique_ptr<Brick> b;
  if (it->second.ram) {
    b = std::move(it->second.ram);
    lru_.erase(it->second.lru);
    stats_.ram_bytes -= kBrickBytes;
  } else {
    b = std::make_unique<Brick>();
    readRecord(it->second, *b);
    b->coord = c;
  }
  index_.erase(it);
  return b;
}

bool WorldModel::read(const Eigen::Vector3i& c, Brick& out) const {
  const auto it = index_.find(key(c));
  if (it == index_.end()) return false;
  if (it->second.ram) std::memcpy(out.voxels, it->second.ram->voxels, kVoxelBytes);
  else readRecord(it->second, out);
  out.coord = c;
  return true;
}

std::vector<Eigen::Vector3i> WorldModel::coordsInBox(const Eigen::Vector3i& lo, int n) const {
  std::vector<Eigen::Vector3i> out;
  for (const auto& [k, e] : index_) {
    const Eigen::Vector3i c = decode(k);
    if (((c - lo).array() >= 0).all() && ((c - lo).array() < n).all()) out.push_back(c);
  }
  return out;
}

std::vector<Eigen::Vector3i> WorldModel::coords() const {
  std::vector<Eigen::Vector3i> out;
  out.reserve(index_.size());
  for (const auto& [k, e] : index_) out.push_back(decode(k));
  return out;
}

WorldModelStats WorldModel::stats() const {
  WorldModelStats s = stats_;
  s.bricks = index_.size();
  s.bricks_in_ram = lru_.size();
  s.spill_file_bytes = end_;
  return s;
}

}  // namespace vofusion::fusion
