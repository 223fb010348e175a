// core/atomic_file.h: outputs appear whole or not at all, and staging a killed run left behind
// does not stay.
#include <gtest/gtest.h>
#include <fcntl.h>
#include <sys/inotify.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "support.h"
#include "sync_watch.h"
#include "vofusion/core/atomic_file.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/text_file.h"

using namespace vofusion;
namespace fs = std::filesystem;

// Without RENAME_EXCHANGE (NFS, FUSE) a folder is replaced in two renames: the earlier one to
// "<path>.old-<pid>", then the complete staging to <path>. A run killed between them left nothing at
// <path>; the next writer removed the new folder as a dead run's staging and never saw the earlier one.
// Now it finishes that commit; killed after both renames, the earlier folder is removed.
TEST(AtomicFile, ACommitKilledBetweenItsTwoRenamesIsFinishedByTheNextWriter) {
  const std::string dir = test::tempDir("atomic_dead_commit");
  const pid_t child = ::fork();
  if (child == 0) ::_exit(0);
  ASSERT_GT(child, 0);
  ASSERT_EQ(::waitpid(child, nullptr, 0), child);
  const std::string pid = std::to_string(child);
  // Between the renames: the new folder at the staging name, the earlier one aside.
  fs::create_directories(dir + "/out.tmp-" + pid);
  std::ofstream(dir + "/out.tmp-" + pid + "/mesh.ply") << "new";
  fs::create_directories(dir + "/out.old-" + pid);
  std::ofstream(dir + "/out.old-" + pid + "/mesh.ply") << "earlier";
  { AtomicPath next(dir + "/out"); }  // another output's writer: only cleans up
  EXPECT_EQ(readTextFile(dir + "/out/mesh.ply"), "new");
  EXPECT_FALSE(fs::exists(dir + "/out.tmp-" + pid));
  EXPECT_FALSE(fs::exists(dir + "/out.old-" + pid));
  // After both renames: the new folder in place, the earlier one still aside.
  fs::create_directories(dir + "/out.old-" + pid);
  std::ofstream(dir + "/out.old-" + pid + "/mesh.ply") << "earlier";
  { AtomicPath next(dir + "/out"); }
  EXPECT_EQ(readTextFile(dir + "/out/mesh.ply"), "new");
  EXPECT_FALSE(fs::exists(dir + "/out.old-" + pid));
}

// A run killed by a signal leaves "<path>.tmp-<pid>" behind; the next writer of <path> removes it,
// but not the staging of a process that still runs (another run writing there now).
TEST(AtomicFile, RemovesStagingOfProcessesThatAreGone) {
  namespace fs = std::filesystem;
  const std::string dir = test::tempDir("atomic_stale");
  const pid_t child = ::fork();
  if (child == 0) ::_exit(0);
  ASSERT_GT(child, 0);
  ASSERT_EQ(::waitpid(child, nullptr, 0), child);  // reaped: its pid names no process now
  const std::string gone = dir + "/summary.json.tmp-" + std::to_string(child);
  const std::string live = dir + "/summary.json.tmp-" + std::to_string(::getppid());
  const std::string other = dir + "/mesh.ply.tmp-" + std::to_string(child);
  fs::create_directories(gone);
  std::ofstream(gone + "/part") << "half";
  std::ofstream(live) << "in progress";
  std::ofstream(other) << "another file's";
  writeFileAtomically(dir + "/summary.json", "{}\n");
  EXPECT_FALSE(fs::exists(gone));
  EXPECT_TRUE(fs::exists(live));
  EXPECT_TRUE(fs::exists(other));  // only the staging of the path being written
  EXPECT_EQ(readTextFile(dir + "/summary.json"), "{}\n");
}

// Several outputs move into place together: none is at its path before commit(), a writer that fails
// leaves the earlier files as they were, and its error names the file asked for, not its temporary.
TEST(AtomicFile, ASetOfFilesMovesIntoPlaceTogether) {
  const std::string dir = test::tempDir("atomic_set");
  writeFileAtomically(dir + "/a.txt", "earlier a");
  {
    AtomicFileSet set;
    set.write(dir + "/a.txt", [](const std::string& tmp) { writeFileAtomically(tmp, "new a"); });
    try {
      set.write(dir + "/b.txt", [](const std::string& tmp) { throw InputError(tmp, "cannot write: disk full"); });
      FAIL() << "no error";
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()), dir + "/b.txt: cannot write: disk full");
    }
  }  // never committed
  EXPECT_EQ(readTextFile(dir + "/a.txt"), "earlier a");
  AtomicFileSet set;
  set.write(dir + "/a.txt", [](const std::string& tmp) { writeFileAtomically(tmp, "new a"); });
  set.write(dir + "/b.txt", [](const std::string& tmp) { writeFileAtomically(tmp, "new b"); });
  EXPECT_EQ(readTextFile(dir + "/a.txt"), "earlier a");
  set.commit();
  EXPECT_EQ(readTextFile(dir + "/a.txt"), "new a");
  EXPECT_EQ(readTextFile(dir + "/b.txt"), "new b");
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir), {}), 2);
  // A file whose bytes cannot be synced (EIO) fails the set before any file is replaced: the first was
  // new and the second old.
  {
    test::SyncWatch watch;
    watch.fail("fsync", dir + "/b.txt.tmp-" + std::to_string(::getpid()), EIO);
    AtomicFileSet failing;
    failing.write(dir + "/a.txt", [](const std::string& tmp) { writeFileAtomically(tmp, "newer a"); });
    failing.write(dir + "/b.txt", [](const std::string& tmp) { writeFileAtomically(tmp, "newer b"); });
    EXPECT_THROW(failing.commit(), InputError);
  }
  EXPECT_EQ(readTextFile(dir + "/a.txt"), "new a");
  EXPECT_EQ(readTextFile(dir + "/b.txt"), "new b");
  // So does a folder where a file goes (the rename fails: the first file was in place, new).
  fs::create_directories(dir + "/c.txt/x");
  AtomicFileSet blocked;
  blocked.write(dir + "/a.txt", [](const std::string& tmp) { writeFileAtomically(tmp, "newest a"); });
  blocked.write(dir + "/c.txt", [](const std::string& tmp) { writeFileAtomically(tmp, "c"); });
  try {
    blocked.commit();
    ADD_FAILURE() << "a file put over a folder";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), dir + "/c.txt: is a folder: cannot write the file there");
  }
  EXPECT_EQ(readTextFile(dir + "/a.txt"), "new a");
}

// A folder replaced by commit() is removed by the destructor, after the outputs committed with it;
// revert() before that puts it back (a rawlog that could not be renamed keeps its own images folder).
TEST(AtomicFile, AReplacedFolderGoesWithTheWriterAndRevertPutsItBack) {
  const std::string dir = test::tempDir("atomic_folder_revert");
  const std::string images = dir + "/a_Images";
  fs::create_directories(images);
  writeFileAtomically(images + "/old.png", "earlier");
  const auto names = [&] {
    std::vector<std::string> n;
    for (const auto& e : fs::directory_iterator(dir)) n.push_back(e.path().filename().string());
    std::sort(n.begin(), n.end());
    return n;
  };
  {
    AtomicPath out(images);
    fs::create_directories(out.tmp());
    writeFileAtomically(out.tmp() + "/new.png", "this run's");
    out.commit();
    EXPECT_TRUE(fs::exists(images + "/new.png"));
    EXPECT_FALSE(fs::exists(images + "/old.png"));
    out.revert();
    EXPECT_EQ(readTextFile(images + "/old.png"), "earlier");
    EXPECT_FALSE(fs::exists(images + "/new.png"));
  }
  EXPECT_EQ(names(), std::vector<std::string>{"a_Images"}) << "the reverted folder removed";
  {
    AtomicPath out(images);
    fs::create_directories(out.tmp());
    writeFileAtomically(out.tmp() + "/new.png", "this run's");
    out.commit();
    EXPECT_EQ(names().size(), 2u) << "the earlier folder kept until the writer goes";
  }
  EXPECT_EQ(names(), std::vector<std::string>{"a_Images"});
  EXPECT_EQ(readTextFile(images + "/new.png"), "this run's");
}

// A folder replaced, and put back, is swapped with its staging in one step: no other name is ever
// made beside it. Three renames (the old one aside to "<path>.old-<pid>") left a moment with nothing at
// the path; killed there, the next run removed the new folder as a dead run's staging.
TEST(AtomicFile, AFolderIsReplacedAndPutBackInOneStep) {
  const std::string dir = test::tempDir("atomic_folder_swap");
  const std::string images = dir + "/a_Images";
  fs::create_directories(images);
  writeFileAtomically(images + "/old.png", "earlier");
  fs::create_directories(dir + "/probe_a");
  fs::create_directories(dir + "/probe_b");
  if (::renameat2(AT_FDCWD, (dir + "/probe_a").c_str(), AT_FDCWD, (dir + "/probe_b").c_str(), RENAME_EXCHANGE) != 0)
    GTEST_SKIP() << "this file system swaps no folders (" << std::strerror(errno) << "): AtomicPath takes three renames";
  fs::remove(dir + "/probe_a");
  fs::remove(dir + "/probe_b");
  const int fd = ::inotify_init1(IN_NONBLOCK | IN_CLOEXEC);
  ASSERT_GE(fd, 0);
  const std::unique_ptr<int, void (*)(int*)> close_fd(new int(fd), [](int* f) { ::close(*f), delete f; });
  ASSERT_GE(::inotify_add_watch(fd, dir.c_str(), IN_CREATE | IN_MOVED_FROM | IN_MOVED_TO | IN_DELETE), 0);
  std::string staging;
  {
    AtomicPath out(images);
    staging = fs::path(out.tmp()).filename().string();
    fs::create_directories(out.tmp());
    writeFileAtomically(out.tmp() + "/new.png", "this run's");
    out.commit();
    EXPECT_EQ(readTextFile(images + "/new.png"), "this run's");
    out.revert();
    EXPECT_EQ(readTextFile(images + "/old.png"), "earlier");
  }
  std::vector<std::string> named;
  alignas(inotify_event) char buf[8192];
  for (ssize_t n; (n = ::read(fd, buf, sizeof buf)) > 0;)
    for (char* p = buf; p < buf + n; p += sizeof(inotify_event) + reinterpret_cast<inotify_event*>(p)->len)
      if (const auto* e = reinterpret_cast<inotify_event*>(p); e->len > 0) named.push_back(e->name);
  ASSERT_FALSE(named.empty()) << "no event seen";
  for (const std::string& n : named) EXPECT_TRUE(n == "a_Images" || n == staging) << n;
}

// A folder named with a trailing slash (a shell's completion adds it) is staged beside it and replaced
// as without one (staged inside it, the rename of the folder into itself failed at the end of the work).
TEST(AtomicFile, AFolderNamedWithATrailingSlashIsReplaced) {
  const std::string dir = test::tempDir("atomic_trailing_slash");
  fs::create_directories(dir + "/out");
  writeFileAtomically(dir + "/out/old.txt", "earlier");
  {
    AtomicPath out(dir + "/out//");
    EXPECT_EQ(out.path(), dir + "/out");
    fs::create_directories(out.tmp());
    writeFileAtomically(out.tmp() + "/new.txt", "this run's");
    ASSERT_NO_THROW(out.commit());
  }
  EXPECT_EQ(readTextFile(dir + "/out/new.txt"), "this run's");
  EXPECT_FALSE(fs::exists(dir + "/out/old.txt"));
  EXPECT_EQ(std::distance(fs::directory_iterator(dir), {}), 1);
}

// Every commit puts the bytes on the disk before the rename and the rename after it: fsync() of the
// temporary, then of the folder (a folder's files by one syncfs() first). Watched by SyncWatch. Nothing
// written: an error.
TEST(AtomicFile, ACommitSyncsTheBytesThenTheRename) {
  using test::SyncWatch;
  const std::string dir = test::tempDir("atomic_durable");
  const std::string path = dir + "/checkpoint", tmp = path + ".tmp-" + std::to_string(::getpid());
  std::ofstream(path) << "earlier";
  {
    SyncWatch watch;
    AtomicPath out(path);
    std::ofstream(out.tmp()) << "this run's";
    out.commit();
    EXPECT_EQ(watch.synced(), (std::vector<std::string>{"fsync " + tmp, "fsync " + dir}));
  }
  EXPECT_EQ(readTextFile(path), "this run's");
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir), {}), 1);  // no temporary left
  {
    SyncWatch watch;
    writeFileAtomically(dir + "/summary.json", "{}");
    EXPECT_EQ(watch.synced(),
              (std::vector<std::string>{"fsync " + dir + "/summary.json.tmp-" + std::to_string(::getpid()), "fsync " + dir}));
  }
  {
    SyncWatch watch;
    AtomicPath folder(dir + "/images");
    fs::create_directories(folder.tmp());
    std::ofstream(folder.tmp() + "/1.png") << "png";
    folder.commit();
    EXPECT_EQ(watch.synced(),
              (std::vector<std::string>{"syncfs " + folder.tmp(), "fsync " + folder.tmp(), "fsync " + dir}));
  }
  AtomicPath nothing(dir + "/never");
  EXPECT_THROW(nothing.commit(), InputError);
}

// A commit that throws changed nothing: a file whose bytes cannot be synced is not put in place (the
// earlier one stays). Once renamed, the output is whole: a folder that cannot be synced after it is
// said, not a failure (it threw with the new file already in place, and a rawlog's caller then put
// the earlier images back beside it); one that cannot be synced at all (EINVAL: some FUSE and network
// mounts) is no failure either.
TEST(AtomicFile, ACommitThatThrowsChangedNothing) {
  using test::SyncWatch;
  const std::string dir = test::tempDir("atomic_sync_fails");
  const std::string path = dir + "/out.txt", tmp = path + ".tmp-" + std::to_string(::getpid());
  std::ofstream(path) << "earlier";
  {
    SyncWatch watch;
    watch.fail("fsync", tmp, EIO);
    AtomicPath out(path);
    std::ofstream(out.tmp()) << "this run's";
    EXPECT_THROW(out.commit(), InputError);
  }
  EXPECT_EQ(readTextFile(path), "earlier");
  {  // A file system that cannot sync (EINVAL) has nothing more to give: put in place.
    SyncWatch watch;
    watch.fail("fsync", tmp, EINVAL);
    AtomicPath out(path);
    std::ofstream(out.tmp()) << "unsynced";
    EXPECT_NO_THROW(out.commit());
    EXPECT_EQ(readTextFile(path), "unsynced");
  }
  for (const int err : {EIO, EINVAL}) {
    SyncWatch watch;
    watch.fail("fsync", dir, err);
    AtomicPath out(path);
    std::ofstream(out.tmp()) << "this run's " << err;
    EXPECT_NO_THROW(out.commit()) << err;
    EXPECT_EQ(readTextFile(path), "this run's " + std::to_string(err));
    EXPECT_EQ(watch.synced().back(), "fsync " + dir + " failed");
  }
}

// A path inside a folder, by its parts once resolved as samePath resolves them: "a/bc" is not in "a/b",
// a link into the folder is, and neither needs to exist.
TEST(AtomicFile, WhetherAPathIsWithinAFolder) {
  const std::string dir = testing::TempDir() + "/within";
  fs::create_directories(dir + "/b");
  std::error_code ec;
  fs::remove(dir + "/link", ec);
  fs::create_directory_symlink(dir + "/b", dir + "/link");
  EXPECT_TRUE(isWithin(dir + "/b/c/d.txt", dir + "/b"));
  EXPECT_TRUE(isWithin(dir + "/b", dir + "/b/"));
  EXPECT_TRUE(isWithin(dir + "/link/x.bin", dir + "/b"));
  EXPECT_TRUE(isWithin(dir + "/b/../b/x", dir + "/b"));
  EXPECT_FALSE(isWithin(dir + "/bc", dir + "/b"));
  EXPECT_FALSE(isWithin(dir, dir + "/b"));
}
