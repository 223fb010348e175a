#include "vofusion/core/atomic_file.h"

#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "vofusion/core/errors.h"

namespace fs = std::filesystem;

namespace vofusion {

AtomicPath::AtomicPath(std::string final_path)
    : final_(std::move(final_path)), tmp_(final_ + ".tmp-" + std::to_string(::getpid())) {
  std::error_code ec;
  fs::remove_all(tmp_, ec);  // a leftover of a crashed run with the same pid
}

AtomicPath::~AtomicPath() {
  if (!committed_) {
    std::error_code ec;
    fs::remove_all(tmp_, ec);
  }
}

void AtomicPath::commit() {
  std::error_code ec;
  if (!fs::exists(tmp_, ec)) throw InputError(final_, "nothing was written");
  if (fs::is_directory(tmp_) && fs::exists(final_)) {
    // rename() cannot replace a non-empty directory: move the old one aside first.
    const std::string old = final_ + ".old-" + std::to_string(::getpid());
    fs::remove_all(old, ec);
    fs::rename(final_, old, ec);
    if (ec) throw InputError(final_, "cannot replace: " + ec.message());
    fs::rename(tmp_, final_, ec);
    if (ec) {
      fs::rename(old, final_);
      throw InputError(final_, "cannot write: " + ec.message());
    }
    fs::remove_all(old, ec);
  } else {
    fs::rename(tmp_, final_, ec);
    if (ec) throw InputError(final_, "cannot write: " + ec.message());
  }
  committed_ = true;
}

void writeFileAtomically(const std::string& path, const std::string& contents) {
  AtomicPath out(path);
  {
    std::FILE* f = std::fopen(out.tmp().c_str(), "wb");
    if (!f) throw InputError(path, std::string("cannot write: ") + std::strerror(errno));
    const bool ok = std::fwrite(contents.data(), 1, contents.size(), f) == contents.size();
    const int err = errno;
    // fclose flushes: a full disk may only show here.
    if (std::fclose(f) != 0 || !ok)
      throw InputError(path, std::string("write failed: ") + std::strerror(ok ? errno : err));
  }
  out.commit();
}

void ensureWritableDirectory(const std::string& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw InputError(dir, "cannot create output folder: " + ec.message());
  if (!fs::is_directory(dir)) throw InputError(dir, "output path exists and is not a folder");
  if (::access(dir.c_str(), W_OK) != 0) throw InputError(dir, "output folder is not writable");
}

}  // namespace vofusion
