#include "vofusion/io/png_decode.h"

#include <sys/stat.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <vector>

#include <libdeflate.h>  // its CRC-32
#include <opencv2/imgproc.hpp>

#include "vofusion/core/deflate.h"
#include "vofusion/core/text_file.h"

namespace vofusion {

namespace {

std::uint32_t be32(const std::uint8_t* p) {
  return (std::uint32_t(p[0]) << 24) | (std::uint32_t(p[1]) << 16) | (std::uint32_t(p[2]) << 8) | p[3];
}

bool isChunk(const std::uint8_t* tag, const char* name) { return std::memcmp(tag, name, 4) == 0; }

const std::uint8_t kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};

// The chunks' header and the image stream (IDAT chunks joined); false for anything outside the two
// supported types.
struct PngImage {
  std::uint32_t width = 0, height = 0;
  int bytes_per_pixel = 0, type = -1;  // 2 / CV_16UC1 or 3 / CV_8UC3
  std::vector<std::uint8_t>& stream;
};

// Per thread, kept from one image to the next: a fresh buffer of a frame's size is fresh pages for
// the kernel to fault in and zero (that took more time than the inflating).
struct Buffers {
  std::vector<std::uint8_t> file, stream, raw;
};
Buffers& buffers() {
  thread_local Buffers b;
  return b;
}

// The size a PNG's first 24 bytes state (signature, then IHDR's width and height); empty for no PNG.
cv::Size headerSizeOf(const std::uint8_t* h, std::size_t n) {
  if (n < 24 || std::memcmp(h, kSignature, 8) != 0 || !isChunk(h + 12, "IHDR")) return {};
  const std::uint32_t w = be32(h + 16), ht = be32(h + 20);
  constexpr std::uint32_t kIntMax = std::uint32_t(std::numeric_limits<int>::max());
  return {int(std::min(w, kIntMax)), int(std::min(ht, kIntMax))};
}

bool readChunks(const std::uint8_t* p, std::size_t n, PngImage& img) {
  if (n < 8 || std::memcmp(p, kSignature, 8) != 0) return false;
  bool header = false, in_stream = false, stream_ended = false;
  for (std::size_t at = 8; at + 12 <= n;) {
    const std::uint32_t len = be32(p + at);
    if (len > n - at - 12) return false;
    const std::uint8_t* tag = p + at + 4;
    const std::uint8_t* body = tag + 4;
    if (libdeflate_crc32(0, tag, len + 4) != be32(body + len)) return false;
    // The order libpng insists on: IHDR first and once, the IDATs one after the other.
    if (header == isChunk(tag, "IHDR")) return false;
    if (isChunk(tag, "IHDR")) {
      // 13 bytes: width, height, bit depth, colour type, compression, filter method, interlace.
      if (len != 13 || body[10] != 0 || body[11] != 0 || body[12] != 0) return false;
      img.width = be32(body), img.height = be32(body + 4);
      if (body[8] == 16 && body[9] == 0) img.bytes_per_pixel = 2, img.type = CV_16UC1;
      else if (body[8] == 8 && body[9] == 2) img.bytes_per_pixel = 3, img.type = CV_8UC3;
      else return false;
      header = true;
    } else if (isChunk(tag, "IDAT")) {
      if (stream_ended) return false;
      in_stream = true;
      img.stream.insert(img.stream.end(), body, body + len);
    } else {
      stream_ended = in_stream;
      if (isChunk(tag, "IEND"))
        return in_stream && img.width > 0 && img.height > 0 && img.width <= (1u << 15) && img.height <= (1u << 15);
      // Transparency; an eXIf chunk (left to imread, which the readers ask to ignore its orientation:
      // depth and colour pair on the sensor's grid); a critical chunk this decoder does not know (PLTE, ...).
      if (isChunk(tag, "tRNS") || isChunk(tag, "eXIf") || !(tag[0] & 0x20)) return false;
    }
    at += 12 + std::size_t(len);
  }
  return false;  // no IEND
}

int paeth(int a, int b, int c) {
  const int p = a + b - c, pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
  return pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
}

// Undoes row y's filter in place (prior: the row above, unfiltered; zeros for the first row).
bool unfilter(std::uint8_t filter, std::uint8_t* cur, const std::uint8_t* prior, std::size_t stride, int bpp) {
  switch (filter) {
    case 0:
      return true;
    case 1:
      for (std::size_t i = bpp; i < stride; ++i) cur[i] = std::uint8_t(cur[i] + cur[i - bpp]);
      return true;
    case 2:
      for (std::size_t i = 0; i < stride; ++i) cur[i] = std::uint8_t(cur[i] + prior[i]);
      return true;
    case 3:
      for (std::size_t i = 0; i < stride; ++i) cur[i] = std::uint8_t(cur[i] + ((i >= std::size_t(bpp) ? cur[i - bpp] : 0) + prior[i]) / 2);
      return true;
    case 4:
      for (std::size_t i = 0; i < std::size_t(bpp); ++i) cur[i] = std::uint8_t(cur[i] + prior[i]);
      for (std::size_t i = bpp; i < stride; ++i) cur[i] = std::uint8_t(cur[i] + paeth(cur[i - bpp], prior[i], prior[i - bpp]));
      return true;
    default:
      return false;
  }
}

// A row with filter 1 (Sub, which OpenCV's writer gives every row: all TUM files), unfiltered and
// converted in one pass, each channel its own running sum; the unfiltered bytes are kept in `cur`
// for the next row's filter. The same bytes as unfilter() and the loops below (PngDecode tests).
void subRowToMat(std::uint8_t* cur, cv::Mat& out, int y) {
  if (out.type() == CV_16UC1) {
    std::uint16_t* o = out.ptr<std::uint16_t>(y);
    std::uint8_t hi = 0, lo = 0;
    for (int x = 0; x < out.cols; ++x) {
      hi = cur[2 * x] = std::uint8_t(cur[2 * x] + hi);
      lo = cur[2 * x + 1] = std::uint8_t(cur[2 * x + 1] + lo);
      o[x] = std::uint16_t((hi << 8) | lo);  // big-endian
    }
    return;
  }
  std::uint8_t* o = out.ptr<std::uint8_t>(y);
  std::uint8_t r = 0, g = 0, b = 0;
  for (int x = 0; x < out.cols; ++x) {
    r = cur[3 * x] = std::uint8_t(cur[3 * x] + r);
    g = cur[3 * x + 1] = std::uint8_t(cur[3 * x + 1] + g);
    b = cur[3 * x + 2] = std::uint8_t(cur[3 * x + 2] + b);
    o[3 * x] = b, o[3 * x + 1] = g, o[3 * x + 2] = r;  // RGB -> BGR
  }
}

}  // namespace

cv::Mat decodePlainPng(const std::uint8_t* data, std::size_t size) {
  Buffers& b = buffers();
  struct Release {  // an unusually large image's buffers are not kept for the thread's next frames
    Buffers& b;
    ~Release() {
      constexpr std::size_t kKeep = std::size_t(64) << 20;
      for (auto* v : {&b.file, &b.stream, &b.raw})
        if (v->capacity() > kKeep) std::vector<std::uint8_t>().swap(*v);
    }
  } release{b};
  b.stream.clear();
  PngImage img{0, 0, 0, -1, b.stream};
  if (!readChunks(data, size, img)) return {};
  const int bpp = img.bytes_per_pixel;
  const std::size_t stride = std::size_t(img.width) * bpp, row = stride + 1;
  // Deflate expands at most ~1032:1: a header claiming more than the stream can hold is not this image's.
  if (row * img.height > img.stream.size() * 1032 + 1024) return {};
  std::vector<std::uint8_t>& raw = b.raw;
  raw.resize(row * img.height);
  if (!zlibUncompress(img.stream.data(), img.stream.size(), raw.data(), raw.size())) return {};
  const std::vector<std::uint8_t> zeros(stride, 0);
  cv::Mat out(int(img.height), int(img.width), img.type);
  for (int y = 0; y < out.rows; ++y) {
    std::uint8_t* cur = raw.data() + row * y + 1;
    if (cur[-1] == 1) {
      subRowToMat(cur, out, y);
      continue;
    }
    if (!unfilter(cur[-1], cur, y > 0 ? cur - row : zeros.data(), stride, bpp)) return {};
    if (img.type == CV_16UC1) {
      std::uint16_t* o = out.ptr<std::uint16_t>(y);
      for (std::uint32_t x = 0; x < img.width; ++x) o[x] = std::uint16_t((cur[2 * x] << 8) | cur[2 * x + 1]);  // big-endian
    } else {
      std::uint8_t* o = out.ptr<std::uint8_t>(y);
      for (std::uint32_t x = 0; x < img.width; ++x) o[3 * x] = cur[3 * x + 2], o[3 * x + 1] = cur[3 * x + 1], o[3 * x + 2] = cur[3 * x];
    }
  }
  return out;
}

// Far beyond any image (a 16-bit 4096x3072 frame is 25 MB uncompressed): read whole at the size it
// reports, such a file was a gigabyte allocation whose failure (std::bad_alloc) ended the run.
constexpr long kMaxImageFileBytes = 256L << 20;

// Only regular files are opened (openRegularFile): a FIFO named as an image (a rawlog's external file)
// waited for a writer, and a folder seeks to a huge "end" on some file systems (ext4: LLONG_MAX).
bool readWholeFile(const std::string& path, std::vector<std::uint8_t>& bytes) {
  std::FILE* f = openRegularFile(path);
  if (!f) return false;
  const long size = std::fseek(f, 0, SEEK_END) == 0 ? std::ftell(f) : -1;
  bool read = size >= 0 && size <= kMaxImageFileBytes && std::fseek(f, 0, SEEK_SET) == 0;
  if (read) {
    bytes.resize(std::size_t(size));
    read = std::fread(bytes.data(), 1, bytes.size(), f) == bytes.size();
  }
  std::fclose(f);
  return read;
}

cv::Mat readPlainPng(const std::string& path, cv::Size expect, cv::Size* header, double most_pixels) {
  std::vector<std::uint8_t>& bytes = buffers().file;
  if (header) *header = cv::Size();
  if (!readWholeFile(path, bytes)) return {};
  const cv::Size stated = headerSizeOf(bytes.data(), bytes.size());
  if (header) *header = stated;
  if (!expect.empty() && !stated.empty() && stated != expect) return {};
  if (most_pixels > 0 && double(stated.area()) > most_pixels) return {};
  return decodePlainPng(bytes.data(), bytes.size());
}

bool isRgb8Png(const std::vector<std::uint8_t>& bytes, int width, int height) {
  // Signature, then IHDR first: length, name, width, height, bit depth 8, colour type 2.
  return bytes.size() >= 29 && headerSizeOf(bytes.data(), bytes.size()) == cv::Size(width, height) && bytes[24] == 8 &&
         bytes[25] == 2;
}

bool readFileStart(const std::string& path, std::uint8_t* out, std::size_t n) {
  std::FILE* f = openRegularFile(path);
  if (!f) return false;
  const bool read = std::fread(out, 1, n, f) == n;
  std::fclose(f);
  return read;
}

cv::Size pngHeaderSize(const std::string& path) {
  std::uint8_t h[24];
  return readFileStart(path, h, sizeof h) ? headerSizeOf(h, sizeof h) : cv::Size();
}

namespace {
// Where a JPEG's entropy-coded data starts: its segments walked from SOI to SOS (each a marker and a
// big-endian length); n when the file ends before it (cut in its header); 2 when the segments cannot
// be walked (or end at an EOI before any scan). The header segments may hold an end marker of their own
// (an EXIF thumbnail's), which says nothing of the image's.
std::size_t jpegScanStart(const std::uint8_t* p, std::size_t n) {
  std::size_t at = 2;
  while (true) {
    if (at + 4 > n) return n;
    if (p[at] != 0xFF) return 2;
    const std::uint8_t marker = p[at + 1];
    if (marker == 0xFF) {  // fill byte
      ++at;
      continue;
    }
    if (marker == 0xD9) return 2;  // EOI before any scan: tables only
    if (marker == 0x01 || (marker >= 0xD0 && marker <= 0xD8)) {  // TEM, RSTn, SOI: no length
      at += 2;
      continue;
    }
    const std::size_t len = (std::size_t(p[at + 2]) << 8) | p[at + 3];
    if (len < 2) return 2;
    if (at + 2 + len > n) return n;  // cut inside a header segment
    at += 2 + len;
    if (marker == 0xDA) return at;  // SOS: the scan's data follows its header
  }
}
}  // namespace

namespace {
// A whole PNG of the kinds decodePlainPng reads: what is wrong with its image data, which libpng
// would say on a line of its own ("libpng error: Not enough image data"); empty when nothing is (or
// when the PNG is of another kind: OpenCV decides). Data past the last row is no damage (libpng warns).
std::string plainImageDataDamage(const std::uint8_t* data, std::size_t size) {
  std::vector<std::uint8_t> stream;
  PngImage img{0, 0, 0, -1, stream};
  if (!readChunks(data, size, img)) return {};
  const std::size_t stride = std::size_t(img.width) * img.bytes_per_pixel, row = stride + 1;
  if (row * img.height > img.stream.size() * 1032 + 1024) return "damaged PNG: its image data is far short of its size";
  if (row * img.height > kMaxImageFileBytes) return {};  // beyond any frame: not inflated here
  std::vector<std::uint8_t> raw(row * img.height);
  switch (zlibInflate(img.stream.data(), img.stream.size(), raw.data(), raw.size())) {
    case Inflated::Short: return "damaged PNG: its image data ends before its last row";
    case Inflated::Corrupt: return "damaged PNG: its image data cannot be inflated";
    default: break;
  }
  for (std::size_t y = 0; y < img.height; ++y)
    if (raw[row * y] > 4) return "damaged PNG: row " + std::to_string(y) + "'s filter type is " + std::to_string(raw[row * y]) + " (0-4)";
  return {};
}
}  // namespace

// A PNG's chunks walked to IEND, each critical one's CRC checked (libpng stops at a bad one with its
// own "libpng error" line; an ancillary chunk with a bad CRC it only drops); a JPEG's end marker after
// its scan starts.
std::string imageFileDamage(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0 && S_ISREG(st.st_mode) && st.st_size > kMaxImageFileBytes)
    return std::to_string(st.st_size) + " bytes, larger than any image";
  thread_local std::vector<std::uint8_t> bytes;
  if (!readWholeFile(path, bytes)) return {};
  const std::uint8_t* p = bytes.data();
  const std::size_t n = bytes.size();
  if (n >= 2 && p[0] == 0xFF && p[1] == 0xD8) {  // JPEG: an end-of-image marker, the last one searched
    const std::size_t scan = jpegScanStart(p, n);  // from the end (a writer may append data after it)
    for (std::size_t i = n - 1; i > scan && i >= 3; --i)
      if (p[i - 1] == 0xFF && p[i] == 0xD9) return {};
    return "truncated JPEG";
  }
  if (n < 8 || std::memcmp(p, kSignature, 8) != 0) return {};  // neither: OpenCV decides
  for (std::size_t at = 8; at + 12 <= n; at += 12 + std::size_t(be32(p + at))) {
    const std::uint32_t len = be32(p + at);
    if (len > n - at - 12) break;  // the chunk runs past the end
    const std::uint8_t* tag = p + at + 4;
    const bool critical = !(tag[0] & 0x20);  // IHDR, PLTE, IDAT, IEND: an upper-case first letter
    if (critical && libdeflate_crc32(0, tag, len + 4) != be32(tag + 4 + len))
      return "damaged PNG: its " + std::string(reinterpret_cast<const char*>(tag), 4) + " chunk fails its CRC";
    if (isChunk(tag, "IEND")) return plainImageDataDamage(p, n);
  }
  return "truncated PNG";
}

cv::Mat asBgr8(cv::Mat image) {
  const int depth = image.depth();
  if (depth != CV_8U)
    image.convertTo(image, CV_8U, depth == CV_32F || depth == CV_64F ? 255.0 : depth == CV_16U ? 1.0 / 256 : 1.0);
  if (image.channels() == 2) cv::extractChannel(image, image, 0);  // grey and alpha: the grey
  if (image.channels() == 1) cv::cvtColor(image, image, cv::COLOR_GRAY2BGR);
  else if (image.channels() == 4) cv::cvtColor(image, image, cv::COLOR_BGRA2BGR);
  return image;
}

}  // namespace vofusion
