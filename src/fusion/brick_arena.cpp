#include "vofusion/fusion/brick_arena.h"

#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <new>
#include <stdexcept>

#include "vofusion/core/mapped_allocator.h"

namespace vofusion::fusion {

namespace {
std::size_t pageSize() {
  static const std::size_t page = static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
  return page;
}
std::size_t roundUpToPage(std::size_t bytes) { return (bytes + pageSize() - 1) / pageSize() * pageSize(); }
}  // namespace

BrickArena::BrickArena(std::size_t capacity) : capacity_(capacity) {
  if (capacity_ == 0 || capacity_ > static_cast<std::size_t>(INT32_MAX)) throw std::invalid_argument("BrickArena: capacity");
  bricks_ = MappedAllocator<Brick>().allocate(capacity_);
}

BrickArena::~BrickArena() { MappedAllocator<Brick>().deallocate(bricks_, capacity_); }

std::int32_t BrickArena::append() {
  if (size_ == capacity_) throw std::length_error("BrickArena: more bricks than the volume has slots");
  touched_bytes_ = std::max(touched_bytes_, roundUpToPage((size_ + 1) * sizeof(Brick)));
  return static_cast<std::int32_t>(size_++);
}

std::int32_t BrickArena::add(const Eigen::Vector3i& coord) {
  const std::int32_t id = append();
  Brick* b = new (&bricks_[id]) Brick();  // value-initialised: every voxel unobserved
  b->coord = coord;
  return id;
}

std::int32_t BrickArena::add(const Brick& brick) {
  const std::int32_t id = append();
  std::memcpy(static_cast<void*>(&bricks_[id]), &brick, sizeof(Brick));
  return id;
}

std::int32_t BrickArena::remove(std::int32_t id) {
  const auto last = static_cast<std::int32_t>(size_ - 1);
  --size_;
  if (id == last) return -1;
  std::memcpy(static_cast<void*>(&bricks_[id]), &bricks_[last], sizeof(Brick));
  return last;
}

void BrickArena::clear() {
  size_ = 0;
  releaseUnusedPages();
}

void BrickArena::releaseUnusedPages() {
  const std::size_t keep = roundUpToPage(size_ * sizeof(Brick));
  if (touched_bytes_ <= keep + kSlackBytes) return;
  // MADV_DONTNEED: the pages are dropped now (RSS falls) and read back as zeros if written again.
  ::madvise(reinterpret_cast<char*>(bricks_) + keep, touched_bytes_ - keep, MADV_DONTNEED);
  touched_bytes_ = keep;
}

}  // namespace vofusion::fusion
