#pragma once
// NARF interest points (Steder et al., ICRA 2011) computed as pcl::NarfKeypoint with
// pcl::RangeImageBorderExtractor compute them (PCL 1.13, default parameters, sparse interest image,
// no polynomial refinement), step for step and constant for constant, but for our case: one small
// planar range image, flat per-pixel arrays instead of PCL's per-pixel heap objects; the border
// extraction's per-pixel passes on every core, the interest search on one (as PCL must for stable results).
// The float operations follow PCL's order so that the keypoints come out the same.
#include <cstdint>
#include <limits>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "vofusion/core/camera.h"

namespace vofusion::narf {

// The depth image as PCL's RangeImagePlanar after setUnseenToMaxRange(): a pixel without depth is
// a "max range" point (range +inf), so the edges of depth holes count as borders, as they do in PCL.
struct RangeImage {
  int width = 0, height = 0;
  float cx = 0, cy = 0, fx_inv = 0, fy_inv = 0;  // pixels, 1/pixels
  std::vector<Eigen::Vector3f> points;           // m, camera frame (NaN where range is +inf)
  std::vector<float> range;                      // m, +inf: no reading

  RangeImage(const cv::Mat& depth, const CameraIntrinsics& camera);  // depth: CV_32F metres, 0 = none
  bool inImage(int x, int y) const { return x >= 0 && x < width && y >= 0 && y < height; }
  bool valid(int i) const { return range[i] < kInf; }
  bool valid(int x, int y) const { return inImage(x, y) && valid(y * width + x); }
  static constexpr float kInf = std::numeric_limits<float>::infinity();
};

// Border traits PCL's later stages read (PCL keeps more, e.g. the side of each shadow border).
enum Trait : std::uint8_t {
  kObstacle = 1, kObstacleLeft = 2, kObstacleRight = 4, kObstacleTop = 8, kObstacleBottom = 16,
  kShadow = 32, kVeil = 64,
};

// NarfKeypoint's min_surface_change_score: weaker surface changes play no part in the interest values.
constexpr float kMinSurfaceChange = 0.2f;

// What RangeImageBorderExtractor hands to the keypoint stage, per pixel.
struct Borders {
  std::vector<std::uint8_t> traits;          // Trait bits
  std::vector<float> change_score;           // [0,1], 1 on obstacle borders, else principal curvature
  std::vector<Eigen::Vector3f> change_dir;   // unit, camera frame (border direction or main curvature);
                                             // only where change_score >= kMinSurfaceChange
};

// PCL's RangeImageBorderExtractor with its default parameters.
Borders extractBorders(const RangeImage& image);

struct KeypointParams {
  float support_size = 0.2f;        // m
  float min_interest_value = 0.45f; // [0,1]
  int max_points = -1;              // strongest kept, <= 0: all
};

// The interest search's direction histogram cell of a surface change, in the seed's viewer frame: PCL
// takes the angle of its direction (x, y) as 2 acos(x) folded to [-90, 90) degrees, so the cell depends
// on the normalised x alone. cellOfX is that computation. DirectionCells gives the same cell for every
// float of [-1, 1] (a normalised x) by comparisons: the cell is a step function of x that falls over
// [-1, ~0) and again over [~0, 1] (acosf is monotone), and its 17 steps are found by bisection over the
// floats with cellOfX itself, once per process (test Narf.DirectionCellsAreAcosCells).
constexpr int kDirectionCells = 18;
int cellOfX(float x);
class DirectionCells {
 public:
  DirectionCells();
  int cellOf(float x) const {
    int steps_passed = 0;
    for (int i = 0; i < kDirectionCells - 1; ++i) steps_passed += x >= step_[i];
    return cell_[steps_passed];
  }

 private:
  float step_[kDirectionCells - 1];  // ascending: where the cell changes
  int cell_[kDirectionCells];        // below the first step, then after each
};

// pcl::NarfKeypoint: the pixel indices of the interest points in raster order (as NarfKeypoint::compute
// lists them); `interest` receives the interest image (0 where no value).
std::vector<int> interestPoints(const RangeImage& image, const Borders& borders, const KeypointParams& params,
                                std::vector<float>& interest);

}  // namespace vofusion::narf
