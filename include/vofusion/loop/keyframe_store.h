#pragma once
// The run's keyframes, with memory bounded by a budget rather than by the path: every keyframe's
// pose and path length stay in RAM (the pose graph and the candidates' eligibility need them), but
// its features and depth (~0.2 MB) only for the newest ones within `cache_bytes`; older ones go
// zlib-compressed to a SpillFile (while it can be written: then all stay in RAM) and are read back
// when a loop candidate is verified against them.
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "vofusion/core/spill_file.h"
#include "vofusion/loop/keyframe.h"

namespace vofusion::loop {

// Features and depth <-> bytes (depth zlib-compressed); decode throws std::runtime_error on a bad record.
std::vector<std::uint8_t> encodeKeyframeData(const Keyframe& k);
void decodeKeyframeData(const std::vector<std::uint8_t>& bytes, Keyframe& k);

struct KeyframeStoreStats {
  std::size_t keyframes = 0, in_ram = 0;  // in_ram: keyframes whose features and depth are in RAM
  std::size_t spilled = 0, reloaded = 0;
  std::size_t lost = 0;     // spilled keyframes whose record could not be read back (no features, no depth)
  std::uint64_t spill_file_bytes = 0;
  std::string spill_error;  // why the spill file could not be written (disk full); empty when it could
};

class KeyframeStore {
 public:
  KeyframeStore(std::size_t cache_bytes, std::string spill_dir);
  // The next keyframe (ids 0, 1, 2, ... in order); the oldest ones in RAM beyond the budget are spilled.
  // A spill file that cannot be created or written (disk full) is warned of once (stats().spill_error):
  // from then on every keyframe stays in RAM, over the budget.
  void add(Keyframe k);
  std::size_t size() const { return keyframes_.size(); }
  // The stored keyframe: its features and depth are null / empty once spilled (load() has them).
  const Keyframe& at(std::size_t id) const { return keyframes_.at(id); }
  const Keyframe& back() const { return keyframes_.back(); }
  // The whole keyframe, read back from disk when spilled (not cached again: old keyframes are
  // visited once per loop candidate). One whose record cannot be read back whole (an I/O error, bytes
  // damaged on the disk) comes back without features and depth, from load and data alike: it is no
  // place to close a loop or relocalise at any more, and the run goes on. Said once, counted in stats().lost.
  Keyframe load(std::size_t id) const;
  // Its record could not be read back (load() gives it without features): no place any more.
  bool lost(std::size_t id) const { return spill_.isLost(id); }
  // Its depth and features as encodeKeyframeData() gives them: a spilled keyframe's record as stored,
  // not read back, decoded and encoded again (a checkpoint does so for every keyframe of the run).
  std::vector<std::uint8_t> data(std::size_t id) const;
  KeyframeStoreStats stats() const;

 private:
  std::size_t cache_bytes_;
  SpillFile spill_;
  std::vector<Keyframe> keyframes_;
  std::vector<SpillFile::Record> records_;  // per keyframe, its place in spill_ (id < spilled_)
  std::size_t spilled_ = 0;                 // keyframes [0, spilled_) are on disk
  std::size_t ram_bytes_ = 0;
  mutable std::atomic<std::size_t> reloaded_{0};  // load() runs on the loop thread and in relocalise()
  // The keyframe's record, or (damaged) none: k keeps its pose, its features and depth are dropped.
  bool readBack(std::size_t id, std::vector<std::uint8_t>& bytes, Keyframe& k) const;
};

}  // namespace vofusion::loop
