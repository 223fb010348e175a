#include "vofusion/core/gzip_members.h"

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <stdexcept>

#include <tbb/task_arena.h>
#include <tbb/task_group.h>

#include "vofusion/core/deflate.h"
#include "vofusion/core/errors.h"

namespace vofusion {

struct GzipMembersFile::Member {
  std::vector<std::uint8_t> raw, gz;
  std::exception_ptr error;
  std::atomic<bool> done{false};
  // Its own context: a writer inside a TBB task whose group is cancelled still compresses every member.
  tbb::task_group_context context{tbb::task_group_context::isolated};
  tbb::task_group task{context};
};

bool gzipTrailerSays(const std::string& path, std::uint64_t uncompressed_bytes) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return false;
  std::uint8_t head[2] = {0, 0}, tail[4] = {0, 0, 0, 0};
  const bool read = std::fread(head, 1, 2, f) == 2 && std::fseek(f, -4, SEEK_END) == 0 && std::fread(tail, 1, 4, f) == 4;
  const long size = std::ftell(f);
  std::fclose(f);
  if (!read || size < 18 || head[0] != 0x1f || head[1] != 0x8b) return false;  // 18: header and trailer alone
  return gzipStoredLength(tail + 4) == std::uint32_t(uncompressed_bytes);
}

GzipMembersFile::GzipMembersFile(const std::string& path)
    : path_(path),
      // Two members a core: the cores stay busy while the writer fills the next, and at most a few MiB wait.
      max_in_flight_(2 * std::size_t(std::max(1, tbb::this_task_arena::max_concurrency()))) {
  file_ = std::fopen(path.c_str(), "wb");
  if (!file_) throw InputError(path, std::string("cannot write: ") + std::strerror(errno));
  buffer_.reserve(kMemberBytes);
}

GzipMembersFile::~GzipMembersFile() {
  for (auto& m : in_flight_) m->task.wait();  // no task outlives its member
  if (file_) std::fclose(file_);
}

size_t GzipMembersFile::Write(const void* data, size_t size) {
  if (!file_) throw std::logic_error("GzipMembersFile: write after close");
  const auto* p = static_cast<const std::uint8_t*>(data);
  for (size_t left = size; left > 0;) {
    const size_t n = std::min(left, kMemberBytes - buffer_.size());
    buffer_.insert(buffer_.end(), p, p + n);
    p += n, left -= n;
    if (buffer_.size() == kMemberBytes) startMember();
  }
  written_ += size;
  return size;
}

void GzipMembersFile::startMember() {
  in_flight_.push_back(std::make_unique<Member>());
  Member& m = *in_flight_.back();
  m.raw.swap(buffer_);
  buffer_.reserve(kMemberBytes);
  m.task.run([&m] {
    try {
      m.gz = gzipCompress(m.raw.data(), m.raw.size());
    } catch (...) {
      m.error = std::current_exception();
    }
    m.raw = {};
    m.done.store(true, std::memory_order_release);
  });
  while (!in_flight_.empty() && in_flight_.front()->done.load(std::memory_order_acquire)) writeOldest();
  // The file takes members in order: past the limit, wait for the oldest (this thread compresses
  // queued ones meanwhile).
  while (in_flight_.size() >= max_in_flight_) writeOldest();
}

void GzipMembersFile::writeOldest() {
  Member& m = *in_flight_.front();
  m.task.wait();
  if (!m.done.load(std::memory_order_acquire)) throw std::runtime_error("GzipMembersFile: a compression did not run");
  if (m.error) std::rethrow_exception(m.error);
  if (std::fwrite(m.gz.data(), 1, m.gz.size(), file_) != m.gz.size())
    throw InputError(path_, std::string("cannot write: ") + std::strerror(errno));  // stops the serialisation at once
  in_flight_.pop_front();
}

void GzipMembersFile::close() {
  if (!file_) return;
  std::FILE* f = file_;
  try {
    // An empty file has one empty member, as gzip writes one: a reader finds a gzip header either way.
    if (!buffer_.empty() || written_ == 0) startMember();
    while (!in_flight_.empty()) writeOldest();
  } catch (...) {
    for (auto& m : in_flight_) m->task.wait();
    in_flight_.clear();
    file_ = nullptr;
    std::fclose(f);
    throw;
  }
  file_ = nullptr;
  if (std::fclose(f) != 0) throw InputError(path_, std::string("cannot write: ") + std::strerror(errno));
}

size_t GzipMembersFile::Read(void*, size_t) { throw std::logic_error("GzipMembersFile is write-only"); }

uint64_t GzipMembersFile::Seek(int64_t, mrpt::io::CStream::TSeekOrigin) {
  throw std::logic_error("GzipMembersFile cannot seek");
}

}  // namespace vofusion
