// decodePlainPng gives cv::imdecode's pixels for 16-bit grey and 8-bit RGB PNGs, with each of PNG's
// five row filters (PNGs made here row by row) and on the shared TUM sequence's real files; for
// anything else it gives an empty Mat, so that the caller's cv::imread decides. encodeRgb8Png's files
// decode, by OpenCV and by decodePlainPng, to exactly the pixels encoded.
#include <gtest/gtest.h>

#include <sys/stat.h>

#include <chrono>
#include <filesystem>
#include <future>
#include <memory>
#include <thread>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <zlib.h>

#include "support.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/text_file.h"
#include "vofusion/io/jpeg_decode.h"
#include "vofusion/io/png_decode.h"
#include "vofusion/io/png_encode.h"
#include "vofusion/io/tum_source.h"

using namespace vofusion;
namespace fs = std::filesystem;

namespace {

void put32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  for (int s = 24; s >= 0; s -= 8) out.push_back(std::uint8_t(v >> s));
}

void chunk(std::vector<std::uint8_t>& png, const char* tag, const std::vector<std::uint8_t>& body) {
  put32(png, std::uint32_t(body.size()));
  const std::size_t start = png.size();
  png.insert(png.end(), tag, tag + 4);
  png.insert(png.end(), body.begin(), body.end());
  put32(png, std::uint32_t(crc32(0, png.data() + start, uInt(png.size() - start))));
}

struct PngSpec {
  int bit_depth = 16, colour_type = 0, interlace = 0;
  int first_filter = 0;              // row y is filtered with (first_filter + y) % 5
  const char* extra = nullptr;       // another chunk (empty body) after IHDR, e.g. "tRNS", "eXIf"
  bool text_between_idats = false;   // an ancillary chunk splitting the IDATs (libpng refuses it)
  int rows_in_stream = -1;           // the image data stops after this many rows (-1: all of them)
  int bad_filter_row = -1;           // this row's filter type byte is 7 (PNG has 0-4)
};

// A PNG of `img` (CV_16UC1 or CV_8UC3 BGR) whose row y is filtered with filter (first + y) % 5, as an
// encoder would: each byte minus its predictor from the raw (unfiltered) bytes.
std::vector<std::uint8_t> makePng(const cv::Mat& img, const PngSpec& spec = {}) {
  const int bpp = img.type() == CV_16UC1 ? 2 : 3;
  const std::size_t stride = std::size_t(img.cols) * bpp;
  std::vector<std::uint8_t> raw(img.rows * stride);
  for (int y = 0; y < img.rows; ++y)
    for (int x = 0; x < img.cols; ++x) {
      std::uint8_t* r = &raw[y * stride + x * bpp];
      if (bpp == 2) {
        const std::uint16_t v = img.at<std::uint16_t>(y, x);
        r[0] = std::uint8_t(v >> 8), r[1] = std::uint8_t(v);
      } else {
        const cv::Vec3b v = img.at<cv::Vec3b>(y, x);
        r[0] = v[2], r[1] = v[1], r[2] = v[0];
      }
    }
  std::vector<std::uint8_t> filtered;
  for (int y = 0; y < img.rows; ++y) {
    const int f = (spec.first_filter + y) % 5;
    filtered.push_back(std::uint8_t(f));
    for (std::size_t i = 0; i < stride; ++i) {
      const int a = i >= std::size_t(bpp) ? raw[y * stride + i - bpp] : 0;
      const int b = y > 0 ? raw[(y - 1) * stride + i] : 0;
      const int c = y > 0 && i >= std::size_t(bpp) ? raw[(y - 1) * stride + i - bpp] : 0;
      const int p = a + b - c, pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
      const int predictor[5] = {0, a, b, (a + b) / 2, pa <= pb && pa <= pc ? a : pb <= pc ? b : c};
      filtered.push_back(std::uint8_t(raw[y * stride + i] - predictor[f]));
    }
  }
  if (spec.rows_in_stream >= 0) filtered.resize(spec.rows_in_stream * (stride + 1));
  if (spec.bad_filter_row >= 0) filtered[spec.bad_filter_row * (stride + 1)] = 7;
  std::vector<std::uint8_t> z(compressBound(uLong(filtered.size())));
  uLongf zlen = z.size();
  EXPECT_EQ(compress2(z.data(), &zlen, filtered.data(), uLong(filtered.size()), 6), Z_OK);
  z.resize(zlen);
  std::vector<std::uint8_t> png = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'}, ihdr;
  put32(ihdr, std::uint32_t(img.cols));
  put32(ihdr, std::uint32_t(img.rows));
  ihdr.insert(ihdr.end(), {std::uint8_t(spec.bit_depth), std::uint8_t(spec.colour_type), 0, 0, std::uint8_t(spec.interlace)});
  chunk(png, "IHDR", ihdr);
  if (spec.extra) chunk(png, spec.extra, {0, 0});
  chunk(png, "tEXt", {'a', 0, 'b'});  // an ancillary chunk is skipped
  // The stream in two IDAT chunks, as encoders split it.
  const std::size_t half = z.size() / 2;
  chunk(png, "IDAT", std::vector<std::uint8_t>(z.begin(), z.begin() + half));
  if (spec.text_between_idats) chunk(png, "tEXt", {'c', 0, 'd'});
  chunk(png, "IDAT", std::vector<std::uint8_t>(z.begin() + half, z.end()));
  chunk(png, "IEND", {});
  return png;
}

cv::Mat depthImage(int w, int h) {
  cv::Mat d(h, w, CV_16UC1);
  cv::RNG rng(3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) d.at<std::uint16_t>(y, x) = rng.uniform(0, 8) == 0 ? 0 : std::uint16_t(5000 + 37 * x + 11 * y + rng.uniform(0, 400));
  return d;
}

cv::Mat colourImage(int w, int h) {
  cv::Mat c(h, w, CV_8UC3);
  cv::RNG(5).fill(c, cv::RNG::UNIFORM, 0, 256);
  return c;
}

void expectSameAs(const cv::Mat& got, const cv::Mat& want) {
  ASSERT_FALSE(got.empty());
  ASSERT_EQ(got.type(), want.type());
  ASSERT_EQ(got.size(), want.size());
  EXPECT_EQ(cv::norm(got, want, cv::NORM_INF), 0.0);
}

cv::Mat decode(const std::vector<std::uint8_t>& png) { return decodePlainPng(png.data(), png.size()); }

std::string writeBytes(const std::string& path, const std::vector<std::uint8_t>& bytes) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  std::fwrite(bytes.data(), 1, bytes.size(), f);
  std::fclose(f);
  return path;
}

}  // namespace

TEST(PngDecode, EveryRowFilterAsOpenCvDecodesIt) {
  // Each filter also on the first row (nothing above it).
  for (const cv::Size size : {cv::Size(37, 23), cv::Size(640, 10)})
  for (int first = 0; first < 5; ++first) {
    const cv::Mat depth = depthImage(size.width, size.height), colour = colourImage(size.width, size.height);
    const std::vector<std::uint8_t> dpng = makePng(depth, {16, 0, 0, first}), cpng = makePng(colour, {8, 2, 0, first});
    const cv::Mat d_cv = cv::imdecode(dpng, cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR), c_cv = cv::imdecode(cpng, cv::IMREAD_COLOR);
    expectSameAs(d_cv, depth);  // the PNGs made here are right
    expectSameAs(c_cv, colour);
    expectSameAs(decode(dpng), d_cv);
    expectSameAs(decode(cpng), c_cv);
  }
}

TEST(PngDecode, OpenCvsOwnPngsAsOpenCvDecodesThem) {
  const cv::Mat depth = depthImage(160, 120), colour = colourImage(160, 120);
  for (const int level : {0, 1, 9}) {
    std::vector<std::uint8_t> dpng, cpng;
    ASSERT_TRUE(cv::imencode(".png", depth, dpng, {cv::IMWRITE_PNG_COMPRESSION, level}));
    ASSERT_TRUE(cv::imencode(".png", colour, cpng, {cv::IMWRITE_PNG_COMPRESSION, level}));
    expectSameAs(decode(dpng), depth);
    expectSameAs(decode(cpng), colour);
  }
}

TEST(PngDecode, AnythingElseIsLeftToOpenCv) {
  const cv::Mat depth = depthImage(20, 10);
  EXPECT_TRUE(decode(makePng(depth, {16, 0, 1})).empty()) << "interlaced";
  EXPECT_TRUE(decode(makePng(depth, {16, 0, 0, 0, "tRNS"})).empty()) << "transparency";
  EXPECT_TRUE(decode(makePng(depth, {16, 0, 0, 0, "eXIf"})).empty()) << "an orientation imread would apply";
  EXPECT_TRUE(decode(makePng(depth, {16, 0, 0, 0, "IHDR"})).empty()) << "a second IHDR";
  EXPECT_TRUE(decode(makePng(depth, {16, 0, 0, 0, "PLTE"})).empty()) << "a critical chunk it does not know";
  EXPECT_TRUE(decode(makePng(depth, {16, 0, 0, 0, nullptr, true})).empty()) << "IDATs not one after the other";
  EXPECT_FALSE(decode(makePng(depth, {16, 0, 0, 0, "sRGB"})).empty()) << "an ancillary chunk is skipped";
  std::vector<std::uint8_t> grey8;
  ASSERT_TRUE(cv::imencode(".png", cv::Mat(10, 20, CV_8UC1, cv::Scalar(7)), grey8));
  EXPECT_TRUE(decode(grey8).empty()) << "8-bit grey";
  std::vector<std::uint8_t> png = makePng(depth);
  ASSERT_FALSE(decode(png).empty());
  std::vector<std::uint8_t> bad_crc = png;
  bad_crc[40] ^= 1;  // the text chunk's name: its CRC no longer matches
  EXPECT_TRUE(decode(bad_crc).empty()) << "bad CRC";
  EXPECT_TRUE(decode(std::vector<std::uint8_t>(png.begin(), png.end() - 12)).empty()) << "no IEND";
  EXPECT_TRUE(decode(std::vector<std::uint8_t>(png.begin(), png.begin() + png.size() / 2)).empty()) << "truncated";
  EXPECT_TRUE(decode(std::vector<std::uint8_t>(5, 0)).empty()) << "not a PNG";
}

TEST(PngDecode, TumFilesAsOpenCvDecodesThem) {
  const std::string seq = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(seq);
  int n = 0;
  for (const char* sub : {"depth", "rgb"})
    for (const auto& e : fs::directory_iterator(fs::path(seq) / sub)) {
      if (n++ % 25 != 0) continue;  // 24 of the 600 files
      const std::string path = e.path().string();
      const bool depth = std::string(sub) == "depth";
      expectSameAs(readPlainPng(path), cv::imread(path, depth ? cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR : cv::IMREAD_COLOR));
    }
  EXPECT_GT(n, 500);
}

TEST(PngEncode, DecodesToExactlyThePixelsEncoded) {
  cv::Mat smooth(48, 64, CV_8UC3);
  for (int y = 0; y < smooth.rows; ++y)
    for (int x = 0; x < smooth.cols; ++x) smooth.at<cv::Vec3b>(y, x) = cv::Vec3b(uchar(4 * x), uchar(5 * y), uchar(x + y));
  std::vector<cv::Mat> images = {smooth, colourImage(1, 1), colourImage(7, 1), colourImage(1, 7), colourImage(33, 17),
                                 colourImage(640, 480)};
  images.push_back(colourImage(80, 60)(cv::Rect(5, 3, 31, 20)));  // a view into a wider image: its own stride
  for (const cv::Mat& image : images) {
    SCOPED_TRACE(std::to_string(image.cols) + "x" + std::to_string(image.rows));
    const std::vector<std::uint8_t> png = encodeRgb8Png(image);
    EXPECT_TRUE(isRgb8Png(png, image.cols, image.rows));
    expectSameAs(cv::imdecode(png, cv::IMREAD_UNCHANGED), image);
    expectSameAs(decode(png), image);
  }
}

TEST(PngEncode, RefusesAnythingButEightBitBgr) {
  EXPECT_THROW(encodeRgb8Png(cv::Mat()), std::invalid_argument);
  EXPECT_THROW(encodeRgb8Png(cv::Mat(4, 4, CV_8UC1)), std::invalid_argument);
  EXPECT_THROW(encodeRgb8Png(cv::Mat(4, 4, CV_16UC3)), std::invalid_argument);
  EXPECT_THROW(encodeRgb8Png(cv::Mat(4, 4, CV_8UC4)), std::invalid_argument);
  const int sizes[3] = {2, 2, 2};
  EXPECT_THROW(encodeRgb8Png(cv::Mat(3, sizes, CV_8UC3)), std::invalid_argument);
}

// The files are no larger than OpenCV's at its fastest level on real colour (TUM's, as a Kinect records it).
TEST(PngEncode, TumColourAsSmallAsOpenCvsFastestFiles) {
  const std::string seq = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(seq);
  std::size_t ours = 0, opencv = 0;
  int n = 0;
  for (const auto& e : fs::directory_iterator(fs::path(seq) / "rgb")) {
    if (n++ % 50 != 0) continue;  // 6 of the 300 files
    const cv::Mat image = cv::imread(e.path().string(), cv::IMREAD_COLOR);
    const std::vector<std::uint8_t> png = encodeRgb8Png(image);
    expectSameAs(decode(png), image);
    std::vector<std::uint8_t> level1;
    ASSERT_TRUE(cv::imencode(".png", image, level1, {cv::IMWRITE_PNG_COMPRESSION, 1}));
    ours += png.size(), opencv += level1.size();
  }
  EXPECT_LT(double(ours), 1.02 * double(opencv)) << "ours " << ours << " bytes, OpenCV's " << opencv;
}

TEST(PngDecode, AnyColourImageBecomesEightBitBgr) {
  const cv::Mat bgr = colourImage(6, 4);
  cv::Mat grey, grey_alpha, bgra, wide;
  cv::cvtColor(bgr, grey, cv::COLOR_BGR2GRAY);
  cv::merge(std::vector<cv::Mat>{grey, cv::Mat(grey.size(), CV_8UC1, cv::Scalar(255))}, grey_alpha);
  cv::cvtColor(bgr, bgra, cv::COLOR_BGR2BGRA);
  bgr.convertTo(wide, CV_16U, 256.0);
  cv::Mat grey_bgr;
  cv::cvtColor(grey, grey_bgr, cv::COLOR_GRAY2BGR);
  expectSameAs(asBgr8(bgr), bgr);
  expectSameAs(asBgr8(grey), grey_bgr);
  expectSameAs(asBgr8(grey_alpha), grey_bgr);
  expectSameAs(asBgr8(bgra), bgr);
  expectSameAs(asBgr8(wide), bgr);
}

// What is wrong with an image file, said before OpenCV's decoder (libpng prints its own line, libjpeg
// fills a cut JPEG with grey).
TEST(PngDecode, DamageIsNamedBeforeOpenCvSeesIt) {
  const std::string dir = test::tempDir("png_damage");
  cv::Mat img(48, 64, CV_8UC3);
  cv::RNG(7).fill(img, cv::RNG::UNIFORM, 0, 255);  // its own generator: the data whichever tests ran before
  std::vector<std::uint8_t> png;
  ASSERT_TRUE(cv::imencode(".png", img, png));
  const auto write = [&](const std::string& name, const std::vector<std::uint8_t>& bytes) { return writeBytes(dir + "/" + name, bytes); };
  EXPECT_EQ(imageFileDamage(write("whole.png", png)), "");
  EXPECT_EQ(imageFileDamage(write("cut.png", std::vector<std::uint8_t>(png.begin(), png.end() - 5))), "truncated PNG");
  EXPECT_EQ(imageFileDamage(write("header.png", std::vector<std::uint8_t>(png.begin(), png.begin() + 20))), "truncated PNG");
  auto flipped = png;
  const std::size_t idat = std::string(png.begin(), png.end()).find("IDAT");
  ASSERT_NE(idat, std::string::npos);
  flipped[idat + 10] ^= 1;
  EXPECT_EQ(imageFileDamage(write("flipped.png", flipped)), "damaged PNG: its IDAT chunk fails its CRC");
  std::vector<std::uint8_t> jpeg;
  ASSERT_TRUE(cv::imencode(".jpg", img, jpeg));
  EXPECT_EQ(imageFileDamage(write("whole.jpg", jpeg)), "");
  auto padded = jpeg;  // data appended after the end marker (some writers do): still whole
  padded.insert(padded.end(), 300, std::uint8_t(0));
  EXPECT_EQ(imageFileDamage(write("padded.jpg", padded)), "");
  EXPECT_EQ(imageFileDamage(write("cut.jpg", std::vector<std::uint8_t>(jpeg.begin(), jpeg.end() - 100))), "truncated JPEG");
  // A camera's JPEG holds an EXIF thumbnail (a JPEG with its own end marker) in an APP1 segment before
  // the image: cut inside the image, it is truncated all the same (the thumbnail's marker passed it).
  std::vector<std::uint8_t> thumb;
  ASSERT_TRUE(cv::imencode(".jpg", img(cv::Rect(0, 0, 16, 12)), thumb));
  std::vector<std::uint8_t> app1{'E', 'x', 'i', 'f', 0, 0};
  app1.insert(app1.end(), thumb.begin(), thumb.end());
  const std::size_t len = app1.size() + 2;
  std::vector<std::uint8_t> camera{0xFF, 0xD8, 0xFF, 0xE1, std::uint8_t(len >> 8), std::uint8_t(len & 0xFF)};
  camera.insert(camera.end(), app1.begin(), app1.end());
  camera.insert(camera.end(), jpeg.begin() + 2, jpeg.end());  // the image's segments after its SOI
  EXPECT_EQ(imageFileDamage(write("camera.jpg", camera)), "");
  EXPECT_FALSE(cv::imread(dir + "/camera.jpg").empty());
  EXPECT_EQ(imageFileDamage(write("camera_cut.jpg", std::vector<std::uint8_t>(camera.begin(), camera.end() - 100))),
            "truncated JPEG");
  // Cut in its header, after the thumbnail (in the tables before the scan): truncated too.
  EXPECT_EQ(imageFileDamage(write("camera_head.jpg", std::vector<std::uint8_t>(camera.begin(), camera.begin() + 6 + app1.size() + 40))),
            "truncated JPEG");
  EXPECT_EQ(imageFileDamage(write("text.png", {'n', 'o', 't'})), "");  // neither: OpenCV decides
  EXPECT_EQ(imageFileDamage(dir), "");                                 // a folder is no file to read
  std::vector<std::uint8_t> bytes{1, 2, 3};
  EXPECT_FALSE(readWholeFile(dir, bytes));
}

// A whole PNG (CRCs, IEND) whose image data is damaged: short of its last rows, or a row with a filter
// type PNG has not. The plain decoder declined it and libpng, under cv::imread, printed "libpng error:
// Not enough image data" on a line of its own before the reader's line naming the file.
TEST(PngDecode, DamagedImageDataIsNamedBeforeOpenCvSeesIt) {
  const std::string dir = test::tempDir("png_data_damage");
  const cv::Mat depth = depthImage(40, 30);
  const auto write = [&](const std::string& name, const PngSpec& spec) { return writeBytes(dir + "/" + name, makePng(depth, spec)); };
  PngSpec few;
  few.rows_in_stream = 10;
  PngSpec bad_filter;
  bad_filter.bad_filter_row = 12;
  EXPECT_EQ(imageFileDamage(write("whole.png", {})), "");
  EXPECT_EQ(imageFileDamage(write("few.png", few)), "damaged PNG: its image data ends before its last row");
  EXPECT_EQ(imageFileDamage(write("filter.png", bad_filter)), "damaged PNG: row 12's filter type is 7 (0-4)");
  for (const char* name : {"few.png", "filter.png"}) {
    testing::internal::CaptureStderr();
    try {
      loadRawDepthPng(dir + "/" + name, 40, 30);
      ADD_FAILURE() << name << " decoded";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(std::string(name) + ": cannot decode depth image (damaged PNG"), std::string::npos) << e.what();
    }
    EXPECT_EQ(testing::internal::GetCapturedStderr(), "") << name;
  }
}

// A PNG's header states its size: a frame of another size is refused by it before decoding. A crafted
// 30000x30000 depth PNG of a few hundred bytes was decoded by OpenCV into a 1.8 GB image first.
TEST(PngDecode, AnImageOfAnotherSizeIsRefusedByItsHeader) {
  const std::string dir = test::tempDir("png_header_size");
  const auto write = [&](const std::string& name, const std::vector<std::uint8_t>& bytes) { return writeBytes(dir + "/" + name, bytes); };
  std::vector<std::uint8_t> png = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'}, ihdr;
  put32(ihdr, 30000);
  put32(ihdr, 30000);
  ihdr.insert(ihdr.end(), {16, 0, 0, 0, 0});
  chunk(png, "IHDR", ihdr);
  const std::vector<std::uint8_t> zeros(60001, 0);  // one row, filter 0
  std::vector<std::uint8_t> z(compressBound(uLong(zeros.size())));
  uLongf zlen = z.size();
  ASSERT_EQ(compress2(z.data(), &zlen, zeros.data(), uLong(zeros.size()), 9), Z_OK);
  z.resize(zlen);
  chunk(png, "IDAT", z);
  chunk(png, "IEND", {});
  const std::string huge = write("huge.png", png);
  EXPECT_EQ(pngHeaderSize(huge), cv::Size(30000, 30000));
  for (const bool colour : {false, true})
    try {
      colour ? loadColour(huge, 64, 48) : loadRawDepthPng(huge, 64, 48);
      ADD_FAILURE() << "a 30000x30000 image was taken for 64x48";
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()), huge + (colour ? ": colour" : ": depth") + " image is 30000x30000, expected 64x48");
    }
  // A whole image of another size: the same line as after decoding.
  std::vector<std::uint8_t> small;
  ASSERT_TRUE(cv::imencode(".png", depthImage(32, 24), small));
  const std::string other = write("other.png", small);
  EXPECT_EQ(pngHeaderSize(other), cv::Size(32, 24));
  EXPECT_THROW(loadRawDepthPng(other, 64, 48), InputError);
  EXPECT_EQ(loadRawDepthPng(other, 32, 24).size(), cv::Size(32, 24));
  EXPECT_TRUE(pngHeaderSize(write("text.png", {'n', 'o', 't'})).empty());
  EXPECT_TRUE(pngHeaderSize(dir + "/missing.png").empty());
}

// A FIFO named as an image (a rawlog's external colour file) is not opened: opening it waits for a
// writer, and the reader hung instead of saying one line. Each reader gives up at once, and the
// cause is said.
TEST(PngDecode, AFifoNamedAsAnImageIsNeverOpened) {
  const std::string fifo = test::tempDir("png_fifo") + "/colour.png";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const std::optional<std::string> said = test::resultWithin<std::string>(10, [fifo] {
    cv::Size stated;
    const bool nothing = readPlainPng(fifo, {}, &stated).empty() && stated.empty() && pngHeaderSize(fifo).empty() &&
                         imageFileDamage(fifo).empty() && readJpeg(fifo).header.empty();
    return nothing ? whyUnreadable(fifo) : std::string("a reader got something from it");
  });
  ASSERT_TRUE(said.has_value()) << "blocked opening the FIFO";
  EXPECT_EQ(*said, "not a regular file (a FIFO or a device?)");
  EXPECT_EQ(whyUnreadable(test::tempDir("png_fifo")), "a folder, not a file");
}
