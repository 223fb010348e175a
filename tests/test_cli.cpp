// vofusion::CommandLine and runApp: what the thin apps rely on for parsing and error reporting; the
// heap's restart with huge pages and the process clock they start with.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "vofusion/core/cli.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/heap.h"
#include "vofusion/core/timing.h"
#include "support.h"

using namespace vofusion;

namespace {
// argv from words (argv[0] is the program name).
struct Args {
  explicit Args(std::vector<std::string> words) : words_(std::move(words)) {
    words_.insert(words_.begin(), "app");
    for (auto& w : words_) ptrs_.push_back(w.data());
  }
  int argc() { return int(ptrs_.size()); }
  char** argv() { return ptrs_.data(); }

 private:
  std::vector<std::string> words_;
  std::vector<char*> ptrs_;
};

CommandLine parse(std::vector<std::string> words) {
  Args a(std::move(words));
  return CommandLine(a.argc(), a.argv(), {"--out", "--set", "--n", "--x"}, {"--help", "--flag"});
}

std::string usageError(std::vector<std::string> words) {
  try {
    parse(std::move(words));
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(CommandLine, ValuesFlagsAndPositionals) {
  const auto cl = parse({"in", "--out", "o1", "--flag", "--out=o2", "more"});
  EXPECT_EQ(cl.value("--out", ""), "o2");  // the last occurrence wins
  EXPECT_TRUE(cl.flag("--flag"));
  EXPECT_FALSE(cl.flag("--help"));
  EXPECT_EQ(cl.positional(), (std::vector<std::string>{"in", "more"}));
  EXPECT_FALSE(cl.value("--set").has_value());
}

TEST(CommandLine, RepeatableOptionKeepsEveryOccurrenceInOrder) {
  const auto cl = parse({"--set", "a.b=1", "--set=c.d=2", "--set", "a.b=3"});
  EXPECT_EQ(cl.values("--set"), (std::vector<std::string>{"a.b=1", "c.d=2", "a.b=3"}));
  EXPECT_TRUE(parse({}).values("--set").empty());
}

TEST(CommandLine, ShortHelpAndUnknownOptions) {
  EXPECT_TRUE(parse({"-h"}).flag("--help"));
  EXPECT_NE(usageError({"-x"}).find("unknown option -x"), std::string::npos);
  EXPECT_NE(usageError({"--nope"}).find("unknown option --nope"), std::string::npos);
  EXPECT_NE(usageError({"--flag=1"}).find("unknown option --flag"), std::string::npos);
  EXPECT_NE(usageError({"--out"}).find("--out needs a value"), std::string::npos);
}

TEST(CommandLine, IntegerWithMinimum) {
  EXPECT_EQ(parse({}).count("--n", 7, 1), 7u);
  EXPECT_EQ(parse({"--n", "3"}).count("--n", 0, 1), 3u);
  EXPECT_EQ(parse({"--n", "0"}).count("--n", 5), 0u);
  for (const char* bad : {"0", "-2", "2.5", "x", ""}) {
    try {
      parse({"--n", bad}).count("--n", 0, 1);
      ADD_FAILURE() << bad;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("--n expects an integer >= 1"), std::string::npos) << e.what();
    }
  }
}

TEST(CommandLine, NumberInRange) {
  EXPECT_DOUBLE_EQ(parse({}).number("--x", 0.5, 0.0, 1.0), 0.5);
  EXPECT_DOUBLE_EQ(parse({"--x", "1"}).number("--x", 0.5, 0.0, 1.0), 1.0);  // upper bound included
  EXPECT_DOUBLE_EQ(parse({"--x", "1e9"}).number("--x", 1.0, 0.0), 1e9);     // no upper bound
  for (const char* bad : {"0", "-1", "1.5", "nan"}) {
    try {
      parse({"--x", bad}).number("--x", 0.5, 0.0, 1.0);
      ADD_FAILURE() << bad;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("--x expects a number > 0 and <= 1"), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(parse({"--x", "abc"}).number("--x", 0.5, 0.0, 1.0), InputError);
}

namespace {
int throwsInput(int, char**) { throw InputError("f.txt", "bad"); }
int throwsOther(int, char**) { throw std::runtime_error("boom"); }
int returns7(int, char**) { return 7; }
}  // namespace

TEST(RunApp, ExitCodesAndOneLine) {
  testing::internal::CaptureStderr();
  EXPECT_EQ(runApp("app", throwsInput, 0, nullptr), 2);
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "app: error: f.txt: bad\n");
  testing::internal::CaptureStderr();
  EXPECT_EQ(runApp("app", throwsOther, 0, nullptr), 1);
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "app: error: boom\n");
  testing::internal::CaptureStderr();
  EXPECT_EQ(runApp(nullptr, throwsInput, 0, nullptr), 2);
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "f.txt: bad\n");
  EXPECT_EQ(runApp("app", returns7, 0, nullptr), 7);
}

TEST(Heap, HugePagesAddedToTheTunablesUnlessTheyAlreadySayHowThePagesGo) {
  EXPECT_EQ(tunablesWithHugePageHeap(nullptr), "glibc.malloc.hugetlb=1");
  EXPECT_EQ(tunablesWithHugePageHeap(""), "glibc.malloc.hugetlb=1");
  EXPECT_EQ(tunablesWithHugePageHeap("glibc.malloc.arena_max=2"), "glibc.malloc.arena_max=2:glibc.malloc.hugetlb=1");
  EXPECT_EQ(tunablesWithHugePageHeap("glibc.malloc.hugetlb=0"), std::nullopt);
  EXPECT_EQ(tunablesWithHugePageHeap("glibc.malloc.arena_max=2:glibc.malloc.hugetlb=1"), std::nullopt);
  // Keys, not substrings: another key's value that happens to hold the text is not the setting.
  EXPECT_EQ(tunablesWithHugePageHeap("glibc.rtld.x=glibc.malloc.hugetlb=0"), "glibc.rtld.x=glibc.malloc.hugetlb=0:glibc.malloc.hugetlb=1");
}

namespace {
// The probe's output lines, run with `env` first (e.g. "-u GLIBC_TUNABLES"); never under a preloaded
// tool the suite itself may run under.
std::vector<std::string> probeLines(const std::string& env) {
  std::string out;
  EXPECT_EQ(test::run("env -u LD_PRELOAD " + env + " " + test::app("heap_restart_probe") + " a 'b c'", &out), 0) << out;
  return test::lines(out);
}
// "start <pid>" -> "<pid>"
std::string pidOf(const std::string& start_line) { return start_line.substr(std::string("start ").size()); }
// "running <pid> <name> <marker> " as the probe prints it; the name is cut at 15 characters, as the kernel keeps it.
std::string running(const std::string& start_line) { return "running " + pidOf(start_line) + " heap_restart_pr no-marker "; }
}  // namespace

TEST(Heap, AnAppRestartsOnceInPlaceWithHugePagesAndTheSameArguments) {
  if (kernelHugePagesOff()) GTEST_SKIP() << "this kernel's transparent huge pages are off: apps do not restart";
  const std::vector<std::string> lines = probeLines("-u GLIBC_TUNABLES");
  ASSERT_EQ(lines.size(), 3u);  // started, restarted, ran
  const std::string pid = pidOf(lines[0]);
  EXPECT_EQ(lines[0], "start " + pid);
  EXPECT_EQ(lines[1], "start " + pid);  // the same process, started again
  EXPECT_EQ(lines[2], running(lines[0]) + "glibc.malloc.hugetlb=1 a b c");  // its own name, not "exe"
}

TEST(Heap, TheUsersTunablesKeptAndTheirHugePageChoiceStands) {
  std::vector<std::string> lines;
  if (!kernelHugePagesOff()) {
    lines = probeLines("GLIBC_TUNABLES=glibc.malloc.arena_max=4");
    ASSERT_EQ(lines.size(), 3u);
    EXPECT_EQ(lines[2], running(lines[0]) + "glibc.malloc.arena_max=4:glibc.malloc.hugetlb=1 a b c");
  }
  lines = probeLines("GLIBC_TUNABLES=glibc.malloc.hugetlb=0");
  ASSERT_EQ(lines.size(), 2u);  // no restart
  EXPECT_EQ(lines[1], running(lines[0]) + "glibc.malloc.hugetlb=0 a b c");
}

TEST(Heap, NeverASecondRestart) {
  // The restarted process is marked; the mark goes before anything else runs.
  const std::vector<std::string> lines = probeLines("-u GLIBC_TUNABLES VOFUSION_HEAP_RESTARTED=1");
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_EQ(lines[1], running(lines[0]) + "(unset) a b c");
}

TEST(Heap, NoRestartUnderAPreloadedTool) {
  // heaptrack and valgrind preload their library: a restarted process would escape them.
  const std::vector<std::string> lines = probeLines("-u GLIBC_TUNABLES LD_PRELOAD=libm.so.6");
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_EQ(lines[1], running(lines[0]) + "(unset) a b c");
}

TEST(Heap, NoRestartUnderHeaptrack) {
  // heaptrack takes its library out of LD_PRELOAD once it is loaded.
  if (test::run("command -v heaptrack") != 0) GTEST_SKIP() << "heaptrack is not installed";
  std::string out;
  ASSERT_EQ(test::run("cd " + test::tempDir("heaptrack") + " && env -u GLIBC_TUNABLES heaptrack -o probe " +
                          test::app("heap_restart_probe") + " a",
                      &out),
            0)
      << out;
  const std::size_t first = out.find("start ");
  ASSERT_NE(first, std::string::npos) << out;
  EXPECT_EQ(out.find("start ", first + 1), std::string::npos) << "restarted under heaptrack:\n" << out;
  EXPECT_NE(out.find("no-marker (unset) a"), std::string::npos) << out;
}

namespace {
// Set while this test program starts (static initialisation, before main).
const auto kProgramStarted = std::chrono::steady_clock::now();
}  // namespace

TEST(Timing, TheProcessClockCountsFromTheProcessStart) {
  const auto first_read = std::chrono::steady_clock::now();
  const double a = secondsSinceProcessStart();
  ASSERT_TRUE(std::isfinite(a));
  // At least the time since static initialisation (/proc counts in 10 ms steps), and not the machine's
  // uptime: loading the libraries before it takes well under 5 s.
  const double since_static_init = std::chrono::duration<double>(first_read - kProgramStarted).count();
  EXPECT_GE(a, since_static_init - 0.02);
  EXPECT_LE(a, since_static_init + 5.0);
  std::this_thread::sleep_for(std::chrono::milliseconds(80));
  const double b = secondsSinceProcessStart();
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - first_read).count();
  // The sleep at least, all the time since the first reading at most, within two 10 ms steps.
  EXPECT_GE(b - a, 0.08 - 0.02);
  EXPECT_LE(b - a, elapsed + 0.02);
}
