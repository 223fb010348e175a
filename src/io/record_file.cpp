#include "record_file.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <stdexcept>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/errors.h"

namespace vofusion {

namespace {
// Where link(2) cannot make a file appear (FAT, some FUSE file systems), not whether it could here.
bool noHardLinks(int err) { return err == EPERM || err == EOPNOTSUPP || err == ENOSYS; }

// The old order, where no name of its own can be made or linked: created in place, unlocked for a moment.
int createInPlace(const std::string& path) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0) throw InputError(path, std::string("cannot create: ") + std::strerror(errno));
  ::flock(fd, LOCK_EX | LOCK_NB);
  return fd;
}

// An empty file beside `path` under a name of its own (set in `staged`), open for writing; -1 (errno)
// when none can be made. A name a killed process with this pid left is passed over.
int createStaged(const std::string& path, std::string& staged) {
  static std::atomic<unsigned> made{0};
  for (int attempt = 0; attempt < 100; ++attempt) {
    staged = path + "." + std::to_string(::getpid()) + "." + std::to_string(made++) + ".new";
    const int fd = ::open(staged.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    if (fd >= 0 || errno != EEXIST) return fd;
  }
  return -1;
}

bool sameFile(const struct stat& a, const struct stat& b) { return a.st_dev == b.st_dev && a.st_ino == b.st_ino; }
}  // namespace

RecordFile::RecordFile(const std::string& path) : path_(path), last_sync_(std::chrono::steady_clock::now()) {
  // Created under its own name and locked there first: created in place and locked after, another
  // recorder could find it empty and unlocked in between, take it for an abandoned one and remove it.
  std::string staged;
  lock_fd_ = createStaged(path, staged);
  if (lock_fd_ < 0 && errno == ENAMETOOLONG) {  // the recording's name is near the longest a file's may be
    fd_ = createInPlace(path);
    return;
  }
  if (lock_fd_ < 0) throw InputError(path, std::string("cannot create: ") + std::strerror(errno));
  ::flock(lock_fd_, LOCK_EX | LOCK_NB);  // no other process knows the file yet (a file system without locks: unheld)
  const int linked = ::link(staged.c_str(), path.c_str()), err = errno;
  ::unlink(staged.c_str());
  if (linked != 0) {
    ::close(lock_fd_);
    lock_fd_ = -1;
    if (!noHardLinks(err)) throw InputError(path, std::string("cannot create: ") + std::strerror(err));
    fd_ = createInPlace(path);
    return;
  }
  // Written through its own name (what /proc and the sync calls name); the lock stays with the first open.
  fd_ = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
  const std::string why = fd_ < 0 ? std::strerror(errno) : "replaced as it was made";
  struct stat locked, opened, named;
  const bool have_locked = ::fstat(lock_fd_, &locked) == 0;
  if (fd_ >= 0 && have_locked && ::fstat(fd_, &opened) == 0 && sameFile(opened, locked)) return;
  // Not left behind empty where it was linked (the next recorder would take it for an abandoned one).
  if (have_locked && ::stat(path.c_str(), &named) == 0 && sameFile(named, locked)) ::unlink(path.c_str());
  if (fd_ >= 0) ::close(fd_);
  ::close(lock_fd_);
  fd_ = lock_fd_ = -1;
  throw InputError(path, "cannot create: " + why);
}

bool RecordFile::removeIfAbandoned(const std::string& path, const std::function<bool()>& also_remove) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) return false;
  struct stat opened, named;
  // Locked here until the file is gone: a second process probing it meanwhile finds it held.
  const bool abandoned = ::fstat(fd, &opened) == 0 && S_ISREG(opened.st_mode) && opened.st_size == 0 &&
                         ::flock(fd, LOCK_EX | LOCK_NB) == 0 && ::stat(path.c_str(), &named) == 0 &&
                         sameFile(named, opened) && also_remove() && ::unlink(path.c_str()) == 0;
  ::close(fd);
  return abandoned;
}

RecordFile::~RecordFile() {
  if (fd_ >= 0) ::close(fd_);  // an unfinished record is not appended: the file ends at a whole one
  if (lock_fd_ >= 0) ::close(lock_fd_);
}

size_t RecordFile::Write(const void* bytes, size_t n) {
  record_.append(static_cast<const char*>(bytes), n);
  return n;
}

size_t RecordFile::Read(void*, size_t) { throw std::logic_error("RecordFile is write-only"); }
uint64_t RecordFile::Seek(int64_t, TSeekOrigin) { throw std::logic_error("RecordFile cannot seek"); }

void RecordFile::endRecord() {
  if (!torn_.empty()) {
    record_.clear();
    throw InputError(path_, torn_);
  }
  std::size_t done = 0;
  while (done < record_.size()) {
    const ssize_t n = ::write(fd_, record_.data() + done, record_.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int err = errno;
      // A partial record would make the file unreadable from there: cut it back to the last whole one.
      const std::string why = std::string("cannot write: ") + std::strerror(n < 0 ? err : ENOSPC);
      if (done > 0 && (::ftruncate(fd_, off_t(written_)) != 0 || ::lseek(fd_, off_t(written_), SEEK_SET) < 0))
        torn_ = why + "; its last record could not be cut back (" + std::strerror(errno) + "): nothing more is recorded";
      record_.clear();
      throw InputError(path_, torn_.empty() ? why : torn_);
    }
    done += std::size_t(n);
  }
  written_ += record_.size();
  record_.clear();
}

void RecordFile::syncIfDue() {
  if (std::chrono::steady_clock::now() - last_sync_ > std::chrono::seconds(1)) sync();
}

namespace {
bool syncFailed(int rc) { return rc != 0 && !syncUnsupported(errno); }
}  // namespace

void RecordFile::sync() {
  if (syncFailed(::fdatasync(fd_))) throw InputError(path_, std::string("cannot write: ") + std::strerror(errno));
  last_sync_ = std::chrono::steady_clock::now();
}

void RecordFile::syncWithItsFolder() {
  if (syncFailed(::syncfs(fd_))) throw InputError(path_, std::string("cannot write: ") + std::strerror(errno));
  last_sync_ = std::chrono::steady_clock::now();
}

}  // namespace vofusion
