#pragma once
// PNG decoding for the two image types RGB-D recordings hold (TUM, 7-Scenes, the colour our rawlogs
// copy): 16-bit grey depth and 8-bit RGB colour, not interlaced. libdeflate inflates the image data
// in about half the time zlib takes under libpng (OpenCV's decoder); the row filters are PNG's five.
//
// The result is what cv::imread gives for such a file (IMREAD_ANYDEPTH | IMREAD_ANYCOLOR for depth:
// CV_16UC1; IMREAD_COLOR for colour: CV_8UC3, BGR). Anything else gives an empty Mat, and the caller
// decodes with cv::imread as before (and fails as before where it fails): another pixel type,
// interlacing, a palette or transparency, an eXIf chunk (the readers ask imread to ignore its orientation), an unknown
// critical chunk, chunks out of libpng's order, a bad CRC, a damaged or short image stream.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace vofusion {

cv::Mat decodePlainPng(const std::uint8_t* data, std::size_t size);
// The same for a file (empty also when it cannot be read). header: the size its PNG header states
// (empty for a file that is no PNG), from the same bytes; a PNG stating another size than `expect`
// (when given), or more pixels than `most_pixels` (when given), is not decoded, so the caller refuses
// it before any decoder allocates its pixels.
cv::Mat readPlainPng(const std::string& path, cv::Size expect = {}, cv::Size* header = nullptr, double most_pixels = 0);

// The file's bytes into `bytes` (its storage reused); false when it cannot be read, is no regular file or
// is larger than any image (256 MiB).
bool readWholeFile(const std::string& path, std::vector<std::uint8_t>& bytes);
// The file's first n bytes into `out`; false when it cannot be read or is shorter (nothing else read:
// a file's kind is told by them).
bool readFileStart(const std::string& path, std::uint8_t* out, std::size_t n);
// Whether `bytes` is a PNG whose header says 8-bit RGB of width x height (nothing decoded): the
// rawlog writer then copies a recording's colour PNG instead of encoding its pixels again.
bool isRgb8Png(const std::vector<std::uint8_t>& bytes, int width, int height);
// The width and height a PNG file's header states (its first 24 bytes; nothing decoded, no CRC
// checked); an empty size for a file that is no PNG or cannot be read. A recording's image size is
// voted by it (a crafted 2 MB PNG says 30000x30000, and a decoder allocated its 1.8 GB to find out).
cv::Size pngHeaderSize(const std::string& path);
// A colour image of 1 to 4 channels (8- or 16-bit, or float in [0, 1]) as 8-bit BGR: what the
// frames carry whatever the file held (grey, grey and alpha, BGRA, 16 bits a channel). An 8-bit
// BGR image comes back as it is (its pixels shared).
cv::Mat asBgr8(cv::Mat image);
// What is wrong with an image file: a PNG cut short ("truncated PNG"), with a chunk whose CRC fails
// ("damaged PNG: its IDAT chunk fails its CRC") or, of the kinds decodePlainPng reads, with image data
// short of its last row or with a row filter PNG has not, a JPEG cut short ("truncated JPEG"), a file larger than
// any image ("... bytes, larger than any image": over 256 MiB); empty for a whole
// one, or a file of another kind. Checked before cv::imread: libpng prints its own line to stderr for
// such a PNG, and libjpeg fills a cut JPEG's missing rows with grey and returns it.
std::string imageFileDamage(const std::string& path);

}  // namespace vofusion
