#include "vofusion/fusion/brick_index.h"

#include <algorithm>
#include <stdexcept>

namespace vofusion::fusion {

BrickIndex::BrickIndex() { sorted_.reserve(kReserved); }

const BrickIndex::Entry* BrickIndex::findSorted(std::uint64_t k) const {
  const auto it = std::lower_bound(sorted_.begin(), sorted_.end(), k, [](const Entry& e, std::uint64_t key) { return e.key < key; });
  return it != sorted_.end() && it->key == k ? &*it : nullptr;
}

BrickIndex::Entry* BrickIndex::findSorted(std::uint64_t k) {
  return const_cast<Entry*>(static_cast<const BrickIndex*>(this)->findSorted(k));
}

void BrickIndex::set(std::uint64_t k, Record r) {
  if (r.length == 0) throw std::invalid_argument("BrickIndex: a record of length 0");
  if (Entry* e = findSorted(k)) {  // replaced, or an erased entry back in use
    if (e->record.length == 0) --erased_, ++size_;
    e->record = r;
    return;
  }
  const auto [it, fresh] = recent_.insert_or_assign(k, r);
  if (fresh) ++size_;
  if (recent_.size() >= kRecentMax) merge();
}

std::optional<BrickIndex::Record> BrickIndex::find(std::uint64_t k) const {
  if (const auto it = recent_.find(k); it != recent_.end()) return it->second;
  const Entry* e = findSorted(k);
  if (!e || e->record.length == 0) return std::nullopt;
  return e->record;
}

bool BrickIndex::erase(std::uint64_t k) {
  if (recent_.erase(k)) {
    --size_;
    return true;
  }
  Entry* e = findSorted(k);
  if (!e || e->record.length == 0) return false;
  e->record.length = 0;
  ++erased_, --size_;
  if (erased_ > sorted_.size() / 2) merge();
  return true;
}

void BrickIndex::merge() {
  // In place, so that no second array is ever held: erased entries out, the recent ones appended
  // in order, the two runs merged (std::inplace_merge buffers only the shorter, recent run).
  const auto by_key = [](const Entry& a, const Entry& b) { return a.key < b.key; };
  sorted_.erase(std::remove_if(sorted_.begin(), sorted_.end(), [](const Entry& e) { return e.record.length == 0; }),
                sorted_.end());
  const std::size_t old = sorted_.size();
  for (const auto& [k, r] : recent_) sorted_.push_back({k, r});
  std::sort(sorted_.begin() + std::ptrdiff_t(old), sorted_.end(), by_key);
  std::inplace_merge(sorted_.begin(), sorted_.begin() + std::ptrdiff_t(old), sorted_.end(), by_key);
  recent_.clear();
  erased_ = 0;
}

}  // namespace vofusion::fusion
