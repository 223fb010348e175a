#pragma once
// Outputs appear whole or not at all: write to "<path>.tmp-<pid>", then rename over <path>.
// If the writer is destroyed without commit() (an exception, Ctrl-C unwinding), the temporary is
// removed and any earlier <path> is left untouched. A run killed by a signal leaves its temporary:
// the next AtomicPath for the same <path> removes those whose process is gone.
#include <string>

namespace vofusion {

class AtomicPath {
 public:
  explicit AtomicPath(std::string final_path);
  ~AtomicPath();
  AtomicPath(const AtomicPath&) = delete;
  AtomicPath& operator=(const AtomicPath&) = delete;

  const std::string& tmp() const { return tmp_; }     // write here (a file or a directory)
  const std::string& path() const { return final_; }
  void commit();  // rename tmp -> final (replacing a file or directory); throws InputError on failure

 private:
  std::string final_, tmp_;
  bool committed_ = false;
};

// Convenience for text outputs; throws InputError(path, strerror) if the write fails (disk full...).
void writeFileAtomically(const std::string& path, const std::string& contents);
// Throws InputError(dir, ...) if dir cannot be created or written to.
void ensureWritableDirectory(const std::string& dir);

}  // namespace vofusion
