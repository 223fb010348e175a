#pragma once
// The TUM RGB-D benchmark's trajectory metrics (Sturm et al. 2012, evaluate_ate.py / evaluate_rpe.py):
// ATE after a rigid (no scale) Horn/Umeyama alignment, and RPE over pose pairs `delta` seconds apart.
#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include <mrpt/poses/CPose3D.h>

#include "vofusion/core/trajectory.h"

namespace vofusion {

struct ErrorStats {
  std::size_t count = 0;
  double rmse = 0, mean = 0, median = 0, std = 0, min = 0, max = 0;  // std: population (numpy.std)
  double p95 = 0;  // 95th percentile, nearest rank (the smallest value with 95 % of the errors at or below it)
};
ErrorStats computeStats(const std::vector<double>& errors);

// Greedy nearest-timestamp matching as associate.py: pairs within max_dt, each stamp used once,
// in ground-truth time order. Returns (gt index, est index). Neither needs its stamps sorted.
std::vector<std::pair<std::size_t, std::size_t>> associateTrajectories(const Trajectory& gt, const Trajectory& est,
                                                                       double max_dt = 0.02);

struct AteResult {
  bool success = false;         // false if fewer than 3 associated poses (message says why)
  std::string message;
  ErrorStats trans;             // m, translational error after alignment
  std::vector<double> times;    // s, ground-truth stamps of the associated pairs
  std::vector<double> errors;   // m, per pair
  Trajectory gt;                // associated ground-truth poses
  Trajectory est_aligned;       // associated estimated poses, aligned onto the ground truth
  mrpt::poses::CPose3D alignment;  // est -> gt rigid transform
};
// Of estimated poses sharing a stamp, the last is evaluated (onePosePerStamp), as TUM's scripts read them.
AteResult computeAte(const Trajectory& gt, const Trajectory& est, double max_dt = 0.02);

struct RpeResult {
  bool success = false;
  std::string message;
  double delta = 1.0;           // s
  ErrorStats trans;             // m
  ErrorStats rot_deg;           // degrees
  std::vector<double> times;    // s, estimate stamp of each pair's first pose
  std::vector<double> trans_errors, rot_errors_deg;
};
// evaluate_rpe.py --fixed_delta --delta <delta> --delta_unit s: for each estimated pose i the pose j
// nearest to t_i + delta (pairs whose j is the last pose are dropped); ground-truth poses nearest to
// both stamps (within max_dt); error = (est_i^-1 est_j) (gt_i^-1 gt_j)^-1. Unlike the script, a pose
// is never its own partner (over a gap in the poses): such a pair, and two poses on one ground-truth
// pose, measure no motion and would score 0.
RpeResult computeRpe(const Trajectory& gt, const Trajectory& est, double delta = 1.0, double max_dt = 0.02);

// ---- Plots (PNG via OpenCV drawing, written atomically; throw InputError(png, ...) on failure)

// Top view on the two axes of largest ground-truth extent: ground truth, aligned estimate and the
// error vector between each associated pair; metre ticks, legend.
void plotTrajectoryTopView(const std::string& png, const Trajectory& gt, const Trajectory& est_aligned,
                           const std::string& title);
// Error (m) over time (s, from the first stamp).
void plotErrorOverTime(const std::string& png, const std::vector<double>& times, const std::vector<double>& errors,
                       const std::string& title, const std::string& y_label = "translational error [m]");
// Several labelled estimates (already aligned) over one ground truth, e.g. the pipeline's modes.
void plotTrajectoriesOverlay(const std::string& png, const Trajectory& gt,
                             const std::vector<std::pair<std::string, Trajectory>>& estimates,
                             const std::string& title);
// The ATE result as rgbd-eval --plot draws it: top view (left) and error over time (right) in one image.
void plotAteReport(const std::string& png, const AteResult& ate, const std::string& title);

}  // namespace vofusion
