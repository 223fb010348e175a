#include "record_file.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/errors.h"

namespace vofusion {

RecordFile::RecordFile(const std::string& path) : path_(path), last_sync_(std::chrono::steady_clock::now()) {
  fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd_ < 0) throw InputError(path, std::string("cannot create: ") + std::strerror(errno));
  ::flock(fd_, LOCK_EX | LOCK_NB);  // held while recording: another recorder leaves this file alone
}

bool RecordFile::heldByAnother(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return false;
  const bool held = ::flock(fd, LOCK_EX | LOCK_NB) != 0 && errno == EWOULDBLOCK;
  ::close(fd);  // and with it the lock taken here, if it was free
  return held;
}

RecordFile::~RecordFile() {
  if (fd_ >= 0) ::close(fd_);  // an unfinished record is not appended: the file ends at a whole one
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
