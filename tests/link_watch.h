#pragma once
// Whether a file was locked (flock, by another open) when link(2) gave it a name: link_watch.cpp defines
// link() for the test programs linked with it, noting each call while a LinkWatch lives, then calling
// libc's. The library's calls reach it before libc's (as sync_watch.h's).
#include <string>
#include <vector>

namespace vofusion::test {

class LinkWatch {
 public:
  struct Linked {
    std::string from, to;
    bool locked;  // `from` was held by a lock when it was linked to `to`
  };
  LinkWatch();
  ~LinkWatch();
  LinkWatch(const LinkWatch&) = delete;
  LinkWatch& operator=(const LinkWatch&) = delete;
  std::vector<Linked> linked() const;
};

}  // namespace vofusion::test
