#include <Eigen/Dense>
// ATE / RPE against hand-computed answers, and the plots.
#include <cmath>
#include <filesystem>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "support.h"
#include "vofusion/eval/trajectory_eval.h"

using namespace vofusion;
using mrpt::poses::CPose3D;
namespace fs = std::filesystem;

namespace {
// A wavy 10 s ground truth at 30 Hz.
Trajectory wavy(double t_offset = 0.0) {
  Trajectory t;
  for (int i = 0; i < 300; ++i) {
    const double s = i / 30.0;
    t.push_back({100.0 + s + t_offset, CPose3D(0.5 * std::sin(s), 0.3 * std::cos(0.7 * s), 0.1 * s, 0.2 * std::sin(0.5 * s),
                                              0.1 * std::cos(s), 0.05 * s)});
  }
  return t;
}
}  // namespace

TEST(Eval, StatsByHand) {
  const ErrorStats s = computeStats({1, 2, 3, 4});
  EXPECT_DOUBLE_EQ(s.mean, 2.5);
  EXPECT_DOUBLE_EQ(s.median, 2.5);
  EXPECT_DOUBLE_EQ(s.rmse, std::sqrt(30.0 / 4));
  EXPECT_DOUBLE_EQ(s.std, std::sqrt(1.25));
  EXPECT_DOUBLE_EQ(s.max, 4);
  EXPECT_DOUBLE_EQ(s.min, 1);
  EXPECT_DOUBLE_EQ(s.p95, 4);  // nearest rank: ceil(0.95 * 4) = the 4th
  std::vector<double> twenty;
  for (int i = 20; i >= 1; --i) twenty.push_back(i);
  EXPECT_DOUBLE_EQ(computeStats(twenty).p95, 19);  // 19 of 20 at or below it
}

TEST(Eval, RigidlyMovedCopyHasZeroAteAndRpe) {
  const Trajectory gt = wavy();
  Trajectory est;
  const CPose3D T(3.0, -2.0, 1.0, 1.0, 0.4, -0.3);
  for (const auto& p : gt) est.push_back({p.timestamp + 0.005, T + p.pose});  // also a small time offset
  const AteResult ate = computeAte(gt, est);
  ASSERT_TRUE(ate.success);
  EXPECT_EQ(ate.trans.count, 300u);
  EXPECT_LT(ate.trans.rmse, 1e-9);
  EXPECT_LT(ate.trans.max, 1e-9);
  // The alignment recovers T^-1.
  EXPECT_LT(((ate.alignment + T).asVectorVal()).norm(), 1e-8);
  const RpeResult rpe = computeRpe(gt, est, 1.0);
  ASSERT_TRUE(rpe.success);
  EXPECT_LT(rpe.trans.max, 1e-9);
  EXPECT_LT(rpe.rot_deg.max, 1e-5);
  // Pairs 1 s apart: 300 poses, those whose partner is past the end (or is the last pose) dropped.
  EXPECT_EQ(rpe.trans.count, 300u - 31u);
}

TEST(Eval, ConstantDriftGivesKnownRpe) {
  // Ground truth: 1 m/s along x. Estimate: 1.1 m/s and an extra yaw of 2 deg/s, both at 30 Hz.
  Trajectory gt, est;
  const double yaw_rate = 2.0 * M_PI / 180.0;
  CPose3D e;
  for (int i = 0; i < 200; ++i) {
    const double t = i / 30.0;
    gt.push_back({t, CPose3D(t, 0, 0, 0, 0, 0)});
    if (i > 0) e = e + CPose3D(1.1 / 30.0, 0, 0, yaw_rate / 30.0, 0, 0);
    est.push_back({t, e});
  }
  const RpeResult r = computeRpe(gt, est, 1.0);
  ASSERT_TRUE(r.success);
  // Over 1 s the estimated relative motion is 30 steps of (1.1/30 m forward, turn 2/30 deg): the error is
  // that relative pose composed with the inverse of (1 m, 0 deg): rotation exactly 2 deg, translation
  // |p_est - R_est * (1,0,0)| computed here by composing the steps by hand.
  double x = 0, y = 0, th = 0;
  for (int k = 0; k < 30; ++k) {
    x += 1.1 / 30.0 * std::cos(th);
    y += 1.1 / 30.0 * std::sin(th);
    th += yaw_rate / 30.0;
  }
  const double ex = x - std::cos(th), ey = y - std::sin(th);
  const double expect_t = std::hypot(ex, ey);
  EXPECT_NEAR(r.trans.mean, expect_t, 1e-9);
  EXPECT_NEAR(r.trans.std, 0.0, 1e-9);
  EXPECT_NEAR(r.rot_deg.mean, 2.0, 1e-6);
  EXPECT_NEAR(r.rot_deg.max, 2.0, 1e-6);
  EXPECT_NEAR(expect_t, 0.1, 0.02);  // sanity: about the 0.1 m/s speed drift
}

// A pose is never its own partner: over a gap (frames lost or skipped) or a delta shorter than half a
// frame the nearest pose to t + delta is the pose itself, and the pair scored 0 m and 0 deg.
TEST(Eval, RpeNeverPairsAPoseWithItself) {
  const Trajectory gt = wavy();
  Trajectory est;
  for (std::size_t i = 0; i < gt.size(); ++i) {
    if (i >= 100 && i < 104) continue;  // four frames missing: 133 ms without a pose
    // A drift of 1 cm a frame in the world's z: every pair of poses a frame or more apart is off by 1 cm or more.
    est.push_back({gt[i].timestamp, CPose3D(gt[i].pose.x(), gt[i].pose.y(), gt[i].pose.z() + 0.01 * double(i),
                                            gt[i].pose.yaw(), gt[i].pose.pitch(), gt[i].pose.roll())});
  }
  const RpeResult r = computeRpe(gt, est, 0.05);
  ASSERT_TRUE(r.success) << r.message;
  for (std::size_t k = 0; k < r.trans_errors.size(); ++k)
    EXPECT_GT(r.trans_errors[k], 0.009) << "the pair at " << r.times[k] << " s";
  // Every pose but the one before the gap and the two whose partner is the last pose.
  EXPECT_EQ(r.trans_errors.size(), est.size() - 3);
  const RpeResult too_short = computeRpe(gt, est, 0.01);
  EXPECT_FALSE(too_short.success) << too_short.trans.count << " pairs under half a frame apart";
  EXPECT_EQ(too_short.message, "no pose pairs 0.01 s apart with ground truth (sequence too short?)");
  EXPECT_EQ(computeRpe(gt, est, 1e-300).message, "no pose pairs 1e-300 s apart with ground truth (sequence too short?)");
}

TEST(Eval, NoiseOfKnownMagnitude) {
  // Every estimated position displaced by exactly 5 cm in alternating +-z: after the (rigid) alignment
  // the offsets cancel on average, so every error is 5 cm and RMSE = mean = 0.05.
  const Trajectory gt = wavy();
  Trajectory est = gt;
  for (std::size_t i = 0; i < est.size(); ++i) {
    const double s = (i % 2) ? 0.05 : -0.05;
    est[i].pose = CPose3D(est[i].pose.x(), est[i].pose.y(), est[i].pose.z() + s, est[i].pose.yaw(), est[i].pose.pitch(),
                          est[i].pose.roll());
  }
  const AteResult ate = computeAte(gt, est);
  ASSERT_TRUE(ate.success);
  EXPECT_NEAR(ate.trans.rmse, 0.05, 1e-3);
  EXPECT_NEAR(ate.trans.median, 0.05, 1e-3);
  EXPECT_NEAR(ate.trans.std, 0.0, 1e-3);
}

// Neither trajectory needs its stamps in order (a rawlog's come as recorded): swapped neighbours lost
// a pair (the search for gt's stamp among the estimate's stopped at the later one) and RPE paired wrongly.
TEST(Eval, StampsOutOfOrderAreMatchedAsSorted) {
  const Trajectory gt = wavy();
  Trajectory est = gt;
  for (auto& p : est) p.pose = CPose3D(p.pose.x() + 0.01 * std::sin(7 * p.timestamp), p.pose.y(), p.pose.z(), p.pose.yaw(),
                                       p.pose.pitch(), p.pose.roll());
  Trajectory shuffled = est, gt_shuffled = gt;
  for (std::size_t i = 10; i + 1 < shuffled.size(); i += 37) std::swap(shuffled[i], shuffled[i + 1]);
  for (std::size_t i = 5; i + 1 < gt_shuffled.size(); i += 41) std::swap(gt_shuffled[i], gt_shuffled[i + 1]);
  const auto pairs = associateTrajectories(gt_shuffled, shuffled);
  ASSERT_EQ(pairs.size(), gt.size());
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    EXPECT_EQ(gt_shuffled[pairs[k].first].timestamp, shuffled[pairs[k].second].timestamp);
    if (k) {
      EXPECT_LT(gt_shuffled[pairs[k - 1].first].timestamp, gt_shuffled[pairs[k].first].timestamp) << "in time order";
    }
  }
  const AteResult sorted_ate = computeAte(gt, est), ate = computeAte(gt_shuffled, shuffled);
  ASSERT_TRUE(ate.success);
  EXPECT_NEAR(ate.trans.rmse, sorted_ate.trans.rmse, 1e-12);
  const RpeResult sorted_rpe = computeRpe(gt, est, 0.05), rpe = computeRpe(gt_shuffled, shuffled, 0.05);
  ASSERT_TRUE(rpe.success);
  EXPECT_EQ(rpe.trans.count, sorted_rpe.trans.count);
  EXPECT_NEAR(rpe.trans.rmse, sorted_rpe.trans.rmse, 1e-12);
}

// Too few poses to align: the message says which trajectory is short, and rgbd-eval names that file.
TEST(Eval, TooFewPosesNamesTheShortTrajectory) {
  const Trajectory est = wavy();
  const Trajectory gt(est.begin(), est.begin() + 2);
  EXPECT_EQ(computeAte(gt, est).message, "only 2 poses associated within 0.02 s (need 3; the ground truth has 2)");
  EXPECT_EQ(computeAte(est, gt, 1e-7).message, "only 2 poses associated within 1e-07 s (need 3; the estimate has 2)");
  const std::string dir = test::tempDir("eval_short_gt");
  writeTumTrajectory(dir + "/gt.txt", gt);
  writeTumTrajectory(dir + "/est.txt", est);
  std::string log;
  EXPECT_EQ(test::run(test::app("rgbd-eval") + " " + dir + "/gt.txt " + dir + "/est.txt 2>&1", &log), 2);
  EXPECT_EQ(log.rfind("rgbd-eval: error: " + dir + "/gt.txt: only 2 poses", 0), 0u) << log;
}

// Stamps that never meet: the message gives both spans, and a power of 1000 between them is named as
// another unit (ROS 2 and EuRoC write nanoseconds: "do the timestamps match?" alone left the user to find it).
TEST(Eval, StampsThatNeverMeetAreShownWithTheirUnit) {
  const Trajectory gt = wavy(1305031002.0);  // from 1305031102 s
  Trajectory nanoseconds = gt, elsewhere = gt;
  for (auto& p : nanoseconds) p.timestamp *= 1e9;
  for (auto& p : elsewhere) p.timestamp += 100.0;
  const std::string ns = computeAte(gt, nanoseconds).message, later = computeAte(gt, elsewhere).message;
  EXPECT_EQ(ns.rfind("only 0 poses associated within 0.02 s (need 3; do the timestamps match?: the ground truth's run from 1305031102 to ", 0), 0u) << ns;
  EXPECT_NE(ns.find(", the estimate's from 1.305031102e+18 to "), std::string::npos) << ns;
  EXPECT_NE(ns.find("(the estimate's in nanoseconds?))"), std::string::npos) << ns;
  EXPECT_NE(computeAte(nanoseconds, gt).message.find("(the ground truth's in nanoseconds?))"), std::string::npos);
  EXPECT_NE(later.find("the estimate's from 1305031202 to "), std::string::npos) << later;
  EXPECT_EQ(later.find("seconds?"), std::string::npos) << later;
  // A clock from 0 (a simulator's) against the same in milliseconds: told by the ends.
  Trajectory from_zero = gt, milliseconds;
  for (auto& p : from_zero) p.timestamp -= gt.front().timestamp;
  milliseconds = from_zero;
  for (auto& p : milliseconds) p.timestamp *= 1e3;
  const std::string ms = computeAte(from_zero, milliseconds).message;
  EXPECT_NE(ms.find("(the estimate's in milliseconds?))"), std::string::npos) << ms;
}

// A stamp written twice (a recording whose clock repeated one) is one pose, the last, as TUM's scripts
// read a file into a dict by stamp: both were associated (the copy with another ground-truth pose
// within 20 ms) and counted, and rgbd-eval says so.
TEST(Eval, ARepeatedStampIsOnePoseTheLast) {
  const Trajectory gt = wavy(), est = wavy();
  Trajectory repeated = est;
  repeated.insert(repeated.begin() + 51, {est[50].timestamp, mrpt::poses::CPose3D(9, 9, 9, 0, 0, 0)});
  std::swap(repeated[50], repeated[51]);  // the odd pose first, the right one last
  const AteResult a = computeAte(gt, est), b = computeAte(gt, repeated);
  ASSERT_TRUE(b.success) << b.message;
  EXPECT_EQ(b.trans.count, a.trans.count);
  EXPECT_NEAR(b.trans.rmse, a.trans.rmse, 1e-12);
  const RpeResult ra = computeRpe(gt, est, 0.05), rb = computeRpe(gt, repeated, 0.05);
  EXPECT_EQ(rb.trans.count, ra.trans.count);
  EXPECT_NEAR(rb.trans.rmse, ra.trans.rmse, 1e-12);
  EXPECT_EQ(onePosePerStamp(repeated).size(), est.size());
  const std::string dir = test::tempDir("eval_repeated_stamp");
  writeTumTrajectory(dir + "/gt.txt", gt);
  writeTumTrajectory(dir + "/est.txt", repeated);
  std::string log;
  EXPECT_EQ(test::run("{ " + test::app("rgbd-eval") + " " + dir + "/gt.txt " + dir + "/est.txt 2>&1 >/dev/null; }", &log), 0);
  EXPECT_EQ(log, "warning: " + dir + "/est.txt: 1 pose repeats an earlier pose's stamp: the last pose of each stamp is "
                 "evaluated, as TUM's scripts read the file\n");
}

TEST(Eval, AssociationTolerance) {
  const Trajectory gt = wavy();
  const Trajectory late = wavy(0.5);  // 0.5 s off: only overlapping stamps 1/30 s grid -> none within 0.02
  Trajectory sparse, shifted;  // 10 Hz, so a 0.021 s shift is nearer its own stamp than any other
  for (std::size_t i = 0; i < gt.size(); i += 3) sparse.push_back(gt[i]);
  shifted = sparse;
  for (auto& p : shifted) p.timestamp += 0.021;
  EXPECT_FALSE(computeAte(sparse, shifted, 0.02).success);
  EXPECT_EQ(computeAte(sparse, shifted, 0.03).trans.count, sparse.size());
  EXPECT_EQ(associateTrajectories(gt, late, 0.02).size(), 285u);  // 0.5 s = 15 frames of overlap lost
  // A gap of exactly max_dt is no pair, as associate.py's "< max_difference" has it (dyadic stamps:
  // the difference is exact).
  Trajectory one = {sparse.front()}, at_limit = one;
  one.front().timestamp = 0.5;
  at_limit.front().timestamp = 0.5 + 0.015625;
  EXPECT_TRUE(associateTrajectories(one, at_limit, 0.015625).empty());
  EXPECT_EQ(associateTrajectories(one, at_limit, 0.016).size(), 1u);
}

// A path drawn without ground truth lists no "ground truth" in its legend: the first entry's swatch
// (legend at the plot box's corner, 90 + 8, 50 + 8) is the estimate's blue, not black.
TEST(Eval, APathWithoutGroundTruthHasNoGroundTruthInItsLegend) {
  const std::string dir = test::tempDir("eval_plot_no_gt");
  plotTrajectoriesOverlay(dir + "/o.png", {}, {{"estimate", wavy()}}, "path");
  const cv::Mat img = cv::imread(dir + "/o.png");
  ASSERT_FALSE(img.empty());
  const cv::Vec3b swatch = img.at<cv::Vec3b>(58 + 12, 98 + 20);
  EXPECT_GT(int(swatch[0]), 150) << "blue channel";  // BGR
  EXPECT_LT(int(swatch[2]), 150) << "red channel";
}

// A path of one pose (a run that tracked one frame) shows as a dot where it starts: its plot was empty.
TEST(Eval, APathOfOnePoseShows) {
  const std::string dir = test::tempDir("eval_plot_one_pose");
  const Trajectory one = {wavy().front()};
  plotTrajectoriesOverlay(dir + "/o.png", {}, {{"estimate", one}}, "path");
  const cv::Mat img = cv::imread(dir + "/o.png");
  ASSERT_FALSE(img.empty());
  const cv::Mat plot = img(cv::Rect(90, 120, 580, 510));  // the plot box below the legend
  cv::Mat blue;
  cv::inRange(plot, cv::Scalar(150, 0, 0), cv::Scalar(255, 120, 120), blue);
  EXPECT_GT(cv::countNonZero(blue), 10);
}

// Samples either side of a gap (frames lost, a blackout) are not joined: a line drew a smooth ramp
// over the error plot's gap and a chord across the top view's.
TEST(Eval, PlotsLeaveGapsOpen) {
  const std::string dir = test::tempDir("eval_plot_gaps");
  std::vector<double> times, errors;
  for (int i = 0; i < 20; ++i) times.push_back(0.1 * i), errors.push_back(0.01);
  for (int i = 0; i < 20; ++i) times.push_back(5.0 + 0.1 * i), errors.push_back(0.01);
  plotErrorOverTime(dir + "/e.png", times, errors, "err");
  cv::Mat img = cv::imread(dir + "/e.png");
  ASSERT_FALSE(img.empty());
  // The plot box is x 90..870 over t 0..6.9 (5 % margins); the column at t = 3.5 s, in the gap.
  const int gap_x = 90 + int(780 * (0.05 * 6.9 + 3.5) / (1.1 * 6.9)), ok_x = 90 + int(780 * (0.05 * 6.9 + 1.0) / (1.1 * 6.9));
  const auto redIn = [&](int x, int width = 1) {
    cv::Mat red;
    cv::inRange(img(cv::Rect(x, 50, width, 580)), cv::Scalar(0, 0, 150), cv::Scalar(120, 120, 255), red);
    return cv::countNonZero(red);
  };
  EXPECT_GT(redIn(ok_x), 0) << "the line where there are samples";
  EXPECT_EQ(redIn(gap_x), 0) << "a line across the gap";
  // A sample alone between two gaps shows, as a dot.
  std::vector<double> lone_t = times, lone_e = errors;
  lone_t.insert(lone_t.begin() + 20, 3.5), lone_e.insert(lone_e.begin() + 20, 0.01);
  plotErrorOverTime(dir + "/lone.png", lone_t, lone_e, "err");
  img = cv::imread(dir + "/lone.png");
  EXPECT_GT(redIn(gap_x - 40, 80), 0) << "the sample at 3.5 s, alone";
  img = cv::imread(dir + "/e.png");
  EXPECT_EQ(redIn(gap_x - 40, 80), 0) << "the same columns without it";
  // The top view: a straight walk along x with the same gap; no blue at its middle.
  Trajectory walk;
  for (double t : times) walk.push_back({t, CPose3D(t, 0.1 * std::sin(t), 0, 0, 0, 0)});
  plotTrajectoriesOverlay(dir + "/o.png", {}, {{"estimate", walk}}, "path");
  img = cv::imread(dir + "/o.png");
  ASSERT_FALSE(img.empty());
  cv::Mat blue;
  const int mid = 90 + 290;  // x = 3.45 m at the box's centre (equal aspect, centred)
  cv::inRange(img(cv::Rect(mid - 20, 50, 40, 580)), cv::Scalar(150, 0, 0), cv::Scalar(255, 120, 120), blue);
  EXPECT_EQ(cv::countNonZero(blue), 0) << "a chord across the gap";
  cv::inRange(img(cv::Rect(90 + 60, 50, 40, 580)), cv::Scalar(150, 0, 0), cv::Scalar(255, 120, 120), blue);
  EXPECT_GT(cv::countNonZero(blue), 0) << "the path where there are poses";
}

TEST(Eval, PlotsAreWritten) {
  const std::string dir = test::tempDir("eval_plots");
  const Trajectory gt = wavy();
  Trajectory est = gt;
  for (auto& p : est) p.pose = CPose3D(0.02, 0, 0, 0.01, 0, 0) + p.pose;
  const AteResult ate = computeAte(gt, est);
  plotAteReport(dir + "/r.png", ate, "test");
  plotTrajectoryTopView(dir + "/t.png", ate.gt, ate.est_aligned, "top");
  plotErrorOverTime(dir + "/e.png", ate.times, ate.errors, "err");
  plotTrajectoriesOverlay(dir + "/o.png", gt, {{"a", est}, {"b", gt}}, "modes");
  for (const char* f : {"r.png", "t.png", "e.png", "o.png"}) {
    const cv::Mat img = cv::imread(dir + "/" + f);
    ASSERT_FALSE(img.empty()) << f;
    // Something was drawn in colour (trajectories, error curves): the frame, grid, ticks and labels are
    // black and grey, so dark or light pixels alone are no plot.
    cv::Mat hsv, coloured;
    cv::cvtColor(img, hsv, cv::COLOR_BGR2HSV);
    cv::inRange(hsv, cv::Scalar(0, 100, 60), cv::Scalar(180, 255, 255), coloured);
    EXPECT_GT(cv::countNonZero(coloured), 300) << f;
  }
  EXPECT_EQ(cv::imread(dir + "/r.png").cols, 1600);
}
