// scripts/batch for real on this machine: synthetic recordings through GNU parallel, two at a time,
// one table at the end; a failed recording leaves the others alone and --resume reruns only it.
#include <sched.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "support.h"

using namespace vofusion;
namespace fs = std::filesystem;

namespace {

// GNU parallel is a Debian package (scripts/install-deps): missing = skip here, fail in CI.
#define REQUIRE_PARALLEL()                                                                              \
  do {                                                                                                  \
    if (test::run("command -v parallel") != 0) {                                                        \
      if (test::inCi()) FAIL() << "GNU parallel missing in CI (scripts/install-deps installs it)";      \
      GTEST_SKIP() << "GNU parallel not installed (apt-get install parallel)";                          \
    }                                                                                                   \
  } while (0)

std::string batch() { return test::sourceDir() + "/scripts/batch"; }
std::string build() { return (fs::path(test::binDir()) / "..").lexically_normal().string(); }

std::string slurp(const std::string& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

std::vector<std::string> split(const std::string& line, char sep) {
  std::vector<std::string> out;
  std::istringstream in(line);
  for (std::string f; std::getline(in, f, sep);) out.push_back(f);
  return out;
}

// The Markdown table's data rows (after the header and its |---| line).
std::vector<std::vector<std::string>> tableRows(const std::string& md) {
  std::vector<std::vector<std::string>> rows;
  for (const auto& l : test::lines(md))
    if (l.rfind("| ", 0) == 0 && l.find("| recording |") != 0) {
      std::vector<std::string> cells;
      for (auto& c : split(l.substr(2, l.size() - 4), '|')) {
        c.erase(0, c.find_first_not_of(' '));
        c.erase(c.find_last_not_of(' ') + 1);
        cells.push_back(c);
      }
      rows.push_back(cells);
    }
  return rows;
}

struct Job {
  std::string folder;
  double start = 0, runtime = 0;
  int exitval = -1;
};
// parallel --joblog: a header, then Seq Host Starttime JobRuntime Send Receive Exitval Signal Command.
std::vector<Job> joblog(const std::string& path) {
  std::vector<Job> jobs;
  const auto ls = test::lines(slurp(path));
  for (std::size_t i = 1; i < ls.size(); ++i) {
    const auto f = split(ls[i], '\t');
    if (f.size() < 9) continue;
    Job j;
    j.start = std::stod(f[2]);
    j.runtime = std::stod(f[3]);
    j.exitval = std::stoi(f[6]);
    const auto words = split(f[8], ' ');  // batch-job <vofusion> <out> <folder> ...
    if (words.size() > 3) j.folder = words[3];
    jobs.push_back(j);
  }
  return jobs;
}

// Vofusion options for every job: a small volume, no rawlog, no CGAL post-processing (seconds, not minutes).
std::string smallConfig(const std::string& dir) {
  const std::string path = dir + "/small.ini";
  std::ofstream(path) << "[kinfu]\nvolume_voxels = 256\nvoxel_size = 0.012\ntruncation = 0.05\n"
                         "[output]\nimage_width = 320\nimage_height = 240\nwrite_rawlog = false\nclean_mesh = false\n";
  return path;
}

void simulate(const std::string& out, const std::string& args, int frames = 40) {
  std::string log;
  ASSERT_EQ(test::run(test::app("rgbd-simulate") + " --out " + out + " " + args + " --frames " +
                          std::to_string(frames) + " --size 320x240",
                      &log),
            0)
      << log;
}

}  // namespace

TEST(Batch, FourRecordingsTwoAtATimeGiveOneTable) {
  REQUIRE_PARALLEL();
  const std::string dir = test::tempDir("batch4");
  // Three scenes as TUM folders and the shaking room as a rawlog: both kinds of recording, four names.
  simulate(dir + "/rec/room", "--scene room");
  simulate(dir + "/rec/corridor", "--scene corridor");
  simulate(dir + "/rec/bare_wall", "--scene bare_wall");
  simulate(dir + "/rec/shake.rawlog", "--scene room --trajectory shake");
  const std::string out = dir + "/out";
  std::string log;
  // TMPDIR: the jobs' CPU locks private to this test, so which CPUs they get is known.
  const int rc = test::run("TMPDIR=" + dir + " " + batch() + " --out " + out + " --jobs 2 --build " + build() + " " +
                               dir + "/rec/room " + dir + "/rec/corridor " + dir + "/rec/bare_wall " + dir +
                               "/rec/shake.rawlog -- --config " + smallConfig(dir),
                           &log);
  ASSERT_EQ(rc, 0) << log;

  const std::vector<std::string> names = {"room", "corridor", "bare_wall", "shake"};
  std::set<std::string> cpu_sets;
  for (const auto& n : names) {
    const std::string f = out + "/" + n;
    for (const char* file : {"summary.json", "trajectory.txt", "mesh.ply", "vofusion.log"})
      EXPECT_TRUE(fs::exists(f + "/" + file)) << f << "/" << file << "\n" << log;
    EXPECT_EQ(slurp(f + "/exit_code"), "0\n") << n;
    // batch-job's first log line: which CPUs it was pinned to ("taskset -c <list>").
    const std::string first = test::lines(slurp(f + "/vofusion.log")).at(0);
    const auto at = first.find("taskset -c ");
    if (std::thread::hardware_concurrency() >= 2) {
      ASSERT_NE(at, std::string::npos) << first;
      cpu_sets.insert(split(first.substr(at + 11), ' ').at(0));
    }
  }
  // Two jobs at a time, each claiming a free CPU: two CPUs used, never the same one twice at once.
  if (std::thread::hardware_concurrency() >= 2) {
    EXPECT_EQ(cpu_sets.size(), 2u) << log;
  }

  const auto jobs = joblog(out + "/joblog");
  ASSERT_EQ(jobs.size(), 4u) << slurp(out + "/joblog");
  std::set<std::string> logged;
  for (const auto& j : jobs) {
    EXPECT_EQ(j.exitval, 0) << j.folder;
    logged.insert(j.folder);
  }
  EXPECT_EQ(logged, std::set<std::string>(names.begin(), names.end()));
  // Really two at a time: at the first two jobs' start, both were running; never three.
  int most = 0;
  for (const auto& a : jobs) {
    int running = 0;
    for (const auto& b : jobs) running += b.start <= a.start && a.start < b.start + b.runtime;
    most = std::max(most, running);
  }
  EXPECT_EQ(most, 2) << slurp(out + "/joblog");

  // One table: printed and in summary.md, a row per recording in the order given.
  const std::string md = slurp(out + "/summary.md");
  EXPECT_NE(log.find(md.substr(0, md.find("\n"))), std::string::npos) << log;
  const auto rows = tableRows(md);
  ASSERT_EQ(rows.size(), 4u) << md;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    ASSERT_EQ(rows[i].size(), 10u) << md;
    EXPECT_EQ(rows[i][0], names[i]) << md;
    EXPECT_EQ(rows[i][1], "joint");
    EXPECT_EQ(rows[i][2], "40");
    EXPECT_GT(std::stod(rows[i][3]), 0.0) << md;   // fps
    EXPECT_LT(std::stod(rows[i][4]), 0.05) << md;  // ATE RMSE [m]: synthetic ground truth
    EXPECT_GT(std::stod(rows[i][7]), 0.0) << md;   // peak RSS
    EXPECT_GT(std::stoi(rows[i][8]), 1000) << md;  // mesh faces
    EXPECT_EQ(rows[i][9], "ok") << md;
  }
  EXPECT_NE(md.find("4 of 4 runs ok."), std::string::npos) << md;

  // The same table as JSON and CSV, from any folder of runs.
  std::string json_text, csv;
  ASSERT_EQ(test::run("python3 " + test::sourceDir() + "/bench/collect.py " + out + " --json 2>/dev/null", &json_text),
            0);
  const auto j = nlohmann::json::parse(json_text);
  ASSERT_EQ(j.size(), 4u);
  for (const auto& r : j) {
    EXPECT_EQ(r["status"], "ok");
    EXPECT_EQ(r["frames"], 40);
  }
  ASSERT_EQ(test::run("python3 " + test::sourceDir() + "/bench/collect.py " + out + " --csv 2>/dev/null", &csv), 0);
  const auto csv_lines = test::lines(csv);
  ASSERT_EQ(csv_lines.size(), 5u) << csv;
  EXPECT_EQ(csv_lines[0].rfind("recording,mode,frames,fps,ate_rmse_m,", 0), 0u) << csv;
}

TEST(Batch, FailedRecordingLeavesTheOthersAndResumeRerunsIt) {
  REQUIRE_PARALLEL();
  const std::string dir = test::tempDir("batch_fail");
  simulate(dir + "/rec/room", "--scene room", 15);
  fs::create_directories(dir + "/rec/empty");  // not a recording: vofusion fails on it
  const std::string out = dir + "/out";
  auto cmd = [&](const std::string& options) {
    return "TMPDIR=" + dir + " " + batch() + " --out " + out + " --jobs 2 --build " + build() + options + " " + dir +
           "/rec/empty " + dir + "/rec/room -- --config " + smallConfig(dir);
  };
  std::string log;
  EXPECT_EQ(test::run(cmd(""), &log), 1) << log;
  EXPECT_NE(log.find("batch: 1 of 2 recordings failed: empty (" + dir + "/rec/empty)"), std::string::npos) << log;
  EXPECT_EQ(slurp(out + "/room/exit_code"), "0\n");
  EXPECT_TRUE(fs::exists(out + "/room/summary.json"));
  EXPECT_EQ(slurp(out + "/empty/exit_code"), "2\n");
  auto rows = tableRows(slurp(out + "/summary.md"));
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[0][0], "empty");
  // The failed row says why: vofusion's error line from the job's log.
  EXPECT_NE(rows[0][9].find("failed (exit 2): vofusion: error: " + dir + "/rec/empty: folder is not a TUM RGB-D"),
            std::string::npos)
      << rows[0][9];
  EXPECT_EQ(rows[1][9], "ok");

  // Fix the recording and resume: only the failed job runs again.
  simulate(dir + "/rec/empty", "--scene corridor", 15);
  const auto room_time = fs::last_write_time(out + "/room/summary.json");
  EXPECT_EQ(test::run(cmd(" --resume"), &log), 0) << log;
  EXPECT_EQ(fs::last_write_time(out + "/room/summary.json"), room_time);
  const auto jobs = joblog(out + "/joblog");
  ASSERT_EQ(jobs.size(), 3u) << slurp(out + "/joblog");
  EXPECT_EQ(jobs[2].folder, "empty");
  EXPECT_EQ(jobs[2].exitval, 0);
  rows = tableRows(slurp(out + "/summary.md"));
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[0][9], "ok");
  EXPECT_EQ(rows[1][9], "ok");
}

// A Slurm time limit or scancel (scripts/slurm: --signal=B:TERM) signals the job's shell, batch-job:
// it passes SIGTERM on to vofusion, which writes what it has built and its checkpoint, and records
// vofusion's exit code. The job run again goes on from the checkpoint.
TEST(Batch, ATermToAJobLetsVofusionWriteWhatItBuiltAndTheJobRunAgainResumes) {
  VOFUSION_REQUIRE_DATA(test::tumFirst300());
  const std::string dir = test::tempDir("batch_term");
  const std::string out = dir + "/out";
  const std::string job = test::sourceDir() + "/scripts/batch-job " + test::app("vofusion") + " " + out + " xyz 0 " +
                          test::tumFirst300() + " --config " + smallConfig(dir) + " --checkpoint-every 1000";
  // TERM to batch-job alone (not its process group) once vofusion's progress shows a few frames.
  const auto term = test::runSignalledMidway(job, dir + "/job.txt", 300, "TERM", 3, out + "/xyz/vofusion.log");
  EXPECT_EQ(term.exit_code, 143) << term.log << slurp(out + "/xyz/vofusion.log");
  EXPECT_EQ(slurp(out + "/xyz/exit_code"), "143\n");
  EXPECT_EQ(slurp(dir + "/job.txt").rfind("STOPPED xyz (exit 143): vofusion: ", 0), 0u)
      << slurp(dir + "/job.txt");
  const auto stopped = nlohmann::json::parse(slurp(out + "/xyz/summary.json"));
  EXPECT_TRUE(stopped["interrupted"].get<bool>());
  EXPECT_EQ(stopped.value("stop_signal", ""), "SIGTERM");
  const int frames = stopped["frames"].get<int>();
  EXPECT_LT(frames, 300);
  std::string table;
  ASSERT_EQ(test::run("python3 " + test::sourceDir() + "/bench/collect.py " + out, &table), 0) << table;
  const auto rows = tableRows(table);
  ASSERT_EQ(rows.size(), 1u) << table;
  EXPECT_EQ(rows[0][9], "interrupted (SIGTERM)") << table;

  std::string log;
  ASSERT_EQ(test::run(job, &log), 0) << log << slurp(out + "/xyz/vofusion.log");
  EXPECT_NE(slurp(out + "/xyz/vofusion.log").find("--resume " + out + "/xyz/checkpoint"), std::string::npos);
  const auto resumed = nlohmann::json::parse(slurp(out + "/xyz/summary.json"));
  EXPECT_FALSE(resumed["interrupted"].get<bool>());
  EXPECT_EQ(resumed["frames"].get<int>(), 300);
  // The last frame the stopped run read was held back for the one after it (Reconstruction::push): not in
  // its checkpoint, so the resumed run reads it again.
  EXPECT_EQ(resumed["checkpoints"]["resumed_at_frame"].get<int>(), frames - 1);
  EXPECT_FALSE(fs::exists(out + "/xyz/checkpoint")) << "a finished run leaves no checkpoint";
}

// A TERM that reaches batch-job as it starts vofusion. With the traps installed after the start, the
// job died alone in that instant and its vofusion ran on: this loop left one running in each of its 3
// runs against that script. The stand-in for vofusion sleeps 20 s; each job gets TERM 0-19.9 ms after
// it starts (about half of them reached the stand-in here).
TEST(Batch, ATermAsTheJobStartsNeverLeavesVofusionRunningAlone) {
  const std::string dir = test::tempDir("batch_term_at_start");
  const std::string stand_in = dir + "/stand-in-vofusion";
  fs::create_directories(dir + "/pids");
  {
    std::ofstream f(stand_in);
    f << "#!/bin/bash\ntouch " << dir << "/pids/$$\ntrap 'kill $s; exit 143' TERM INT\nsleep 20 & s=$!\nwait\n";
  }
  fs::permissions(stand_in, fs::perms::owner_all);
  const std::string job = test::sourceDir() + "/scripts/batch-job " + stand_in + " " + dir + "/out j$i 0 " + dir;
  std::string log;
  test::run("for i in $(seq 1 600); do " + job + " >/dev/null 2>&1 & p=$!; sleep $(printf 0.%04d $((i % 200))); " +
                "kill -TERM $p; wait $p; done; sleep 0.3; cd " + dir + "/pids && echo started=$(ls | wc -l) && " +
                "for pid in *; do kill -0 $pid 2>/dev/null && echo alone=$pid && kill $pid; done",
            &log);
  EXPECT_EQ(log.find("alone="), std::string::npos) << log;
  EXPECT_EQ(log.find("started=0"), std::string::npos) << "no job reached vofusion: " << log;
}

// A Ctrl-C (SIGINT) to a job, as a terminal's sends it to a job of its own. vofusion, started in the
// background by batch-job, begins with SIGINT ignored (the shell's rule without job control), so an INT
// passed on as INT reached a vofusion still starting (and the stand-in here, a script, never) and the job
// waited for it to end: passed on as TERM, each job stops within seconds.
TEST(Batch, ACtrlCToAJobStopsItsVofusion) {
  const std::string dir = test::tempDir("batch_int");
  const std::string stand_in = dir + "/stand-in-vofusion";
  {
    std::ofstream f(stand_in);
    // "ready" once its trap is set: the INT is sent to a job whose vofusion runs (a timer let it land on
    // a loaded machine before batch-job's own trap).
    f << "#!/bin/bash\ntrap 'kill $s; exit 143' TERM INT\ntouch " << dir << "/ready\nsleep 20 & s=$!\nwait\n";
  }
  fs::permissions(stand_in, fs::perms::owner_all);
  const std::string job = test::sourceDir() + "/scripts/batch-job " + stand_in + " " + dir + "/out j$i 0 " + dir;
  // bash with set -m: each job in a process group of its own, with SIGINT not ignored, as from a terminal.
  // INT to batch-job alone (jobs 1-2), and to the job's process group as a terminal sends it (3-4).
  std::ofstream(dir + "/four-jobs") << "set -m\nfor i in 1 2 3 4; do rm -f " + dir + "/ready; " + job + " >/dev/null 2>&1 & p=$!; " +
                                           "for t in $(seq 1 400); do [ -e " + dir + "/ready ] && break; sleep 0.05; done; " +
                                           "[ -e " + dir + "/ready ] || echo \"job $i: its vofusion never started\"; " +
                                           "s=$(date +%s%N); kill -INT $([ $i -le 2 ] || echo -)$p; " +
                                           "wait $p; echo \"rc=$? ms=$(( ($(date +%s%N) - s) / 1000000 ))\"; done\n";
  std::string log;
  test::run("bash " + dir + "/four-jobs", &log);
  std::istringstream lines(log);
  int jobs = 0;
  for (std::string line; std::getline(lines, line); ++jobs) {
    int rc = 0, ms = 0;
    ASSERT_EQ(std::sscanf(line.c_str(), "rc=%d ms=%d", &rc, &ms), 2) << log;
    EXPECT_EQ(rc, 143) << log;
    EXPECT_LT(ms, 10000) << "the job waited for its vofusion to end by itself: " << log;
  }
  EXPECT_EQ(jobs, 4) << log;
}

// A Ctrl-C to the whole batch (its process group, as a terminal sends it) reaches each running vofusion
// once and waits for it to write what it built: parallel's own sequence (TERM three times in 300 ms,
// then KILL) ended it mid-write. The stand-in takes a second to write.
TEST(Batch, ACtrlCToTheBatchLetsEachVofusionWriteWhatItBuilt) {
  REQUIRE_PARALLEL();
  const std::string dir = test::tempDir("batch_ctrl_c");
  fs::create_directories(dir + "/b/bin");
  fs::create_directories(dir + "/rec");
  {
    std::ofstream f(dir + "/b/bin/vofusion");
    f << "#!/bin/bash\nout=''; while [ $# -gt 0 ]; do [ \"$1\" = --out ] && out=$2; shift; done\n"
         "trap 'sleep 1; touch \"$out/wrote\"; exit 143' TERM INT\ntouch \"$out/started\"\nsleep 30 & wait\n";
  }
  fs::permissions(dir + "/b/bin/vofusion", fs::perms::owner_all);
  std::ofstream(dir + "/ctrl-c") << "set -m\nbash " + test::sourceDir() + "/scripts/batch --out " + dir + "/out --build " + dir +
                                        "/b " + dir + "/rec >/dev/null 2>&1 & p=$!\n"
                                        "for i in $(seq 1 400); do [ -e " + dir + "/out/rec/started ] && break; sleep 0.05; done\n"
                                        "[ -e " + dir + "/out/rec/started ] || echo 'its vofusion never started'\n"
                                        "kill -INT -$p; wait $p; echo rc=$?\n";
  std::string log;
  test::run("bash " + dir + "/ctrl-c", &log);
  EXPECT_EQ(log.find("never started"), std::string::npos) << log;
  const std::size_t rc = log.find("rc=");
  ASSERT_NE(rc, std::string::npos) << log;
  EXPECT_NE(std::stoi(log.substr(rc + 3)), 0) << "a stopped batch is no success: " << log;
  EXPECT_TRUE(fs::exists(dir + "/out/rec/wrote")) << "the job's vofusion was killed before it wrote: " << log;
  std::ifstream code(dir + "/out/rec/exit_code");
  std::string job_rc;
  code >> job_rc;
  EXPECT_EQ(job_rc, "143") << "the job's own exit code, after it wrote: " << log;
}

// A --list line: blank lines and # comments skipped, a '#' inside a path kept (it cut /data/take#2 to
// /data/take, a recording that was not there or, worse, another one).
TEST(Batch, AListKeepsAHashInsideAPath) {
  const std::string dir = test::tempDir("batch_list");
  fs::create_directories(dir + "/take#2");
  fs::create_directories(dir + "/take");
  std::ofstream(dir + "/list.txt") << "# the recordings\n" << dir << "/take#2   # the second take\n\n  " << dir << "/take\n";
  std::string log;
  ASSERT_EQ(test::run(batch() + " --out " + dir + "/o --list " + dir + "/list.txt --dry-run", &log), 0) << log;
  EXPECT_EQ(log, "take_2\t" + dir + "/take#2\ntake\t" + dir + "/take\n");
}

// A batch's job that was killed (no exit_code) is a failure, though an earlier run's summary.json is
// still in its folder; a folder of a plain vofusion run (no jobs list) is judged by its summary.
TEST(Batch, AKilledJobIsNotTheEarlierRunsResult) {
  const std::string dir = test::tempDir("batch_killed");
  fs::create_directories(dir + "/a");
  std::ofstream(dir + "/a/summary.json") << R"({"input": "/rec/a", "frames": 10, "fps": 20.0})";
  std::ofstream(dir + "/a/vofusion.log") << "vofusion [joint] 3/10 frames\n";
  std::ofstream(dir + "/jobs.tsv") << "a\t/rec/a\n";
  const std::string collect = "python3 " + test::sourceDir() + "/bench/collect.py " + dir + " --json";
  std::string log;
  ASSERT_EQ(test::run(collect + " --jobs " + dir + "/jobs.tsv", &log), 0) << log;
  EXPECT_EQ(nlohmann::json::parse(log)[0].at("status"), "failed: the job did not finish (no exit code): vofusion [joint] 3/10 frames")
      << log;
  ASSERT_EQ(test::run(collect, &log), 0) << log;
  EXPECT_EQ(nlohmann::json::parse(log)[0].at("status"), "ok") << log;
  // Without the jobs list (a Slurm array, collected as its script says), a log that batch-job began
  // tells a job: killed, it did not finish. It was "ok", with the earlier run's figures.
  std::ofstream(dir + "/a/vofusion.log") << "batch-job: node7 unpinned vofusion /rec/a --out " << dir << "/a\n"
                                         << "vofusion [joint] 3/10 frames\n";
  ASSERT_EQ(test::run(collect, &log), 0) << log;
  EXPECT_EQ(nlohmann::json::parse(log)[0].at("status"), "failed: the job did not finish (no exit code): vofusion [joint] 3/10 frames")
      << log;
}

TEST(Batch, BadArgumentsFailInOneLine) {
  const std::string dir = test::tempDir("batch_args");
  struct Case {
    std::string args, message;
  };
  const std::vector<Case> cases = {
      {"a", "batch: --out <dir> is required"},
      {"--out " + dir + "/o", "batch: no recordings given"},
      {"--out " + dir + "/o --jobs 0 " + dir, "batch: --jobs 0: expected a positive whole number"},
      {"--out " + dir + "/o " + dir + "/missing", "batch: " + dir + "/missing: no such recording"},
      {"--out " + dir + "/o --list " + dir + "/missing.txt", "batch: " + dir + "/missing.txt: cannot read"},
      {"--out " + dir + "/o --resume " + dir, "batch: " + dir + "/o/joblog: no earlier batch to resume"},
      {"--out " + dir + "/o --threads x " + dir, "batch: --threads x: expected a whole number >= 0"},
  };
  for (const auto& c : cases) {
    std::string log;
    EXPECT_EQ(test::run(batch() + " " + c.args, &log), 2) << c.args << "\n" << log;
    EXPECT_EQ(std::count(log.begin(), log.end(), '\n'), 1) << log;
    EXPECT_EQ(log.rfind(c.message, 0), 0u) << log;
  }
  std::string log;
  EXPECT_NE(test::run("python3 " + test::sourceDir() + "/bench/collect.py " + dir, &log), 0);
  EXPECT_EQ(log, "collect: " + dir + ": no summary.json or vofusion.log under it\n");
}

// bench/run's tables: two 7-Scenes scenes' seq-01 are two tables, and a partial run (a --modes subset,
// --max-frames, --quick) writes them beside its runs, never over the committed bench/results. Stub
// vofusion / rgbd-eval binaries stand in: what is tested is where the script writes.
TEST(Batch, BenchTablesNameTheSceneAndAPartialRunLeavesTheCommittedOnesAlone) {
  const std::string dir = test::tempDir("bench_tables");
  fs::create_directories(dir + "/build/bin");
  {
    std::ofstream(dir + "/build/bin/vofusion")
        << "#!/bin/sh\nwhile [ $# -gt 0 ]; do [ \"$1\" = --out ] && out=$2; shift; done\n"
           "mkdir -p \"$out\" && echo '{\"frames\": 1, \"fps\": 1}' > \"$out/summary.json\" && : > \"$out/trajectory.txt\"\n";
    std::ofstream(dir + "/build/bin/rgbd-eval") << "#!/bin/sh\necho '{}'\n";
  }
  for (const char* exe : {"/build/bin/vofusion", "/build/bin/rgbd-eval"})
    fs::permissions(dir + exe, fs::perms::owner_all, fs::perm_options::add);
  for (const char* scene : {"chess", "fire"}) {
    fs::create_directories(dir + "/" + scene + "/seq-01");
    std::ofstream(dir + "/" + scene + "/seq-01/frame-000000.depth.png");
  }
  std::string log;
  ASSERT_EQ(test::run("python3 " + test::sourceDir() + "/bench/bench.py " + dir + "/chess/seq-01 " + dir +
                          "/fire/seq-01 --modes joint --build " + dir + "/build --work " + dir + "/work",
                      &log),
            0)
      << log;
  EXPECT_TRUE(fs::exists(dir + "/work/results/chess_seq-01.md")) << log;
  EXPECT_TRUE(fs::exists(dir + "/work/results/fire_seq-01.md")) << log;
  EXPECT_NE(log.find("tables go to " + dir + "/work/results"), std::string::npos) << log;
  for (const char* name : {"seq-01.md", "chess_seq-01.md", "fire_seq-01.md"})
    EXPECT_FALSE(fs::exists(test::sourceDir() + "/bench/results/" + name)) << name;
}

// bench/run --loops on a subset of seeds writes its tables beside its runs: it replaced the committed
// bench/results/loops.md (five seeds, two lengths) with one seed's. Stubs stand in for the apps (the
// run fails: its row says so, and where the table went is what is tested).
TEST(Batch, ALoopsBenchOnASubsetLeavesTheCommittedTableAlone) {
  const std::string dir = test::tempDir("bench_loops_subset");
  fs::create_directories(dir + "/build/bin");
  {
    std::ofstream(dir + "/build/bin/rgbd-simulate")
        << "#!/bin/sh\nwhile [ $# -gt 0 ]; do [ \"$1\" = --out ] && out=$2; shift; done\n: > \"$out\"\n";
    std::ofstream(dir + "/build/bin/vofusion") << "#!/bin/sh\nexit 1\n";
  }
  for (const char* exe : {"/build/bin/vofusion", "/build/bin/rgbd-simulate"})
    fs::permissions(dir + exe, fs::perms::owner_all, fs::perm_options::add);
  const std::string committed = test::sourceDir() + "/bench/results/loops.md";
  const auto before = fs::exists(committed) ? fs::last_write_time(committed) : fs::file_time_type{};
  std::string log;
  EXPECT_NE(test::run("python3 " + test::sourceDir() + "/bench/loops.py --seeds 1 --lengths 10 --build " + dir + "/build", &log), 0);
  EXPECT_TRUE(fs::exists(dir + "/build/bench-runs/results/loops.md")) << log;
  EXPECT_NE(log.find("tables written to " + dir + "/build/bench-runs/results"), std::string::npos) << log;
  if (fs::exists(committed)) EXPECT_EQ(fs::last_write_time(committed), before);
}

// OMP_NUM_THREADS=1 (many clusters export it) is what GNU nproc answers when it is set: the batch took
// it for the machine's CPUs and ran its recordings one at a time. A stub vofusion stands in.
TEST(Batch, OmpNumThreadsDoesNotShrinkTheBatch) {
  REQUIRE_PARALLEL();
  cpu_set_t allowed;  // the CPUs this process may use (a cpuset, taskset), as nproc counts them
  ASSERT_EQ(sched_getaffinity(0, sizeof allowed, &allowed), 0);
  const int cpus = CPU_COUNT(&allowed);
  if (cpus < 2) GTEST_SKIP() << "one CPU: the batch runs one job at a time anyway";
  const std::string dir = test::tempDir("batch_omp");
  fs::create_directories(dir + "/build/bin");
  std::ofstream(dir + "/build/bin/vofusion")
      << "#!/bin/sh\nwhile [ $# -gt 0 ]; do [ \"$1\" = --out ] && out=$2; shift; done\n"
         "mkdir -p \"$out\" && echo '{\"frames\": 1, \"fps\": 1}' > \"$out/summary.json\"\n";
  fs::permissions(dir + "/build/bin/vofusion", fs::perms::owner_all, fs::perm_options::add);
  std::string log;
  test::run("TMPDIR=" + dir + " OMP_NUM_THREADS=1 OMP_THREAD_LIMIT=1 " + batch() + " --out " + dir + "/o --build " +
                dir + "/build synthetic:room synthetic:corridor",
            &log);
  EXPECT_NE(log.find("batch: 2 recordings, " + std::to_string(cpus) + " at a time, 1 CPU(s) each"), std::string::npos)
      << log;
}
