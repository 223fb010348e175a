#include "sync_watch.h"

#include <dlfcn.h>
#include <unistd.h>

#include <mutex>

namespace vofusion::test {
namespace {

std::mutex g_mutex;
std::vector<std::string>* g_synced = nullptr;  // the live watch's list
std::vector<std::string> g_list;

void note(const char* call, int fd) {
  std::lock_guard<std::mutex> lock(g_mutex);
  if (!g_synced) return;
  char target[4096];
  const ssize_t n = ::readlink(("/proc/self/fd/" + std::to_string(fd)).c_str(), target, sizeof target);
  g_synced->push_back(std::string(call) + " " + (n > 0 ? std::string(target, std::size_t(n)) : "?"));
}

int (*libc(const char* name))(int) { return reinterpret_cast<int (*)(int)>(::dlsym(RTLD_NEXT, name)); }

}  // namespace

SyncWatch::SyncWatch() {
  std::lock_guard<std::mutex> lock(g_mutex);
  g_list.clear();
  g_synced = &g_list;
}

SyncWatch::~SyncWatch() {
  std::lock_guard<std::mutex> lock(g_mutex);
  g_synced = nullptr;
}

std::vector<std::string> SyncWatch::synced() const {
  std::lock_guard<std::mutex> lock(g_mutex);
  return g_list;
}

}  // namespace vofusion::test

extern "C" int fsync(int fd) {
  vofusion::test::note("fsync", fd);
  static const auto real = vofusion::test::libc("fsync");
  return real(fd);
}

extern "C" int fdatasync(int fd) {
  vofusion::test::note("fdatasync", fd);
  static const auto real = vofusion::test::libc("fdatasync");
  return real(fd);
}

extern "C" int syncfs(int fd) {
  vofusion::test::note("syncfs", fd);
  static const auto real = vofusion::test::libc("syncfs");
  return real(fd);
}
