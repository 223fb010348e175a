// vofusion-grab end to end: replay through the live path, outputs written and readable, and the
// no-sensor failure is one line, quick and non-zero (no hardware on the test machines).
#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <regex>
#include <map>
#include <sstream>
#include <vector>

#include <opencv2/core.hpp>

#include "support.h"
#include "vofusion/core/trajectory.h"
#include <nlohmann/json.hpp>
#include "vofusion/pipeline/run_session.h"
#include "vofusion/io/frame_source.h"
#include "vofusion/sim/any_source.h"

using namespace vofusion;
namespace fs = std::filesystem;

namespace {

std::map<std::string, std::string> readSummary(const std::string& path) {
  std::map<std::string, std::string> kv;
  std::ifstream f(path);
  std::string line;
  while (std::getline(f, line)) {
    const auto c = line.find(": ");
    if (c != std::string::npos) kv[line.substr(0, c)] = line.substr(c + 2);
  }
  return kv;
}

// The count rawlog-edit --info gives a sensor label ("Sensor (Label/Occurs/Rate/Durat.) :   KINECT /  6 /...");
// the count is right-aligned in a field, so its padding depends on its digits. -1: not listed.
long sensorOccurrences(const std::string& info, const std::string& label) {
  std::istringstream lines(info);
  for (std::string line; std::getline(lines, line);) {
    const std::size_t at = line.find(" " + label + " /");
    if (line.find("Sensor (Label/Occurs") == std::string::npos || at == std::string::npos) continue;
    return std::stol(line.substr(at + label.size() + 3));
  }
  return -1;
}

std::size_t countLines(const std::string& s) {
  std::size_t n = 0;
  for (char c : s) n += c == '\n';
  return n;
}

}  // namespace

TEST(GrabApp, ReplayWithSlowProcessingDropsAndRecordsEverything) {
  const std::string tum = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(tum);
  const std::string out = test::tempDir("grab_app_replay");
  std::string log;
  const int rc = test::run(test::app("vofusion-grab") + " --replay " + tum + " --out " + out +
                               " --max-frames 40 --queue 2 --simulate-work-ms 500",
                           &log);
  ASSERT_EQ(rc, 0) << log;
  auto kv = readSummary(out + "/grab-summary.txt");
  ASSERT_FALSE(kv.empty()) << log;
  const long played = std::stol(kv["frames_played"]), processed = std::stol(kv["frames_processed"]),
             dropped = std::stol(kv["frames_dropped"]);
  EXPECT_EQ(played, 40);
  EXPECT_GT(dropped, 0);
  EXPECT_EQ(processed + dropped, played);
  EXPECT_EQ(kv["frames_recorded"], "40");
  EXPECT_EQ(kv["stop"], "max frames reached");
  // The rawlog is a valid input for vofusion's own reader.
  auto back = openFrameSource(out + "/grab.rawlog");
  std::size_t n = 0;
  Frame f;
  while (back->next(f)) {
    EXPECT_TRUE(f.valid());
    ++n;
  }
  EXPECT_EQ(n, 40u);
}

TEST(GrabApp, NoSensorFailsInOneLineQuicklyWithNonZeroExit) {
  const std::string out = test::tempDir("grab_app_nosensor");
  std::string log;
  // The shipped config with a sensor timeout no start-up comes near: told at once, not after it.
  std::string config;
  {
    std::ifstream in(test::shareDir() + "/grab-openni2.ini");
    config.assign(std::istreambuf_iterator<char>(in), {});
  }
  const std::regex timeout_line(R"(\nsensor_timeout *= *5\b)");
  ASSERT_TRUE(std::regex_search(config, timeout_line));
  std::ofstream(out + "/grab.ini") << std::regex_replace(config, timeout_line, "\nsensor_timeout = 30");
  const auto t0 = std::chrono::steady_clock::now();
  // timeout(1) guards against a hang: it would exit 124.
  const int rc = test::run("timeout 60 " + test::app("vofusion-grab") + " --config " + out + "/grab.ini --out " + out +
                               " --no-gui",
                           &log);
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(rc, 2) << log;
  EXPECT_EQ(countLines(log), 1u) << log;
  EXPECT_NE(log.find("OpenNI2"), std::string::npos) << log;
  EXPECT_LT(secs, 15.0);  // ~0.8 s here, against the 30 s sensor timeout
  EXPECT_FALSE(fs::exists(out + "/grab.rawlog"));  // nothing half-written
  // A folder to be made is not made for a session that cannot start.
  EXPECT_EQ(test::run("timeout 60 " + test::app("vofusion-grab") + " --config " + test::shareDir() +
                          "/grab-openni2.ini --out " + out + "/new --no-gui",
                      &log),
            2)
      << log;
  EXPECT_FALSE(fs::exists(out + "/new")) << log;
  // A sensor label that cannot name the recording's image files is refused before the sensor is opened.
  std::ofstream(out + "/label.ini") << std::regex_replace(config, std::regex(R"(\nsensorLabel *= *\S+)"), "\nsensorLabel = cam/left");
  EXPECT_EQ(test::run("timeout 60 " + test::app("vofusion-grab") + " --config " + out + "/label.ini --out " + out + "/l --no-gui", &log),
            2);
  EXPECT_NE(log.find("sensorLabel: 'cam/left' cannot name the recording's image files (no '/', at most 100 characters)"),
            std::string::npos)
      << log;
}

TEST(GrabApp, UsageErrorsExitTwo) {
  std::string log;
  EXPECT_EQ(test::run(test::app("vofusion-grab") + " --bogus", &log), 2);
  EXPECT_EQ(countLines(log), 1u) << log;
  EXPECT_EQ(test::run(test::app("vofusion-grab") + " --replay /nonexistent/folder --out " +
                          test::tempDir("grab_app_usage"),
                      &log),
            2);
  EXPECT_NE(log.find("/nonexistent/folder"), std::string::npos) << log;
  EXPECT_EQ(test::run(test::app("vofusion-grab") + " --max-frames abc", &log), 2);
  // 0 frames is no run (vofusion took it as every frame; the converters refused it). vofusion-grab's 0
  // is its config's "until Ctrl-C".
  EXPECT_EQ(test::run(test::app("vofusion") + " synthetic --max-frames 0 --out " + test::tempDir("grab_app_usage_0"), &log), 2);
  EXPECT_EQ(log, "vofusion: error: usage: --max-frames expects an integer >= 1, got '0'\n");
  // A sensor beside a replay was ignored.
  EXPECT_EQ(test::run(test::app("vofusion-grab") + " --replay synthetic --sensor KINECT", &log), 2);
  EXPECT_EQ(log, "vofusion-grab: error: --sensor: with --replay the frames come from the recording, not a sensor: give one of the two\n");
  // Options that would change nothing were taken and ignored (a --mode with --live forgotten only recorded).
  EXPECT_EQ(test::run(test::app("vofusion-grab") + " --replay synthetic --mode kinfu", &log), 2);
  EXPECT_EQ(log, "vofusion-grab: error: --mode: needs --live (without it nothing is reconstructed)\n");
  EXPECT_EQ(test::run(test::app("vofusion-grab") + " --speed 2 --no-gui", &log), 2);
  EXPECT_EQ(log, "vofusion-grab: error: --speed: needs --replay (a sensor gives its own)\n");
  // A speed whose waits overflow the clock (every frame then played at once) and a queue without bound.
  EXPECT_EQ(test::run(test::app("vofusion-grab") + " --replay synthetic --speed 1e-12 --no-gui", &log), 2);
  EXPECT_EQ(log, "vofusion-grab: error: --speed: must be 0 (as fast as frames load) or in [0.001, 1000] x the recorded rate\n");
  EXPECT_EQ(test::run(test::app("vofusion-grab") + " --replay synthetic --queue 100000 --no-gui", &log), 2);
  EXPECT_EQ(log, "vofusion-grab: error: --queue: must be in [1, 1000] frames (each waiting frame holds ~2 MB)\n");
  EXPECT_EQ(test::run(test::app("vofusion-grab") + " --depth-scale 1000", &log), 2);
  EXPECT_EQ(log, "vofusion-grab: error: --depth-scale: needs --replay (a sensor gives its own)\n");
}

TEST(GrabApp, UnknownKeyInOwnSectionIsReported) {
  const std::string dir = test::tempDir("grab_app_badkey");
  {
    std::ofstream f(dir + "/bad.ini");
    f << "[vofusion-grab]\nqueue_capacty = 3\n";
  }
  std::string log;
  EXPECT_EQ(test::run(test::app("vofusion-grab") + " --config " + dir + "/bad.ini --replay synthetic --out " + dir + "/out", &log), 2);
  EXPECT_NE(log.find("queue_capacty"), std::string::npos) << log;
}

// A bad reconstruction value fails before the recording is created (it used to fail once the live
// session started, leaving grab.rawlog and grab_Images behind, so the same --out was refused next time).
TEST(GrabApp, BadLiveValueFailsBeforeAnythingIsRecorded) {
  const std::string dir = test::tempDir("grab_app_badvalue");
  std::ofstream(dir + "/bad.ini") << "[kinfu]\nvoxel_size = 1cm\n";
  std::string log;
  EXPECT_EQ(test::run(test::app("vofusion-grab") + " --config " + dir + "/bad.ini --replay synthetic --out " + dir +
                          "/out --live --no-gui",
                      &log),
            2);
  EXPECT_NE(log.find(dir + "/bad.ini: [kinfu] voxel_size: '1cm' is not a number"), std::string::npos) << log;
  EXPECT_FALSE(std::filesystem::exists(dir + "/out")) << log;
}

// A live run that fails before its first frame (here: no display for the window) leaves no empty
// recording behind, so the same --out can be used at once (it used to be refused: "a recording is
// already there").
TEST(GrabApp, AFailureBeforeTheFirstFrameLeavesNoRecording) {
  const std::string tum = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(tum);
  const std::string out = test::tempDir("grab_app_nodisplay") + "/out";
  const std::string cmd = "env -u DISPLAY -u WAYLAND_DISPLAY " + test::app("vofusion-grab") + " --replay " + tum + " --out " + out;
  std::string log;
  EXPECT_EQ(test::run(cmd + " --live --max-frames 3", &log), 2);
  EXPECT_NE(log.find("--no-gui"), std::string::npos) << log;
  EXPECT_FALSE(std::filesystem::exists(out + "/grab.rawlog")) << log;
  EXPECT_FALSE(std::filesystem::exists(out + "/grab_Images")) << log;
  EXPECT_EQ(test::run(cmd + " --max-frames 3", &log), 0) << log;
  EXPECT_TRUE(std::filesystem::exists(out + "/grab.rawlog")) << log;
}

// A display that names no X server: MRPT gives no window (after its start-up timeout, ~5 s), and the
// first frame took that for the user closing it: a run "interrupted" after one frame, exit 0. Now the
// same one line as without a display, and no recording left.
TEST(GrabApp, ADisplayThatCannotBeOpenedIsAnErrorBeforeTheFirstFrame) {
  const std::string out = test::tempDir("grab_app_bad_display") + "/out";
  std::string log;
  EXPECT_EQ(test::run("env -u WAYLAND_DISPLAY DISPLAY=:97 " + test::app("vofusion-grab") + " --replay synthetic --out " + out +
                          " --live --max-frames 3",
                      &log),
            2)
      << log;
  EXPECT_NE(log.find("vofusion-grab: error: --live: cannot open the live window on the display (DISPLAY=:97): add --no-gui"),
            std::string::npos)
      << log;
  EXPECT_FALSE(std::filesystem::exists(out + "/grab.rawlog")) << log;
}

// A run that stops before its first frame is recorded (here every frame damaged; a sensor that fails at
// once is the same) leaves no empty recording: the next run in the folder records.
TEST(GrabApp, ARunThatRecordsNoFrameLeavesNoRecording) {
  const std::string dir = test::tempDir("grab_app_no_frame");
  ASSERT_EQ(test::run(test::app("rgbd-simulate") + " --out " + dir + "/rec --frames 3 --size 320x240"), 0);
  const std::string cmd = test::app("vofusion-grab") + " --replay " + dir + "/rec --out " + dir + "/out --no-gui --speed 4";
  fs::rename(dir + "/rec/depth", dir + "/depth");
  std::string log;
  EXPECT_EQ(test::run(cmd, &log), 1) << log;
  EXPECT_NE(log.find("0 recorded"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(dir + "/out/grab.rawlog")) << log;
  EXPECT_FALSE(fs::exists(dir + "/out/grab_Images")) << log;
  fs::rename(dir + "/depth", dir + "/rec/depth");
  ASSERT_EQ(test::run(cmd, &log), 0) << log;
  EXPECT_EQ(readSummary(dir + "/out/grab-summary.txt").at("frames_recorded"), "3") << log;
}

TEST(GrabApp, CtrlCStopsCleanlyAndWritesTheRecording) {
  const std::string tum = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(tum);
  const std::string out = test::tempDir("grab_app_sigint");
  std::string log;
  // The whole 300-frame sequence takes 10 s; SIGINT 1 s after the app says it records stops it.
  // Start-up is waited for, not guessed: on a loaded machine it took over 3 s, and sh starts a
  // background job with SIGINT ignored, so a SIGINT sent before the app's handler is in place is lost.
  const std::string err = test::tempDir("grab_app_sigint_err") + "/stderr.txt";
  const int rc = test::run("sh -c '" + test::app("vofusion-grab") + " --replay " + tum + " --out " + out + " 2> " + err +
                               " & pid=$!; i=0; until grep -q \"Ctrl-C to stop\" " + err +
                               " 2>/dev/null || ! kill -0 $pid 2>/dev/null || [ $i -ge 1200 ]; do sleep 0.05; i=$((i+1)); done; "
                               "[ $i -lt 1200 ] || echo \"no start-up line in 60 s\" >&2; sleep 1; kill -INT $pid; wait $pid'",
                           &log);
  log += std::string(std::istreambuf_iterator<char>(std::ifstream(err).rdbuf()), {});
  ASSERT_EQ(rc, 0) << log;
  auto kv = readSummary(out + "/grab-summary.txt");
  ASSERT_FALSE(kv.empty()) << log;
  EXPECT_EQ(kv["stop"], "interrupted");
  const long played = std::stol(kv["frames_played"]);
  EXPECT_GT(played, 0);
  EXPECT_LT(played, 300);
  EXPECT_EQ(std::stol(kv["frames_processed"]) + std::stol(kv["frames_dropped"]), played);
  auto back = openFrameSource(out + "/grab.rawlog");
  std::size_t n = 0;
  Frame f;
  while (back->next(f)) ++n;
  EXPECT_EQ(long(n), played);
}

// A recording is valid at every moment: kill -9 at random moments of a replayed live session leaves a
// grab.rawlog under its final name that vofusion reconstructs and rawlog-edit reads, every frame whole.
// A kill that lands inside the write(2) of a record can leave the file ending inside it (Linux cuts
// the write short between pages): the frames before it are read, and the reader says where it ends.
TEST(GrabApp, KilledAtRandomMomentsTheRecordingReadsToItsLastFrame) {
  const std::string tum = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(tum);
  const std::string cfg = test::tempDir("grab_app_kill_cfg") + "/path_only.ini";
  std::ofstream(cfg) << "[output]\nmesh = false\nwrite_rawlog = false\n";
  std::srand(11);
  for (int i = 0; i < 10; ++i) {
    const std::string out = test::tempDir("grab_app_kill") + "/run" + std::to_string(i);
    const double after = 3.0 * double(std::rand()) / RAND_MAX;  // s after its first record was written
    SCOPED_TRACE("killed " + std::to_string(after) + " s after the recording appeared");
    std::string log;
    // Start-up is waited for, not guessed: it takes longer on a loaded machine (up to 30 s here).
    test::run("sh -c '" + test::app("vofusion-grab") + " --replay " + tum + " --out " + out +
                  " --live --no-gui & pid=$!; i=0; while [ ! -s " + out + "/grab.rawlog ] && [ $i -lt 600 ]; do sleep 0.05; i=$((i+1)); done; sleep " +
                  std::to_string(after) + "; kill -9 $pid; wait $pid'",
              &log);
    ASSERT_TRUE(fs::exists(out + "/grab.rawlog")) << log;
    for (const auto& e : fs::directory_iterator(out))  // the recording's files: no temporary name (one ends in a pid)
      if (e.path().filename().string().rfind("grab", 0) == 0) {
        EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
      }
    // The replay's own ground truth beside it from its first frame (it came with commit(), never reached).
    ASSERT_TRUE(fs::exists(out + "/grab.groundtruth.txt"));
    EXPECT_EQ(readTumTrajectory(out + "/grab.groundtruth.txt").size(), readTumTrajectory(tum + "/groundtruth.txt").size());
    // Every frame decodes, depth and colour.
    auto back = openFrameSource(out + "/grab.rawlog");
    std::size_t frames = 0;
    Frame f;
    try {
      while (back->next(f)) {
        EXPECT_TRUE(f.valid());
        EXPECT_GT(cv::countNonZero(f.depth > 0), 1000);
        ++frames;
      }
    } catch (const RecordingCutShort& e) {
      EXPECT_EQ(e.problem().rfind("truncated rawlog (ends inside entry ", 0), 0u) << e.what();
    }
    EXPECT_GT(frames, 0u);
    std::string info;
    ASSERT_EQ(test::run("rawlog-edit --info -i " + out + "/grab.rawlog", &info), 0) << info;
    EXPECT_EQ(sensorOccurrences(info, "KINECT"), long(frames)) << info;
    std::string rec;
    ASSERT_EQ(test::run(test::app("vofusion") + " " + out + "/grab.rawlog --out " + out + "/rec --config " + cfg, &rec), 0)
        << rec;
    EXPECT_NE(rec.find("vofusion: " + std::to_string(frames) + " frames"), std::string::npos) << rec;
  }
}

// A TUM folder of `frames` synthetic 320x240 frames at `folder`: its depth images, in frame order (none
// when rgbd-simulate failed).
static std::vector<fs::path> simulatedRecording(const std::string& folder, int frames) {
  std::vector<fs::path> depth;
  if (test::run(test::app("rgbd-simulate") + " --out " + folder + " --frames " + std::to_string(frames) + " --size 320x240") != 0)
    return depth;
  for (const auto& e : fs::directory_iterator(folder + "/depth")) depth.push_back(e.path());
  std::sort(depth.begin(), depth.end());
  return depth;
}

// Replaying a damaged recording: the damaged frame is skipped with one warning, the rest recorded, and
// the count is in grab-summary.txt, the last line and, live, summary.json (as vofusion's).
TEST(GrabApp, ReplaySkipsADamagedFrame) {
  const std::string dir = test::tempDir("grab_app_damaged");
  const std::vector<fs::path> depth = simulatedRecording(dir + "/rec", 20);
  ASSERT_EQ(depth.size(), 20u);
  fs::remove(depth[7]);
  std::string log;
  ASSERT_EQ(test::run(test::app("vofusion-grab") + " --replay " + dir + "/rec --out " + dir + "/out --no-gui --speed 4", &log),
            0)
      << log;
  EXPECT_NE(log.find("warning: " + depth[7].string() + ": depth image is missing (frame 7 skipped)"), std::string::npos) << log;
  EXPECT_NE(log.find("19 played, 1 skipped as damaged"), std::string::npos) << log;
  EXPECT_EQ(readSummary(dir + "/out/grab-summary.txt").at("frames_skipped"), "1");
  auto back = openFrameSource(dir + "/out/grab.rawlog");
  std::size_t n = 0;
  Frame f;
  while (back->next(f)) ++n;
  EXPECT_EQ(n, 19u);

  std::ofstream(dir + "/nomesh.ini") << "[output]\nmesh = false\nwrite_rawlog = false\n";
  ASSERT_EQ(test::run(test::app("vofusion-grab") + " --replay " + dir + "/rec --out " + dir + "/live --live --no-gui --config " +
                          dir + "/nomesh.ini",
                      &log),
            0)
      << log;
  std::ifstream summary_file(dir + "/live/summary.json");
  const auto summary = nlohmann::json::parse(summary_file);
  EXPECT_EQ(summary.at("frames_skipped"), 1) << summary.dump();
  ASSERT_EQ(summary.at("skipped_frames").size(), 1u);
  EXPECT_EQ(summary["skipped_frames"][0].at("frame"), 7);
  EXPECT_EQ(summary["skipped_frames"][0].at("file"), depth[7].string());
}

// A live run stopped by a signal says which in summary.json, as vofusion's does (interrupted, stop_signal).
TEST(GrabApp, ALiveRunStoppedByASignalSaysWhich) {
  const std::string dir = test::tempDir("grab_app_live_signal");
  ASSERT_EQ(simulatedRecording(dir + "/rec", 150).size(), 150u);
  std::ofstream(dir + "/nomesh.ini") << "[output]\nmesh = false\nwrite_rawlog = false\n";
  const std::string out = dir + "/out";
  std::string log;
  // 5 s at 30 Hz; SIGTERM once the recording has its first frame.
  test::run("sh -c '" + test::app("vofusion-grab") + " --replay " + dir + "/rec --out " + out + " --live --no-gui --config " + dir +
                "/nomesh.ini 2>/dev/null & pid=$!; i=0; while [ ! -s " + out + "/grab.rawlog ] && [ $i -lt 600 ]; do sleep 0.05; "
                "i=$((i+1)); done; sleep 0.5; kill -TERM $pid; wait $pid; echo rc=$?'",
            &log);
  ASSERT_TRUE(fs::exists(out + "/summary.json")) << log;
  const auto summary = nlohmann::json::parse(std::ifstream(out + "/summary.json"));
  // Skipped only when the whole replay was played before the signal came; a signal ignored fails.
  if (!summary.at("interrupted").get<bool>() && summary["live"].at("played").get<int>() == 150)
    GTEST_SKIP() << "the replay had ended before the signal: " << log;
  EXPECT_TRUE(summary.at("interrupted").get<bool>()) << summary.dump();
  EXPECT_EQ(summary.value("stop_signal", ""), "SIGTERM") << summary.dump();
}

// A live run stopped by a failure (here a replay more than a fifth damaged) whose outputs then fail on
// their own (a folder where trajectory.txt goes) says both in its stop line: the outputs are not
// silently missing behind the first cause.
TEST(GrabApp, OutputsThatFailAfterAFailedRunAreNamed) {
  const std::string dir = test::tempDir("grab_app_failed_twice");
  const std::vector<fs::path> depth = simulatedRecording(dir + "/rec", 30);
  ASSERT_EQ(depth.size(), 30u);
  for (std::size_t i = 20; i < 27; ++i) fs::remove(depth[i]);
  fs::create_directories(dir + "/out/trajectory.txt");
  std::ofstream(dir + "/nomesh.ini") << "[output]\nmesh = false\nwrite_rawlog = false\n";
  std::string log;
  EXPECT_EQ(test::run(test::app("vofusion-grab") + " --replay " + dir + "/rec --out " + dir + "/out --live --no-gui --config " +
                          dir + "/nomesh.ini 2>&1",
                      &log),
            1)
      << log;
  const std::size_t at = log.find("vofusion-grab: stopped: ");
  ASSERT_NE(at, std::string::npos) << log;
  const std::string line = log.substr(at, log.find('\n', at) - at);
  EXPECT_NE(line.find("more than one in five"), std::string::npos) << line;
  EXPECT_NE(line.find(" frames recorded before it; writing the outputs then failed too: "), std::string::npos) << line;
  EXPECT_NE(line.find("trajectory.txt"), std::string::npos) << line;
}

// An earlier recording in the output folder is never overwritten: the grab refuses in one line.
TEST(GrabApp, AnEarlierRecordingIsNeverOverwritten) {
  const std::string tum = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(tum);
  const std::string out = test::tempDir("grab_app_keep");
  std::ofstream(out + "/grab.rawlog") << "an earlier recording";
  std::string log;
  EXPECT_EQ(test::run(test::app("vofusion-grab") + " --replay " + tum + " --out " + out + " --max-frames 5", &log), 2);
  EXPECT_NE(log.find("a recording is already there"), std::string::npos) << log;
  std::ifstream in(out + "/grab.rawlog");
  EXPECT_EQ(std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>()), "an earlier recording");
}

// A full disk stops the recording with one line naming the file it could not write; what was
// recorded before stays readable.
TEST(GrabApp, AFullDiskStopsTheRecordingAndKeepsWhatWasWritten) {
  const std::string tum = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(tum);
  const std::string mnt = test::tempDir("grab_app_tmpfs");
  const test::ScopedTmpfs tmpfs(mnt, "6m");
  if (!tmpfs.mounted()) GTEST_SKIP() << "cannot mount a tmpfs here";
  std::string log;
  // The app's own status, kept past the pipe (sh has no pipefail): a crash after its line was grep's 0.
  std::filesystem::remove(mnt + "/../grab_status");
  EXPECT_EQ(test::run("(" + test::app("vofusion-grab") + " --replay " + tum + " --out " + mnt + "/g --no-gui; echo $? > " +
                          mnt + "/../grab_status) 2>&1 | grep -v '^recording '",
                      &log),
            0);  // grep's status: the line is there
  std::string status;
  std::ifstream(mnt + "/../grab_status") >> status;
  EXPECT_TRUE(status == "0" || status == "1" || status == "2") << "exit status " << status << "\n" << log;
  EXPECT_NE(log.find("No space left on device"), std::string::npos) << log;
  auto back = openFrameSource(mnt + "/g/grab.rawlog");
  std::size_t n = 0;
  Frame f;
  while (back->next(f)) n += f.valid();
  EXPECT_GT(n, 3u);
  // After the banner: when the space the failed image had taken (it is removed) lets the recording
  // close, the run's line with the frames recorded and the stop's line; else the one error line.
  const bool closed = log.find("; " + std::to_string(n) + " recorded to ") != std::string::npos;
  EXPECT_TRUE(closed || log.find(std::to_string(n) + " frames recorded before it") != std::string::npos) << log;
  EXPECT_EQ(countLines(log), closed ? 3u : 2u) << log;
}

// A checkpoint comes after the session's last frame too, before its end phase (the map fused again,
// the meshing): a crash there is resumed at the end phase. With a period longer than the session it
// is the only one; there was none.
TEST(GrabApp, ALiveSessionIsCheckpointedAfterItsLastFrame) {
  const std::string tum = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(tum);
  const std::string out = test::tempDir("grab_app_last_checkpoint");
  std::string log;
  const int rc = test::run(test::app("vofusion-grab") + " --replay " + tum + " --live --no-gui --max-frames 6 --out " +
                               out + " --checkpoint-every 100000",
                           &log);
  ASSERT_EQ(rc, 0) << log;
  std::ifstream summary_file(out + "/summary.json");
  EXPECT_EQ(nlohmann::json::parse(summary_file)["checkpoints"]["written"].get<int>(), 1) << log;
  EXPECT_FALSE(fs::exists(out + "/checkpoint")) << "a session that ended normally has nothing to resume";
}

TEST(GrabApp, LiveReconstructionWritesTheSameOutputsAsVofusion) {
  const std::string tum = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(tum);
  const std::string out = test::tempDir("grab_app_live");
  std::string log;
  const int rc = test::run(test::app("vofusion-grab") + " --replay " + tum + " --live --no-gui --max-frames 20 --out " +
                               out + " --checkpoint-every 0.1",
                           &log);
  ASSERT_EQ(rc, 0) << log;
  // Checkpoints were written, and deleted at the end: a session that ended normally has nothing to resume.
  std::ifstream summary_file(out + "/summary.json");
  EXPECT_GT(nlohmann::json::parse(summary_file)["checkpoints"]["written"].get<int>(), 0) << log;
  EXPECT_FALSE(fs::exists(out + "/checkpoint")) << "a session that ended normally has nothing to resume";
  for (const char* f : {"grab.rawlog", "trajectory.txt", "mesh.ply", "scene.3Dscene", "summary.json", "poses.rawlog"})
    EXPECT_TRUE(fs::exists(fs::path(out) / f)) << f << "\n" << log;
  const auto kv = readSummary(out + "/grab-summary.txt");
  const long played = std::stol(kv.at("frames_played"));
  const long processed = std::stol(kv.at("frames_processed"));
  const long dropped = std::stol(kv.at("frames_dropped"));
  EXPECT_EQ(played, 20);
  EXPECT_GE(processed, 1);
  EXPECT_EQ(processed + dropped, played);
  // poses.rawlog's images are the recording's, linked: each file of poses_Images is one of grab_Images.
  std::size_t poses_images = 0, linked = 0;
  for (const auto& p : fs::directory_iterator(out + "/poses_Images")) {
    ++poses_images;
    for (const auto& g : fs::directory_iterator(out + "/grab_Images"))
      if (fs::equivalent(p.path(), g.path())) {
        ++linked;
        break;
      }
  }
  EXPECT_EQ(poses_images, std::size_t(2 * processed));
  EXPECT_EQ(linked, poses_images);
  // One trajectory pose per processed frame.
  std::ifstream traj(out + "/trajectory.txt");
  std::string line;
  long poses = 0;
  while (std::getline(traj, line)) poses += !line.empty() && line[0] != '#';
  EXPECT_EQ(poses, processed);
}

// A live session killed (-9) mid-run: its recording and its last checkpoint let vofusion finish the
// reconstruction offline from where the checkpoint was made, with every recorded frame after it.
TEST(GrabApp, AKilledLiveSessionIsFinishedOfflineFromItsCheckpoint) {
  const std::string tum = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(tum);
  const std::string dir = test::tempDir("grab_app_checkpoint");
  const std::string cfg = dir + "/path_only.ini", out = dir + "/live";
  std::ofstream(cfg) << "[output]\nmesh = false\n";
  std::string log;
  // Killed 1.5 s after its first checkpoint (waited for up to a minute).
  test::run("sh -c '" + test::app("vofusion-grab") + " --replay " + tum + " --out " + out + " --config " + cfg +
                " --live --no-gui --checkpoint-every 0.3 & pid=$!; for i in $(seq 600); do sleep 0.1; " +
                "[ -s " + out + "/checkpoint ] && break; done; " +
                "sleep 1.5; kill -9 $pid; wait $pid'",
            &log);
  const auto checkpoint = RunSession::peek(out + "/checkpoint");
  ASSERT_TRUE(checkpoint.has_value()) << log;
  ASSERT_GT(checkpoint->frames, 0u);
  std::size_t recorded = 0;
  {
    auto rec = openFrameSource(out + "/grab.rawlog");
    Frame f;
    while (rec->next(f)) ++recorded;
  }
  ASSERT_GT(recorded, checkpoint->frames);
  ASSERT_EQ(test::run(test::app("vofusion") + " " + out + "/grab.rawlog --out " + out + " --config " + cfg +
                          " --resume " + out + "/checkpoint",
                      &log),
            0)
      << log;
  std::ifstream summary_file(out + "/summary.json");
  const auto summary = nlohmann::json::parse(summary_file);
  EXPECT_EQ(summary["checkpoints"]["resumed_at_frame"].get<std::size_t>(), checkpoint->frames);
  // The checkpoint's frames, then every recorded frame after the last of them; tracked throughout.
  const std::size_t poses = summary["frames"].get<std::size_t>();
  EXPECT_GT(poses, checkpoint->frames);
  EXPECT_LE(poses, recorded);
  EXPECT_LT(summary["ate"]["rmse"].get<double>(), 0.03);
  EXPECT_FALSE(fs::exists(out + "/checkpoint")) << "the finished run deleted it";
}

// A checkpoint in the folder is an interrupted run's, which --live's checkpoints would replace and the
// session's end delete: the session does not start, and the checkpoint is as it was.
TEST(GrabApp, ALiveSessionDoesNotReplaceAnEarlierRunsCheckpoint) {
  const std::string out = test::tempDir("grab_app_earlier_checkpoint");
  std::ofstream(out + "/checkpoint") << "an earlier run's checkpoint";
  std::string log;
  EXPECT_EQ(test::run(test::app("vofusion-grab") + " --replay synthetic --out " + out + " --max-frames 3 --live --no-gui", &log), 2);
  EXPECT_EQ(countLines(log), 1u) << log;
  EXPECT_NE(log.find(out + "/checkpoint: an earlier run's checkpoint"), std::string::npos) << log;
  std::ifstream in(out + "/checkpoint");
  EXPECT_EQ(std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>()), "an earlier run's checkpoint");
  EXPECT_FALSE(fs::exists(out + "/grab.rawlog"));
  // Without checkpoints, nothing is replaced: the session runs.
  EXPECT_EQ(test::run(test::app("vofusion-grab") + " --replay synthetic --out " + out +
                          " --max-frames 3 --live --no-gui --checkpoint-every 0",
                      &log),
            0)
      << log;
}

// An empty recording file with no image beside it, as a kill before the first frame left it (the
// stop handler came after the file was made), holds nothing: the next recording into the folder
// replaces it. It was refused ("a recording is already there") until deleted by hand.
TEST(GrabApp, AnEmptyRecordingLeftByAKillDoesNotBlockTheFolder) {
  const std::string out = test::tempDir("grab_app_empty_left");
  std::ofstream(out + "/grab.rawlog");
  fs::create_directories(out + "/grab_Images");
  std::string log;
  ASSERT_EQ(test::run(test::app("vofusion-grab") + " --replay synthetic --out " + out + " --max-frames 3", &log), 0) << log;
  EXPECT_EQ(readSummary(out + "/grab-summary.txt").at("frames_recorded"), "3") << log;
  EXPECT_EQ(openFrameSource(out + "/grab.rawlog")->size(), 3u);
}

// A checkpoint that cannot be written (here its name is a folder that is not empty) is said once and
// checkpoints stop; the recording and the reconstruction go on. It used to end the session there
// ("processing error"), its recording cut short.
TEST(GrabApp, ACheckpointThatFailsLeavesTheSessionGoingOn) {
  const std::string dir = test::tempDir("grab_app_checkpoint_fails");
  const std::string cfg = dir + "/path_only.ini", out = dir + "/live";
  std::ofstream(cfg) << "[output]\nmesh = false\nwrite_rawlog = false\n";
  fs::create_directories(out + "/checkpoint/in_the_way");
  std::string log;
  ASSERT_EQ(test::run(test::app("vofusion-grab") + " --replay synthetic --out " + out + " --config " + cfg +
                          " --live --no-gui --max-frames 20 --checkpoint-every 0.05",
                      &log),
            0)
      << log;
  EXPECT_NE(log.find("; no more checkpoints this session, which goes on without them"), std::string::npos) << log;
  const auto kv = readSummary(out + "/grab-summary.txt");
  EXPECT_EQ(kv.at("frames_recorded"), "20") << log;
  EXPECT_EQ(kv.at("stop"), "max frames reached") << log;
}
