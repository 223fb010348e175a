#include "vofusion/core/atomic_file.h"

#include <algorithm>
#include <fcntl.h>
#include <sys/stat.h>
#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <vector>

#include "vofusion/core/errors.h"
#include "vofusion/core/progress.h"

namespace fs = std::filesystem;

namespace vofusion {

namespace {

// The pid of "<name><tag><digits>" (a process that is gone), or 0.
pid_t deadPidOf(const std::string& n, const std::string& prefix) {
  if (n.size() <= prefix.size() || n.size() > prefix.size() + 9 || n.compare(0, prefix.size(), prefix) != 0) return 0;
  const std::string digits = n.substr(prefix.size());
  if (digits.find_first_not_of("0123456789") != std::string::npos) return 0;
  const pid_t pid = static_cast<pid_t>(std::stol(digits));
  return pid > 0 && ::kill(pid, 0) != 0 && errno == ESRCH ? pid : 0;
}

// A dead run's "<name>.old-<pid>": commit() without RENAME_EXCHANGE moved the earlier folder there,
// then its complete staging to the name. Killed between the two, nothing is at the name: the staging
// (synced before the first rename) goes there. Killed after them, the earlier folder is removed.
void finishDeadCommit(const fs::path& final_path, const fs::path& old, pid_t pid) {
  std::error_code ec;
  const fs::path staging = final_path.string() + ".tmp-" + std::to_string(pid);
  if (!fs::exists(final_path, ec) && fs::is_directory(staging, ec)) fs::rename(staging, final_path, ec);
  if (fs::exists(final_path, ec)) fs::remove_all(old, ec);
  else fs::rename(old, final_path, ec);  // no staging left: the earlier folder back
}

// "<name>.tmp-<pid>" beside `final_path` whose process no longer runs: staging a killed run left
// (a signal skips the destructor). A live pid's, another run's in progress, stays. A dead run's
// "<name>.old-<pid>" first has its commit finished.
void removeStaleStaging(const std::string& final_path) {
  const fs::path p(final_path);
  const fs::path dir = p.has_parent_path() ? p.parent_path() : fs::path(".");
  const std::string prefix = p.filename().string() + ".tmp-", old_prefix = p.filename().string() + ".old-";
  std::vector<fs::path> stale;
  std::vector<std::pair<fs::path, pid_t>> old;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string n = it->path().filename().string();
    if (deadPidOf(n, prefix)) stale.push_back(it->path());
    else if (const pid_t pid = deadPidOf(n, old_prefix)) old.emplace_back(it->path(), pid);
  }
  for (const auto& [o, pid] : old) finishDeadCommit(p, o, pid);
  for (const fs::path& s : stale) fs::remove_all(s, ec);
}

// Its bytes on the disk: fsync() of a file or of a folder's entries; with `folder_files`, a folder's
// files too, by syncfs() first (one call, where an fsync() each would cost a journal commit each).
// 0, or the errno of what failed. A file system that cannot sync a folder (some FUSE and network
// mounts: EINVAL) has nothing more to give: that is no failure.
int syncToDisk(const std::string& path, bool folder_files = true) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  struct stat st {};
  const bool ok = fd >= 0 && ::fstat(fd, &st) == 0 && (!folder_files || !S_ISDIR(st.st_mode) || ::syncfs(fd) == 0) &&
                  ::fsync(fd) == 0;
  const int err = ok ? 0 : errno;
  if (fd >= 0) ::close(fd);
  return syncUnsupported(err) ? 0 : err;
}

// After a rename the output is in place, whole: a folder that does not sync is said, not a failure
// (a throw from commit() means that nothing changed).
void syncRenameOrSay(const std::string& folder, const std::string& what) {
  if (const int err = syncToDisk(folder, false))
    printWarning(what + ": written, but its folder could not be synced to the disk (" + std::strerror(err) + ")");
}

std::string parentOf(const std::string& path) {
  const fs::path p(path);
  return p.has_parent_path() ? p.parent_path().string() : ".";
}

// "out/" names the folder "out": its staging goes beside it, not into it (rgbd-simulate --out sim/ staged
// in sim/.tmp-<pid>, and the commit's rename of sim/ into itself failed after every frame was made).
std::string withoutTrailingSlashes(std::string path) {
  if (path.size() > 1 && (path.back() == '/' || path.back() == '.')) path = fs::path(path).lexically_normal().string();  // "sim/."
  while (path.size() > 1 && path.back() == '/') path.pop_back();
  return path;
}

// The folder the process runs in is `path` or lies inside it ("--out ." or ".."): staged beside it and
// renamed over it, the rename fails (EBUSY for "."), after all the work.
void refuseTheWorkingFolder(const std::string& path) {
  std::error_code here_ec, path_ec;
  const fs::path here = fs::current_path(here_ec), target = fs::weakly_canonical(path, path_ec);
  if (here_ec || path_ec || target.empty()) return;
  const auto [t, h] = std::mismatch(target.begin(), target.end(), here.begin(), here.end());
  if (t == target.end())
    throw InputError(path, "is the folder this command runs in, or holds it: it cannot be replaced (name the folder "
                           "from outside it)");
}

}  // namespace

AtomicPath::AtomicPath(std::string final_path)
    : final_(withoutTrailingSlashes(std::move(final_path))), tmp_(final_ + ".tmp-" + std::to_string(::getpid())) {
  refuseTheWorkingFolder(final_);
  std::error_code ec;
  fs::remove_all(tmp_, ec);  // a leftover of a crashed run with the same pid
  removeStaleStaging(final_);
}

AtomicPath::~AtomicPath() {
  if (!committed_ || replaced_) {  // this run's staging, or the folder it replaced (moved to tmp_)
    std::error_code ec;
    fs::remove_all(tmp_, ec);
  }
}

void AtomicPath::prepare() {
  if (prepared_) return;
  std::error_code ec;
  if (!fs::exists(tmp_, ec)) throw InputError(final_, "nothing was written");
  if (!fs::is_directory(tmp_, ec)) refuseFolderWhereAFileGoes(final_);
  // The bytes before the rename: ext4 forces a file's data out before a rename only where it replaces
  // one, XFS and btrfs never; after a power cut a new name could hold an empty file.
  if (const int err = syncToDisk(tmp_)) throw InputError(final_, std::string("cannot write: ") + std::strerror(err));
  prepared_ = true;
}

void AtomicPath::commit() {
  prepare();
  std::error_code ec;
  if (fs::is_directory(tmp_) && fs::exists(final_)) {
    // rename() cannot replace a non-empty directory: the two are swapped in one step, the old one
    // taking the staging name, removed by the destructor (or revert() swaps them back). Removing a
    // large folder takes seconds: done after the outputs committed with it are in place too. Three
    // renames left a moment with nothing at the path: killed there, the next run removed the new
    // folder as a dead run's staging, and the old one stayed aside for good.
    if (::renameat2(AT_FDCWD, tmp_.c_str(), AT_FDCWD, final_.c_str(), RENAME_EXCHANGE) == 0) {
      replaced_ = true;
      committed_ = true;
      syncRenameOrSay(parentOf(final_), final_);
      return;
    }
    // A file system without the exchange (EINVAL: some network and FUSE mounts): the old one aside.
    const std::string old = final_ + ".old-" + std::to_string(::getpid());
    fs::remove_all(old, ec);
    fs::rename(final_, old, ec);
    if (ec) throw InputError(final_, "cannot replace: " + ec.message());
    fs::rename(tmp_, final_, ec);
    if (ec) {
      std::error_code back;  // the earlier folder back in place; where it is when that fails too
      fs::rename(old, final_, back);
      throw InputError(final_, "cannot write: " + ec.message() + (back ? " (the earlier one is at " + old + ")" : ""));
    }
    fs::rename(old, tmp_, ec);
    replaced_ = !ec;
    if (ec) fs::remove_all(old, ec);
  } else {
    fs::rename(tmp_, final_, ec);
    if (ec) throw InputError(final_, "cannot write: " + ec.message());
  }
  committed_ = true;
  syncRenameOrSay(parentOf(final_), final_);  // the rename itself
}

void AtomicPath::revert() {
  if (!committed_) return;
  std::error_code ec, undo;
  if (replaced_ && ::renameat2(AT_FDCWD, tmp_.c_str(), AT_FDCWD, final_.c_str(), RENAME_EXCHANGE) == 0) {
    // swapped back: the old one at the path, the new one at the staging name (removed)
  } else if (replaced_) {  // the new one aside, the old one back, the new one to the staging name (removed)
    const std::string aside = final_ + ".tmp-new-" + std::to_string(::getpid());
    fs::rename(final_, aside, ec);
    if (!ec) {
      fs::rename(tmp_, final_, ec);
      if (ec) fs::rename(aside, final_, undo);  // as committed again
    }
    if (!ec) {
      std::error_code moved;
      fs::rename(aside, tmp_, moved);
      if (moved) fs::remove_all(aside, moved);
    }
  } else {
    fs::rename(final_, tmp_, ec);
  }
  if (ec) {
    // Left as committed, and the earlier one where it is: the destructor no longer removes it.
    const bool earlier_kept = replaced_;
    replaced_ = false;
    throw InputError(final_, "cannot put the earlier one back: " + ec.message() +
                                 (earlier_kept ? " (it is at " + tmp_ + ")" : ""));
  }
  committed_ = replaced_ = false;
}

bool syncUnsupported(int err) { return err == EINVAL || err == ENOTSUP || err == EOPNOTSUPP; }

void syncFolderEntries(const std::string& dir) { syncRenameOrSay(dir, dir); }

void syncFileToDisk(const std::string& path) {
  if (const int err = syncToDisk(path)) throw InputError(path, std::string("cannot write: ") + std::strerror(err));
}

void syncFileSystemOf(const std::string& path) {
  const int fd = ::open(parentOf(path).c_str(), O_RDONLY | O_CLOEXEC);
  const bool ok = fd >= 0 && ::syncfs(fd) == 0;
  const int err = ok ? 0 : errno;
  if (fd >= 0) ::close(fd);
  if (!ok && !syncUnsupported(err))
    throw InputError(path, std::string("cannot write: ") + std::strerror(err));
}

void AtomicFileSet::write(const std::string& path, const std::function<void(const std::string& tmp)>& write_to) {
  // A second AtomicPath for the same file would remove the first one's temporary and take its place.
  for (const auto& f : files_)
    if (samePath(f->path(), path)) throw InputError(path, "named twice as an output");
  auto file = std::make_unique<AtomicPath>(path);
  try {
    write_to(file->tmp());
  } catch (const InputError& e) {
    if (e.file() != file->tmp()) throw;
    throw InputError(path, e.problem());
  }
  files_.push_back(std::move(file));
}

void AtomicFileSet::commit() {
  // Every file's bytes on the disk before any replaces its earlier one: a sync that fails (EIO, a full
  // NFS disk) on the second file left the first one new and the second one old.
  for (auto& f : files_) f->prepare();
  for (auto& f : files_) f->commit();
}

void refuseFolderWhereAFileGoes(const std::string& path) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) throw InputError(path, "is a folder: cannot write the file there");
}

namespace {
// "a/./b", "a/../a/b" and symlinks resolved as far as they exist.
fs::path canonicalPath(const std::string& p) {
  std::error_code ec;
  const fs::path c = fs::weakly_canonical(p, ec);
  if (!ec) return c;
  const fs::path a = fs::absolute(p, ec);  // the throwing overload threw for "" (an unset $SEQ)
  return (ec ? fs::path(p) : a).lexically_normal();
}
}  // namespace

bool samePath(const std::string& a, const std::string& b) { return canonicalPath(a) == canonicalPath(b); }

bool isWithin(const std::string& path, const std::string& folder) {
  const fs::path p = canonicalPath(path), f = canonicalPath(folder);
  auto pi = p.begin();
  for (auto fi = f.begin(); fi != f.end(); ++fi, ++pi)
    if (fi->empty() && std::next(fi) == f.end()) return true;  // a trailing separator
    else if (pi == p.end() || *pi != *fi) return false;
  return true;
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
