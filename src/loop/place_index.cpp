#include "vofusion/loop/place_index.h"

#include <algorithm>
#include <cstring>
#include <map>
#include <numeric>
#include <random>
#include <stdexcept>

namespace vofusion::loop {

namespace {
constexpr int kDescriptorBytes = 32;

// At most n rows, spread evenly over the keyframe (the STAR keypoints come first, then NARF's).
cv::Mat spreadRows(const cv::Mat& d, int n) {
  if (d.rows <= n) return d;
  cv::Mat out(n, d.cols, d.type());
  for (int i = 0; i < n; ++i) d.row(int(std::int64_t(i) * d.rows / n)).copyTo(out.row(i));
  return out;
}

void checkDescriptors(const cv::Mat& d) {
  if (!d.empty() && (d.type() != CV_8U || d.cols != kDescriptorBytes))
    throw std::invalid_argument("place index: descriptors must be CV_8U with 32 bytes a row");
}
}  // namespace

PlaceIndex::PlaceIndex(const LoopParams& params) : params_(params) {
  // Each table's key bits, drawn at random as FLANN's LshTable does (fixed seed: runs repeat exactly).
  std::mt19937 rng(20121);
  std::vector<int> all(kDescriptorBytes * 8);
  std::iota(all.begin(), all.end(), 0);
  for (int t = 0; t < params_.lsh_tables; ++t) {
    std::shuffle(all.begin(), all.end(), rng);
    table_bits_.emplace_back(all.begin(), all.begin() + params_.lsh_key_bits);
  }
  tables_.resize(table_bits_.size());
  for (auto& t : tables_) t.reserve(kReservedRows);
  rows_.reserve(kReservedRows);
  owner_.reserve(kReservedRows);
}

PlaceIndex::Bits PlaceIndex::bitsOf(const std::uint8_t* descriptor) {
  Bits b;
  std::memcpy(b.data(), descriptor, kDescriptorBytes);
  return b;
}

std::uint32_t PlaceIndex::keyOf(const Bits& d, std::size_t table) const {
  std::uint32_t key = 0;
  for (const int bit : table_bits_[table]) key = (key << 1) | std::uint32_t((d[std::size_t(bit / 64)] >> (bit % 64)) & 1u);
  return key;
}

void PlaceIndex::add(std::size_t keyframe, const cv::Mat& all) {
  checkDescriptors(all);
  if (all.empty()) return;
  const cv::Mat d = spreadRows(all, params_.place_descriptors);
  const auto first = std::uint32_t(rows_.size());
  keyframes_.push_back(keyframe);
  for (int i = 0; i < d.rows; ++i) {
    rows_.push_back(bitsOf(d.ptr<std::uint8_t>(i)));
    owner_.push_back(std::uint32_t(keyframes_.size() - 1));
  }
  for (std::size_t t = 0; t < tables_.size(); ++t) {
    auto& table = tables_[t];
    const std::size_t old = table.size();
    for (std::uint32_t r = first; r < rows_.size(); ++r) table.emplace_back(keyOf(rows_[r], t), r);
    std::sort(table.begin() + std::ptrdiff_t(old), table.end());
    std::inplace_merge(table.begin(), table.begin() + std::ptrdiff_t(old), table.end());
  }
}

// Every key within `flips` more bit flips of `key` (flipping bits >= from only, so each is visited once).
template <class Visit>
void PlaceIndex::probe(std::uint32_t key, int flips, int from, Visit&& visit) const {
  visit(key);
  if (flips == 0) return;
  for (int b = from; b < params_.lsh_key_bits; ++b) probe(key ^ (1u << b), flips - 1, b + 1, visit);
}

std::pair<int, int> PlaceIndex::nearest(const std::uint8_t* descriptor) const {
  const Bits q = bitsOf(descriptor);
  int best_row = -1, best = kDescriptorBytes * 8 + 1;
  for (std::size_t t = 0; t < tables_.size(); ++t) {
    const auto& table = tables_[t];
    probe(keyOf(q, t), params_.lsh_probe_level, 0, [&](std::uint32_t key) {
      auto it = std::lower_bound(table.begin(), table.end(), std::make_pair(key, std::uint32_t(0)));
      for (; it != table.end() && it->first == key; ++it) {
        const Bits& r = rows_[it->second];
        const int dist = __builtin_popcountll(q[0] ^ r[0]) + __builtin_popcountll(q[1] ^ r[1]) +
                         __builtin_popcountll(q[2] ^ r[2]) + __builtin_popcountll(q[3] ^ r[3]);
        if (dist < best || (dist == best && int(it->second) < best_row)) best = dist, best_row = int(it->second);
      }
    });
  }
  return {best_row, best_row < 0 ? -1 : best};
}

std::vector<PlaceCandidate> PlaceIndex::query(const cv::Mat& all, const std::function<bool(std::size_t)>& usable) const {
  checkDescriptors(all);
  if (keyframes_.empty() || all.empty()) return {};
  const cv::Mat descriptors = spreadRows(all, params_.place_descriptors);
  std::vector<int> votes(keyframes_.size(), 0);  // by position in the index
  for (int i = 0; i < descriptors.rows; ++i) {
    const auto [row, dist] = nearest(descriptors.ptr<std::uint8_t>(i));
    if (row >= 0 && dist <= params_.max_hamming) ++votes[owner_[std::size_t(row)]];
  }
  return placesByVotes(votes, usable);
}

// Indexed keyframes are index_spacing apart along the path and see much of the same scene, so each
// descriptor's vote goes to whichever of them holds its nearest neighbour: a place seen again splits
// its votes among two or three of them (on the loop scene 16 + 5 where one keyframe alone would have
// had 20). As ORB-SLAM scores a loop candidate with its covisible keyframes (DBoW2's islands), a
// place is an indexed keyframe with its neighbours in the index, scored by their votes together, and
// verified through its best-voted keyframe.
std::vector<PlaceCandidate> PlaceIndex::placesByVotes(const std::vector<int>& votes,
                                                     const std::function<bool(std::size_t)>& usable) const {
  struct Place {
    std::size_t best;  // position in the index of the place's best-voted keyframe
    int votes;         // the place's: the keyframe's and its two neighbours'
  };
  const std::size_t n = votes.size();
  std::vector<Place> places;
  for (std::size_t i = 0; i < n; ++i) {
    // Centred on a keyframe without votes too: a place's votes may fall on either side of it alone.
    // A window with votes names one of its usable keyframes that has some (a lost one wasted a
    // candidate at every visit: read from disk again, and refused again).
    // Ties go to the centre, then to the older neighbour.
    Place p{i, 0};
    bool named = false;
    const auto consider = [&](std::size_t j) {
      p.votes += votes[j];
      if (votes[j] == 0 || (usable && !usable(keyframes_[j]))) return;
      if (!named || votes[j] > votes[p.best]) p.best = j, named = true;
    };
    consider(i);
    if (i > 0) consider(i - 1);
    if (i + 1 < n) consider(i + 1);
    if (named && p.votes >= params_.min_votes) places.push_back(p);
  }
  // Most votes first; ties: the better best keyframe, then the older.
  std::sort(places.begin(), places.end(), [&](const Place& a, const Place& b) {
    if (a.votes != b.votes) return a.votes > b.votes;
    if (votes[a.best] != votes[b.best]) return votes[a.best] > votes[b.best];
    return a.best < b.best;
  });
  std::vector<PlaceCandidate> out;
  for (const Place& p : places) {
    if (out.size() == std::size_t(params_.candidates)) break;
    const std::size_t id = keyframes_[p.best];  // neighbouring places often share their best keyframe
    if (std::none_of(out.begin(), out.end(), [&](const PlaceCandidate& o) { return o.keyframe == id; }))
      out.push_back({id, p.votes});
  }
  return out;
}

}  // namespace vofusion::loop
