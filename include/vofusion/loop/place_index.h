#pragma once
// Place recognition: the BRAND descriptors of keyframes in OpenCV's FLANN LSH index (binary
// descriptors, Hamming distance). A query keyframe's descriptors each vote for the keyframe holding
// their nearest neighbour; the keyframes with most votes are the loop candidates.
#include <cstddef>
#include <utility>
#include <vector>

#include <opencv2/features2d.hpp>

#include "vofusion/loop/loop_params.h"

namespace vofusion::loop {

struct PlaceCandidate {
  std::size_t keyframe = 0;
  int votes = 0;
};

class PlaceIndex {
 public:
  explicit PlaceIndex(const LoopParams& params);
  // descriptors: CV_8U, 32 bytes a row; at most [loop] place_descriptors of them are kept, spread evenly.
  void add(std::size_t keyframe, const cv::Mat& descriptors);
  std::size_t size() const { return keyframes_.size(); }
  // Keyframes with at least min_votes votes from `descriptors` (nearest neighbours within max_hamming),
  // most votes first, at most `candidates` of them.
  std::vector<PlaceCandidate> query(const cv::Mat& descriptors);

 private:
  LoopParams params_;
  static constexpr std::size_t kBatch = 16;
  cv::FlannBasedMatcher matcher_;
  std::vector<std::size_t> keyframes_;  // matcher image index -> keyframe id (all added, indexed or not)
  std::size_t indexed_ = 0;             // keyframes_[0, indexed_) are in the LSH index
  std::vector<cv::Mat> pending_;        // descriptors of keyframes_[indexed_, ...)
};

}  // namespace vofusion::loop
