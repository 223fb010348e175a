#pragma once
// The world model's index of its bricks on disk: brick key -> spill-file record, 16 bytes a brick.
// One sorted array (mapped: core/mapped_allocator.h) and a small hash map of the latest insertions,
// merged into the array when it fills; an erased entry is marked in place and dropped at the next
// merge. An std::unordered_map costs ~40 bytes a brick (node and bucket) and leaves its outgrown
// bucket arrays in the heap: over a 100 m walk (~400 k bricks) ~16 MiB and as much again in holes.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <unordered_map>
#include <utility>
#include <vector>

#include "vofusion/core/mapped_allocator.h"
#include "vofusion/core/spill_file.h"

namespace vofusion::fusion {

class BrickIndex {
 public:
  BrickIndex();  // reserves room (address space) for kReserved bricks
  using Record = SpillFile::Record;
  // Inserts k or replaces its record. A record's length is never 0 (0 marks erased entries).
  void set(std::uint64_t k, Record r);
  std::optional<Record> find(std::uint64_t k) const;
  bool erase(std::uint64_t k);  // true when k was there
  std::size_t size() const { return size_; }
  // RAM held: the array's entries (its reserved capacity is address space, resident only once
  // written) and ~40 bytes a recent entry (hash node and bucket).
  std::size_t bytes() const { return sorted_.size() * sizeof(Entry) + recent_.size() * 40; }
  template <class F>
  void forEachKey(F&& f) const {
    for (const auto& [k, r] : recent_) f(k);
    for (const Entry& e : sorted_)
      if (e.record.length != 0) f(e.key);
  }
  // The keys forEachKey gives, in its order, of those the latest insertions for which keep(k) holds
  // and of the sorted ones those within one of `ranges` ([first, last] each, ascending, apart): a
  // binary search per range instead of a walk over every brick.
  template <class Keep, class F>
  void forEachKeyIn(const std::vector<std::pair<std::uint64_t, std::uint64_t>>& ranges, Keep&& keep, F&& f) const {
    for (const auto& [k, r] : recent_)
      if (keep(k)) f(k);
    auto it = sorted_.begin();
    for (const auto& [first, last] : ranges) {
      it = std::lower_bound(it, sorted_.end(), first, [](const Entry& e, std::uint64_t key) { return e.key < key; });
      for (; it != sorted_.end() && it->key <= last; ++it)
        if (it->record.length != 0) f(it->key);
    }
  }

 private:
  struct Entry {
    std::uint64_t key;
    Record record;
  };
  static constexpr std::size_t kRecentMax = 4096;
  static constexpr std::size_t kReserved = std::size_t(1) << 23;  // 128 MiB of address space, ~2 km of corridor
  Entry* findSorted(std::uint64_t k);
  const Entry* findSorted(std::uint64_t k) const;
  void merge();  // recent_ into sorted_ (in place), erased entries dropped

  std::vector<Entry, MappedAllocator<Entry>> sorted_;  // by key
  std::unordered_map<std::uint64_t, Record> recent_;   // keys not in sorted_
  std::size_t erased_ = 0;                             // marked entries in sorted_
  std::size_t size_ = 0;
};

}  // namespace vofusion::fusion
