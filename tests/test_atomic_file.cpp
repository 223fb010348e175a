// core/atomic_file.h: outputs appear whole or not at all, and staging a killed run left behind
// does not stay.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "support.h"
#include "vofusion/core/atomic_file.h"
#include "vofusion/core/text_file.h"

using namespace vofusion;

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
