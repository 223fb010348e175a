#pragma once
// A gzip file written as a series of members of up to 1 MiB each, compressed by libdeflate (level 1,
// as MRPT's CFileGZOutputStream writes) on every core while the writer goes on serialising. zlib's
// gzread, and so MRPT's CFileGZInputStream and every `load` built on it, reads the members one after
// the other as one stream, as `gzip -d` does. The bytes read back are the bytes written.
//
//   GzipMembersFile f(path);                       // throws InputError(path, ...) if it cannot be created
//   mrpt::serialization::archiveFrom(f) << scene;
//   f.close();                                     // throws InputError(path, ...) if a write failed
//
// A failed write throws InputError(path, ...) from the Write or close() that meets it. A writer
// destroyed without close() (an exception) waits for its compressions and leaves a truncated file:
// write it through AtomicPath, which removes it.
#include <cstdint>
#include <cstdio>
#include <deque>
#include <memory>
#include <string>
#include <vector>

#include <mrpt/io/CStream.h>

namespace vofusion {

// Whether the one-member gzip file at `path` ends with the trailer of `uncompressed_bytes` (ISIZE, RFC
// 1952: the length mod 2^32). MRPT's CFileGZOutputStream::close() drops gzclose's result, so a write
// that failed while the last block and the trailer were flushed (a full disk) shows only here; a file
// cut short ends in deflate data, whose last four bytes match by a 1 in 2^32 chance.
bool gzipTrailerSays(const std::string& path, std::uint64_t uncompressed_bytes);

class GzipMembersFile : public mrpt::io::CStream {
 public:
  static constexpr std::size_t kMemberBytes = std::size_t(1) << 20;

  explicit GzipMembersFile(const std::string& path);
  ~GzipMembersFile() override;
  GzipMembersFile(const GzipMembersFile&) = delete;
  GzipMembersFile& operator=(const GzipMembersFile&) = delete;

  size_t Write(const void* data, size_t size) override;  // after close(): std::logic_error
  // Compresses what is left, writes every member in order and closes the file. Once it has returned
  // or thrown, the file is closed and a second call does nothing.
  void close();

  // Write-only: reading and seeking throw std::logic_error.
  size_t Read(void* data, size_t size) override;
  uint64_t Seek(int64_t offset, mrpt::io::CStream::TSeekOrigin origin = sFromBeginning) override;
  uint64_t getTotalBytesCount() const override { return written_; }  // uncompressed bytes so far
  uint64_t getPosition() const override { return written_; }
  std::string getStreamDescription() const override { return "GzipMembersFile(" + path_ + ")"; }

 private:
  struct Member;
  void startMember();   // hands the filled buffer to a compression task, writes what is done
  void writeOldest();   // waits for the oldest member in flight and writes it

  std::string path_;
  std::FILE* file_ = nullptr;
  std::vector<std::uint8_t> buffer_;     // the member being filled
  std::deque<std::unique_ptr<Member>> in_flight_;  // file order
  std::size_t max_in_flight_;
  std::uint64_t written_ = 0;
};

}  // namespace vofusion
