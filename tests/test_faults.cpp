#include <Eigen/Dense>
// The bad-input and fault matrix: every case runs a real app on a broken input made in tempDir() and
// expects a clean failure: exit code != 0 without a signal, exactly one error line on stderr naming
// the file and the problem (progress lines aside), and no half-written output: nothing new in the
// output folder (no *.tmp-*), an earlier result there unchanged byte for byte.
//
// Apps: rgbd-odometry and tum2rawlog (every input kind), rgbd-eval (trajectories), and vofusion,
// the main app, for the cases it shares (skipped locally until it is built, required under CI); the
// trackers with --strict: by default they skip a damaged frame and go on ("Damaged frames" at the end).
#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <regex>
#include <sstream>

#include <mrpt/core/Clock.h>
#include <nlohmann/json.hpp>
#include <mrpt/io/CFileGZOutputStream.h>
#include <mrpt/obs/CObservationOdometry.h>
#include <mrpt/serialization/CArchive.h>
#include <opencv2/imgcodecs.hpp>

#include "support.h"
#include "vofusion/io/tum_source.h"

using namespace vofusion;
namespace fs = std::filesystem;

namespace {

std::string readAll(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::ostringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

void writeText(const std::string& path, const std::string& text) {
  fs::create_directories(fs::path(path).parent_path());
  std::ofstream(path, std::ios::binary) << text;
}

std::string quote(const std::string& s) { return "'" + s + "'"; }

struct Outcome {
  bool crashed = false;  // killed by a signal (directly or as the shell reports it: 128 + n)
  int code = 0;
  std::vector<std::string> error_lines;  // stderr without Progress lines
  std::string stderr_text;
};

// Informational lines, not errors: Progress ("<label> 12/300 frames ...", "<label> 300 frames in ...",
// "meshing [...] 3/25 regions ..."),
// rgbd-odometry's stage times, vofusion's start banner ("vofusion: <input>, mode joint, 4 frames -> <out>"),
// warnings about an assumption ("warning: <file>: ...", e.g. guessed intrinsics).
bool isProgressLine(const std::string& l) {
  static const std::regex progress(R"(^.+ \d+(/\d+)? (frames|regions) .*)");
  static const std::regex stage_times(R"(^per-stage time .*)");
  static const std::regex banner(R"(^vofusion: .+, mode [\w-]+, \d+ frames -> .*)");
  return (std::regex_match(l, progress) && l.find("error") == std::string::npos) ||
         std::regex_match(l, stage_times) || std::regex_match(l, banner) || l.rfind("warning: ", 0) == 0;
}

Outcome runSplit(const std::string& cmd, const std::string& shell_prefix = "") {
  static int n = 0;
  const std::string err = (fs::path(test::tempDir("faults_stderr")).parent_path() /
                           ("faults_stderr_" + std::to_string(::getpid()) + "_" + std::to_string(n++) + ".txt"))
                              .string();
  const std::string full = shell_prefix + cmd + " >/dev/null 2>" + quote(err);
  const int status = std::system(("bash -c " + quote(full)).c_str());
  Outcome o;
  if (WIFSIGNALED(status)) {
    o.crashed = true;
  } else {
    o.code = WEXITSTATUS(status);
    o.crashed = o.code >= 128;
  }
  o.stderr_text = readAll(err);
  std::istringstream in(o.stderr_text);
  std::string line;
  while (std::getline(in, line))
    if (!line.empty() && !isProgressLine(line)) o.error_lines.push_back(line);
  fs::remove(err);
  return o;
}

std::vector<std::string> listing(const std::string& dir) {
  std::vector<std::string> names;
  if (!fs::exists(dir)) return names;
  for (const auto& e : fs::recursive_directory_iterator(dir)) names.push_back(e.path().string());
  std::sort(names.begin(), names.end());
  return names;
}

// An output folder holding an earlier run's result.
const char* kEarlier = "# an earlier result that a failed run must not touch\n1.0 0 0 0 0 0 0 1\n";
std::string outWithEarlierResult(const std::string& name) {
  const std::string out = test::tempDir(name);
  writeText(out + "/trajectory.txt", kEarlier);
  return out;
}

// The whole clean-failure contract. `out` may be "" (no output folder involved).
void expectCleanFailure(const std::string& cmd, const std::string& file, const std::string& problem,
                        const std::string& out = "", const std::string& shell_prefix = "") {
  SCOPED_TRACE(cmd);
  const auto before = listing(out);
  const Outcome o = runSplit(cmd, shell_prefix);
  EXPECT_FALSE(o.crashed) << "crashed; stderr:\n" << o.stderr_text;
  EXPECT_NE(o.code, 0) << "stderr:\n" << o.stderr_text;
  ASSERT_EQ(o.error_lines.size(), 1u) << "stderr:\n" << o.stderr_text;
  const std::string& e = o.error_lines[0];
  EXPECT_NE(e.find(file), std::string::npos) << "error line does not name '" << file << "': " << e;
  std::smatch m;
  EXPECT_TRUE(std::regex_search(e, m, std::regex(problem, std::regex::icase)))
      << "error line does not say /" << problem << "/: " << e;
  if (!out.empty()) {
    EXPECT_EQ(listing(out), before) << "the output folder changed";
    if (fs::exists(out + "/trajectory.txt")) {
      EXPECT_EQ(readAll(out + "/trajectory.txt"), kEarlier);
    }
  }
}

// The apps that reconstruct/track from a frame source: rgbd-odometry always, vofusion when built.
std::vector<std::string> trackers() {
  std::vector<std::string> apps{test::app("rgbd-odometry")};
  if (fs::exists(test::app("vofusion")) || test::inCi()) apps.push_back(test::app("vofusion"));
  return apps;
}
// vofusion without the slow extras (CGAL mesh post-processing, poses.rawlog) unless a case gives --config.
std::string fastVofusionConfig() {
  const std::string path = test::tempDir("faults_cfg") + "/fast.ini";  // in this test case's own folder
  writeText(path, "[output]\nwrite_rawlog = false\nclean_mesh = false\n");
  return path;
}
std::string trackCmd(const std::string& app, const std::string& input, const std::string& out,
                     const std::string& extra = "") {
  std::string cmd = quote(app) + " " + quote(input) + " --out " + quote(out) + " --max-frames 5 " + extra;
  const std::string name = fs::path(app).filename().string();
  if (name == "vofusion" && extra.find("--config") == std::string::npos) cmd += " --config " + quote(fastVofusionConfig());
  if (name == "vofusion" || name == "rgbd-odometry") cmd += " --strict";  // the first damaged frame stops the run
  return cmd;
}

// A small TUM folder whose lists point at the shared sequence's images (absolute paths), so that
// only the files a case breaks are written locally.
struct TumFixture {
  std::string dir;
  std::vector<TumAssociation> pairs;
  std::string rgbList() const { return dir + "/rgb.txt"; }
  std::string depthList() const { return dir + "/depth.txt"; }
  // Two colour frames may share their nearest depth frame: depth.txt lists each depth frame once.
  void writeLists() const {
    std::string rgb = "# color images\n", depth = "# depth images\n";
    std::string last_depth;
    for (const auto& p : pairs) {
      rgb += std::to_string(p.rgb.timestamp) + " " + p.rgb.file + "\n";
      const std::string d = std::to_string(p.depth.timestamp) + " " + p.depth.file + "\n";
      if (d != last_depth) depth += d;
      last_depth = d;
    }
    writeText(rgbList(), rgb);
    writeText(depthList(), depth);
  }
};

TumFixture makeTum(const std::string& name, std::size_t n = 3) {
  const std::string tum = test::tumFirst300();
  TumFixture f;
  f.dir = test::tempDir(name);
  // One-to-one pairs: every image in the fixture's lists once, so a case can break one entry.
  SourceOptions one_to_one;
  one_to_one.unique_depth = true;
  TumFolderSource src(tum, one_to_one);
  for (std::size_t i = 0; i < n; ++i) {
    TumAssociation a = src.pairs()[i];
    a.rgb.file = (fs::path(tum) / a.rgb.file).string();
    a.depth.file = (fs::path(tum) / a.depth.file).string();
    f.pairs.push_back(a);
  }
  f.writeLists();
  fs::copy_file(fs::path(tum) / "groundtruth.txt", f.dir + "/groundtruth.txt");
  return f;
}

// Replaces frame i's depth (or colour) image by a local file written by `write`.
template <class Write>
std::string replaceImage(TumFixture& f, std::size_t i, bool depth, Write write) {
  const std::string local = f.dir + (depth ? "/depth/" : "/rgb/") + std::to_string(i) + ".png";
  fs::create_directories(fs::path(local).parent_path());
  const std::string original = depth ? f.pairs[i].depth.file : f.pairs[i].rgb.file;
  write(local, original);
  for (auto& p : f.pairs) {  // every colour frame that shares this depth frame
    std::string& file = depth ? p.depth.file : p.rgb.file;
    if (file == original) file = local;
  }
  f.writeLists();
  return local;
}

#define REQUIRE_TUM() VOFUSION_REQUIRE_DATA(test::tumFirst300())

// A 5-frame rawlog of the shared sequence, images embedded (one self-contained file).
std::string makeRawlog(const std::string& name) {
  const std::string dir = test::tempDir(name);
  const std::string path = dir + "/in.rawlog";
  std::string log;
  const int rc = test::run(quote(test::app("tum2rawlog")) + " " + quote(test::tumFirst300()) + " " + quote(path) +
                               " --max-frames 5 --embed-images",
                           &log);
  EXPECT_EQ(rc, 0) << log;
  return path;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Input folders and lists

TEST(FaultsInput, MissingFolder) {
  for (const auto& app : trackers()) {
    const std::string out = outWithEarlierResult("faults_missing_out");
    const std::string in = test::tempDir("faults_missing") + "/no_such_sequence";
    expectCleanFailure(trackCmd(app, in, out), in, "no such file or folder", out);
  }
}

TEST(FaultsInput, EmptyFolder) {
  for (const auto& app : trackers()) {
    const std::string out = outWithEarlierResult("faults_empty_out");
    const std::string in = test::tempDir("faults_empty");
    expectCleanFailure(trackCmd(app, in, out), in, "not a TUM RGB-D sequence", out);
  }
  const std::string in = test::tempDir("faults_empty");
  expectCleanFailure(quote(test::app("tum2rawlog")) + " " + quote(in) + " " + quote(in + "/x.rawlog"),
                     in + "/rgb.txt", "missing");
}

// In a list of two lines one damaged line is more than one in five: the run stops, naming it (in a
// longer list it costs its frame: AppsIoBadInput.MalformedListLine).
TEST(FaultsInput, RgbListMalformedLines) {
  REQUIRE_TUM();
  const std::vector<std::pair<std::string, std::string>> cases{
      {"not-a-number rgb/a.png\n", "line 3: expected 'timestamp filename'"},
      {"1305031102.5\n", "line 3: expected 'timestamp filename'"},
      {"1305031102.5 rgb/a.png surplus\n", "line 3: unexpected extra field 'surplus'"},
      {"nan rgb/a.png\n", "line 3: expected 'timestamp filename'"},
  };
  for (const auto& app : trackers()) {
    for (const auto& [line, problem] : cases) {
      TumFixture f = makeTum("faults_rgblist");
      writeText(f.rgbList(), "# color images\n" + std::to_string(f.pairs[0].rgb.timestamp) + " " + f.pairs[0].rgb.file +
                                 "\n" + line);
      const std::string out = outWithEarlierResult("faults_rgblist_out");
      expectCleanFailure(trackCmd(app, f.dir, out), f.rgbList(), problem, out);
    }
  }
}

// Three lines, one out of order: more than one in five (as above).
TEST(FaultsInput, TimestampsOutOfOrderOrDuplicated) {
  REQUIRE_TUM();
  for (const auto& app : trackers()) {
    for (bool duplicate : {false, true}) {
      TumFixture f = makeTum("faults_stamps");
      // Entries 2 and 3 (lines 3 and 4) swapped, or entry 3 given entry 2's stamp.
      std::swap(f.pairs[1].rgb, f.pairs[duplicate ? 1 : 2].rgb);
      if (duplicate) f.pairs[2].rgb.timestamp = f.pairs[1].rgb.timestamp;
      f.writeLists();
      const std::string out = outWithEarlierResult("faults_stamps_out");
      expectCleanFailure(trackCmd(app, f.dir, out), f.rgbList(), "line 4: timestamp .* out of order or duplicated",
                         out);
    }
  }
}

TEST(FaultsInput, GroundTruthOutOfOrder) {
  REQUIRE_TUM();
  TumFixture f = makeTum("faults_gt");
  writeText(f.dir + "/groundtruth.txt",
            "1305031102.20 1 0 0 0 0 0 1\n1305031102.10 1 0 0 0 0 0 1\n1305031102.30 1 0 0 0 0 0 1\n");
  for (const auto& app : trackers()) {
    const std::string out = outWithEarlierResult("faults_gt_out");
    expectCleanFailure(trackCmd(app, f.dir, out), f.dir + "/groundtruth.txt", "not strictly increasing", out);
  }
  // The evaluation app reads the same files.
  const std::string est = f.dir + "/est.txt";
  writeText(est, "1305031102.20 1 0 0 0 0 0 1\n1305031102.30 1 0 0 0 0 0 1\n1305031102.40 1 0 0 0 0 0 1\n");
  expectCleanFailure(quote(test::app("rgbd-eval")) + " " + quote(f.dir + "/groundtruth.txt") + " " + quote(est),
                     f.dir + "/groundtruth.txt", "not strictly increasing");
  // An estimate is read as written: a run's frames in their order, where a recording's clock may step
  // back (it was refused as "not strictly increasing").
  writeText(est, "1305031103.00 1 0 0 0 0 0 1\n1305031102.90 1 0 0 0 0 0 1\n1305031103.10 1 0 0 0 0 0 1\n");
  std::string said;
  EXPECT_EQ(test::run(quote(test::app("rgbd-eval")) + " " + quote(test::tumFirst300() + "/groundtruth.txt") + " " + quote(est) +
                          " 2>&1",
                      &said),
            0)
      << said;
  EXPECT_NE(said.find("3 poses associated"), std::string::npos) << said;
  writeText(est, "1305031102.20 1 0 0 0 0 0 1\n1305031102.30 1 0 0 0.5 0 0\n");
  expectCleanFailure(quote(test::app("rgbd-eval")) + " " + quote(test::tumFirst300() + "/groundtruth.txt") + " " +
                         quote(est),
                     est, "line 2: expected 'timestamp tx ty tz qx qy qz qw'");
}

// ---------------------------------------------------------------------------------------------
// Images

// A damaged accelerometer.txt (a last line cut short by a download) costs its "up", not the run, as a
// damaged groundtruth.txt costs the evaluation; --strict stops at it.
TEST(FaultsInput, AccelerometerLineCutShort) {
  REQUIRE_TUM();
  TumFixture f = makeTum("faults_accel", 3);
  const std::string accel = f.dir + "/accelerometer.txt";
  writeText(accel, "# accelerometer data\n" + std::to_string(f.pairs[0].depth.timestamp) + " -0.1 9.8 0.2\n" +
                       std::to_string(f.pairs[1].depth.timestamp) + " -0.1 9.8\n");
  const std::string out = test::tempDir("faults_accel_out");
  std::string log;
  EXPECT_EQ(test::run(quote(test::app("vofusion")) + " " + quote(f.dir) + " --out " + quote(out) + " --config " +
                          quote(fastVofusionConfig()),
                      &log),
            0)
      << log;
  EXPECT_NE(log.find("warning: " + accel + ": line 3: expected 'timestamp ax ay az' (read without the accelerometer's up)"),
            std::string::npos)
      << log;
  EXPECT_TRUE(fs::exists(out + "/trajectory.txt")) << log;
  const std::string strict_out = outWithEarlierResult("faults_accel_strict_out");
  expectCleanFailure(trackCmd(test::app("vofusion"), f.dir, strict_out), accel, "line 3: expected", strict_out);
}

TEST(FaultsImages, ColourPngMissing) {
  REQUIRE_TUM();
  for (const auto& app : trackers()) {
    TumFixture f = makeTum("faults_png_missing");
    f.pairs[1].rgb.file = f.dir + "/rgb/gone.png";
    f.writeLists();
    const std::string out = outWithEarlierResult("faults_png_missing_out");
    expectCleanFailure(trackCmd(app, f.dir, out), f.dir + "/rgb/gone.png", "colour image is missing", out);
  }
}

TEST(FaultsImages, TruncatedPngFirstAndMidSequence) {
  REQUIRE_TUM();
  for (const auto& app : trackers()) {
    for (std::size_t frame : {std::size_t(0), std::size_t(1)}) {
      for (bool depth : {true, false}) {
        TumFixture f = makeTum("faults_png_trunc");
        const std::string png = replaceImage(f, frame, depth, [](const std::string& dst, const std::string& src) {
          const std::string bytes = readAll(src);
          writeText(dst, bytes.substr(0, bytes.size() / 2));
        });
        const std::string out = outWithEarlierResult("faults_png_trunc_out");
        expectCleanFailure(trackCmd(app, f.dir, out), png, "cannot decode .* image", out);
      }
    }
  }
}

TEST(FaultsImages, WrongSizeOrBitDepth) {
  REQUIRE_TUM();
  struct Case {
    bool depth;
    cv::Mat img;
    std::string problem;
  };
  const std::vector<Case> cases{
      {true, cv::Mat(240, 320, CV_16UC1, cv::Scalar(5000)), "depth image is 320x240, expected 640x480"},
      {true, cv::Mat(480, 640, CV_8UC1, cv::Scalar(100)), "must be 16-bit single channel"},
      {true, cv::Mat(480, 640, CV_16UC3, cv::Scalar(5000, 5000, 5000)), "must be 16-bit single channel"},
      {false, cv::Mat(240, 320, CV_8UC3, cv::Scalar(1, 2, 3)), "colour image is 320x240, expected 640x480"},
  };
  for (const auto& app : trackers()) {
    for (const Case& c : cases) {
      TumFixture f = makeTum("faults_png_size");
      // Colour frame 0 sets the sequence's image size, so a wrong colour size is tested on frame 1.
      const std::string png = replaceImage(f, c.depth ? 0 : 1, c.depth, [&](const std::string& dst, const std::string&) {
        cv::imwrite(dst, c.img);
      });
      const std::string out = outWithEarlierResult("faults_png_size_out");
      expectCleanFailure(trackCmd(app, f.dir, out), png, c.problem, out);
    }
  }
}

// Every depth image all zero: nothing can be tracked or fused, so the run fails and says why.
// (One zero frame among good ones is a lost frame, not an error: see DepthZeroInOneFrameIsNotFatal.)
TEST(FaultsImages, DepthAllZero) {
  REQUIRE_TUM();
  for (const auto& app : trackers()) {
    TumFixture f = makeTum("faults_depth_zero");
    for (std::size_t i = 0; i < f.pairs.size(); ++i)
      replaceImage(f, i, true, [](const std::string& dst, const std::string&) {
        cv::imwrite(dst, cv::Mat(480, 640, CV_16UC1, cv::Scalar(0)));
      });
    const std::string out = outWithEarlierResult("faults_depth_zero_out");
    expectCleanFailure(trackCmd(app, f.dir, out), f.dir, "no depth", out);
  }
}

TEST(FaultsImages, DepthZeroInOneFrameIsNotFatal) {
  REQUIRE_TUM();
  for (const auto& app : trackers()) {
    TumFixture f = makeTum("faults_depth_zero1");
    replaceImage(f, 2, true, [](const std::string& dst, const std::string&) {
      cv::imwrite(dst, cv::Mat(480, 640, CV_16UC1, cv::Scalar(0)));
    });
    const std::string out = test::tempDir("faults_depth_zero1_out");
    std::string log;
    ASSERT_EQ(test::run(trackCmd(app, f.dir, out), &log), 0) << log;
    EXPECT_EQ(readTumTrajectory(out + "/trajectory.txt").size(), f.pairs.size());
  }
}

// ---------------------------------------------------------------------------------------------
// Rawlogs

TEST(FaultsRawlog, TruncatedOrCorrupt) {
  REQUIRE_TUM();
  const std::string good = makeRawlog("faults_rawlog");
  const std::string bytes = readAll(good);
  ASSERT_GT(bytes.size(), 1000u);
  const std::string dir = fs::path(good).parent_path().string();
  struct Case {
    std::string name, contents, problem;
  };
  std::string flipped = bytes;
  for (std::size_t i = 40; i < flipped.size(); i += 97) flipped[i] = char(flipped[i] ^ 0x5a);
  const std::vector<Case> cases{
      {"half.rawlog", bytes.substr(0, bytes.size() / 2), "truncated|corrupt"},
      {"tail.rawlog", bytes.substr(0, bytes.size() - 1000), "truncated|corrupt"},
      {"flipped.rawlog", flipped, "truncated|corrupt"},
      {"garbage.rawlog", std::string(5000, 'x'), "not an MRPT rawlog|corrupt"},
      {"empty.rawlog", "", "contains no CObservation3DRangeScan|empty|corrupt"},
  };
  for (const auto& app : trackers()) {
    for (const Case& c : cases) {
      const std::string in = dir + "/" + c.name;
      writeText(in, c.contents);
      const std::string out = outWithEarlierResult("faults_rawlog_out");
      expectCleanFailure(trackCmd(app, in, out), in, c.problem, out);
    }
  }
}

TEST(FaultsRawlog, NoThreeDObservations) {
  const std::string in = test::tempDir("faults_rawlog_no3d") + "/odometry_only.rawlog";
  {
    mrpt::io::CFileGZOutputStream f(in);
    auto arch = mrpt::serialization::archiveFrom(f);
    for (int i = 0; i < 3; ++i) {
      mrpt::obs::CObservationOdometry o;
      o.timestamp = mrpt::Clock::fromDouble(100.0 + i);
      o.odometry = mrpt::poses::CPose2D(0.1 * i, 0, 0);
      arch << o;
    }
  }
  for (const auto& app : trackers()) {
    const std::string out = outWithEarlierResult("faults_rawlog_no3d_out");
    expectCleanFailure(trackCmd(app, in, out), in, "contains no CObservation3DRangeScan", out);
  }
}

// ---------------------------------------------------------------------------------------------
// Intrinsics and configuration

TEST(FaultsIntrinsics, UnknownOrInconsistentPreset) {
  REQUIRE_TUM();
  TumFixture f = makeTum("faults_intrinsics");
  const std::vector<std::pair<std::string, std::string>> cases{
      {"fr9", "unknown intrinsics 'fr9'"},
      {"525,525,319.5", "unknown intrinsics"},
      {"525,525,abc,239.5", "unknown intrinsics"},
      {"inf,inf,319.5,239.5", "unknown intrinsics"},
      {"525,525,319.5,239.5,", "unknown intrinsics"},
      {"525,525,900,239.5", "principal point .* outside"},
      {"-525,525,319.5,239.5", "focal"},
  };
  for (const auto& [spec, problem] : cases) {
    const std::string out = test::tempDir("faults_intrinsics_out");
    writeText(out + "/x.rawlog", kEarlier);
    expectCleanFailure(quote(test::app("tum2rawlog")) + " " + quote(f.dir) + " " + quote(out + "/x.rawlog") +
                           " --intrinsics " + quote(spec),
                       "--intrinsics", problem, out);
    EXPECT_EQ(readAll(out + "/x.rawlog"), kEarlier);
    if (fs::exists(test::app("vofusion")) || test::inCi()) {
      const std::string vout = outWithEarlierResult("faults_intrinsics_vout");
      expectCleanFailure(trackCmd(test::app("vofusion"), f.dir, vout, "--intrinsics " + quote(spec)), "--intrinsics",
                         problem, vout);
    }
  }
}

TEST(FaultsConfig, UnknownKeyOrSectionOutOfRangeOrMissing) {
  REQUIRE_TUM();
  TumFixture f = makeTum("faults_config");
  const std::string cfg = f.dir + "/user.ini";
  struct Case {
    std::string ini, problem;
  };
  const std::vector<Case> cases{
      {"[odometry]\nkeypoint = star\n", "unknown key 'keypoint' in section \\[odometry\\]"},
      {"[odometri]\nkeypoints = star\n", "unknown section \\[odometri\\]"},
      {"[odometry]\nkeypoints = sift\n", "keypoints.*must be one of union \\| star \\| narf"},
      {"[odometry]\nmotion_method = magic\n", "motion_method.*must be one of paper \\| robust"},
      {"[narf]\nimplementation = magic\n", "implementation.*must be one of fast \\| pcl"},
      {"[motion]\nsample_size = 2\n", "sample_size.*must be in \\[3, 100\\], got 2"},
  };
  for (const auto& app : trackers()) {
    for (const Case& c : cases) {
      writeText(cfg, c.ini);
      const std::string out = outWithEarlierResult("faults_config_out");
      expectCleanFailure(trackCmd(app, f.dir, out, "--config " + quote(cfg)), cfg, c.problem, out);
    }
    const std::string out = outWithEarlierResult("faults_config_out");
    expectCleanFailure(trackCmd(app, f.dir, out, "--config " + quote(f.dir + "/nope.ini")), f.dir + "/nope.ini",
                       "not found|cannot|no such|missing", out);
  }
}

// ---------------------------------------------------------------------------------------------
// Outputs

TEST(FaultsOutput, OutputFolderNotCreatable) {
  REQUIRE_TUM();
  TumFixture f = makeTum("faults_out");
  const std::string base = test::tempDir("faults_out_base");
  writeText(base + "/file", "a regular file\n");
  for (const auto& app : trackers()) {
    // Under a regular file (root ignores permission bits, so chmod would not block anything).
    expectCleanFailure(trackCmd(app, f.dir, base + "/file/out"), base + "/file/out", "cannot create output folder");
    // The output path is itself a file.
    expectCleanFailure(trackCmd(app, f.dir, base + "/file"), base + "/file", "not a (folder|directory)");
    EXPECT_EQ(readAll(base + "/file"), "a regular file\n");
    // A read-only file system.
    expectCleanFailure(trackCmd(app, f.dir, "/proc/vofusion_out"), "/proc/vofusion_out", "cannot create output folder");
  }
  expectCleanFailure(quote(test::app("tum2rawlog")) + " " + quote(f.dir) + " " + quote(base + "/file/x.rawlog"),
                     base + "/file", "cannot|not a directory");
}

// A folder where an output file goes (out/summary.json/ made by hand) fails the run before any output
// moves: trajectory.txt and the rest were in place, new, beside the earlier run's summary.
TEST(FaultsOutput, AFolderWhereAnOutputGoesChangesNothing) {
  const std::string out = outWithEarlierResult("faults_folder_in_the_way");
  fs::create_directories(out + "/summary.json/x");
  expectCleanFailure(quote(test::app("vofusion")) + " synthetic:room --max-frames 3 --out " + quote(out) + " --config " +
                         quote(fastVofusionConfig()),
                     out + "/summary.json", "is a folder", out);
  // With poses.rawlog (the default): an earlier run's rawlog and ground truth stay as they were.
  const std::string with_rawlog = outWithEarlierResult("faults_folder_in_the_way_rawlog");
  fs::create_directories(with_rawlog + "/summary.json/x");
  writeText(with_rawlog + "/poses.rawlog", kEarlier);
  writeText(with_rawlog + "/poses.groundtruth.txt", kEarlier);
  const std::string cfg = test::tempDir("faults_folder_in_the_way_cfg") + "/rawlog.ini";
  writeText(cfg, "[output]\nclean_mesh = false\n");
  expectCleanFailure(quote(test::app("vofusion")) + " synthetic:room --max-frames 3 --out " + quote(with_rawlog) +
                         " --config " + quote(cfg),
                     with_rawlog + "/summary.json", "is a folder", with_rawlog);
  EXPECT_EQ(readAll(with_rawlog + "/poses.rawlog"), kEarlier);
  EXPECT_EQ(readAll(with_rawlog + "/poses.groundtruth.txt"), kEarlier);
}

// The disk fills while outputs are written: a file size limit (ulimit -f, SIGXFSZ ignored so writes
// fail with EFBIG as on a full disk) lets the small files through but not the images/rawlog.
TEST(FaultsOutput, DiskFullFileSizeLimit) {
  REQUIRE_TUM();
  TumFixture f = makeTum("faults_fsize");
  for (const auto& app : trackers()) {
    const std::string out = outWithEarlierResult("faults_fsize_out");
    expectCleanFailure(trackCmd(app, f.dir, out), out, "write|File too large", out, "trap \"\" XFSZ; ulimit -f 64; ");
    // The file it names is where the user looks: not its staged copy (a folder gone by then).
    const Outcome o = runSplit(trackCmd(app, f.dir, out), "trap \"\" XFSZ; ulimit -f 64; ");
    ASSERT_EQ(o.error_lines.size(), 1u) << o.stderr_text;
    EXPECT_EQ(o.error_lines[0].find(".staging"), std::string::npos) << o.error_lines[0];
    EXPECT_EQ(o.error_lines[0].find(".tmp-"), std::string::npos) << o.error_lines[0];
  }
  {
    // vofusion's poses.rawlog: the image its writer thread could not write, named once (it was
    // "poses.rawlog: <image>: cannot write image"), as a warning when it happens: poses.rawlog is given
    // up and the run goes on (it lost every output at its end). Here the next output over 20 KiB fails too.
    const std::string out = outWithEarlierResult("faults_fsize_poses");
    const std::string cfg = test::tempDir("faults_fsize_poses_cfg") + "/rawlog.ini";
    writeText(cfg, "[output]\nmesh = false\n");
    const std::string cmd = trackCmd(test::app("vofusion"), f.dir, out, "--config " + quote(cfg));
    const Outcome o = runSplit(cmd, "trap \"\" XFSZ; ulimit -f 20; ");
    const std::string warned = "warning: " + out + "/poses_Images/";
    const std::size_t at = o.stderr_text.find(warned);
    ASSERT_NE(at, std::string::npos) << o.stderr_text;
    EXPECT_EQ(o.stderr_text.find(warned, at + 1), std::string::npos) << "said once: " << o.stderr_text;
    const std::string line = o.stderr_text.substr(at, o.stderr_text.find('\n', at) - at);
    EXPECT_NE(line.find("cannot write image"), std::string::npos) << line;
    EXPECT_NE(line.find("(the run goes on without poses.rawlog)"), std::string::npos) << line;
    ASSERT_EQ(o.error_lines.size(), 1u) << o.stderr_text;
    EXPECT_EQ(o.error_lines[0].find("/poses"), std::string::npos) << o.error_lines[0];  // the later output's error
    EXPECT_EQ(o.code, 2) << o.stderr_text;
    EXPECT_EQ(readAll(out + "/trajectory.txt"), kEarlier) << "a failed run replaced an earlier output";
  }
  const std::string out = test::tempDir("faults_fsize_rawlog");
  writeText(out + "/x.rawlog", kEarlier);
  expectCleanFailure(quote(test::app("tum2rawlog")) + " " + quote(f.dir) + " " + quote(out + "/x.rawlog") + " --overwrite",
                     out + "/x_Images/", "write|File too large", out, "trap \"\" XFSZ; ulimit -f 64; ");
  EXPECT_EQ(readAll(out + "/x.rawlog"), kEarlier);
}

// A real full file system: a 300 KiB tmpfs (needs mount rights; skipped where the sandbox has none).
TEST(FaultsOutput, DiskFullTmpfs) {
  REQUIRE_TUM();
  const std::string mnt = test::tempDir("faults_tmpfs");
  const test::ScopedTmpfs tmpfs(mnt, "300k");
  if (!tmpfs.mounted()) GTEST_SKIP() << "cannot mount a tmpfs here";
  TumFixture f = makeTum("faults_tmpfs_in");
  for (const auto& app : trackers()) {
    const std::string out = mnt + "/out";
    fs::remove_all(out);
    writeText(out + "/trajectory.txt", kEarlier);
    expectCleanFailure(trackCmd(app, f.dir, out), out, "write|No space left", out);
  }
  writeText(mnt + "/x.rawlog", kEarlier);
  expectCleanFailure(quote(test::app("tum2rawlog")) + " " + quote(f.dir) + " " + quote(mnt + "/x.rawlog") + " --overwrite",
                     mnt + "/x_Images/", "write|No space left", mnt);
}

// ---------------------------------------------------------------------------------------------
// Damaged frames: vofusion skips them (one warning line each, the first three with each problem), counts them in summary.json and
// writes every output; the path is as good as the clean run's.

namespace {

struct SkipRun {
  int code = 0;
  std::string log;
  nlohmann::json summary;
  std::size_t poses = 0;
};

SkipRun runSkipping(const std::string& input, const std::string& name, std::size_t frames) {
  const std::string out = test::tempDir(name);
  const std::string cfg = test::tempDir(name + "_cfg") + "/path_only.ini";
  writeText(cfg, "[output]\nmesh = false\nwrite_rawlog = false\n[loop]\nenabled = false\n");
  SkipRun r;
  r.code = test::run(quote(test::app("vofusion")) + " " + quote(input) + " --out " + quote(out) + " --max-frames " +
                         std::to_string(frames) + " --config " + quote(cfg),
                     &r.log);
  if (r.code != 0) return r;
  for (const char* f : {"trajectory.txt", "scene.3Dscene", "summary.json"})
    EXPECT_TRUE(fs::exists(out + "/" + f)) << f << " missing\n" << r.log;
  r.summary = nlohmann::json::parse(readAll(out + "/summary.json"));
  r.poses = readTumTrajectory(out + "/trajectory.txt").size();
  return r;
}

double ateOf(const SkipRun& r) { return r.summary["ate"]["rmse"].get<double>(); }

// Damages frame i of the fixture: its depth image missing, or its colour image truncated or garbage.
std::string damage(TumFixture& f, std::size_t i, int kind) {
  if (kind == 0) {
    const std::string gone = f.dir + "/depth/gone" + std::to_string(i) + ".png";
    f.pairs[i].depth.file = gone;
    f.writeLists();
    return gone;
  }
  return replaceImage(f, i, false, [kind](const std::string& dst, const std::string& src) {
    const std::string bytes = readAll(src);
    writeText(dst, kind == 1 ? bytes.substr(0, bytes.size() / 3) : std::string(bytes.size(), '\x5a'));
  });
}

}  // namespace

TEST(DamagedFrames, EachCostsOneFrameAndThePathStaysAsGood) {
  REQUIRE_TUM();
  constexpr std::size_t kFrames = 60;
  const TumFixture clean_fixture = makeTum("damaged_clean", kFrames);
  const SkipRun clean = runSkipping(clean_fixture.dir, "damaged_clean_out", kFrames);
  ASSERT_EQ(clean.code, 0) << clean.log;
  EXPECT_EQ(clean.summary["frames_skipped"], 0);
  const std::vector<std::size_t> positions{0, 14, 29, 44, kFrames - 1};
  for (std::size_t k = 0; k < positions.size(); ++k) {
    TumFixture f = makeTum("damaged_one", kFrames);
    const std::string file = damage(f, positions[k], int(k % 3));
    const SkipRun r = runSkipping(f.dir, "damaged_one_out", kFrames);
    SCOPED_TRACE(file);
    ASSERT_EQ(r.code, 0) << r.log;
    EXPECT_NE(r.log.find("warning: " + file), std::string::npos) << r.log;
    EXPECT_NE(r.log.find("(frame " + std::to_string(positions[k]) + " skipped)"), std::string::npos) << r.log;
    EXPECT_EQ(r.summary["frames_skipped"], 1);
    EXPECT_EQ(r.summary["skipped_frames"][0]["frame"], positions[k]);
    EXPECT_EQ(r.summary["skipped_frames"][0]["file"], file);
    EXPECT_EQ(r.poses, kFrames - 1);
    std::printf("frame %zu damaged: ATE %.5f m, clean %.5f m\n", positions[k], ateOf(r), ateOf(clean));
    EXPECT_LT(std::abs(ateOf(r) - ateOf(clean)), 0.001);
  }
  // All five in one run.
  TumFixture f = makeTum("damaged_five", kFrames);
  for (std::size_t k = 0; k < positions.size(); ++k) damage(f, positions[k], int(k % 3));
  const SkipRun r = runSkipping(f.dir, "damaged_five_out", kFrames);
  ASSERT_EQ(r.code, 0) << r.log;
  EXPECT_EQ(r.summary["frames_skipped"], positions.size());
  EXPECT_EQ(r.poses, kFrames - positions.size());
}

// A list line naming a folder, and a colour PNG of full length with a byte flipped inside its image
// data: each costs its frame in one line of ours (libpng prints its own line for a file it finds
// damaged, so the check comes before OpenCV's decoder; a folder once ended the run in bad_alloc).
TEST(DamagedFrames, AFolderOrAFlippedByteCostsOneFrameInOneLine) {
  REQUIRE_TUM();
  constexpr std::size_t kFrames = 25;
  TumFixture f = makeTum("damaged_folder_crc", kFrames);
  const std::string folder = f.dir + "/depth_folder";
  fs::create_directories(folder);
  f.pairs[5].depth.file = folder;
  f.writeLists();
  const std::string flipped = replaceImage(f, 12, false, [](const std::string& dst, const std::string& src) {
    std::string bytes = readAll(src);
    const std::size_t idat = bytes.find("IDAT");
    ASSERT_NE(idat, std::string::npos);
    bytes[idat + 4 + 100] ^= 0x10;
    writeText(dst, bytes);
  });
  // A whole JPEG whose frame header claims 40000x40000 pixels (within JPEG's limit, past OpenCV's):
  // refused by its header before any pixel is allocated (OpenCV threw an exception for its size, which
  // once ended the run with OpenCV's assertion text).
  const std::string huge = replaceImage(f, 16, false, [](const std::string& dst, const std::string& src) {
    std::vector<std::uint8_t> jpeg;
    ASSERT_TRUE(cv::imencode(".jpg", cv::imread(src), jpeg));
    const std::string bytes(jpeg.begin(), jpeg.end());
    const std::size_t sof = bytes.find("\xFF\xC0");
    ASSERT_NE(sof, std::string::npos);
    std::string patched = bytes;
    for (const std::size_t k : {sof + 5, sof + 7}) patched[k] = '\x9C', patched[k + 1] = '\x40';  // height, width
    writeText(dst, patched);
  });
  // A file far larger than any image (a sparse 1 TiB one) is damage too: it was read whole, and the
  // failed allocation (std::bad_alloc) ended the run.
  const std::string oversized = replaceImage(f, 9, false, [](const std::string& dst, const std::string&) {
    std::ofstream(dst).close();
    fs::resize_file(dst, std::uintmax_t(1) << 40);
  });
  const SkipRun r = runSkipping(f.dir, "damaged_folder_crc_out", kFrames);
  ASSERT_EQ(r.code, 0) << r.log;
  EXPECT_NE(r.log.find("warning: " + oversized + ": cannot decode colour image (1099511627776 bytes, larger than any image)"),
            std::string::npos)
      << r.log;
  EXPECT_NE(r.log.find("warning: " + folder + ": depth image is not a file (a folder?) (frame 5 skipped)"), std::string::npos)
      << r.log;
  EXPECT_NE(r.log.find("warning: " + flipped + ": cannot decode colour image (damaged PNG: its IDAT chunk fails its CRC)"),
            std::string::npos)
      << r.log;
  EXPECT_NE(r.log.find("warning: " + huge + ": colour image is 40000x40000, expected 640x480"), std::string::npos) << r.log;
  EXPECT_EQ(r.log.find("libpng"), std::string::npos) << r.log;
  EXPECT_EQ(r.summary["frames_skipped"], 4);
  EXPECT_EQ(r.poses, kFrames - 4);
}

TEST(DamagedFrames, MoreThanOneInFiveStopsTheRun) {
  REQUIRE_TUM();
  TumFixture f = makeTum("damaged_many", 20);
  for (std::size_t i = 3; i < 8; ++i) damage(f, i, 0);
  const std::string out = outWithEarlierResult("damaged_many_out");
  const Outcome o = runSplit(quote(test::app("vofusion")) + " " + quote(f.dir) + " --out " + quote(out) + " --config " +
                             quote(fastVofusionConfig()));
  EXPECT_NE(o.code, 0) << o.stderr_text;
  EXPECT_FALSE(o.crashed);
  ASSERT_FALSE(o.error_lines.empty()) << o.stderr_text;
  EXPECT_NE(o.error_lines.back().find("5 of 20 frames are damaged"), std::string::npos) << o.stderr_text;
  EXPECT_EQ(readAll(out + "/trajectory.txt"), kEarlier);
}

// A rawlog cut off anywhere (a crash while recording): read to its last whole frame, with a warning.
TEST(DamagedFrames, RawlogCutAtRandomOffsetsIsReadToItsLastWholeFrame) {
  REQUIRE_TUM();
  const std::string good = makeRawlog("damaged_rawlog");
  const std::string bytes = readAll(good);
  const std::string in = fs::path(good).parent_path().string() + "/cut.rawlog";
  std::mt19937 rng(7);
  std::size_t read_at_least_one = 0;
  for (int i = 0; i < 10; ++i) {
    const std::size_t at = 1000 + rng() % (bytes.size() - 1000);
    writeText(in, bytes.substr(0, at));
    SCOPED_TRACE("cut at byte " + std::to_string(at) + " of " + std::to_string(bytes.size()));
    const SkipRun r = runSkipping(in, "damaged_rawlog_out", 100);
    if (r.code != 0) {  // cut inside the first frame: nothing to reconstruct, one clear line
      EXPECT_NE(r.log.find("truncated"), std::string::npos) << r.log;
      continue;
    }
    ++read_at_least_one;
    EXPECT_GE(r.poses, 1u);
    EXPECT_LE(r.poses, 5u);
    EXPECT_TRUE(r.summary.contains("recording_cut_short")) << r.log;
    EXPECT_NE(r.log.find("warning: " + in), std::string::npos) << r.log;
  }
  EXPECT_GT(read_at_least_one, 5u);
}

TEST(DamagedFrames, RgbdOdometrySkipsThemToo) {
  REQUIRE_TUM();
  TumFixture f = makeTum("damaged_odometry", 10);
  const std::string file = damage(f, 4, 0);
  const std::string out = test::tempDir("damaged_odometry_out");
  std::string log;
  ASSERT_EQ(test::run(quote(test::app("rgbd-odometry")) + " " + quote(f.dir) + " --out " + quote(out) + " --no-rawlog", &log), 0)
      << log;
  EXPECT_NE(log.find("warning: " + file + ": depth image is missing (frame 4 skipped)"), std::string::npos) << log;
  EXPECT_EQ(readTumTrajectory(out + "/trajectory.txt").size(), 9u);
}
