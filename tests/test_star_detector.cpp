// STAR / CenSurE: detections on synthetic blobs, repeatability under rotation and scale.
#include <random>

#include <opencv2/imgproc.hpp>

#include "support.h"
#include "vofusion/features/star_detector.h"

using namespace vofusion;

namespace {
// Random bright/dark discs and squares of several sizes on a smooth background.
cv::Mat blobImage(int w, int h, std::uint32_t seed) {
  cv::Mat img(h, w, CV_8U, cv::Scalar(128));
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> x(0, w - 1), y(0, h - 1), r(3, 14), c(0, 255);
  for (int i = 0; i < 160; ++i) {
    const cv::Point p(x(rng), y(rng));
    if (i % 3) cv::circle(img, p, r(rng), cv::Scalar(c(rng)), cv::FILLED, cv::LINE_AA);
    else { const int s = r(rng); cv::rectangle(img, p - cv::Point(s, s), p + cv::Point(s, s), cv::Scalar(c(rng)), cv::FILLED); }
  }
  cv::GaussianBlur(img, img, cv::Size(0, 0), 1.0);
  return img;
}
// Fraction of keypoints of `a`, mapped by the 2x3 affine M, that have a keypoint of `b` within tol
// pixels (only those landing well inside b's image count).
double repeatability(const std::vector<cv::KeyPoint>& a, const std::vector<cv::KeyPoint>& b, const cv::Mat& M,
                     cv::Size size_b, float tol) {
  int seen = 0, found = 0;
  for (const auto& k : a) {
    const cv::Point2f q(float(M.at<double>(0, 0) * k.pt.x + M.at<double>(0, 1) * k.pt.y + M.at<double>(0, 2)),
                        float(M.at<double>(1, 0) * k.pt.x + M.at<double>(1, 1) * k.pt.y + M.at<double>(1, 2)));
    if (q.x < 80 || q.y < 80 || q.x > size_b.width - 80 || q.y > size_b.height - 80) continue;
    ++seen;
    for (const auto& kb : b)
      if (cv::norm(kb.pt - q) <= tol) { ++found; break; }
  }
  return seen ? double(found) / seen : 0.0;
}
}  // namespace

TEST(Star, FindsAnIsolatedBlobAtItsCentreWithItsScale) {
  cv::Mat img(240, 240, CV_8U, cv::Scalar(60));
  cv::circle(img, {120, 110}, 8, cv::Scalar(220), cv::FILLED, cv::LINE_AA);
  const auto kps = detectStar(img);
  ASSERT_FALSE(kps.empty());
  const auto best = *std::max_element(kps.begin(), kps.end(),
                                      [](const cv::KeyPoint& a, const cv::KeyPoint& b) { return a.response < b.response; });
  EXPECT_LE(cv::norm(best.pt - cv::Point2f(120, 110)), 1.5f);
  // A disc of radius 8 responds best to a filter of comparable size (OpenCV's scales 4..32 here).
  EXPECT_GE(best.size, 6.f);
  EXPECT_LE(best.size, 16.f);
  EXPECT_GT(best.response, 30.f);  // bright centre
}

// A small image (160x120, a sensor's low mode) has its keypoints: the largest pattern taken is one
// whose border leaves responses inside the image. None was found on a side of 138 px or less. Images
// of 139 px and more take the same patterns as before.
TEST(Star, SmallImagesStillDetect) {
  EXPECT_FALSE(detectStar(blobImage(160, 120, 7)).empty());
  EXPECT_FALSE(detectStar(blobImage(120, 100, 7)).empty());
}

// A blob centred between pixels: the response peak's parabola vertex finds it to a fraction of a pixel,
// the integer extremum only to the nearest pixel.
// Every value a key's range allows detects something: a trace^2/det limit of 4 or less calls every
// point a line (trace^2 >= 4 det for any such matrix), and a largest size under 6 leaves only scales
// that are tagged unlocalised or too small. Those ends let STAR find nothing, silently.
TEST(Star, EveryValueInRangeDetectsSomething) {
  const cv::Mat img = blobImage(640, 480, 7);
  for (const char* key : {"max_size", "line_threshold_projected", "line_threshold_binarized"}) {
    StarParams p;
    mrpt::config::CConfigFileMemory cfg;
    p.saveToConfigFile(cfg, "star");
    // The smallest value the range takes: what a load of a value just under it refuses.
    for (int v = 0; v <= 8; ++v) {
      cfg.write("star", key, v);
      StarParams q;
      try {
        q.loadFromConfigFile(cfg, "star");
      } catch (const std::exception&) {
        continue;  // refused: fine
      }
      EXPECT_FALSE(detectStar(img, q).empty()) << key << " = " << v << " is accepted and finds nothing";
    }
  }
}

TEST(Star, SubpixelPositionOfAnOffCentreBlob) {
  const cv::Point2f centre(120.35f, 110.7f);
  cv::Mat img(240, 240, CV_8U, cv::Scalar(60));
  constexpr int kShift = 8;  // fractional drawing: coordinates in 1/256 px
  cv::circle(img, cv::Point(cvRound(centre.x * 256), cvRound(centre.y * 256)), 8 * 256, cv::Scalar(220), cv::FILLED,
             cv::LINE_AA, kShift);
  auto strongest = [&](bool subpixel) {
    StarParams p;
    p.subpixel = subpixel;
    const auto kps = detectStar(img, p);
    EXPECT_FALSE(kps.empty());
    return std::max_element(kps.begin(), kps.end(), [](const cv::KeyPoint& a, const cv::KeyPoint& b) {
             return a.response < b.response;
           })->pt;
  };
  const float whole = float(cv::norm(strongest(false) - centre)), fine = float(cv::norm(strongest(true) - centre));
  EXPECT_LT(fine, 0.3f);
  EXPECT_LT(fine, whole);
}

TEST(Star, FlatAndStraightEdgeImagesGiveNothing) {
  cv::Mat flat(240, 320, CV_8U, cv::Scalar(90));
  EXPECT_TRUE(detectStar(flat).empty());
  cv::Mat edge = flat.clone();
  edge(cv::Rect(160, 0, 160, 240)).setTo(200);  // a long straight edge: line suppression
  EXPECT_TRUE(detectStar(edge).empty());
}

TEST(Star, RepeatableUnderRotation) {
  const cv::Mat img = blobImage(640, 480, 7);
  const auto a = detectStar(img);
  ASSERT_GT(a.size(), 40u);
  for (double angle : {15.0, 45.0, 90.0}) {
    const cv::Mat M = cv::getRotationMatrix2D(cv::Point2f(320, 240), angle, 1.0);
    cv::Mat rot;
    cv::warpAffine(img, rot, M, img.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    const double rep = repeatability(a, detectStar(rot), M, rot.size(), 3.f);
    // Octagon-like filters are nearly isotropic: most blobs are found again.
    EXPECT_GT(rep, angle == 90.0 ? 0.8 : 0.6) << "rotation " << angle;
  }
}

TEST(Star, RepeatableUnderScale) {
  const cv::Mat img = blobImage(640, 480, 8);
  const auto a = detectStar(img);
  for (double s : {0.8, 1.25}) {
    const cv::Mat M = cv::getRotationMatrix2D(cv::Point2f(320, 240), 0.0, s);
    cv::Mat sc;
    cv::warpAffine(img, sc, M, img.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    const double rep = repeatability(a, detectStar(sc), M, sc.size(), 3.f);
    EXPECT_GT(rep, 0.5) << "scale " << s;
  }
}
