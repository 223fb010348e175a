#pragma once
// A scratch file for records that leave RAM (the world model's bricks, old keyframes): created in
// `dir` (the system's temporary folder when empty or "auto") at the first append and unlinked at
// once, so it never outlives the process. Records are read back by their place. A released record's
// place is written again by later appends (best fit among the free places, neighbours merged), so a
// map walked back and forth keeps its file at the size of what is stored, not of all it ever stored.
// append() and read() may run on different threads (pwrite/pread at fixed offsets); appends come from
// one thread at a time.
#include <atomic>
#include <cstdint>
#include <map>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <unordered_set>
#include <vector>

namespace vofusion {

class SpillFile {
 public:
  // A record's place, 8 bytes (an index of millions of them stays small): up to 1 TiB of file,
  // records up to 16 MiB.
  struct Record {
    std::uint64_t offset : 40;
    std::uint64_t length : 24;
  };
  static constexpr std::uint64_t kMaxRecordBytes = (std::uint64_t(1) << 24) - 1;
  static constexpr std::uint64_t kMaxFileBytes = std::uint64_t(1) << 40;  // what a Record's offset can say

  // what: names the file in errors ("the world model's spill file"). max_bytes: the file's size past
  // which an append fails as a full disk does (kMaxFileBytes; less only in tests).
  SpillFile(std::string dir, std::string what, std::uint64_t max_bytes = kMaxFileBytes);
  ~SpillFile();
  SpillFile(const SpillFile&) = delete;
  SpillFile& operator=(const SpillFile&) = delete;

  // The record's place; std::nullopt when the file cannot be created or written (a full disk, or the
  // file at max_bytes: a place past it was written over the file's start before): the
  // first failure is warned of once ("<folder>: cannot write <what>: <why>: what would go to it stays
  // in memory from now on") and kept (failure()), and every later append returns std::nullopt without
  // trying. The caller keeps in RAM what it could not spill, so nothing is lost. Throws
  // std::runtime_error for a record over kMaxRecordBytes.
  std::optional<Record> append(const std::vector<std::uint8_t>& bytes);
  // Why the file could not be created or written; empty while it could.
  std::string failure() const;
  // A record that cannot be read whole: what() is "<folder>: cannot read <what>: <cause>".
  struct ReadError : std::runtime_error {
    ReadError(const std::string& message, std::string why) : std::runtime_error(message), cause(std::move(why)) {}
    std::string cause;  // "short file", or the system's error text
  };
  // Throws ReadError when the record cannot be read whole.
  std::vector<std::uint8_t> read(Record r) const;
  // Where the file was made, for errors about what it holds (once a record was appended).
  const std::string& folder() const { return folder_; }
  // The caller's item `id` (a brick's key, a keyframe's id) could not be read back: counted once however
  // often it is met again, and `warning` printed for the first item lost (once per file). Any thread.
  void lost(std::uint64_t id, const std::string& warning) const;
  std::size_t lostCount() const;
  bool isLost(std::uint64_t id) const;  // lost() was called for it
  // r's place may be written again: only once nothing will read r (the world model releases a brick
  // when it takes it back, on the thread that appends).
  void release(Record r);
  std::uint64_t bytes() const { return end_.load(); }  // the file's size
  std::uint64_t freeBytes() const;                      // of it, released and not written again
  std::size_t freePlaces() const;                       // the free places those bytes make up

 private:
  void open();  // throws InputError(folder, ...)
  void fail(const std::string& why);  // the first failure: kept and warned of
  std::uint64_t place(std::uint64_t size);  // where `size` bytes go: a free place, else the end
  void addFree(std::uint64_t offset, std::uint64_t size);
  std::string dir_, what_;
  std::uint64_t max_bytes_;
  std::string folder_;  // where the file was made (dir_, or the temporary folder for "auto")
  mutable std::mutex open_mu_;
  std::string failure_;  // under open_mu_
  std::atomic<bool> failed_{false};
  std::atomic<int> fd_{-1};
  std::atomic<std::uint64_t> end_{0};
  mutable std::mutex free_mu_;
  std::map<std::uint64_t, std::uint64_t> free_by_offset_;       // offset -> size
  std::multimap<std::uint64_t, std::uint64_t> free_by_size_;    // size -> offset
  std::uint64_t free_bytes_ = 0;
  mutable std::mutex lost_mu_;
  mutable std::unordered_set<std::uint64_t> lost_;  // under lost_mu_
};

}  // namespace vofusion
