#include "vofusion/core/trajectory.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <unordered_map>

#include <Eigen/Dense>
#include <mrpt/math/CQuaternion.h>
#include <mrpt/poses/CPose3DQuat.h>
#include <mrpt/poses/Lie/SE.h>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/text_file.h"

namespace vofusion {

Trajectory parseTumTrajectory(const std::string& text, const std::string& origin, StampOrder order) {
  Trajectory traj;
  std::vector<std::size_t> line_of;  // each pose's line, for the order's message
  for (const auto& [n, text_line] : dataLines(text)) {
    std::string line = text_line;
    std::replace(line.begin(), line.end(), ',', ' ');  // TUM's tools read comma-separated files too
    std::istringstream ls(line);
    double v[8];
    for (double& x : v) {
      // from_chars, not >>: it reads nan and inf, which are then named (>> failed on them as on a missing
      // field), and it reads no locale's decimal comma.
      std::string field;
      if (!(ls >> field))
        throw InputError(origin, "line " + std::to_string(n) + ": expected 'timestamp tx ty tz qx qy qz qw'");
      const char* first = field.c_str() + (field[0] == '+' && field.size() > 1);
      const auto [end, ec] = std::from_chars(first, field.c_str() + field.size(), x);
      if (ec == std::errc::result_out_of_range) x = std::strtod(first, nullptr);  // 1e999: inf, 1e-999: 0
      else if (ec != std::errc() || end != field.c_str() + field.size())
        throw InputError(origin, "line " + std::to_string(n) + ": expected 'timestamp tx ty tz qx qy qz qw'");
      if (!std::isfinite(x))
        throw InputError(origin, "line " + std::to_string(n) + ": field " + std::to_string(&x - v + 1) + " ('" + field +
                                     "') is not a finite number");
    }
    std::string extra;
    if (ls >> extra) throw InputError(origin, "line " + std::to_string(n) + ": unexpected extra field '" + extra + "'");
    // A camera's path spans metres to kilometres. Beyond this, a value is no position (1e300 made
    // rgbd-eval's RMSE inf and its JSON invalid), and its square would leave double's range.
    constexpr double kFarthest = 1e7;  // m
    if (std::abs(v[1]) > kFarthest || std::abs(v[2]) > kFarthest || std::abs(v[3]) > kFarthest)
      throw InputError(origin, "line " + std::to_string(n) + ": position beyond 10 000 km");
    const double qn = std::sqrt(v[4] * v[4] + v[5] * v[5] + v[6] * v[6] + v[7] * v[7]);
    if (std::abs(qn - 1.0) > 1e-2) {
      char norm[32];
      std::snprintf(norm, sizeof norm, "%.4g", qn);
      throw InputError(origin, "line " + std::to_string(n) + ": quaternion is not unit length (" + norm +
                                   "; a rotation's is 1 within 1 %)");
    }
    mrpt::math::CQuaternionDouble q(v[7] / qn, v[4] / qn, v[5] / qn, v[6] / qn);  // (w, x, y, z)
    traj.push_back({v[0], mrpt::poses::CPose3D(mrpt::poses::CPose3DQuat(v[1], v[2], v[3], q))});
    line_of.push_back(n);
  }
  for (std::size_t i = 1; i < traj.size() && order == StampOrder::Increasing; ++i)
    if (traj[i].timestamp <= traj[i - 1].timestamp)
      throw InputError(origin, "line " + std::to_string(line_of[i]) + ": timestamps are not strictly increasing (" +
                                   std::to_string(traj[i].timestamp) + " after " + std::to_string(traj[i - 1].timestamp) + ")");
  return traj;
}

Trajectory readTumTrajectory(const std::string& path, StampOrder order) {
  return parseTumTrajectory(readTextFile(path), path, order);
}

Trajectory sortedByTime(const Trajectory& t) {
  Trajectory s = t;
  std::stable_sort(s.begin(), s.end(), [](const StampedPose& a, const StampedPose& b) { return a.timestamp < b.timestamp; });
  return s;
}

Trajectory onePosePerStamp(const Trajectory& t) {
  std::unordered_map<double, std::size_t> last;
  for (std::size_t i = 0; i < t.size(); ++i) last[t[i].timestamp] = i;
  if (last.size() == t.size()) return t;
  Trajectory out;
  out.reserve(last.size());
  for (std::size_t i = 0; i < t.size(); ++i)
    if (last[t[i].timestamp] == i) out.push_back(t[i]);
  return out;
}

void writeTumTrajectory(const std::string& path, const Trajectory& traj) {
  std::string out = "# timestamp tx ty tz qx qy qz qw (camera-to-world)\n";
  char buf[256];
  for (const auto& p : traj) {
    const mrpt::poses::CPose3DQuat q(p.pose);
    // Stamps as TUM's lists give them (microseconds); the pose to 1e-9: at 6 decimals evaluate_ate.py on
    // this file gave summary.json's figures (computed from the poses in memory) to 4-5 digits only.
    std::snprintf(buf, sizeof buf, "%.6f %.9f %.9f %.9f %.9f %.9f %.9f %.9f\n", p.timestamp, q.x(), q.y(), q.z(),
                  q.quat().x(), q.quat().y(), q.quat().z(), q.quat().r());
    out += buf;
  }
  writeFileAtomically(path, out);
}

bool interpolatePose(const Trajectory& traj, double t, double max_gap, mrpt::poses::CPose3D& out) {
  if (traj.empty() || !std::isfinite(t)) return false;  // NaN passed every check below as the first pose
  auto it = std::lower_bound(traj.begin(), traj.end(), t,
                             [](const StampedPose& p, double v) { return p.timestamp < v; });
  const double held_within = std::min(max_gap, kHeldPoseWithin);
  if (it == traj.begin()) {
    if (it->timestamp - t > held_within) return false;
    out = it->pose;
    return true;
  }
  if (it == traj.end()) {
    if (t - traj.back().timestamp > held_within) return false;
    out = traj.back().pose;
    return true;
  }
  const StampedPose& a = *(it - 1);
  const StampedPose& b = *it;
  if (b.timestamp - a.timestamp > 2 * max_gap && std::min(t - a.timestamp, b.timestamp - t) > max_gap) return false;
  const double s = (t - a.timestamp) / (b.timestamp - a.timestamp);
  // Interpolate on the manifold: a * exp(s * log(a^-1 b)).
  const mrpt::poses::CPose3D rel = b.pose - a.pose;
  auto twist = mrpt::poses::Lie::SE<3>::log(rel);
  twist *= s;
  out = a.pose + mrpt::poses::Lie::SE<3>::exp(twist);
  return true;
}

}  // namespace vofusion
