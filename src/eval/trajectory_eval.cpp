#include "vofusion/eval/trajectory_eval.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <Eigen/Dense>
#include <Eigen/Geometry>

namespace vofusion {

namespace {
Eigen::Vector3d position(const mrpt::poses::CPose3D& p) { return {p.x(), p.y(), p.z()}; }

double rotationAngle(const mrpt::poses::CPose3D& p) {
  // atan2 keeps precision near zero, where acos((trace-1)/2) loses half the digits.
  const Eigen::Matrix3d R = p.getRotationMatrix().asEigen();
  const double c = (R.trace() - 1.0) / 2.0;
  const double s = 0.5 * Eigen::Vector3d(R(2, 1) - R(1, 2), R(0, 2) - R(2, 0), R(1, 0) - R(0, 1)).norm();
  return std::atan2(s, c);
}

// Index of the stamp in `stamps` (sorted) nearest to t.
std::size_t nearest(const std::vector<double>& stamps, double t) {
  auto it = std::lower_bound(stamps.begin(), stamps.end(), t);
  if (it == stamps.begin()) return 0;
  if (it == stamps.end()) return stamps.size() - 1;
  const std::size_t j = std::size_t(it - stamps.begin());
  return (t - stamps[j - 1] <= stamps[j] - t) ? j - 1 : j;
}

std::vector<double> stampsOf(const Trajectory& t) {
  std::vector<double> s;
  s.reserve(t.size());
  for (const auto& p : t) s.push_back(p.timestamp);
  return s;
}

// The indices of t in time order (equal stamps in index order). A trajectory is not always written
// sorted (a rawlog's stamps come as recorded), and the searches below need its stamps sorted.
std::vector<std::size_t> timeOrder(const Trajectory& t) {
  std::vector<std::size_t> order(t.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return t[a].timestamp < t[b].timestamp; });
  return order;
}

}  // namespace

ErrorStats computeStats(const std::vector<double>& e) {
  ErrorStats s;
  s.count = e.size();
  if (e.empty()) return s;
  double sum = 0, sum2 = 0;
  for (double v : e) sum += v, sum2 += v * v;
  s.mean = sum / e.size();
  s.rmse = std::sqrt(sum2 / e.size());
  s.std = std::sqrt(std::max(0.0, sum2 / e.size() - s.mean * s.mean));
  std::vector<double> sorted = e;
  std::sort(sorted.begin(), sorted.end());
  const std::size_t n = sorted.size();
  s.median = n % 2 ? sorted[n / 2] : 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]);
  s.p95 = sorted[std::size_t(std::ceil(0.95 * double(n))) - 1];
  s.min = sorted.front();
  s.max = sorted.back();
  return s;
}

std::vector<std::pair<std::size_t, std::size_t>> associateTrajectories(const Trajectory& gt, const Trajectory& est,
                                                                       double max_dt) {
  struct Cand { double dt; std::size_t i, j; };
  std::vector<Cand> cands;
  const std::vector<std::size_t> est_order = timeOrder(est);
  std::vector<double> es;
  es.reserve(est.size());
  for (const std::size_t j : est_order) es.push_back(est[j].timestamp);
  // Both in time order, so that ties in dt are taken in (gt stamp, est stamp) order, as associate.py's sort.
  for (const std::size_t i : timeOrder(gt)) {
    auto lo = std::lower_bound(es.begin(), es.end(), gt[i].timestamp - max_dt);
    for (auto it = lo; it != es.end() && *it <= gt[i].timestamp + max_dt; ++it)
      // Closer than max_dt, as TUM's associate.py has it (abs(a - b) < max_difference).
      if (const double dt = std::abs(*it - gt[i].timestamp); dt < max_dt) cands.push_back({dt, i, est_order[std::size_t(it - es.begin())]});
  }
  std::stable_sort(cands.begin(), cands.end(), [](const Cand& a, const Cand& b) { return a.dt < b.dt; });
  std::vector<char> used_g(gt.size(), 0), used_e(est.size(), 0);
  std::vector<std::pair<std::size_t, std::size_t>> out;
  for (const Cand& c : cands) {
    if (used_g[c.i] || used_e[c.j]) continue;
    used_g[c.i] = used_e[c.j] = 1;
    out.emplace_back(c.i, c.j);
  }
  // In ground-truth time order, as associate.py's matches (the plots join the pairs in this order).
  std::sort(out.begin(), out.end(), [&](const auto& a, const auto& b) {
    return std::pair(gt[a.first].timestamp, a.first) < std::pair(gt[b.first].timestamp, b.first);
  });
  return out;
}

namespace {
// What the two trajectories' stamps span, for a user whose stamps do not meet: another unit (ROS 2
// and EuRoC write nanoseconds), a recording's own clock against the benchmark's, another sequence.
std::string stampSpans(const Trajectory& gt, const Trajectory& est) {
  const auto span = [](const Trajectory& t) {
    const auto [lo, hi] = std::minmax_element(t.begin(), t.end(), [](const StampedPose& a, const StampedPose& b) {
      return a.timestamp < b.timestamp;
    });
    return std::pair(lo->timestamp, hi->timestamp);
  };
  const auto [g0, g1] = span(gt);
  const auto [e0, e1] = span(est);
  char text[160];
  std::snprintf(text, sizeof text, ": the ground truth's run from %.10g to %.10g, the estimate's from %.10g to %.10g", g0, g1, e0, e1);
  std::string said = text;
  // Starts a power of 1000 apart (within 1 %), or ends where a clock starts at 0 (a simulator's, a
  // relative one): the same clock in other units.
  const bool starts = g0 > 0 && e0 > 0;
  const double ratio = starts ? e0 / g0 : (g1 > 0 && e1 > 0 ? e1 / g1 : 1.0);
  for (const auto& [factor, unit] : {std::pair(1e3, "milli"), std::pair(1e6, "micro"), std::pair(1e9, "nano")}) {
    if (std::abs(ratio / factor - 1) < 0.01) said += std::string(" (the estimate's in ") + unit + "seconds?)";
    if (std::abs(1 / ratio / factor - 1) < 0.01) said += std::string(" (the ground truth's in ") + unit + "seconds?)";
  }
  return said;
}
}  // namespace

AteResult computeAte(const Trajectory& gt, const Trajectory& est_as_given, double max_dt) {
  const Trajectory est = onePosePerStamp(est_as_given);
  AteResult r;
  const auto pairs = associateTrajectories(gt, est, max_dt);
  if (pairs.size() < 3) {
    char within[32];
    std::snprintf(within, sizeof within, "%g", max_dt);  // 1e-7, not 0.000000
    r.message = "only " + std::to_string(pairs.size()) + " poses associated within " + within + " s (need 3; ";
    if (gt.size() < 3) r.message += "the ground truth has " + std::to_string(gt.size()) + ")";
    else if (est.size() < 3) r.message += "the estimate has " + std::to_string(est.size()) + ")";
    else r.message += "do the timestamps match?" + stampSpans(gt, est) + ")";
    return r;
  }
  Eigen::Matrix3Xd src(3, pairs.size()), dst(3, pairs.size());
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    src.col(k) = position(est[pairs[k].second].pose);
    dst.col(k) = position(gt[pairs[k].first].pose);
  }
  // Rigid alignment without scale (Horn's closed form; Umeyama's equals it with scaling off).
  const Eigen::Matrix4d T = Eigen::umeyama(src, dst, false);
  mrpt::math::CMatrixDouble44 M;
  M.asEigen() = T;
  r.alignment = mrpt::poses::CPose3D(M);
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    const StampedPose& g = gt[pairs[k].first];
    const mrpt::poses::CPose3D aligned = r.alignment + est[pairs[k].second].pose;
    r.gt.push_back(g);
    r.est_aligned.push_back({est[pairs[k].second].timestamp, aligned});
    r.times.push_back(g.timestamp);
    r.errors.push_back((position(aligned) - position(g.pose)).norm());
  }
  r.trans = computeStats(r.errors);
  r.success = true;
  return r;
}

RpeResult computeRpe(const Trajectory& gt_as_given, const Trajectory& est_as_given, double delta, double max_dt) {
  const Trajectory gt = sortedByTime(gt_as_given), est = sortedByTime(onePosePerStamp(est_as_given));
  RpeResult r;
  r.delta = delta;
  if (est.size() < 2 || gt.empty()) {
    r.message = "need at least 2 estimated and 1 ground-truth pose";
    return r;
  }
  const std::vector<double> es = stampsOf(est), gs = stampsOf(gt);
  for (std::size_t i = 0; i < est.size(); ++i) {
    const std::size_t j = nearest(es, es[i] + delta);
    if (j == est.size() - 1) continue;  // as evaluate_rpe.py: the partner ran off the end
    // Unlike evaluate_rpe.py, a pose is not its own partner (over a gap, or a delta under half a
    // frame), nor are two poses on one ground-truth pose: such a pair measures no motion and scored 0.
    if (j <= i) continue;
    const std::size_t g0 = nearest(gs, es[i]), g1 = nearest(gs, es[j]);
    if (g1 == g0) continue;
    if (std::abs(gs[g0] - es[i]) > max_dt || std::abs(gs[g1] - es[j]) > max_dt) continue;
    const mrpt::poses::CPose3D est_rel = est[j].pose - est[i].pose;  // est_i^-1 est_j
    const mrpt::poses::CPose3D gt_rel = gt[g1].pose - gt[g0].pose;
    mrpt::poses::CPose3D gt_rel_inv = gt_rel;
    gt_rel_inv.inverse();
    const mrpt::poses::CPose3D err = est_rel + gt_rel_inv;            // est_rel * gt_rel^-1, as the benchmark
    r.times.push_back(es[i]);
    r.trans_errors.push_back(position(err).norm());
    r.rot_errors_deg.push_back(rotationAngle(err) * 180.0 / M_PI);
  }
  if (r.trans_errors.empty()) {
    char apart[32];  // %g: to_string said 1e-300 s as "0.000000" and 1e308 in 309 digits
    std::snprintf(apart, sizeof apart, "%g", delta);
    r.message = std::string("no pose pairs ") + apart + " s apart with ground truth (sequence too short?)";
    return r;
  }
  r.trans = computeStats(r.trans_errors);
  r.rot_deg = computeStats(r.rot_errors_deg);
  r.success = true;
  return r;
}

}  // namespace vofusion
