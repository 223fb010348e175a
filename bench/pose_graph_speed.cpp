// bench/pose_graph_speed: CPU time of one PoseGraph::optimise as a loop edge comes in, against the
// graph's size: what the loop-closure thread spends per accepted loop on a long run (one keyframe per
// 0.15 m: a walk of an hour at 0.5 m/s makes ~12 000). The graph is a walk round a 60 m lap, lap after
// lap: tracker edges between consecutive keyframes (drifting by 1 % of the distance), and on every lap
// after the first a loop edge every 4th keyframe to the same place one lap before.
// A second column: the same with a false loop (2 m off, 3 mm) beside the new one, which the optimisation
// tries out among its suspects and removes.
//   pose_graph_speed [--sizes 500,1000,2000,5000,10000] [--repeat 3]
// Built by CMake as build/bin/pose_graph_speed (a benchmark, not a test: run it by hand).
#include <time.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "vofusion/core/cli.h"
#include "vofusion/loop/pose_graph.h"

using namespace vofusion;
using namespace vofusion::loop;

namespace {
double threadCpuMs() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return t.tv_sec * 1e3 + t.tv_nsec * 1e-6;
}

constexpr double kSpacing = 0.15;   // m between keyframes
constexpr int kLapKeyframes = 400;  // a 60 m lap
constexpr double kMaxLoopChi2 = 1000, kMaxChainChi2 = 100;  // the loop closer's (docs/loop-closure.md)

// The true pose of keyframe i: round a 20 x 10 m rectangle, facing along it.
Eigen::Isometry3d truePose(int i) {
  const double s = std::fmod(i * kSpacing, 60.0);
  double x, y, yaw;
  if (s < 20) x = s, y = 0, yaw = 0;
  else if (s < 30) x = 20, y = s - 20, yaw = M_PI / 2;
  else if (s < 50) x = 50 - s, y = 10, yaw = M_PI;
  else x = 0, y = 60 - s, yaw = -M_PI / 2;
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(x, y, 0);
  return T;
}

Matrix6 diagonalInformation(double sigma_t, double sigma_r) {
  Matrix6 I = Matrix6::Zero();
  I.diagonal() << Eigen::Vector3d::Constant(1 / (sigma_t * sigma_t)), Eigen::Vector3d::Constant(1 / (sigma_r * sigma_r));
  return I;
}

// A graph of n keyframes, optimised as the loop thread would have it; then the time of one more
// keyframe with a loop edge. false_loop: that loop is a look-alike 2 m off, as crisp as ICP's floor
// (3 mm), which the optimisation must find and remove (trying out each of its suspects).
double msPerLoop(int n, std::mt19937& rng, bool false_loop = false) {
  std::normal_distribution<double> noise(0, 1);
  PoseGraph g;
  Eigen::Isometry3d tracked = truePose(0);
  g.addNode(tracked);
  const auto addKeyframe = [&](int i) {
    Eigen::Isometry3d step = truePose(i - 1).inverse() * truePose(i);
    step.translation() += 0.01 * kSpacing * Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
    step.linear() = step.linear() * Eigen::AngleAxisd(0.002 * noise(rng), Eigen::Vector3d::UnitZ()).toRotationMatrix();
    tracked = tracked * step;
    g.addNode(tracked);
    GraphEdge e;
    e.from = std::size_t(i - 1), e.to = std::size_t(i), e.T_from_to = step;
    e.information = odometryInformation(step, 0.02, 0.002);
    g.addEdge(e);
    if (i >= kLapKeyframes && i % 4 == 0) {
      GraphEdge l;
      l.from = std::size_t(i - kLapKeyframes), l.to = std::size_t(i), l.loop = true;
      l.T_from_to = truePose(i - kLapKeyframes).inverse() * truePose(i);
      l.information = diagonalInformation(0.01, 0.5 * M_PI / 180);
      g.addEdge(l);
      return true;
    }
    return false;
  };
  for (int i = 1; i < n; ++i)
    if (addKeyframe(i) && (i % 64 == 0 || i + 64 >= n)) g.optimise(kMaxLoopChi2, kMaxChainChi2);  // warm, as it went
  int i = n;
  while (!addKeyframe(i)) ++i;  // the next keyframe that closes a loop
  g.chainNewNode(std::size_t(i));
  if (false_loop) {
    GraphEdge l = g.edges().back();
    l.T_from_to = l.T_from_to * Eigen::Translation3d(2.0, 0, 0);
    l.information = diagonalInformation(0.003, 0.003);
    g.addEdge(l);
  }
  const double t0 = threadCpuMs();
  const std::vector<std::size_t> removed = g.optimise(kMaxLoopChi2, kMaxChainChi2);
  const double ms = threadCpuMs() - t0;
  if (false_loop && (removed.size() != 1 || removed[0] != g.edges().size() - 1))
    throw std::runtime_error(std::to_string(n) + " keyframes: the false loop was not the one removed");
  return ms;
}
}  // namespace

int main(int argc, char** argv) {
  try {
    const CommandLine cl(argc, argv, {"--sizes", "--repeat"}, {});
    std::vector<int> sizes;
    std::stringstream list(cl.value("--sizes", std::string("500,1000,2000,5000,10000")));
    for (std::string s; std::getline(list, s, ',');) sizes.push_back(std::stoi(s));
    const int repeat = int(cl.count("--repeat", 3, 1));
    std::printf("| keyframes | ms of CPU per accepted loop (median of %d) | the same with a false loop beside it, removed |\n"
                "|---:|---:|---:|\n",
                repeat);
    std::mt19937 rng(1);
    for (const int n : sizes) {
      std::vector<double> ms, with_false;
      for (int r = 0; r < repeat; ++r) ms.push_back(msPerLoop(n, rng)), with_false.push_back(msPerLoop(n, rng, true));
      std::sort(ms.begin(), ms.end());
      std::sort(with_false.begin(), with_false.end());
      std::printf("| %d | %.1f | %.1f |\n", n, ms[ms.size() / 2], with_false[with_false.size() / 2]);
      std::fflush(stdout);
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "pose_graph_speed: %s\n", e.what());
    return 2;
  }
}
