#pragma once
// Outputs appear whole or not at all: write to "<path>.tmp-<pid>", then rename over <path>; commit()
// puts the bytes on the disk before the rename and the rename after it (fsync), so that a power cut
// leaves the earlier file or this one, never an empty one.
// If the writer is destroyed without commit() (an exception, Ctrl-C unwinding), the temporary is
// removed and any earlier <path> is left untouched. A run killed by a signal leaves its temporary:
// the next AtomicPath for the same <path> removes those whose process is gone.
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace vofusion {

class AtomicPath {
 public:
  // Throws InputError for a path that is the folder the process runs in, or holds it ("." or ".."):
  // that folder cannot be replaced by a rename (nor should a shell be left in the removed one).
  explicit AtomicPath(std::string final_path);
  ~AtomicPath();
  AtomicPath(const AtomicPath&) = delete;
  AtomicPath& operator=(const AtomicPath&) = delete;

  const std::string& tmp() const { return tmp_; }     // write here (a file or a directory)
  const std::string& path() const { return final_; }
  // The bytes written to tmp on the disk (what commit() does first); throws InputError on failure, and
  // then nothing changed.
  void prepare();
  void commit();  // rename tmp -> final (replacing a file or directory); throws InputError on failure,
                  // and then nothing changed (a folder that cannot be synced after the rename is said)
                  // A directory replaced is removed by the destructor, so that the outputs committed
                  // with it are in place before the seconds a large folder takes to remove.
  // Undoes commit(), before the destructor, for outputs that change together: a directory it replaced
  // is back at the path, and this one removed (nothing was there: nothing is). A file it replaced is
  // not back (the rename replaced it): the path then holds nothing.
  void revert();

 private:
  std::string final_, tmp_;
  bool prepared_ = false;
  bool committed_ = false;
  bool replaced_ = false;  // commit() moved an earlier directory to tmp_
};

// Several outputs at paths of their own, moved into place together: each is written to its temporary
// (write), and commit() renames them all once every one was written. One that fails to write leaves
// every earlier file at those paths as it was. A path written twice is refused (InputError). A
// writer's InputError naming the temporary is rethrown
// naming the file asked for (the temporary is gone by the time the error is read).
class AtomicFileSet {
 public:
  void write(const std::string& path, const std::function<void(const std::string& tmp)>& write_to);
  void commit();

 private:
  std::vector<std::unique_ptr<AtomicPath>> files_;
};

// Throws InputError(path, ...) when a folder is where the file `path` is to go (a rename cannot put a
// file over it): checked before any of a set of outputs moves.
void refuseFolderWhereAFileGoes(const std::string& path);

// Whether two paths name one file ("a/./b", "a/../a/b" and symlinks resolved as far as they exist).
bool samePath(const std::string& a, const std::string& b);
// Whether `path` is `folder` or inside it, resolved as samePath resolves (either may not exist yet).
bool isWithin(const std::string& path, const std::string& folder);

// Convenience for text outputs; throws InputError(path, strerror) if the write fails (disk full...).
void writeFileAtomically(const std::string& path, const std::string& contents);
// Whether a failed fsync/fdatasync/syncfs's errno means only that the file system cannot sync (some
// FUSE and network mounts: EINVAL, ENOTSUP): it has nothing more to give, which is no failure.
bool syncUnsupported(int err);
// A file written in place (not through an AtomicPath) on the disk (fsync), or InputError(path, ...).
void syncFileToDisk(const std::string& path);
// The folder's entries on the disk (fsync; a failure is said, the files being in place): for files
// moved into it by rename() outside an AtomicPath, their bytes synced before.
void syncFolderEntries(const std::string& dir);
// Everything written so far on the file system that holds `path`'s folder (syncfs), or InputError(path,
// ...): files another thread writes, for an output that must not outlive them at a power cut.
void syncFileSystemOf(const std::string& path);
// Throws InputError(dir, ...) if dir cannot be created or written to.
void ensureWritableDirectory(const std::string& dir);

}  // namespace vofusion
