#include "vofusion/core/spill_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <iterator>
#include <stdexcept>

#include "vofusion/core/errors.h"
#include "vofusion/core/progress.h"

namespace vofusion {

SpillFile::SpillFile(std::string dir, std::string what, std::uint64_t max_bytes)
    : dir_(std::move(dir)), what_(std::move(what)), max_bytes_(std::min(max_bytes, kMaxFileBytes)) {}

SpillFile::~SpillFile() {
  if (fd_ >= 0) ::close(fd_);
}

void SpillFile::open() {
  std::lock_guard<std::mutex> lock(open_mu_);
  if (fd_ >= 0) return;
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path dir = dir_.empty() || dir_ == "auto" ? fs::temp_directory_path(ec) : fs::path(dir_);
  if (ec) {
    const char* tmpdir = std::getenv("TMPDIR");
    throw InputError(tmpdir ? tmpdir : "TMPDIR", "cannot create " + what_ + ": " + ec.message());
  }
  fs::create_directories(dir, ec);
  std::string name = (dir / "vofusion-spill-XXXXXX").string();
  const int fd = ::mkstemp(name.data());
  if (fd < 0) throw InputError(dir.string(), "cannot create " + what_ + ": " + std::strerror(errno));
  ::unlink(name.c_str());  // gone with the process, whatever happens to it
  folder_ = dir.string();
  fd_ = fd;
}

std::optional<SpillFile::Record> SpillFile::append(const std::vector<std::uint8_t>& bytes) {
  if (bytes.size() > kMaxRecordBytes) throw std::runtime_error(what_ + ": a record of " + std::to_string(bytes.size()) + " bytes is over 16 MiB");
  if (failed_.load(std::memory_order_acquire)) return std::nullopt;
  try {
    if (fd_ < 0) open();
  } catch (const InputError& e) {
    fail(e.what());
    return std::nullopt;
  }
  const std::uint64_t at = place(bytes.size());
  if (at + bytes.size() > max_bytes_) {
    {
      const std::lock_guard<std::mutex> lock(free_mu_);
      free_bytes_ += bytes.size();
      addFree(at, bytes.size());  // its place is free again, as the statistics count it
    }
    fail(folder_ + ": " + what_ + " is full: " + std::to_string(max_bytes_) + " bytes, the most a record's place can say");
    return std::nullopt;
  }
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t w = ::pwrite(fd_, bytes.data() + done, bytes.size() - done, static_cast<off_t>(at + done));
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) {
      const std::string why = w == 0 ? "nothing written (disk full?)" : std::strerror(errno);  // errno is set only below 0
      Record lost;
      lost.offset = at;
      lost.length = bytes.size();
      release(lost);  // the place is free again, as the statistics count it
      fail(folder_ + ": cannot write " + what_ + ": " + why);
      return std::nullopt;
    }
    done += static_cast<std::size_t>(w);
  }
  Record r;
  r.offset = at;
  r.length = bytes.size();
  return r;
}

void SpillFile::fail(const std::string& why) {
  {
    const std::lock_guard<std::mutex> lock(open_mu_);
    if (failed_.load()) return;  // the first is kept and warned of
    failure_ = why;
    failed_.store(true, std::memory_order_release);
  }
  printWarning(why + ": what would go to it stays in memory from now on");
}

std::string SpillFile::failure() const {
  const std::lock_guard<std::mutex> lock(open_mu_);
  return failure_;
}

void SpillFile::lost(std::uint64_t id, const std::string& warning) const {
  bool first;
  {
    const std::lock_guard<std::mutex> lock(lost_mu_);
    first = lost_.insert(id).second && lost_.size() == 1;
  }
  if (first) printWarning(warning);  // outside the lock: stderr may be slow
}

bool SpillFile::isLost(std::uint64_t id) const {
  const std::lock_guard<std::mutex> lock(lost_mu_);
  return lost_.count(id) != 0;
}

std::size_t SpillFile::lostCount() const {
  const std::lock_guard<std::mutex> lock(lost_mu_);
  return lost_.size();
}

std::vector<std::uint8_t> SpillFile::read(Record r) const {
  std::vector<std::uint8_t> bytes(r.length);
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::pread(fd_, bytes.data() + done, bytes.size() - done, static_cast<off_t>(r.offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const std::string cause = n == 0 ? std::string("short file") : std::strerror(errno);
      throw ReadError(folder_ + ": cannot read " + what_ + ": " + cause, cause);
    }
    done += static_cast<std::size_t>(n);
  }
  return bytes;
}

std::uint64_t SpillFile::place(std::uint64_t size) {
  {
    std::lock_guard<std::mutex> lock(free_mu_);
    if (const auto fit = free_by_size_.lower_bound(size); size > 0 && fit != free_by_size_.end()) {
      const std::uint64_t at = fit->second, hole = fit->first;
      free_by_size_.erase(fit);
      free_by_offset_.erase(at);
      free_bytes_ -= size;
      if (hole > size) addFree(at + size, hole - size);
      return at;
    }
  }
  return end_.fetch_add(size);
}

// Under free_mu_. Merged with the free places right before and after it.
void SpillFile::addFree(std::uint64_t offset, std::uint64_t size) {
  const auto unlinkBySize = [this](std::uint64_t at, std::uint64_t n) {
    for (auto [it, end] = free_by_size_.equal_range(n); it != end; ++it)
      if (it->second == at) {
        free_by_size_.erase(it);
        return;
      }
  };
  auto next = free_by_offset_.lower_bound(offset);
  if (next != free_by_offset_.begin()) {
    const auto prev = std::prev(next);
    if (prev->first + prev->second == offset) {
      unlinkBySize(prev->first, prev->second);
      offset = prev->first;
      size += prev->second;
      free_by_offset_.erase(prev);
    }
  }
  if (next != free_by_offset_.end() && offset + size == next->first) {
    unlinkBySize(next->first, next->second);
    size += next->second;
    free_by_offset_.erase(next);
  }
  free_by_offset_[offset] = size;
  free_by_size_.emplace(size, offset);
}

void SpillFile::release(Record r) {
  if (r.length == 0) return;
  std::lock_guard<std::mutex> lock(free_mu_);
  free_bytes_ += r.length;
  addFree(r.offset, r.length);
}

std::uint64_t SpillFile::freeBytes() const {
  std::lock_guard<std::mutex> lock(free_mu_);
  return free_bytes_;
}

std::size_t SpillFile::freePlaces() const {
  std::lock_guard<std::mutex> lock(free_mu_);
  return free_by_offset_.size();
}

}  // namespace vofusion
