#pragma once
// The stream of a rawlog recorded in place (RawlogWriterOptions::in_place): every record MRPT
// serialises is gathered in memory and appended by endRecord() in one write(2) (repeated only if the
// kernel takes part of it), so a recorder that stops, fails or crashes between records leaves the file
// ending between two whole records. A kill during that write(2) can still tear its record: Linux ends
// a write cut short by a fatal signal between two pages, with the first pages in the file. The reader
// then reads to the last whole frame and reports the file as truncated inside the next entry
// (RecordingCutShort). The kernel has the bytes as soon as write(2) returns; the records go to the disk
// at most once a second (fdatasync), and with their images when the recording ends (syncfs). Plain, not gzip: a
// gzip stream is only readable up to its last flush, and a record without its images is small.
#include <chrono>
#include <functional>
#include <string>

#include <mrpt/io/CStream.h>

namespace vofusion {

class RecordFile : public mrpt::io::CStream {
 public:
  // Created (an existing file is an error; throws InputError) and locked (flock) while it lives: made
  // under a name of its own, locked, then linked into place, so no other process ever sees it unlocked.
  explicit RecordFile(const std::string& path);
  ~RecordFile() override;

  size_t Write(const void* bytes, size_t n) override;
  size_t Read(void*, size_t) override;
  uint64_t Seek(int64_t, TSeekOrigin) override;
  uint64_t getTotalBytesCount() const override { return written_ + record_.size(); }
  uint64_t getPosition() const override { return written_ + record_.size(); }

  // Appends the record gathered since the last call; throws InputError (a full disk) with the file
  // left at its last whole record. A partial record that cannot be cut back ends the file: every
  // later record throws (appended after it, they were written but unreadable).
  void endRecord();
  void sync();  // to the disk now; throws InputError (an I/O error)
  // sync() when the last was over a second ago. Apart from endRecord(): a record appended is in the
  // file, counted by its writer, even when the sync after it fails.
  void syncIfDue();
  // Removes the recording at `path` if its recorder left it empty and is gone (a kill before the first
  // frame): an empty regular file no process holds. `also_remove` runs first, while this holds the file's
  // lock and the file is still in place (so no recorder can start there meanwhile), for what was made
  // beside it; it returns false to keep everything. False: nothing was removed. Never throws.
  static bool removeIfAbandoned(const std::string& path, const std::function<bool()>& also_remove);
  // The file and everything written beside it (the images its records name, the folders' entries):
  // syncfs(), one call for all of them.
  void syncWithItsFolder();

 private:
  std::string path_, record_;
  int fd_ = -1;
  int lock_fd_ = -1;  // holds the flock (the file as made, before it was linked into place); -1 without one
  uint64_t written_ = 0;
  std::string torn_;  // why a partial record stays at the end: no record can follow it
  std::chrono::steady_clock::time_point last_sync_;
};

}  // namespace vofusion
