#include "vofusion/core/spill_file.h"

#include <fcntl.h>
#include <unistd.h>
#include <zlib.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <stdexcept>

#include "vofusion/core/errors.h"

namespace vofusion {

std::vector<std::uint8_t> zlibCompress(const void* data, std::size_t size) {
  uLongf len = compressBound(uLong(size));
  std::vector<std::uint8_t> out(len);
  if (size > 0 && compress2(out.data(), &len, static_cast<const Bytef*>(data), uLong(size), 1) != Z_OK)
    throw std::runtime_error("zlib: cannot compress");
  out.resize(size > 0 ? len : 0);
  return out;
}

bool zlibUncompress(const std::uint8_t* data, std::size_t data_size, void* out, std::size_t size) {
  if (size == 0) return data_size == 0;
  uLongf len = uLong(size);
  return uncompress(static_cast<Bytef*>(out), &len, data, uLong(data_size)) == Z_OK && len == size;
}

SpillFile::SpillFile(std::string dir, std::string what) : dir_(std::move(dir)), what_(std::move(what)) {}

SpillFile::~SpillFile() {
  if (fd_ >= 0) ::close(fd_);
}

void SpillFile::open() {
  std::lock_guard<std::mutex> lock(open_mu_);
  if (fd_ >= 0) return;
  namespace fs = std::filesystem;
  const fs::path dir = dir_.empty() || dir_ == "auto" ? fs::temp_directory_path() : fs::path(dir_);
  std::error_code ec;
  fs::create_directories(dir, ec);
  std::string name = (dir / "vofusion-spill-XXXXXX").string();
  const int fd = ::mkstemp(name.data());
  if (fd < 0) throw InputError(dir.string(), "cannot create " + what_ + ": " + std::strerror(errno));
  ::unlink(name.c_str());  // gone with the process, whatever happens to it
  fd_ = fd;
}

SpillFile::Record SpillFile::append(const std::vector<std::uint8_t>& bytes) {
  if (bytes.size() > kMaxRecordBytes) throw std::runtime_error(what_ + ": a record of " + std::to_string(bytes.size()) + " bytes is over 16 MiB");
  if (fd_ < 0) open();
  const std::uint64_t at = end_.fetch_add(bytes.size());
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t w = ::pwrite(fd_, bytes.data() + done, bytes.size() - done, static_cast<off_t>(at + done));
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) throw InputError(dir_.empty() ? "auto" : dir_, "cannot write " + what_ + ": " + std::strerror(errno));
    done += static_cast<std::size_t>(w);
  }
  Record r;
  r.offset = at;
  r.length = bytes.size();
  return r;
}

std::vector<std::uint8_t> SpillFile::read(Record r) const {
  std::vector<std::uint8_t> bytes(r.length);
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::pread(fd_, bytes.data() + done, bytes.size() - done, static_cast<off_t>(r.offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw std::runtime_error("cannot read " + what_ + ": " + (n == 0 ? std::string("short file") : std::strerror(errno)));
    done += static_cast<std::size_t>(n);
  }
  return bytes;
}

}  // namespace vofusion
