#include "vofusion/loop/pose_graph.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include <Eigen/Cholesky>
#include <ceres/ceres.h>
#include <ceres/rotation.h>

namespace vofusion::loop {

namespace {
// An edge's residual at the current poses: translation and rotation vector of measurement^-1 * from^-1
// * to (SE(3)'s pseudo-logarithm, in the coordinates its information is given in), whitened by the
// edge's information (its Cholesky factor), so its squared norm is the edge's chi2. Ceres minimises
// it; updateChi2 evaluates it.
struct EdgeResidual {
  explicit EdgeResidual(const GraphEdge& e)
      : measured_t(e.T_from_to.translation()), measured_q(Eigen::Quaterniond(e.T_from_to.linear()).normalized()),
        whiten(Eigen::LLT<Matrix6>(e.information).matrixU()) {}

  template <typename T>
  bool operator()(const T* t_from, const T* q_from, const T* t_to, const T* q_to, T* out) const {
    using Vec3 = Eigen::Matrix<T, 3, 1>;
    const Eigen::Map<const Vec3> pa(t_from), pb(t_to);
    const Eigen::Map<const Eigen::Quaternion<T>> qa(q_from), qb(q_to);
    const Eigen::Quaternion<T> qm_inv = measured_q.conjugate().template cast<T>();
    const Eigen::Quaternion<T> qd = qm_inv * (qa.conjugate() * qb);
    const Vec3 pd = qm_inv * (qa.conjugate() * (pb - pa) - measured_t.template cast<T>());
    const T qd_wxyz[4] = {qd.w(), qd.x(), qd.y(), qd.z()};
    T rotation[3];
    ceres::QuaternionToAngleAxis(qd_wxyz, rotation);
    Eigen::Matrix<T, 6, 1> r;
    r << pd, rotation[0], rotation[1], rotation[2];
    Eigen::Map<Eigen::Matrix<T, 6, 1>> whitened(out);
    whitened = whiten.template cast<T>() * r;
    return true;
  }

  Eigen::Vector3d measured_t;
  Eigen::Quaterniond measured_q;
  Matrix6 whiten;
};
}  // namespace

Matrix6 odometryInformation(const Eigen::Isometry3d& T, double rate, double floor) {
  const double moved = T.translation().norm(), turned = Eigen::AngleAxisd(T.linear()).angle();
  const double st = floor + rate * (moved + turned), sr = floor + rate * (turned + moved);
  Matrix6 I = Matrix6::Zero();
  for (int i = 0; i < 3; ++i) I(i, i) = 1.0 / (st * st), I(i + 3, i + 3) = 1.0 / (sr * sr);
  return I;
}

std::size_t PoseGraph::addNode(const Eigen::Isometry3d& initial) {
  nodes_.push_back(initial);
  return nodes_.size() - 1;
}

std::size_t PoseGraph::addEdge(const GraphEdge& e) {
  edges_.push_back(e);
  return edges_.size() - 1;
}

void PoseGraph::chainNewNode(std::size_t node) {
  // From the newest edge back: the new node's tracker edge is the last one added (from the first, each
  // keyframe read the whole graph's edges).
  for (auto it = edges_.rbegin(); it != edges_.rend(); ++it)
    if (const GraphEdge& e = *it; !e.loop && e.to == node && e.from < node) {
      nodes_[node] = nodes_[e.from] * e.T_from_to;
      return;
    }
}

void PoseGraph::solve() {
  // Each node: its camera centre and orientation (Eigen's x, y, z, w), kept unit by the manifold.
  std::vector<std::array<double, 3>> t(nodes_.size());
  std::vector<std::array<double, 4>> q(nodes_.size());
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    Eigen::Map<Eigen::Vector3d>(t[i].data()) = nodes_[i].translation();
    Eigen::Map<Eigen::Quaterniond>(q[i].data()) = Eigen::Quaterniond(nodes_[i].linear()).normalized();
  }
  ceres::Problem problem;
  for (const GraphEdge& e : edges_) {
    if (!e.active) continue;
    auto* cost = new ceres::AutoDiffCostFunction<EdgeResidual, 6, 3, 4, 3, 4>(new EdgeResidual(e));
    problem.AddResidualBlock(cost, nullptr, t[e.from].data(), q[e.from].data(), t[e.to].data(), q[e.to].data());
  }
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    if (!problem.HasParameterBlock(t[i].data())) continue;
    problem.SetManifold(q[i].data(), new ceres::EigenQuaternionManifold);
    if (i == 0) problem.SetParameterBlockConstant(t[i].data()), problem.SetParameterBlockConstant(q[i].data());
  }
  ceres::Solver::Options options;
  options.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  options.max_num_iterations = 100;
  options.function_tolerance = 1e-12;
  options.gradient_tolerance = 1e-14;
  options.parameter_tolerance = 1e-12;
  options.num_threads = 1;  // the loop thread's own; the frame loop has the other core
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);
  if (!summary.IsSolutionUsable()) return;  // a residual that is no number: the poses stay as they were
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    if (i == 0 || !problem.HasParameterBlock(t[i].data())) continue;
    nodes_[i].linear() = Eigen::Map<const Eigen::Quaterniond>(q[i].data()).normalized().toRotationMatrix();
    nodes_[i].translation() = Eigen::Map<const Eigen::Vector3d>(t[i].data());
  }
}

void PoseGraph::updateChi2() {
  for (GraphEdge& e : edges_) {
    const Eigen::Vector3d ta = nodes_[e.from].translation(), tb = nodes_[e.to].translation();
    const Eigen::Quaterniond qa(nodes_[e.from].linear()), qb(nodes_[e.to].linear());  // coeffs: x, y, z, w
    Eigen::Matrix<double, 6, 1> whitened;
    const EdgeResidual edge(e);
    edge(ta.data(), qa.coeffs().data(), tb.data(), qb.coeffs().data(), whitened.data());
    e.chi2 = whitened.squaredNorm();
  }
}

namespace {
// A loop's chi2 that is no number (an edge of NaNs) is the worst there is: it lost every comparison,
// and the true loop beside it went instead.
double badness(double chi2) { return std::isnan(chi2) ? std::numeric_limits<double>::infinity() : chi2; }
}  // namespace

double PoseGraph::misfit(double max_loop_chi2, double max_chain_chi2) const {
  // A false loop shows either in its own residual or, when it is trusted more than the chain, in the
  // chain it bent: a tracker edge far beyond its noise. (A chain edge's NaN is left out, as before: it
  // would remove every loop.)
  double worst = 0.0;
  for (const GraphEdge& e : edges_) {
    if (!e.active) continue;
    if (e.loop) worst = std::max(worst, badness(e.chi2) / max_loop_chi2);
    else if (e.chi2 > 0) worst = std::max(worst, e.chi2 / max_chain_chi2);
  }
  return worst;
}

std::vector<std::size_t> PoseGraph::optimise(double max_loop_chi2, double max_chain_chi2) {
  std::vector<std::size_t> removed;
  const std::vector<Eigen::Isometry3d> start = nodes_;
  const auto solveFromStart = [&] {
    nodes_ = start;
    solve();
    updateChi2();
    return misfit(max_loop_chi2, max_chain_chi2);
  };
  for (double now = solveFromStart(); now > 1.0;) {
    // The suspects: the active loops of largest chi2. The one that goes is the one whose removal leaves
    // the graph most consistent (ties: the larger chi2). A loop's own chi2 is its conflict over its
    // certainty, so a crisp false loop scored below the less certain true loop it conflicted with,
    // and the true loop went (tests: ATrueLoopIsNotDroppedForACrisperFalseOne).
    std::vector<std::size_t> suspects;
    for (std::size_t i = 0; i < edges_.size(); ++i)
      if (edges_[i].active && edges_[i].loop) suspects.push_back(i);
    if (suspects.empty()) break;
    std::stable_sort(suspects.begin(), suspects.end(),
                     [&](std::size_t a, std::size_t b) { return badness(edges_[a].chi2) > badness(edges_[b].chi2); });
    if (suspects.size() > kSuspects) suspects.resize(kSuspects);
    std::size_t drop = suspects.front();
    double best = std::numeric_limits<double>::infinity();
    for (const std::size_t i : suspects) {
      edges_[i].active = false;
      const double left = solveFromStart();
      edges_[i].active = true;
      if (left < best) best = left, drop = i;
    }
    edges_[drop].active = false;
    removed.push_back(drop);
    now = solveFromStart();
  }
  return removed;
}

std::vector<std::size_t> PoseGraph::optimiseAll(double max_loop_chi2, double max_chain_chi2) {
  for (GraphEdge& e : edges_) e.active = true;
  return optimise(max_loop_chi2, max_chain_chi2);
}

}  // namespace vofusion::loop
