#pragma once
// JPEG decoding that tells a damaged image from a whole one. libjpeg decodes a JPEG whose entropy-coded
// data is corrupt (a hole in the middle of the file, bytes flipped) to grey or smeared blocks, prints
// "Corrupt JPEG data: ..." to stderr and returns the picture; cv::imread hands it on as a good frame.
// Here the same decoder (libjpeg-turbo) counts its own corrupt-data warnings as the file's damage:
// a bad Huffman or arithmetic code, a data segment ended early, image data left over before a marker,
// a lost restart marker, the file ended early. Not damage: bytes before a restart marker and zeros
// before the end marker (MJPEG cameras leave such in every frame, whose pixels are whole), bytes between
// header segments, scan parameters libjpeg corrects.
// JPEG has no checksum: damage that decodes without a warning is not seen. Of 1000 random damages to
// a TUM frame's JPEG (a bit flipped, 1-64 bytes cut, 16 bytes zeroed) libjpeg warned on 379; of the
// 621 it passed, 368 changed the picture (by over 1 a pixel, the three channels' absolute differences
// summed and averaged): Huffman codes mostly resynchronise within a few blocks
// (bench/results/2026-12-06-fourth-session.md).
#include <cstddef>
#include <cstdint>
#include <string>

#include <opencv2/core.hpp>

namespace vofusion {

struct JpegDecode {
  cv::Mat image;       // CV_8UC3 (BGR) or CV_8UC1 (grey), the sensor's pixel grid (no EXIF orientation)
  std::string damage;  // libjpeg's first corrupt-data message ("Corrupt JPEG data: bad Huffman code")
  cv::Size header;     // the size the JPEG's frame header states (empty for no JPEG or an unreadable header)
};

// Empty image and empty damage for what is no JPEG or a colour space other than grey, YCbCr and RGB
// (CMYK): the caller decodes it with cv::imread. A damaged file gives damage and no image; so does
// one libjpeg refuses (its error message as damage). A header stating another size than `expect`
// (when given), or more pixels than `most_pixels` (when given), is not decoded, so the caller refuses
// it before its pixels are allocated; without either, more pixels than OpenCV's decoders allow (2^30)
// are damage.
JpegDecode decodeJpeg(const std::uint8_t* data, std::size_t size, cv::Size expect = {}, double most_pixels = 0);
// The same for a file (nothing for one that cannot be read).
JpegDecode readJpeg(const std::string& path, cv::Size expect = {}, double most_pixels = 0);

}  // namespace vofusion
