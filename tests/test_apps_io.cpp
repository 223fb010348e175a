#include <algorithm>
#include <Eigen/Dense>
// The I/O apps end to end: rgbd-simulate, tum2rawlog (round trip on real data), rgbd-eval, bad input.
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "support.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/trajectory.h"
#include "vofusion/io/rawlog.h"
#include "vofusion/io/tum_source.h"
#include "vofusion/sim/synthetic_sequence.h"
#include "vofusion/sim/any_source.h"

using namespace vofusion;
namespace fs = std::filesystem;
using test::app;
using test::run;

namespace {
// A small synthetic TUM folder to break in various ways.
std::string smallTum(const std::string& name) {
  const std::string dir = test::tempDir(name) + "/seq";
  std::string out;
  EXPECT_EQ(run(app("rgbd-simulate") + " --out " + dir + " --frames 4 --size 160x120", &out), 0) << out;
  return dir;
}
// Runs a failing command: non-zero exit, exactly one line on stderr naming `needle`, and no output left.
void expectCleanFailure(const std::string& cmd, const std::string& needle, const std::string& out_dir) {
  std::string out;
  const int rc = run("(" + cmd + " 2>&1 >/dev/null)", &out);  // stderr only
  EXPECT_NE(rc, 0) << cmd;
  // Progress lines may precede it; the error itself is the one last line.
  std::vector<std::string> ls;
  std::istringstream in(out);
  for (std::string l; std::getline(in, l);) ls.push_back(l);
  ASSERT_FALSE(ls.empty()) << cmd;
  for (std::size_t i = 0; i + 1 < ls.size(); ++i)
    EXPECT_TRUE(std::regex_search(ls[i], std::regex("^\\S+ \\d+/\\d+ frames"))) << "unexpected line: " << ls[i];
  EXPECT_NE(ls.back().find(needle), std::string::npos) << "expected '" << needle << "' in: " << out;
  for (const auto& e : fs::directory_iterator(out_dir)) ADD_FAILURE() << "left behind: " << e.path();
}
}  // namespace

// --out sim/ (a shell's completion adds the slash) writes sim, as --out sim does, and again over it: the
// folder was staged inside itself and its replacement failed once every frame was made.
TEST(AppsIo, SimulateIntoAFolderNamedWithATrailingSlash) {
  const std::string dir = test::tempDir("simulate_trailing_slash");
  std::string out;
  std::string first_depth;  // pass 0's first depth image; pass 1 (another seed's noise) replaces it
  for (int pass = 0; pass < 2; ++pass) {
    ASSERT_EQ(run(app("rgbd-simulate") + " --out " + dir + "/sim/ --frames 2 --size 160x120 --seed " + std::to_string(pass + 1), &out), 0)
        << out;
    EXPECT_TRUE(fs::exists(dir + "/sim/rgb.txt")) << pass;
    EXPECT_EQ(std::distance(fs::directory_iterator(dir), {}), 1) << pass;
    std::string first;
    for (const auto& e : fs::directory_iterator(dir + "/sim/depth"))
      if (first.empty() || e.path().string() < first) first = e.path().string();
    std::ifstream depth(first, std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(depth)), {});
    ASSERT_FALSE(bytes.empty()) << pass;
    if (pass == 1) {
      EXPECT_NE(bytes, first_depth) << "the folder of pass 0 was not replaced";
    }
    first_depth = bytes;
  }
}

// Into the folder it runs in (or one holding it): refused before the first frame, in one line. It was
// staged inside and its rename refused (EBUSY) after every frame was made.
TEST(AppsIo, SimulateIntoTheFolderItRunsInIsRefusedAtOnce) {
  const std::string dir = test::tempDir("simulate_into_dot");
  for (const char* out : {".", "./"}) {
    std::string log;
    EXPECT_EQ(run("{ cd " + dir + " && " + app("rgbd-simulate") + " --out " + out + " --frames 2 --size 160x120 2>&1 >/dev/null; }", &log),
              2)
        << out;
    EXPECT_EQ(log, "rgbd-simulate: error: .: is the folder this command runs in, or holds it: it cannot be replaced (name the "
                   "folder from outside it)\n")
        << out;
    EXPECT_EQ(std::distance(fs::directory_iterator(dir), {}), 0) << "nothing left in it: " << out;
  }
}

// --overwrite replaces a rawlog; a folder rgbd-simulate wrote is replaced without it and any other never,
// so beside a folder it would change nothing: refused, not ignored (a user expecting a folder replaced
// was told "refusing to replace it" without the option named).
TEST(AppsIo, SimulateRefusesOverwriteForAFolder) {
  const std::string dir = test::tempDir("simulate_overwrite_folder");
  std::string log;
  EXPECT_EQ(run("{ " + app("rgbd-simulate") + " --out " + dir + "/tum --frames 2 --size 160x120 --overwrite 2>&1 >/dev/null; }", &log), 2);
  EXPECT_EQ(log, "rgbd-simulate: error: --overwrite: takes effect with a .rawlog --out only (a folder rgbd-simulate wrote is "
                 "replaced without it, any other never)\n");
  EXPECT_FALSE(fs::exists(dir + "/tum"));
}

// A ground truth already beside the rawlog to write is an earlier recording's too: refused without
// --overwrite, as the rawlog and its images are (it was replaced silently).
TEST(AppsIo, SimulateKeepsAGroundTruthBesideTheRawlogWithoutOverwrite) {
  const std::string dir = test::tempDir("simulate_keeps_gt");
  std::ofstream(dir + "/x.groundtruth.txt") << "1 0 0 0 0 0 0 1\n";
  std::string log;
  EXPECT_EQ(run("{ " + app("rgbd-simulate") + " --out " + dir + "/x.rawlog --frames 2 --size 160x120 2>&1 >/dev/null; }", &log), 2);
  EXPECT_EQ(log, "rgbd-simulate: error: " + dir + "/x.groundtruth.txt: already exists; not replaced (--overwrite replaces it)\n");
  std::ifstream kept(dir + "/x.groundtruth.txt");
  EXPECT_EQ(std::string(std::istreambuf_iterator<char>(kept), {}), "1 0 0 0 0 0 0 1\n");
  EXPECT_FALSE(fs::exists(dir + "/x.rawlog"));
  ASSERT_EQ(run(app("rgbd-simulate") + " --out " + dir + "/x.rawlog --frames 2 --size 160x120 --overwrite", &log), 0) << log;
  std::ifstream replaced(dir + "/x.groundtruth.txt");
  EXPECT_NE(std::string(std::istreambuf_iterator<char>(replaced), {}), "1 0 0 0 0 0 0 1\n");
}

TEST(AppsIo, SimulateTumMatchesSequence) {
  const std::string dir = test::tempDir("apps_sim_tum") + "/room";
  std::string out;
  ASSERT_EQ(run(app("rgbd-simulate") + " --out " + dir + " --frames 5 --size 320x240 --seed 3", &out), 0) << out;
  TumFolderSource src(dir, {});
  ASSERT_EQ(src.size(), 5u);
  sim::SimOptions o;
  o.frames = 5;
  o.seed = 3;
  o.camera = o.camera.scaled(0.5);
  sim::SyntheticSequence seq(o);
  for (std::size_t i = 0; i < 5; ++i) {
    const Frame f = src.read(i), e = seq.render(i);
    EXPECT_NEAR(f.timestamp, e.timestamp, 1e-6);
    EXPECT_EQ(cv::norm(f.rgb, e.rgb, cv::NORM_INF), 0.0);
    EXPECT_LE(cv::norm(f.depth, e.depth, cv::NORM_INF), 0.5 / 5000 + 1e-6);
    ASSERT_TRUE(f.groundTruth.has_value());
    EXPECT_LT((f.groundTruth->asVectorVal() - e.groundTruth->asVectorVal()).norm(), 1e-5);
  }
  // Re-running replaces the earlier sequence whole.
  ASSERT_EQ(run(app("rgbd-simulate") + " --out " + dir + " --frames 3 --size 160x120", &out), 0) << out;
  EXPECT_EQ(TumFolderSource(dir, {}).size(), 3u);
  EXPECT_EQ(std::distance(fs::directory_iterator(dir + "/rgb"), fs::directory_iterator{}), 3);
}

TEST(AppsIo, SimulateRawlog) {
  const std::string dir = test::tempDir("apps_sim_rawlog");
  std::string out;
  ASSERT_EQ(run(app("rgbd-simulate") + " --out " + dir + "/c.rawlog --scene corridor --frames 4 --size 160x120 --no-noise",
                &out), 0) << out;
  auto src = openFrameSource(dir + "/c.rawlog");
  EXPECT_EQ(src->size(), 4u);
  Frame f;
  ASSERT_TRUE(src->next(f));
  ASSERT_TRUE(f.groundTruth.has_value());
  EXPECT_TRUE(fs::exists(dir + "/c.groundtruth.txt"));
}

// rgbd-simulate replaced any folder holding an rgb.txt: a recorded TUM sequence pointed at by mistake
// was lost, notes and all. Now only a folder it wrote itself.
TEST(AppsIo, SimulateNeverReplacesAFolderItDidNotWrite) {
  const std::string dir = smallTum("apps_sim_not_ours");
  std::ofstream(dir + "/NOTES.md") << "where and how this was recorded\n";
  std::string out;
  EXPECT_EQ(run(app("rgbd-simulate") + " --out " + dir + " --frames 2 --size 160x120 2>&1", &out), 2);
  EXPECT_EQ(out, "rgbd-simulate: error: " + dir + ": exists and is not a folder rgbd-simulate wrote; refusing to replace it\n");
  EXPECT_EQ(TumFolderSource(dir, {}).size(), 4u);
  EXPECT_TRUE(fs::exists(dir + "/NOTES.md"));
  fs::remove(dir + "/NOTES.md");
  fs::remove(dir + "/intrinsics.txt");  // a TUM recording has none
  EXPECT_EQ(run(app("rgbd-simulate") + " --out " + dir + " --frames 2 --size 160x120 2>&1", &out), 2) << out;
  EXPECT_EQ(std::distance(fs::directory_iterator(dir + "/rgb"), fs::directory_iterator{}), 4);
}

// A rawlog may be a sensor recording: tum2rawlog and rgbd-simulate replace one only with --overwrite
// (MRPT's rawlog-edit asks the same), and an images folder in the way counts as one.
TEST(AppsIo, AnExistingRawlogIsReplacedOnlyWithOverwrite) {
  const std::string tum = smallTum("apps_rawlog_overwrite");
  const std::string dir = fs::path(tum).parent_path().string();
  std::string out;
  ASSERT_EQ(run(app("tum2rawlog") + " " + tum + " " + dir + "/x.rawlog --max-frames 3", &out), 0) << out;
  const auto bytes = [](const std::string& p) {
    std::ifstream f(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(f), {});
  };
  const std::string first = bytes(dir + "/x.rawlog");
  const std::vector<std::string> refusals = {app("tum2rawlog") + " " + tum + " " + dir + "/x.rawlog",
                                             app("rgbd-simulate") + " --frames 2 --size 160x120 --out " + dir + "/x.rawlog"};
  for (const auto& cmd : refusals) {
    EXPECT_EQ(run(cmd + " 2>&1", &out), 2) << cmd;
    EXPECT_NE(out.find(": error: " + dir + "/x.rawlog: already exists; not replaced (--overwrite replaces it)\n"),
              std::string::npos) << out;
    EXPECT_EQ(bytes(dir + "/x.rawlog"), first);
    EXPECT_EQ(openFrameSource(dir + "/x.rawlog")->size(), 3u);
  }
  fs::create_directories(dir + "/y_Images");
  EXPECT_EQ(run(app("tum2rawlog") + " " + tum + " " + dir + "/y.rawlog 2>&1", &out), 2);
  EXPECT_NE(out.find(dir + "/y_Images: already exists"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir + "/y.rawlog"));
  ASSERT_EQ(run(app("rgbd-simulate") + " --frames 2 --size 160x120 --out " + dir + "/x.rawlog --overwrite", &out), 0) << out;
  EXPECT_EQ(openFrameSource(dir + "/x.rawlog")->size(), 2u);
  ASSERT_EQ(run(app("tum2rawlog") + " " + tum + " " + dir + "/x.rawlog --overwrite", &out), 0) << out;
  EXPECT_EQ(openFrameSource(dir + "/x.rawlog")->size(), 4u);
}

// Ctrl-C or SIGTERM while converting or rendering: exit 130 / 143, one line saying nothing was written,
// the earlier output as it was and no temporary left (before: killed, with *.tmp-<pid> files beside it).
TEST(AppsIo, AStoppedConversionOrRenderingWritesNothingAndLeavesNoTemporary) {
  const std::string dir = test::tempDir("apps_stopped");
  std::string out;
  ASSERT_EQ(run(app("rgbd-simulate") + " --out " + dir + "/s.rawlog --frames 2 --size 160x120", &out), 0) << out;
  ASSERT_EQ(run(app("rgbd-simulate") + " --out " + dir + "/s --frames 2 --size 160x120", &out), 0) << out;
  const std::vector<std::pair<std::string, std::string>> cases = {
      {app("rgbd-simulate") + " --frames 3000 --out " + dir + "/s.rawlog --overwrite", "INT"},
      {app("rgbd-simulate") + " --frames 3000 --out " + dir + "/s", "TERM"},
  };
  for (const auto& [cmd, sig] : cases) {
    // Signalled once its progress shows a frame rendered (or after two minutes).
    const auto stopped = test::runSignalledMidway(cmd, dir + "/log.txt", 3000, sig, 1);
    const std::string& log = stopped.log;
    EXPECT_EQ(stopped.exit_code, sig == "INT" ? 130 : 143) << cmd << "\n" << log;
    EXPECT_NE(log.find("rgbd-simulate: stopped (SIG" + sig + "): nothing written\n"), std::string::npos) << log;
    EXPECT_EQ(openFrameSource(dir + "/s.rawlog")->size(), 2u);
    EXPECT_EQ(TumFolderSource(dir + "/s", {}).size(), 2u);
    for (const auto& e : fs::directory_iterator(dir))
      EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << "left behind: " << e.path();
  }
  const std::string tum = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(tum);  // the conversion's case needs the real recording (long enough to stop)
  const auto stopped = test::runSignalledMidway(app("tum2rawlog") + " " + tum + " " + dir + "/s.rawlog --overwrite",
                                                dir + "/log.txt", 300, "INT", 1);
  const std::string& log = stopped.log;
  // The first progress line shows at frame 1, and the signal goes within 0.2 s of it: only a run that
  // never showed one (all 300 converted at once) is no failure when it ends with 0.
  if (!stopped.signalled_at_a_count) {
    ASSERT_EQ(stopped.exit_code, 0) << "no count showed: it failed, or showed none in 120 s and was stopped: " << log;
    GTEST_SKIP() << "the 300 frames were converted before a progress line showed";
  }
  EXPECT_EQ(stopped.exit_code, 130) << log;
  EXPECT_NE(log.find("tum2rawlog: stopped (SIGINT) after "), std::string::npos) << log;
  EXPECT_EQ(openFrameSource(dir + "/s.rawlog")->size(), 2u);
  for (const auto& e : fs::directory_iterator(dir))
    EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << "left behind: " << e.path();
}

TEST(AppsIo, Tum2RawlogRoundTripOnRealData) {
  const std::string tum = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(tum);
  const std::string dir = test::tempDir("apps_tum2rawlog");
  const std::string rawlog = dir + "/first300.rawlog";
  std::string out;
  ASSERT_EQ(run(app("tum2rawlog") + " " + tum + " " + rawlog, &out), 0) << out;
  EXPECT_NE(out.find("tum2rawlog"), std::string::npos);  // progress shown
  // MRPT's own tool sees 300 3D range scans (plus the ground-truth poses).
  ASSERT_EQ(run("cd " + dir + " && rawlog-edit --list-timestamps -i first300.rawlog --text-file-output ts.txt", &out), 0)
      << out;
  std::ifstream ts(dir + "/ts.txt");
  int scans = 0;
  for (std::string l; std::getline(ts, l);) scans += l.find("CObservation3DRangeScan") != std::string::npos;
  // One CObservation3DRangeScan per colour frame: every one of the 300 has a depth frame within
  // 0.02 s (the benchmark's one-to-one rule would keep only 294).
  TumFolderSource pairs(tum, {});
  EXPECT_EQ(std::size_t(scans), pairs.size());
  EXPECT_EQ(scans, 300);
  ASSERT_EQ(run("cd " + dir + " && rawlog-edit --info -i first300.rawlog", &out), 0) << out;
  EXPECT_TRUE(std::regex_search(out, std::regex("KINECT\\s*/\\s*" + std::to_string(scans) + " "))) << out;
  // Round trip: identical pixels and timestamps.
  TumFolderSource a(tum, {});
  RawlogSource b(rawlog, {});
  ASSERT_EQ(a.size(), b.size());
  Frame fa, fb;
  int checked = 0;
  while (a.next(fa)) {
    ASSERT_TRUE(b.next(fb));
    ASSERT_NEAR(fa.timestamp, fb.timestamp, 1e-6);
    ASSERT_EQ(cv::norm(fa.rgb, fb.rgb, cv::NORM_INF), 0.0) << fa.index;
    ASSERT_EQ(cv::norm(fa.depth, fb.depth, cv::NORM_INF), 0.0) << fa.index;
    ASSERT_EQ(fa.groundTruth.has_value(), fb.groundTruth.has_value());
    if (fa.groundTruth) { EXPECT_LT((fa.groundTruth->asVectorVal() - fb.groundTruth->asVectorVal()).norm(), 1e-5); }
    EXPECT_DOUBLE_EQ(fa.camera.fx, fb.camera.fx);
    ++checked;
  }
  EXPECT_EQ(std::size_t(checked), pairs.size());
}

TEST(AppsIo, Tum2RawlogMaxFramesIntrinsicsAndSfFormat) {
  const std::string tum = smallTum("apps_t2r_opts");
  const std::string rawlog = fs::path(tum).parent_path() / "o.rawlog";
  std::string out;
  ASSERT_EQ(run(app("tum2rawlog") + " " + tum + " " + rawlog + " --max-frames 3 --intrinsics 260,261,79.5,59.5 --format sf",
                &out), 0) << out;
  RawlogSource src(rawlog, {});
  EXPECT_EQ(src.size(), 3u);
  Frame f;
  ASSERT_TRUE(src.next(f));
  EXPECT_DOUBLE_EQ(f.camera.fy, 261.0);
}

// A damaged frame costs that frame, as in vofusion: tum2rawlog skips it and says so; --strict stops.
TEST(AppsIo, Tum2RawlogSkipsADamagedFrame) {
  const std::string dir = test::tempDir("apps_t2r_damaged");
  std::string out;
  ASSERT_EQ(run(app("rgbd-simulate") + " --out " + dir + "/seq --frames 10 --size 160x120", &out), 0) << out;
  std::vector<fs::path> depth;
  for (const auto& e : fs::directory_iterator(dir + "/seq/depth")) depth.push_back(e.path());
  std::sort(depth.begin(), depth.end());
  ASSERT_EQ(depth.size(), 10u);
  std::ofstream(depth[3], std::ios::trunc) << "not a png";
  ASSERT_EQ(run(app("tum2rawlog") + " " + dir + "/seq " + dir + "/o.rawlog", &out), 0) << out;
  EXPECT_NE(out.find("warning: " + depth[3].string() + ": "), std::string::npos) << out;
  EXPECT_NE(out.find("(frame 3 skipped)"), std::string::npos) << out;
  EXPECT_NE(out.find("(1 damaged frames skipped)"), std::string::npos) << out;
  EXPECT_EQ(RawlogSource(dir + "/o.rawlog", {}).size(), 9u);
  EXPECT_EQ(run(app("tum2rawlog") + " " + dir + "/seq " + dir + "/strict.rawlog --strict", &out), 2) << out;
  EXPECT_FALSE(fs::exists(dir + "/strict.rawlog"));
}

TEST(AppsIo, EvalGroundTruthAgainstItselfIsZero) {
  const std::string tum = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(tum);
  const std::string gt = tum + "/groundtruth.txt";
  const std::string dir = test::tempDir("apps_eval");
  std::string out;
  ASSERT_EQ(run(app("rgbd-eval") + " " + gt + " " + gt + " --plot " + dir + "/p.png", &out), 0) << out;
  for (const char* row : {"Std", "Median", "RMS", "Mean", "Max"})
    EXPECT_TRUE(std::regex_search(out, std::regex(std::string(row) + "\\s+0\\.000000\\s+0\\.000000\\s+0\\.000000")))
        << row << "\n" << out;
  EXPECT_FALSE(cv::imread(dir + "/p.png").empty());
  ASSERT_EQ(run(app("rgbd-eval") + " " + gt + " " + gt + " --json --delta 0.5", &out), 0) << out;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(out, m, std::regex("\"ate_m\": \\{\"count\": \\d+, \"rmse\": ([-0-9.e]+)"))) << out;
  EXPECT_LT(std::stod(m[1]), 1e-9);
  EXPECT_NE(out.find("\"delta_s\": 0.5"), std::string::npos) << out;
}

TEST(AppsIo, EvalKnownOffsetThroughFiles) {
  // Estimate = ground truth moved and turned as a whole (a rigid offset the alignment removes): ATE 0,
  // and every relative motion the same: RPE 0.
  const std::string dir = test::tempDir("apps_eval_offset");
  Trajectory gt, est;
  for (int i = 0; i < 100; ++i) {
    const double t = i * 0.05;
    gt.push_back({t, mrpt::poses::CPose3D(t, 0.1 * t * t, 0, 0.1 * t, 0, 0)});
    est.push_back({t + 0.001, mrpt::poses::CPose3D(5, 5, 5, 0, 0, 0) + gt.back().pose});
  }
  writeTumTrajectory(dir + "/gt.txt", gt);
  writeTumTrajectory(dir + "/est.txt", est);
  std::string out;
  ASSERT_EQ(run(app("rgbd-eval") + " " + dir + "/gt.txt " + dir + "/est.txt --json", &out), 0) << out;
  const nlohmann::json rigid = nlohmann::json::parse(out);
  EXPECT_EQ(rigid.at("ate_m").at("count"), 100);
  EXPECT_LT(rigid.at("ate_m").at("rmse").get<double>(), 1e-6) << out;
  EXPECT_LT(rigid.at("rpe").at("trans_m").at("rmse").get<double>(), 1e-6) << out;
  EXPECT_LT(rigid.at("rpe").at("rot_deg").at("rmse").get<double>(), 1e-6) << out;
  // One outlier of exactly 1 m (along z, orthogonal to the planar motion). Unaligned that is an RMSE
  // of sqrt(1/100) = 0.1 m; the alignment can only lower it, and by little: shifting by the outlier's
  // share (1 cm) leaves sqrt((99 * 0.01^2 + 0.99^2) / 100) = 0.0995 m.
  est[50].pose = mrpt::poses::CPose3D(est[50].pose.x(), est[50].pose.y(), est[50].pose.z() + 1.0, est[50].pose.yaw(),
                                      est[50].pose.pitch(), est[50].pose.roll());
  writeTumTrajectory(dir + "/outlier.txt", est);
  ASSERT_EQ(run(app("rgbd-eval") + " " + dir + "/gt.txt " + dir + "/outlier.txt --json", &out), 0) << out;
  const double ate = nlohmann::json::parse(out).at("ate_m").at("rmse").get<double>();
  EXPECT_LE(ate, 0.1 + 1e-9) << out;
  EXPECT_GT(ate, 0.09) << out;
  // --json is JSON whatever the paths hold (a backslash, quotes, a tab).
  const std::string odd = dir + "/seq\\1 \"q\"\t";
  fs::create_directories(odd);
  fs::copy_file(dir + "/gt.txt", odd + "/gt.txt");
  ASSERT_EQ(run(app("rgbd-eval") + " '" + odd + "/gt.txt' '" + dir + "/est.txt' --json", &out), 0) << out;
  const nlohmann::json parsed = nlohmann::json::parse(out);
  EXPECT_EQ(parsed.at("groundtruth"), odd + "/gt.txt");
  EXPECT_EQ(parsed.at("ate_m").at("count"), 100);
}

// ---- Bad input: one line naming the file, exit != 0, nothing left behind.

// A damaged list line costs its frame, as a damaged image does: a recording whose rgb.txt was cut
// mid-line (a crash while it was written) lost its whole run to that line. --strict stops; so does a
// list more than one line in five of which is damaged.
TEST(AppsIoBadInput, MalformedListLine) {
  const std::string dir = test::tempDir("bad_line");
  std::string out;
  ASSERT_EQ(run(app("rgbd-simulate") + " --out " + dir + "/seq --frames 8 --size 160x120", &out), 0) << out;
  const std::string tum = dir + "/seq";
  std::ofstream(tum + "/rgb.txt", std::ios::app) << "99.5 rgb/x.png extra-field\n100.25";  // cut mid-line, no newline
  ASSERT_EQ(run(app("tum2rawlog") + " " + tum + " " + dir + "/o.rawlog", &out), 0) << out;
  EXPECT_NE(out.find("warning: " + tum + "/rgb.txt: line 11: unexpected extra field 'extra-field' (its frame skipped)"),
            std::string::npos) << out;
  EXPECT_NE(out.find("warning: " + tum + "/rgb.txt: line 12: expected 'timestamp filename' (its frame skipped)"),
            std::string::npos) << out;
  EXPECT_EQ(RawlogSource(dir + "/o.rawlog", {}).size(), 8u);
  const std::string outdir = test::tempDir("bad_line_out");
  expectCleanFailure(app("tum2rawlog") + " " + tum + " " + outdir + "/o.rawlog --strict", "rgb.txt: line 11", outdir);
  std::ofstream(tum + "/depth.txt", std::ios::app) << "a\nb\nc\n";  // 3 of 11 lines
  expectCleanFailure(app("tum2rawlog") + " " + tum + " " + outdir + "/o.rawlog",
                     "depth.txt: line 11: expected 'timestamp filename' (3 of its 11 lines damaged: more than one in five)",
                     outdir);
}

TEST(AppsIoBadInput, MissingCorruptWrongSizeAndDepthPng) {
  const std::string tum = smallTum("bad_png");
  const auto list = readTumList(tum + "/depth.txt");
  const auto rgb = readTumList(tum + "/rgb.txt");
  const std::string outdir = test::tempDir("bad_png_out");
  // --strict: each damage stops the conversion (by default it skips the frame: Tum2RawlogSkipsADamagedFrame).
  const std::string cmd = app("tum2rawlog") + " " + tum + " " + outdir + "/o.rawlog --strict";
  // Missing depth PNG (the third frame: output was already being written when it fails).
  const std::string d2 = tum + "/" + list[2].file;
  fs::rename(d2, d2 + ".bak");
  expectCleanFailure(cmd, list[2].file + ": depth image is missing", outdir);
  // Truncated PNG.
  {
    std::ifstream in(d2 + ".bak", std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::ofstream(d2, std::ios::binary) << bytes.substr(0, bytes.size() / 3);
  }
  expectCleanFailure(cmd, list[2].file + ": cannot decode", outdir);
  // 8-bit instead of 16-bit depth.
  cv::imwrite(d2, cv::Mat(120, 160, CV_8UC1, cv::Scalar(7)));
  expectCleanFailure(cmd, list[2].file + ": depth image must be 16-bit", outdir);
  // Wrong size.
  cv::imwrite(d2, cv::Mat(100, 160, CV_16UC1, cv::Scalar(7000)));
  expectCleanFailure(cmd, list[2].file + ": depth image is 160x100", outdir);
  fs::rename(d2 + ".bak", d2);
  // A colour frame of the wrong size.
  cv::imwrite(tum + "/" + rgb[1].file, cv::Mat(240, 320, CV_8UC3, cv::Scalar(1, 2, 3)));
  expectCleanFailure(cmd, rgb[1].file + ": colour image is 320x240", outdir);
  // A depth map listed as colour (it read as a grey picture of the depths, used as colour).
  cv::imwrite(tum + "/" + rgb[1].file, cv::Mat(120, 160, CV_16UC1, cv::Scalar(7000)));
  expectCleanFailure(cmd, rgb[1].file + ": colour image is 16-bit single channel, as depth images are", outdir);
  // 8-bit grey and 16-bit colour PNGs are colour images, made 8-bit BGR.
  cv::imwrite(tum + "/" + rgb[1].file, cv::Mat(120, 160, CV_8UC1, cv::Scalar(90)));
  TumFolderSource grey(tum, {});
  EXPECT_EQ(grey.read(1).rgb.at<cv::Vec3b>(5, 5), cv::Vec3b(90, 90, 90));
  cv::imwrite(tum + "/" + rgb[1].file, cv::Mat(120, 160, CV_16UC3, cv::Scalar(256 * 10, 256 * 20, 256 * 30)));
  TumFolderSource deep(tum, {});
  EXPECT_EQ(deep.read(1).rgb.at<cv::Vec3b>(5, 5), cv::Vec3b(10, 20, 30));
}

TEST(AppsIoBadInput, EmptyFolderUnknownPresetAndMissingInput) {
  const std::string empty = test::tempDir("bad_empty") ;
  fs::create_directories(empty + "/seq");
  const std::string outdir = test::tempDir("bad_empty_out");
  expectCleanFailure(app("tum2rawlog") + " " + empty + "/seq " + outdir + "/o.rawlog", "seq/rgb.txt: missing", outdir);
  const std::string tum = smallTum("bad_preset");
  expectCleanFailure(app("tum2rawlog") + " " + tum + " " + outdir + "/o.rawlog --intrinsics fr7", "fr7", outdir);
  std::ofstream(empty + "/seq/rgb.txt").flush();
  std::ofstream(empty + "/seq/depth.txt") << "1.0 depth/a.png\n";
  expectCleanFailure(app("tum2rawlog") + " " + empty + "/seq " + outdir + "/o.rawlog", "rgb.txt: lists no frames", outdir);
}

// Values no recording could use are refused by their flag: a range unit of 1e-300 m is 0 as the
// rawlog's float (a recording nothing reads); a frame rate of 1e-300 made stamps too long for their
// file names (OpenCV's "could not find a writer" for a name cut before ".png").
TEST(AppsIoBadInput, RangeUnitsAndFrameRatesNoRecordingCouldUse) {
  const std::string tum = smallTum("bad_units");
  const std::string outdir = test::tempDir("bad_units_out");
  for (const char* units : {"1e-300", "1e-7"})
    expectCleanFailure(app("tum2rawlog") + " " + tum + " " + outdir + "/o.rawlog --range-units " + units, "--range-units", outdir);
  for (const char* fps : {"1e-300", "0.05"})
    expectCleanFailure(app("rgbd-simulate") + " --out " + outdir + "/sim --frames 2 --size 160x120 --fps " + fps, "--fps", outdir);
  std::string out;
  EXPECT_EQ(run(app("rgbd-simulate") + " --out " + outdir + "/slow --frames 2 --size 160x120 --fps 0.1", &out), 0) << out;
}

// --depth-scale is read by a TUM folder only: any other input refuses it rather than ignore it.
TEST(AppsIoBadInput, DepthScaleOfAnInputWithItsOwnUnits) {
  const std::string dir = test::tempDir("bad_depth_scale");
  ASSERT_EQ(run(app("rgbd-simulate") + " --out " + dir + "/x.rawlog --frames 2 --size 160x120"), 0);
  const std::string outdir = test::tempDir("bad_depth_scale_out");
  for (const std::string& input : {dir + "/x.rawlog", std::string("synthetic")})
    for (const std::string& tracker : {app("rgbd-odometry"), app("vofusion")})
      expectCleanFailure(tracker + " " + input + " --out " + outdir + "/o --depth-scale 1000",
                         input + ": --depth-scale is for a TUM folder's depth PNGs", outdir);
}

TEST(AppsIoBadInput, EvalBadFiles) {
  const std::string dir = test::tempDir("bad_eval");
  const std::string outdir = test::tempDir("bad_eval_out");
  std::ofstream(dir + "/gt.txt") << "1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 0 1\n3.0 1 0 0 0 0 0 1\n";
  std::ofstream(dir + "/bad.txt") << "1.0 0 0 0 0 0 0 1\n2.0 0 0 zero 0 0 0 1\n";
  std::ofstream(dir + "/far.txt") << "10.0 0 0 0 0 0 0 1\n11.0 0 0 0 0 0 0 1\n12.0 0 0 0 0 0 0 1\n";
  const std::string plot = " --plot " + outdir + "/p.png";
  expectCleanFailure(app("rgbd-eval") + " " + dir + "/gt.txt " + dir + "/bad.txt" + plot, "bad.txt: line 2", outdir);
  expectCleanFailure(app("rgbd-eval") + " " + dir + "/gt.txt " + dir + "/nope.txt" + plot, "nope.txt: cannot open", outdir);
  expectCleanFailure(app("rgbd-eval") + " " + dir + "/gt.txt " + dir + "/far.txt" + plot, "far.txt: only 0 poses", outdir);
  // A plot is a PNG: another name wrote PNG bytes under it.
  expectCleanFailure(app("rgbd-eval") + " " + dir + "/gt.txt " + dir + "/gt.txt --plot " + outdir + "/p.jpg",
                     "--plot: writes a PNG: give a .png name", outdir);
  std::string out;
  EXPECT_EQ(run(app("rgbd-eval") + " " + dir + "/gt.txt", &out), 2);
}

TEST(AppsIoBadInput, RawlogInputs) {
  const std::string dir = test::tempDir("bad_rawlog");
  const std::string outdir = test::tempDir("bad_rawlog_out");
  std::ofstream(dir + "/junk.rawlog") << "not a rawlog at all";
  // tum2rawlog refuses a rawlog as input; the rawlog reader names the file for junk.
  try {
    RawlogSource src(dir + "/junk.rawlog", {});
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("junk.rawlog: "), std::string::npos);
  }
  expectCleanFailure(app("rgbd-simulate") + " --out " + outdir + "/x.rawlog --scene moon", "unknown scene 'moon'", outdir);
  expectCleanFailure(app("rgbd-simulate") + " --out " + outdir + "/x --frames 0", "--frames", outdir);
  // A size too large to render (it failed in the rendering's allocation) or not a number's.
  expectCleanFailure(app("rgbd-simulate") + " --out " + outdir + "/x --size 64000x48000", "--size: width 64000 is outside [24, 4096]",
                     outdir);
  expectCleanFailure(app("rgbd-simulate") + " --out " + outdir + "/x --size 1000000000x750000000", "--size", outdir);
  expectCleanFailure(app("rgbd-simulate") + " --out " + outdir + "/x --seed 4294967297", "--seed expects a whole number below 2^32",
                     outdir);
  // A cover of no length, or between two frames (30 fps: 0.01 to 0.02 s), covers no frame.
  for (const char* cover : {"1:0", "0.01:0.01"})
    expectCleanFailure(app("rgbd-simulate") + " --out " + outdir + "/x --frames 5 --blackout " + cover, "covers no frame", outdir);
  for (const char* cover : {"0:nan", "nan:1"})
    expectCleanFailure(app("rgbd-simulate") + " --out " + outdir + "/x --frames 5 --blackout " + cover,
                       std::string("--blackout: expected T:S (start and length in s), e.g. 4:1.5, got '") + cover + "'", outdir);
}

// A ground truth, accelerometer or intrinsics file that is a link to itself costs what it would give,
// said in one line naming it: std::filesystem::exists threw on it, and the run ended with its error.
TEST(AppsIo, ASidecarFileLinkedToItselfCostsWhatItGives) {
  const std::string seq = smallTum("self_linked_sidecar");
  for (const char* name : {"groundtruth.txt", "accelerometer.txt"}) {
    fs::remove(seq + "/" + name);
    fs::create_symlink(name, seq + "/" + name);
  }
  std::string log;
  ASSERT_EQ(run(app("rgbd-odometry") + " " + seq + " --out " + fs::path(seq).parent_path().string() + "/out", &log), 0) << log;
  EXPECT_NE(log.find(seq + "/groundtruth.txt: "), std::string::npos) << log;
  EXPECT_EQ(log.find("filesystem error"), std::string::npos) << log;
  fs::remove(seq + "/intrinsics.txt");
  fs::create_symlink("intrinsics.txt", seq + "/intrinsics.txt");
  const std::string out2 = fs::path(seq).parent_path().string() + "/out2";
  fs::create_directories(out2);
  expectCleanFailure(app("rgbd-odometry") + " " + seq + " --out " + out2, seq + "/intrinsics.txt: ", out2);
  // A link to nowhere: as a file that is not there, the input named so; an intrinsics file, named.
  fs::remove(seq + "/intrinsics.txt");
  fs::create_symlink("nowhere.txt", seq + "/intrinsics.txt");
  expectCleanFailure(app("rgbd-odometry") + " " + seq + " --out " + out2,
                     seq + "/intrinsics.txt: cannot open file (No such file or directory)", out2);
  const std::string dangling = fs::path(seq).parent_path().string() + "/dangling.rawlog";
  fs::create_symlink("nowhere.rawlog", dangling);
  expectCleanFailure(app("rgbd-odometry") + " " + dangling + " --out " + out2, dangling + ": no such file or folder", out2);
}
