#pragma once
// The store of the bricks that left the moving volume (KinFu Large Scale's WorldModel): the volume
// hands bricks over when they leave (putAll, a shift's batch) and takes them back when the volume
// covers them again (takeAll); nothing else crosses. Bricks are addressed by their world brick
// coordinate. Up to `cache_bytes` of them stay in RAM (least recently handed over first out); the
// rest are written zlib-compressed to a SpillFile in `spill_dir` (while it can be written: then every
// brick stays in RAM). A brick on disk costs RAM only for its index entry (~40 bytes), so a long
// walk's memory grows by that alone; a brick taken back frees its place in the file for the next.
// Every member locks the store: the frame loop hands bricks over (put/take) while the region mesher
// (pipeline/region_premesher.h) reads the regions the volume has left. Reads share the lock, so
// meshing at the end reads and decompresses a region's spilled bricks on every core.
#include <cstdint>
#include <functional>
#include <list>
#include <memory>
#include <atomic>
#include <mutex>
#include <shared_mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "vofusion/core/spill_file.h"
#include "vofusion/fusion/brick_index.h"
#include "vofusion/fusion/voxel_brick.h"

namespace vofusion::fusion {

// Brick voxels <-> zlib (level 1) bytes; decompressBrick returns false on a corrupt record.
std::vector<std::uint8_t> compressBrick(const Brick& b);
bool decompressBrick(const std::uint8_t* data, std::size_t size, Brick& b);

struct WorldModelStats {
  std::size_t bricks = 0;          // stored (RAM + disk)
  std::size_t bricks_in_ram = 0;
  std::size_t ram_bytes = 0;       // brick storage held in RAM (the cache)
  std::size_t index_bytes = 0;     // the indexes of both (estimated: cache map and LRU nodes, BrickIndex)
  std::size_t spill_file_bytes = 0;  // the spill file's size: the records stored, and free places
  std::size_t spill_free_bytes = 0;  // of it, bricks taken back whose place no brick took since
  std::size_t spilled = 0, reloaded = 0;  // bricks written to / read back from the spill file
  std::size_t lost = 0;            // bricks whose record could not be read back (read as never observed)
  double spill_seconds = 0.0;      // wall time compressing + writing + reading + decompressing (batches on every core)
  std::string spill_error;         // why the spill file could not be written (disk full); empty when it could
};

class WorldModel {
 public:
  // cache_bytes: brick storage kept in RAM (0: every brick handed over is spilled).
  WorldModel(std::size_t cache_bytes, std::string spill_dir);
  ~WorldModel();
  WorldModel(const WorldModel&) = delete;
  WorldModel& operator=(const WorldModel&) = delete;

  // Slices out: the brick (its coord set) leaves the volume. A brick already stored there is replaced.
  void put(std::unique_ptr<Brick> brick);
  // Slices back in: the brick at world brick coordinate c, removed from the store; null when none.
  std::unique_ptr<Brick> take(const Eigen::Vector3i& c);
  // Bricks compressed or read at a time: a spill holds at most this many records' buffers (~3 KB each)
  // beyond the cache, and a shift hands over and takes back this many at once, however many move.
  static constexpr std::size_t kBatchBricks = 512;
  // A volume shift's bricks at once: the same as put / take one by one in the order given, the
  // compression and decompression on every core. A brick stays cached until its record is on disk.
  // A spill file that cannot be created or written (disk full) is warned of once (stats().spill_error):
  // from then on every brick stays in the cache, over its limit, and nothing is lost.
  void putAll(std::vector<std::unique_ptr<Brick>> bricks);
  std::vector<std::unique_ptr<Brick>> takeAll(const std::vector<Eigen::Vector3i>& coords);
  // Coordinates of the stored bricks inside the box [lo, lo + n) (per axis).
  std::vector<Eigen::Vector3i> coordsInBox(const Eigen::Vector3i& lo, int n) const;
  // Coordinates of every stored brick.
  std::vector<Eigen::Vector3i> coords() const;
  // Copies a stored brick without changing what is cached; false when there is none. Safe beside
  // other reads on other threads.
  // A spilled brick whose record cannot be read back whole (an I/O error, bytes damaged on the disk)
  // comes back from read, readCompressed and takeAll as never observed (every weight 0): the map loses
  // that brick and the camera sees the place anew, the run goes on. Said once, counted in stats().lost.
  bool read(const Eigen::Vector3i& c, Brick& out) const;
  // A stored brick's voxels as compressBrick() gives them: a brick on disk is its record as stored, not
  // decompressed and compressed again (what a save of a long run's map spent most of its time on).
  // False when there is none.
  bool readCompressed(const Eigen::Vector3i& c, std::vector<std::uint8_t>& out) const;

  std::size_t size() const;
  bool contains(const Eigen::Vector3i& c) const;
  WorldModelStats stats() const;
  static std::uint64_t key(const Eigen::Vector3i& c);
  // Brick coordinates the keys hold: [-kKeyReach, kKeyReach) on each axis (21 bits).
  static constexpr int kKeyReach = 1 << 20;
  static bool keyHolds(const Eigen::Vector3i& c) {
    return (c.array() >= -kKeyReach).all() && (c.array() < kKeyReach).all();
  }

 private:
  struct Cached {
    std::unique_ptr<Brick> brick;
    std::list<std::uint64_t>::iterator lru;    // its place in lru_
    bool due = false;                          // beyond the cache: to be spilled (the back of lru_)
  };
  // Marks the bricks beyond the cache as due, back to front; `due` counts them.
  void markDue(std::size_t& due);
  // Spills the `due` bricks at the back of lru_, oldest first; `due` is 0 after, whatever happens.
  void spillDue(std::size_t& due);
  void cache(std::unique_ptr<Brick> brick);  // into RAM at the front of lru_, replacing what is stored there
  void erase(std::uint64_t k);
  void readRecord(std::uint64_t k, SpillFile::Record r, Brick& out) const;  // under either lock
  void lose(std::uint64_t k, const std::string& why, Brick& out) const;     // out: never observed
  template <class F> void forEachKey(F&& f) const;

  std::size_t cache_bytes_;
  SpillFile spill_;
  std::unordered_map<std::uint64_t, Cached> ram_;             // the cache
  BrickIndex disk_;                            // the rest, by key
  std::list<std::uint64_t> lru_;               // keys of the bricks in RAM, most recent first
  WorldModelStats stats_;                      // but reloaded and spill_seconds' reading part:
  mutable std::atomic<std::size_t> reloaded_{0};          // counted under a shared lock
  mutable std::atomic<std::uint64_t> reload_nanoseconds_{0};
  mutable std::shared_mutex mutex_;            // put/take exclusive, the rest shared
};

}  // namespace vofusion::fusion
