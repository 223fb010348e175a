#pragma once
// PNG encoding of the colour images our recordings hold (a rawlog's external colour files, the rgb/
// folder rgbd-simulate writes): BGR pixels as an 8-bit RGB PNG, each row filtered Sub (the left
// neighbour's difference), the image data compressed by libdeflate at level 1. On TUM's 640x480
// colour that takes ~6 ms against OpenCV's 20 (libpng, zlib at level 1, adaptive filters), for files of
// the same size (494 against 499 KB on fr1_xyz); vofusion-grab encodes one for every frame it records.
//
// cv::imdecode and decodePlainPng give back exactly the pixels encoded (tests: PngEncode.*).
#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

namespace vofusion {

// The PNG file's bytes for an 8-bit, 3-channel BGR image (any stride); std::invalid_argument for any
// other type or an empty image.
std::vector<std::uint8_t> encodeRgb8Png(const cv::Mat& bgr);

}  // namespace vofusion
