#include "vofusion/loop/place_index.h"

#include <algorithm>
#include <cstdint>
#include <map>

#include <opencv2/flann.hpp>

namespace vofusion::loop {

namespace {
// At most n rows, spread evenly over the keyframe (the STAR keypoints come first, then NARF's).
cv::Mat spreadRows(const cv::Mat& d, int n) {
  if (d.rows <= n) return d;
  cv::Mat out(n, d.cols, d.type());
  for (int i = 0; i < n; ++i) d.row(int(std::int64_t(i) * d.rows / n)).copyTo(out.row(i));
  return out;
}
}  // namespace

PlaceIndex::PlaceIndex(const LoopParams& params)
    : params_(params),
      matcher_(cv::makePtr<cv::flann::LshIndexParams>(params.lsh_tables, params.lsh_key_bits, params.lsh_probe_level)) {}

void PlaceIndex::add(std::size_t keyframe, const cv::Mat& descriptors) {
  if (descriptors.empty()) return;
  keyframes_.push_back(keyframe);
  pending_.push_back(spreadRows(descriptors, params_.place_descriptors).clone());
  if (pending_.size() < kBatch) return;
  matcher_.add(pending_);
  matcher_.train();  // rebuilds the whole index (hashing only)
  indexed_ = keyframes_.size();
  pending_.clear();
}

std::vector<PlaceCandidate> PlaceIndex::query(const cv::Mat& all) {
  if (keyframes_.empty() || all.empty()) return {};
  const cv::Mat descriptors = spreadRows(all, params_.place_descriptors);
  // Per query descriptor, the nearest in the index and among the pending keyframes: the closer votes.
  std::vector<cv::DMatch> best(std::size_t(descriptors.rows), cv::DMatch(-1, -1, -1, 1e9f));
  if (indexed_ > 0) {
    std::vector<std::vector<cv::DMatch>> nn;
    matcher_.knnMatch(descriptors, nn, 1);
    for (const auto& m : nn)
      if (!m.empty() && m[0].queryIdx >= 0 && m[0].queryIdx < descriptors.rows) best[std::size_t(m[0].queryIdx)] = m[0];
  }
  if (!pending_.empty()) {
    cv::BFMatcher bf(cv::NORM_HAMMING);
    bf.add(pending_);
    std::vector<std::vector<cv::DMatch>> nn;
    bf.knnMatch(descriptors, nn, 1);
    for (const auto& m : nn) {
      if (m.empty()) continue;
      cv::DMatch& b = best[std::size_t(m[0].queryIdx)];
      if (m[0].distance < b.distance) b = m[0], b.imgIdx += int(indexed_);
    }
  }
  std::map<std::size_t, int> votes;
  for (const auto& m : best)
    if (m.distance <= params_.max_hamming && m.imgIdx >= 0 && std::size_t(m.imgIdx) < keyframes_.size())
      ++votes[keyframes_[std::size_t(m.imgIdx)]];
  std::vector<PlaceCandidate> out;
  for (const auto& [kf, n] : votes)
    if (n >= params_.min_votes) out.push_back({kf, n});
  std::sort(out.begin(), out.end(), [](const PlaceCandidate& a, const PlaceCandidate& b) {
    return a.votes != b.votes ? a.votes > b.votes : a.keyframe < b.keyframe;
  });
  if (out.size() > std::size_t(params_.candidates)) out.resize(std::size_t(params_.candidates));
  return out;
}

}  // namespace vofusion::loop
