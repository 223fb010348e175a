#include "vofusion/loop/pose_graph.h"

#include <algorithm>

#include <mrpt/graphs/CNetworkOfPoses.h>
#include <mrpt/graphslam/levmarq.h>
#include <mrpt/poses/CPose3D.h>

#include "vofusion/core/pose_eigen.h"
namespace vofusion::loop {

namespace {
// Residual of an edge at the current poses, in the coordinates MRPT's optimiser weighs it in:
// translation and rotation vector of measurement^-1 * estimate (SE(3)'s pseudo-logarithm).
Eigen::Matrix<double, 6, 1> residual(const GraphEdge& e, const std::vector<Eigen::Isometry3d>& nodes) {
  const Eigen::Isometry3d d = e.T_from_to.inverse() * nodes[e.from].inverse() * nodes[e.to];
  const Eigen::AngleAxisd a(d.linear());
  Eigen::Matrix<double, 6, 1> r;
  r << d.translation(), a.angle() * a.axis();
  return r;
}
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
  for (const GraphEdge& e : edges_)
    if (!e.loop && e.to == node && e.from < node) {
      nodes_[node] = nodes_[e.from] * e.T_from_to;
      return;
    }
}

void PoseGraph::runSpa() {
  mrpt::graphs::CNetworkOfPoses3DInf g;
  g.root = 0;
  for (std::size_t i = 0; i < nodes_.size(); ++i) g.nodes[i] = toMrpt(nodes_[i]);
  for (const GraphEdge& e : edges_) {
    if (!e.active) continue;
    mrpt::poses::CPose3DPDFGaussianInf m;
    m.mean = toMrpt(e.T_from_to);
    for (int i = 0; i < 6; ++i)
      for (int j = 0; j < 6; ++j) m.cov_inv(i, j) = e.information(i, j);
    g.insertEdge(e.from, e.to, m);
  }
  mrpt::graphslam::TResultInfoSpaLevMarq info;
  mrpt::containers::yaml params = mrpt::containers::yaml::Map();
  params["max_iterations"] = 100;
  mrpt::graphslam::optimize_graph_spa_levmarq(g, info, nullptr, params);
  for (std::size_t i = 0; i < nodes_.size(); ++i) nodes_[i] = toEigen(g.nodes.at(i));
}

void PoseGraph::updateChi2() {
  for (GraphEdge& e : edges_) {
    const auto r = residual(e, nodes_);
    e.chi2 = r.dot(e.information * r);
  }
}

std::vector<std::size_t> PoseGraph::optimise(double max_loop_chi2, double max_chain_chi2) {
  std::vector<std::size_t> removed;
  const std::vector<Eigen::Isometry3d> start = nodes_;
  for (;;) {
    runSpa();
    updateChi2();
    // A false loop shows either in its own residual or, when it is trusted more than the chain, in
    // the chain it bent: a tracker edge far beyond its noise. Either way the worst loop goes.
    double chain = 0.0;
    std::size_t worst = edges_.size();
    for (std::size_t i = 0; i < edges_.size(); ++i) {
      const GraphEdge& e = edges_[i];
      if (!e.active) continue;
      if (!e.loop) chain = std::max(chain, e.chi2);
      else if (worst == edges_.size() || e.chi2 > edges_[worst].chi2) worst = i;
    }
    if (worst == edges_.size() || (edges_[worst].chi2 <= max_loop_chi2 && chain <= max_chain_chi2)) return removed;
    // A false loop bent the map: drop it and start again from the poses before this optimisation.
    edges_[worst].active = false;
    removed.push_back(worst);
    nodes_ = start;
  }
}

std::vector<std::size_t> PoseGraph::optimiseAll(double max_loop_chi2, double max_chain_chi2) {
  for (GraphEdge& e : edges_) e.active = true;
  return optimise(max_loop_chi2, max_chain_chi2);
}

}  // namespace vofusion::loop
