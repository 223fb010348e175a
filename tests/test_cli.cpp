// vofusion::CommandLine and runApp: what the thin apps rely on for parsing and error reporting; the
// heap's huge-page report, the process clock they start with, and their Ctrl-C / SIGTERM handling.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "vofusion/core/cli.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/progress.h"
#include "vofusion/core/stop_signals.h"
#include "vofusion/core/heap.h"
#include "vofusion/core/timing.h"

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

// "--" ends the options, as getopt's: what follows is positional, a path starting with '-' too. It was
// itself taken as an input named "--".
TEST(CommandLine, DoubleDashEndsTheOptions) {
  EXPECT_EQ(parse({"--out", "o", "--", "-take.rawlog"}).positional(), (std::vector<std::string>{"-take.rawlog"}));
  EXPECT_EQ(parse({"in", "--"}).positional(), (std::vector<std::string>{"in"}));
  const auto cl = parse({"--", "--flag"});
  EXPECT_FALSE(cl.flag("--flag"));
  EXPECT_EQ(cl.positional(), (std::vector<std::string>{"--flag"}));
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
  EXPECT_NE(usageError({"--flag=1"}).find("option --flag takes no value"), std::string::npos);
  EXPECT_NE(usageError({"--out"}).find("--out needs a value"), std::string::npos);
  // A forgotten value: the next option is not taken as it (an output folder named "--n").
  EXPECT_NE(usageError({"in", "--out", "--n", "100"}).find("--out needs a value"), std::string::npos);
  EXPECT_NE(usageError({"in", "--out", "--flag"}).find("--out needs a value"), std::string::npos);
  EXPECT_EQ(parse({"--out=--n"}).value("--out", ""), "--n");  // given with '=', it is taken as said
  EXPECT_EQ(parse({"--x", "-1"}).value("--x", ""), "-1");     // a negative number is a value
}

// An empty value ("--config \"$UNSET\"", "--out=") is a slip, not a choice: it ran on the defaults,
// in the temporary folder, or failed naming no file.
TEST(CommandLine, AnEmptyValueIsRefused) {
  EXPECT_NE(usageError({"in", "--out", ""}).find("option --out needs a value (it is empty)"), std::string::npos);
  EXPECT_NE(usageError({"in", "--out="}).find("option --out needs a value (it is empty)"), std::string::npos);
  EXPECT_EQ(parse({"--out", " "}).value("--out", ""), " ");  // a blank name is a name (the app judges it)
}

TEST(CommandLine, IntegerWithMinimum) {
  EXPECT_EQ(parse({}).count("--n", 7, 1), 7u);
  EXPECT_EQ(parse({"--n", "3"}).count("--n", 0, 1), 3u);
  EXPECT_EQ(parse({"--n", "0"}).count("--n", 5), 0u);
  for (const char* bad : {"0", "-2", "2.5", "x", " 5", "\t3"}) {
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
  for (const char* bad : {"0", "-1", "1.5"}) {
    try {
      parse({"--x", bad}).number("--x", 0.5, 0.0, 1.0);
      ADD_FAILURE() << bad;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("--x expects a number > 0 and <= 1"), std::string::npos) << e.what();
    }
  }
  // A closed range, as for a zero meaning "off": the message names the bound as the user gives it.
  EXPECT_DOUBLE_EQ(parse({"--x", "0"}).numberFrom("--x", 5.0, 0.0, 1e6), 0.0);
  EXPECT_DOUBLE_EQ(parse({}).numberFrom("--x", 5.0, 0.0, 1e6), 5.0);
  for (const char* bad : {"-5", "-0.001", "2e6"}) {
    try {
      parse({"--x", bad}).numberFrom("--x", 0.0, 0.0, 1e6);
      ADD_FAILURE() << bad;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("--x expects a number >= 0 and <= 1e+06, got '" + std::string(bad) + "'"),
                std::string::npos)
          << e.what();
    }
  }
  // What std::stod takes but no option means: not a number, whatever the range.
  for (const char* bad : {"abc", "1.5x", "nan", "inf", "-inf", "infinity", "0x10", "0x1p3", " 0.5"}) {
    try {
      parse({"--x", bad}).number("--x", 1.0, 0.0);
      ADD_FAILURE() << bad;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("--x expects a number, got '" + std::string(bad) + "'"), std::string::npos)
          << e.what();
    }
  }
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

TEST(Heap, HugePagesOnlyWhereTheUsersTunablesAskForThem) {
  // summary.json's heap_huge_pages: the apps no longer ask for them (docs/memory.md), a user may.
  const char* before = std::getenv("GLIBC_TUNABLES");
  const std::string kept = before ? before : "";
  const auto asks = [](const char* tunables) {
    if (tunables) setenv("GLIBC_TUNABLES", tunables, 1);
    else unsetenv("GLIBC_TUNABLES");
    return heapAsksForHugePages();
  };
  EXPECT_FALSE(asks(nullptr));
  EXPECT_FALSE(asks("glibc.malloc.arena_max=2"));
  EXPECT_FALSE(asks("glibc.malloc.hugetlb=0"));
  EXPECT_TRUE(asks("glibc.malloc.hugetlb=1"));
  EXPECT_TRUE(asks("glibc.malloc.arena_max=2:glibc.malloc.hugetlb=2"));
  // Keys, not substrings: another key's value that happens to hold the text is not the setting.
  EXPECT_FALSE(asks("glibc.rtld.x=glibc.malloc.hugetlb=1"));
  if (before) setenv("GLIBC_TUNABLES", kept.c_str(), 1);
  else unsetenv("GLIBC_TUNABLES");
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

// A warning is said once per process: a recording opened a second time (the re-fusion) says nothing new.
TEST(Warnings, EachLineOncePerProcess) {
  testing::internal::CaptureStderr();
  printWarning("Warnings.EachLineOncePerProcess: first");
  printWarning("Warnings.EachLineOncePerProcess: second");
  printWarning("Warnings.EachLineOncePerProcess: first");
  const std::string log = testing::internal::GetCapturedStderr();
  EXPECT_NE(log.find("warning: Warnings.EachLineOncePerProcess: first"), std::string::npos) << log;
  EXPECT_EQ(log.find("first"), log.rfind("first")) << log;
  EXPECT_NE(log.find("warning: Warnings.EachLineOncePerProcess: second"), std::string::npos) << log;
}

namespace {

// In a child process (the handlers are the process's): installs the stop signals, raises `first`,
// exits 1 unless it was taken as the stop request, waits `pause_s`, raises `second`, and exits 0 if
// it survived that. How the child ended comes back.
int childRaising(int first, int second, double pause_s) {
  const pid_t pid = fork();
  if (pid == 0) {
    installStopSignals();
    std::raise(first);
    if (!(stopRequested() && stopSignal() == first && stopFlag().load())) _exit(1);
    std::this_thread::sleep_for(std::chrono::duration<double>(pause_s));
    std::raise(second);
    _exit(0);
  }
  int status = 0;
  waitpid(pid, &status, 0);
  return status;
}

// The child's end, for messages: "exit N" or "killed by SIG...".
std::string ending(int status) {
  if (WIFEXITED(status)) return "exit " + std::to_string(WEXITSTATUS(status));
  return std::string("killed by ") + (WIFSIGNALED(status) ? signalName(WTERMSIG(status)) : "?");
}

}  // namespace

// Ctrl-C or SIGTERM asks to stop (the app writes what it has); a second one kills at once, whichever
// signal it is, as a user pressing Ctrl-C twice or Slurm after its grace time expects.
TEST(StopSignals, TheFirstAsksToStopAndTheSecondKills) {
  const double later = kSameRequestSeconds + 0.1;
  for (const auto& [first, second] : {std::pair{SIGINT, SIGINT}, std::pair{SIGTERM, SIGTERM},
                                      std::pair{SIGINT, SIGTERM}, std::pair{SIGTERM, SIGINT}}) {
    SCOPED_TRACE(std::string(signalName(first)) + " then " + signalName(second));
    const int status = childRaising(first, second, later);
    ASSERT_TRUE(WIFSIGNALED(status)) << ending(status) << " (1: the first was not taken as a stop request)";
    EXPECT_EQ(WTERMSIG(status), second);
  }
  EXPECT_STREQ(signalName(SIGINT), "SIGINT");
  EXPECT_STREQ(signalName(SIGTERM), "SIGTERM");
}

// One stop request delivered twice at once is one request: the app goes on writing. Slurm signals
// every process of the job and batch-job passes the signal on; a terminal's Ctrl-C reaches vofusion
// as SIGINT and, through batch-job, as SIGTERM.
TEST(StopSignals, OneRequestDeliveredTwiceAtOnceIsOneRequest) {
  for (const auto& [first, second] :
       {std::pair{SIGTERM, SIGTERM}, std::pair{SIGINT, SIGINT}, std::pair{SIGINT, SIGTERM}}) {
    SCOPED_TRACE(std::string(signalName(first)) + " then " + signalName(second));
    const int status = childRaising(first, second, 0.0);
    ASSERT_TRUE(WIFEXITED(status)) << ending(status);
    EXPECT_EQ(WEXITSTATUS(status), 0);
  }
}

// A stop asked for without a signal (vofusion-grab's window closed) is no signal's, and counts as the
// first request: a Ctrl-C after it kills.
TEST(StopSignals, AStopRequestedInTheAppIsNoSignalAndASignalAfterItKills) {
  const pid_t pid = fork();
  if (pid == 0) {
    installStopSignals();
    requestStop();
    if (!stopRequested() || stopSignal() != 0) _exit(1);
    std::raise(SIGINT);
    _exit(0);
  }
  int status = 0;
  waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFSIGNALED(status)) << ending(status);
  EXPECT_EQ(WTERMSIG(status), SIGINT);
}

// Ctrl-C through "| tee run.log" reaches tee too, which exits: the stop message, or the next progress
// line, then goes to a closed pipe. SIGPIPE ended the run there, before it wrote what it had.
TEST(StopSignals, AClosedPipeOnStderrDoesNotEndTheRun) {
  const pid_t pid = fork();
  if (pid == 0) {
    int fds[2];
    if (pipe(fds) != 0) _exit(3);
    close(fds[0]);  // the reader (tee) is gone
    dup2(fds[1], STDERR_FILENO);
    std::signal(SIGPIPE, SIG_DFL);  // as a shell starts the app, whatever the test runner ignores
    installStopSignals();
    std::raise(SIGINT);                      // "stopping ..." written to the closed pipe
    std::fprintf(stderr, "a progress line\n");  // and the lines after it
    std::fflush(stderr);
    _exit(stopRequested() ? 0 : 1);
  }
  int status = 0;
  waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFEXITED(status)) << ending(status);
  EXPECT_EQ(WEXITSTATUS(status), 0);
}

// What the first signal says is the step's while a ScopedStoppingMessage lives, and the app's again
// after it: vofusion said "what was done is written" while it rendered the default recording, which
// a stop leaves unwritten.
TEST(StopSignals, AStepSaysWhatItsStopLeaves) {
  int fds[2];
  ASSERT_EQ(pipe(fds), 0);
  const auto childSaying = [&](bool during_step) {
    const pid_t pid = fork();
    if (pid == 0) {
      close(fds[0]);
      dup2(fds[1], STDERR_FILENO);
      installStopSignals();
      if (during_step) {
        const ScopedStoppingMessage rendering(kStoppingWithNothingWritten);
        std::raise(SIGINT);
      } else {
        { const ScopedStoppingMessage rendering(kStoppingWithNothingWritten); }
        std::raise(SIGINT);
      }
      _exit(0);
    }
    int status = 0;
    waitpid(pid, &status, 0);
    return status;
  };
  const auto said = [&] {
    char buffer[256] = {};
    const ssize_t n = read(fds[0], buffer, sizeof buffer - 1);
    return std::string(buffer, n > 0 ? std::size_t(n) : 0);
  };
  ASSERT_TRUE(WIFEXITED(childSaying(true)));
  EXPECT_EQ(said(), kStoppingWithNothingWritten);
  ASSERT_TRUE(WIFEXITED(childSaying(false)));
  EXPECT_NE(said().find("what was done is written"), std::string::npos);
  close(fds[0]);
  close(fds[1]);
}

// Progress into a log (not a terminal) prints at most a line every 2 s, and the last item at once,
// once: a caller ticking while nothing moves (a live session waiting for its sensor, total unknown)
// printed a line per tick.
TEST(Progress, TicksWithoutProgressAreNotALinePerTick) {
  testing::internal::CaptureStderr();
  {
    Progress waiting("live", 0);
    for (int i = 0; i < 20; ++i) waiting.update(0);
    Progress drained("live", 5);
    drained.update(4);                               // the first line
    for (int i = 0; i < 20; ++i) drained.update(5);  // the last item at once, once, then the queue drained
  }
  const std::string out = testing::internal::GetCapturedStderr();
  std::size_t lines = 0;
  for (char c : out) lines += c == '\n';
  EXPECT_EQ(lines, 3u) << out;  // the waiting one's first tick, 4/5, 5/5
  EXPECT_NE(out.find("live 5/5"), std::string::npos) << out;
}
