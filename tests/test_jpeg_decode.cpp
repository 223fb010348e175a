// decodeJpeg gives cv::imdecode's pixels for a whole JPEG (colour and grey), and names the damage of
// one whose entropy-coded data libjpeg finds corrupt, where cv::imdecode returns a picture with smeared
// blocks; the TUM reader refuses such a colour image in one line naming the file.
#include <gtest/gtest.h>

#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "support.h"
#include "vofusion/core/errors.h"
#include "vofusion/io/jpeg_decode.h"
#include "vofusion/io/tum_source.h"

using namespace vofusion;

namespace {

// A picture with edges and texture at every scale (random noise alone is one the encoder cannot
// compress, a flat one decodes to no data worth damaging).
cv::Mat scene(int w, int h) {
  cv::Mat img(h, w, CV_8UC3);
  cv::RNG rng(7);
  rng.fill(img, cv::RNG::UNIFORM, 0, 255);
  cv::GaussianBlur(img, img, cv::Size(0, 0), 3.0);
  for (int k = 0; k < 40; ++k)
    cv::rectangle(img, cv::Rect(rng.uniform(0, w), rng.uniform(0, h), rng.uniform(4, w / 3), rng.uniform(4, h / 3)),
                  cv::Scalar(rng.uniform(0, 255), rng.uniform(0, 255), rng.uniform(0, 255)), rng.uniform(-1, 3));
  return img;
}

std::vector<std::uint8_t> encodeJpeg(const cv::Mat& img) {
  std::vector<std::uint8_t> jpeg;
  EXPECT_TRUE(cv::imencode(".jpg", img, jpeg, {cv::IMWRITE_JPEG_QUALITY, 90}));
  return jpeg;
}

bool same(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0;
}

std::string writeFile(const std::string& path, const std::vector<std::uint8_t>& bytes) {
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
  return path;
}

// The two ways a whole-looking file is damaged that libjpeg notices: bytes lost from the middle (a
// copy or a transfer with a hole), and a marker where data should be (test::jpegWithMarkerInside).
std::vector<std::uint8_t> withHole(std::vector<std::uint8_t> jpeg) {
  const std::size_t scan = test::jpegScanStart(jpeg), mid = scan + (jpeg.size() - scan) / 2;
  jpeg.erase(jpeg.begin() + std::ptrdiff_t(mid), jpeg.begin() + std::ptrdiff_t(mid + (jpeg.size() - scan) / 4));
  return jpeg;
}
}  // namespace

TEST(JpegDecode, AWholeJpegDecodesToOpenCvsPixels) {
  const cv::Mat colour = scene(160, 120);
  cv::Mat grey;
  cv::cvtColor(colour, grey, cv::COLOR_BGR2GRAY);
  for (const cv::Mat& img : {colour, grey}) {
    const std::vector<std::uint8_t> jpeg = encodeJpeg(img);
    const JpegDecode d = decodeJpeg(jpeg.data(), jpeg.size());
    EXPECT_EQ(d.damage, "");
    EXPECT_EQ(d.header, cv::Size(160, 120));
    EXPECT_TRUE(same(d.image, cv::imdecode(jpeg, cv::IMREAD_UNCHANGED))) << img.channels() << " channels";
  }
  const std::vector<std::uint8_t> png{0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  const JpegDecode none = decodeJpeg(png.data(), png.size());  // no JPEG: the caller's cv::imread decides
  EXPECT_TRUE(none.image.empty());
  EXPECT_EQ(none.damage, "");
  EXPECT_TRUE(none.header.empty());
}

TEST(JpegDecode, CorruptDataIsDamageWhereOpenCvGivesAPicture) {
  const std::vector<std::uint8_t> whole = encodeJpeg(scene(320, 240));
  const cv::Mat clean = cv::imdecode(whole, cv::IMREAD_UNCHANGED);
  for (const auto& damaged : {withHole(whole), test::jpegWithMarkerInside(whole)}) {
    const cv::Mat passed = cv::imdecode(damaged, cv::IMREAD_UNCHANGED);  // what cv::imread hands on
    ASSERT_EQ(passed.size(), clean.size());
    EXPECT_FALSE(same(passed, clean));
    const JpegDecode d = decodeJpeg(damaged.data(), damaged.size());
    EXPECT_TRUE(d.image.empty());
    EXPECT_EQ(d.damage.rfind("Corrupt JPEG data: ", 0), 0u) << d.damage;
  }
}

// What libjpeg warns of but is no damage: zero bytes before the end marker (some MJPEG cameras pad every
// frame so), zeros between header segments, and a baseline scan whose spectral bytes are zero (libjpeg
// corrects them). Each decodes to the whole file's pixels.
TEST(JpegDecode, PaddingAndCorrectedScanParametersAreNoDamage) {
  const std::vector<std::uint8_t> whole = encodeJpeg(scene(160, 120));
  const cv::Mat clean = cv::imdecode(whole, cv::IMREAD_UNCHANGED);
  auto padded = whole;
  padded.insert(padded.end() - 2, 16, std::uint8_t(0));
  auto spaced = whole;
  const std::size_t dqt = std::string(whole.begin(), whole.end()).find("\xFF\xDB");
  ASSERT_NE(dqt, std::string::npos);
  spaced.insert(spaced.begin() + std::ptrdiff_t(dqt), 4, std::uint8_t(0));
  auto zero_se = whole;
  const std::size_t sos = std::string(whole.begin(), whole.end()).find("\xFF\xDA");
  ASSERT_NE(sos, std::string::npos);
  zero_se[sos + 4 + 1 + 2 * whole[sos + 4] + 1] = 0;  // Se: after the length, Ns, the components and Ss
  for (const auto& bytes : {padded, spaced, zero_se}) {
    const JpegDecode d = decodeJpeg(bytes.data(), bytes.size());
    EXPECT_EQ(d.damage, "");
    EXPECT_TRUE(same(d.image, clean));
  }
}

// A file with restart intervals, as MJPEG webcams write, with a few bytes left before restart markers
// (zeros, or not): libjpeg resynchronises at each marker and the pixels are the whole file's. Every
// frame of such a camera warns "extraneous bytes before marker 0xd<n>".
TEST(JpegDecode, BytesBeforeARestartMarkerAreNoDamage) {
  std::vector<std::uint8_t> whole;
  ASSERT_TRUE(cv::imencode(".jpg", scene(320, 240), whole, {cv::IMWRITE_JPEG_QUALITY, 90, cv::IMWRITE_JPEG_RST_INTERVAL, 4}));
  const cv::Mat clean = cv::imdecode(whole, cv::IMREAD_UNCHANGED);
  std::vector<std::size_t> restarts;  // where each RSTn marker starts
  for (std::size_t at = test::jpegScanStart(whole); at + 1 < whole.size(); ++at)
    if (whole[at] == 0xFF && whole[at + 1] >= 0xD0 && whole[at + 1] <= 0xD7) restarts.push_back(at);
  ASSERT_GT(restarts.size(), 20u);
  for (const std::uint8_t fill : {0x00, 0xAB}) {
    for (const std::size_t k : {restarts.size() / 4, restarts.size() / 2, restarts.size() - 1}) {
      auto padded = whole;
      padded.insert(padded.begin() + std::ptrdiff_t(restarts[k]), 2, fill);
      ASSERT_TRUE(same(cv::imdecode(padded, cv::IMREAD_UNCHANGED), clean)) << "the padding changed the picture";
      const JpegDecode d = decodeJpeg(padded.data(), padded.size());
      EXPECT_EQ(d.damage, "") << int(fill) << " before restart " << k;
      EXPECT_TRUE(same(d.image, clean));
    }
  }
}

// A bit flipped in the scan that leaves the decoder short of its end: the rest of the data is
// discarded before the end marker ("extraneous bytes"), and the picture is another one.
TEST(JpegDecode, ImageDataLeftOverAtTheEndIsDamage) {
  const std::vector<std::uint8_t> whole = encodeJpeg(scene(320, 240));
  const cv::Mat clean = cv::imdecode(whole, cv::IMREAD_UNCHANGED);
  const std::size_t start = test::jpegScanStart(whole) + (whole.size() - test::jpegScanStart(whole)) / 3;
  int found = 0;
  for (std::size_t at = start; at < start + 400 && found < 3; ++at) {
    auto flipped = whole;
    flipped[at] ^= 0x10;
    const JpegDecode d = decodeJpeg(flipped.data(), flipped.size());
    if (d.damage.find("extraneous bytes") == std::string::npos) continue;
    ++found;
    EXPECT_TRUE(d.image.empty());
    EXPECT_FALSE(same(cv::imdecode(flipped, cv::IMREAD_UNCHANGED), clean)) << "byte " << at;
  }
  EXPECT_EQ(found, 3) << "no flip among 400 bytes left data over";
}

// A header stating another size is not decoded (the reader refuses it before allocating its pixels).
TEST(JpegDecode, AnotherSizeIsToldByTheHeaderAlone) {
  const std::vector<std::uint8_t> jpeg = encodeJpeg(scene(160, 120));
  const JpegDecode d = decodeJpeg(jpeg.data(), jpeg.size(), cv::Size(640, 480));
  EXPECT_EQ(d.header, cv::Size(160, 120));
  EXPECT_TRUE(d.image.empty());
  EXPECT_EQ(d.damage, "");
}

TEST(TumImages, ACorruptButCompleteJpegIsRefusedInOneLine) {
  const std::string dir = test::tempDir("tum_corrupt_jpeg");
  const std::vector<std::uint8_t> whole = encodeJpeg(scene(320, 240));
  EXPECT_EQ(loadColour(writeFile(dir + "/whole.jpg", whole), 320, 240).size(), cv::Size(320, 240));
  const std::string damaged = writeFile(dir + "/damaged.jpg", withHole(whole));
  try {
    loadColour(damaged, 320, 240);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()).rfind(damaged + ": cannot decode colour image (Corrupt JPEG data: ", 0), 0u) << e.what();
  }
  // The recording's size comes from a JPEG that decodes whole, and libjpeg prints no line of its own.
  const std::string small = writeFile(dir + "/small.jpg", encodeJpeg(scene(160, 120)));
  testing::internal::CaptureStderr();
  const std::optional<cv::Size> size = recordingImageSize({damaged, small});
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "");
  EXPECT_EQ(size, std::optional<cv::Size>(cv::Size(160, 120)));
  try {
    loadColour(dir + "/whole.jpg", 640, 480);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), dir + "/whole.jpg: colour image is 320x240, expected 640x480");
  }
}
