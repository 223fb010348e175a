// The measurement behind include/vofusion/io/jpeg_decode.h's figures: 1000 random damages to one TUM
// frame's JPEG (quality 95, OpenCV's encoder), which of them libjpeg warns on, and whether those it
// passes change the picture. Built by hand against a checkout:
//   g++ -O1 -std=c++17 -Iinclude $(pkg-config --cflags opencv4) bench/results/2026-12-06-jpeg-damage.cpp \
//     src/io/jpeg_decode.cpp src/io/png_decode.cpp src/core/deflate.cpp -o /tmp/jpeg-damage \
//     $(pkg-config --libs opencv4) -ljpeg -ldeflate
//   /tmp/jpeg-damage ../shared/data/tum/rgbd_dataset_freiburg1_xyz_first300/rgb/1305031102.175304.png
#include <map>
#include <random>
#include <cstdio>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include "vofusion/io/jpeg_decode.h"
using namespace vofusion;
int main(int argc, char** argv) {
  cv::Mat img = cv::imread(argv[1]);
  std::vector<std::uint8_t> jpeg;
  cv::imencode(".jpg", img, jpeg);
  auto whole = decodeJpeg(jpeg.data(), jpeg.size());
  cv::Mat ref = cv::imdecode(jpeg, cv::IMREAD_UNCHANGED);
  printf("whole: damage='%s' same=%d size=%zu\n", whole.damage.c_str(), cv::norm(whole.image, ref, cv::NORM_INF) == 0, jpeg.size());
  std::mt19937 rng(1);
  std::map<std::string, int> hist;
  int undetected_changed = 0, undetected_same = 0;
  for (int t = 0; t < 1000; ++t) {
    auto b = jpeg;
    std::size_t at = 700 + rng() % (b.size() - 800);
    int mode = t % 3;
    if (mode == 0) b[at] ^= std::uint8_t(1 << (rng() % 8));
    else if (mode == 1) b.erase(b.begin() + at, b.begin() + at + 1 + rng() % 64);
    else for (int k = 0; k < 16; ++k) b[at + k] = 0;
    auto d = decodeJpeg(b.data(), b.size());
    if (!d.damage.empty()) hist[std::to_string(mode) + " " + d.damage]++;
    else {
      cv::Mat o = cv::imdecode(b, cv::IMREAD_UNCHANGED);
      double diff = cv::norm(o, ref, cv::NORM_L1) / o.total();
      if (diff > 1) undetected_changed++; else undetected_same++;
      hist[std::to_string(mode) + " none"]++;
    }
  }
  for (auto& [k, v] : hist) printf("%4d %s\n", v, k.c_str());
  printf("undetected: changed %d same %d\n", undetected_changed, undetected_same);
}
