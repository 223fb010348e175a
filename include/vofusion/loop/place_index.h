#pragma once
// Place recognition: the BRAND descriptors of keyframes in a multi-table LSH index (binary
// descriptors, Hamming distance). A query keyframe's descriptors each vote for the keyframe holding
// their nearest neighbour; the places (an indexed keyframe with its neighbours in the index) with most
// votes are the loop candidates.
//
// The hashing is FLANN's (LshIndexParams: each table keys a descriptor by lsh_key_bits of its 256
// bits, chosen at random; multi-probe visits keys up to lsh_probe_level bits away), but the tables
// are stored compactly: one sorted array of (key, row) per table, 8 bytes per descriptor and table.
// OpenCV's FLANN index keeps a hash-map node and a vector per bucket: ~170 KB of RAM per keyframe
// of 300 descriptors at 24-bit keys, 8x this index's 20 KB, and the only part of the keyframe
// database that must stay in RAM (tests/test_loop.cpp checks both find the same neighbours).
#include <array>
#include <functional>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "vofusion/core/mapped_allocator.h"
#include "vofusion/loop/loop_params.h"

namespace vofusion::loop {

struct PlaceCandidate {
  std::size_t keyframe = 0;
  int votes = 0;
};

class PlaceIndex {
 public:
  explicit PlaceIndex(const LoopParams& params);
  // descriptors: CV_8U, 32 bytes a row; at most [loop] place_descriptors of them are kept, spread evenly.
  void add(std::size_t keyframe, const cv::Mat& descriptors);
  std::size_t size() const { return keyframes_.size(); }
  std::size_t descriptors() const { return owner_.size(); }
  // Places with at least min_votes votes from `descriptors` (nearest neighbours within max_hamming)
  // on an indexed keyframe and its two neighbours in the index, most votes first, at most `candidates`
  // of them; each names its best-voted keyframe and the place's votes. A keyframe `usable` says no to
  // (lost from the spill file) names no place: its place is named by its best usable neighbour, if any.
  std::vector<PlaceCandidate> query(const cv::Mat& descriptors,
                                    const std::function<bool(std::size_t keyframe)>& usable = nullptr) const;
  // The indexed row nearest to a 32-byte descriptor found through the tables (LSH: may miss the
  // true nearest), as (row, Hamming distance); row -1 when no table's bucket held any.
  std::pair<int, int> nearest(const std::uint8_t* descriptor) const;
  // The keyframe an indexed row belongs to.
  std::size_t keyframeOfRow(int row) const { return keyframes_[owner_[std::size_t(row)]]; }

 private:
  using Bits = std::array<std::uint64_t, 4>;
  static Bits bitsOf(const std::uint8_t* descriptor);
  std::uint32_t keyOf(const Bits& d, std::size_t table) const;
  template <class Visit> void probe(std::uint32_t key, int flips, int from, Visit&& visit) const;
  // votes: per position in the index. Candidates as query() returns them.
  std::vector<PlaceCandidate> placesByVotes(const std::vector<int>& votes, const std::function<bool(std::size_t)>& usable) const;

  LoopParams params_;
  std::vector<std::vector<int>> table_bits_;  // per table: the descriptor bits its key is made of
  // The arrays that grow with every keyframe are mapped (core/mapped_allocator.h), with room for
  // kReservedRows descriptors reserved up front (address space; ~10 k keyframes, 1.5 km of corridor).
  static constexpr std::size_t kReservedRows = std::size_t(1) << 22;
  template <class T>
  using Growing = std::vector<T, MappedAllocator<T>>;
  std::vector<Growing<std::pair<std::uint32_t, std::uint32_t>>> tables_;  // per table: (key, row), sorted
  Growing<Bits> rows_;                        // every indexed descriptor
  Growing<std::uint32_t> owner_;              // row -> position in keyframes_
  std::vector<std::size_t> keyframes_;        // keyframe ids in the order added
};

}  // namespace vofusion::loop
