#include "sync_watch.h"

#include <dlfcn.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <mutex>

namespace vofusion::test {
namespace {

std::mutex g_mutex;
std::vector<std::string>* g_synced = nullptr;  // the live watch's list
std::vector<std::string> g_list;
struct Failure {
  std::string call, path;
  int err;
};
std::vector<Failure> g_failures;

// Notes the call; returns the errno it is to fail with, or 0.
int note(const char* call, int fd) {
  std::lock_guard<std::mutex> lock(g_mutex);
  if (!g_synced) return 0;
  char target[4096];
  const ssize_t n = ::readlink(("/proc/self/fd/" + std::to_string(fd)).c_str(), target, sizeof target);
  const std::string path = n > 0 ? std::string(target, std::size_t(n)) : "?";
  for (const Failure& f : g_failures)
    if (f.call == call && f.path == path) {
      g_synced->push_back(std::string(call) + " " + path + " failed");
      return f.err;
    }
  g_synced->push_back(std::string(call) + " " + path);
  return 0;
}

int (*libc(const char* name))(int) {
  auto* f = reinterpret_cast<int (*)(int)>(::dlsym(RTLD_NEXT, name));
  if (!f) std::abort();  // no libc function to stand in front of: nothing here can be trusted
  return f;
}

int call(const char* name, int (*real)(int), int fd) {
  if (const int err = note(name, fd)) {
    errno = err;
    return -1;
  }
  return real(fd);
}

}  // namespace

SyncWatch::SyncWatch() {
  std::lock_guard<std::mutex> lock(g_mutex);
  g_list.clear();
  g_synced = &g_list;
}

SyncWatch::~SyncWatch() {
  std::lock_guard<std::mutex> lock(g_mutex);
  g_synced = nullptr;
  g_failures.clear();
}

void SyncWatch::fail(const std::string& call, const std::string& path, int err) {
  std::lock_guard<std::mutex> lock(g_mutex);
  g_failures.push_back({call, path, err});
}

std::vector<std::string> SyncWatch::synced() const {
  std::lock_guard<std::mutex> lock(g_mutex);
  return g_list;
}

}  // namespace vofusion::test

extern "C" int fsync(int fd) {
  static const auto real = vofusion::test::libc("fsync");
  return vofusion::test::call("fsync", real, fd);
}

extern "C" int fdatasync(int fd) {
  static const auto real = vofusion::test::libc("fdatasync");
  return vofusion::test::call("fdatasync", real, fd);
}

extern "C" int syncfs(int fd) {
  static const auto real = vofusion::test::libc("syncfs");
  return vofusion::test::call("syncfs", real, fd);
}
