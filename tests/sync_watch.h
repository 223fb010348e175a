#pragma once
// Which files and folders a test's code synced to the disk, in order: sync_watch.cpp defines fsync(),
// fdatasync() and syncfs() for the test programs linked with it, noting each call's path ("fsync <path>")
// while a SyncWatch lives, then calling libc's. The library's calls reach them before libc's.
#include <string>
#include <vector>

namespace vofusion::test {

class SyncWatch {
 public:
  SyncWatch();
  ~SyncWatch();
  SyncWatch(const SyncWatch&) = delete;
  SyncWatch& operator=(const SyncWatch&) = delete;
  std::vector<std::string> synced() const;
};

}  // namespace vofusion::test
