#pragma once
// Which files and folders a test's code synced to the disk, in order: sync_watch.cpp defines fsync(),
// fdatasync() and syncfs() for the test programs linked with it, noting each call's path ("fsync <path>")
// while a SyncWatch lives, then calling libc's (or failing, as asked). The library's calls reach them
// before libc's.
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
  // From now on, `call` ("fsync", "fdatasync", "syncfs") of a path equal to `path` fails with `err`
  // (noted as "<call> <path> failed").
  void fail(const std::string& call, const std::string& path, int err);
};

}  // namespace vofusion::test
