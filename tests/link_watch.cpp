#include "link_watch.h"

#include <dlfcn.h>
#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <mutex>

namespace vofusion::test {
namespace {

std::mutex g_mutex;
std::vector<LinkWatch::Linked>* g_linked = nullptr;  // the live watch's list
std::vector<LinkWatch::Linked> g_list;

// Whether a lock holds `path` now: a lock taken through another open is refused (and one taken here
// goes with the close).
bool heldByALock(const char* path) {
  const int fd = ::open(path, O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) return false;
  const bool held = ::flock(fd, LOCK_EX | LOCK_NB) != 0 && errno == EWOULDBLOCK;
  ::close(fd);
  return held;
}

}  // namespace

LinkWatch::LinkWatch() {
  std::lock_guard<std::mutex> lock(g_mutex);
  g_list.clear();
  g_linked = &g_list;
}

LinkWatch::~LinkWatch() {
  std::lock_guard<std::mutex> lock(g_mutex);
  g_linked = nullptr;
}

std::vector<LinkWatch::Linked> LinkWatch::linked() const {
  std::lock_guard<std::mutex> lock(g_mutex);
  return g_list;
}

}  // namespace vofusion::test

extern "C" int link(const char* from, const char* to) {
  static const auto real = reinterpret_cast<int (*)(const char*, const char*)>(::dlsym(RTLD_NEXT, "link"));
  if (!real) std::abort();  // no libc function to stand in front of
  {
    const int saved = errno;
    std::lock_guard<std::mutex> lock(vofusion::test::g_mutex);
    if (vofusion::test::g_linked) vofusion::test::g_linked->push_back({from, to, vofusion::test::heldByALock(from)});
    errno = saved;
  }
  return real(from, to);
}
