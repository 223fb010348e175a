#pragma once
// Storage of the moving volume's bricks: one after another in one anonymous mapping with room for
// every slot of the volume (address space only, MAP_NORESERVE: a page becomes resident when written).
// Ids stay dense: removing a brick moves the last one into its place, so the bricks in use are always
// the first size() of the mapping, and the pages past them are given back to the kernel (madvise)
// once more than kSlackBytes lie unused there. So the volume's memory follows the bricks it holds
// now. From glibc's heap, the bricks freed after a dense stretch of the path stayed resident for the
// rest of the run (runApp keeps freed heap for the frame loop's sake).
#include <cstddef>
#include <cstdint>

#include <Eigen/Core>

#include "vofusion/fusion/voxel_brick.h"

namespace vofusion::fusion {

class BrickArena {
 public:
  // Unused bytes past the last brick that are kept resident, so that a volume whose brick count
  // swings by a few hundred does not fault pages in and out at every shift.
  static constexpr std::size_t kSlackBytes = std::size_t{4} << 20;

  explicit BrickArena(std::size_t capacity);  // at most this many bricks at once
  ~BrickArena();
  BrickArena(const BrickArena&) = delete;
  BrickArena& operator=(const BrickArena&) = delete;

  std::int32_t add(const Eigen::Vector3i& coord);  // a never-observed brick at coord; its id
  std::int32_t add(const Brick& brick);            // a copy of brick; its id
  // Removes brick `id`. The last brick moves into its place: returns the id it had (to be replaced by
  // `id` wherever it is referenced), or -1 when `id` was the last.
  std::int32_t remove(std::int32_t id);
  void clear();

  Brick& operator[](std::int32_t id) { return bricks_[id]; }
  const Brick& operator[](std::int32_t id) const { return bricks_[id]; }
  std::size_t size() const { return size_; }

  // Gives the pages past the bricks in use back to the kernel when more than kSlackBytes lie there.
  void releaseUnusedPages();

 private:
  std::int32_t append();
  Brick* bricks_ = nullptr;  // MappedAllocator<Brick> (core/mapped_allocator.h), capacity_ bricks
  std::size_t capacity_ = 0, size_ = 0;
  std::size_t touched_bytes_ = 0;  // page-rounded end of the bricks written since the last release
};

}  // namespace vofusion::fusion
