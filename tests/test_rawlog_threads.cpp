// Readers and writers of different rawlogs in one process (issue 34): each resolves its own external
// files, never through MRPT's process-wide images folder, so none reads or writes another's images.
#include <cstdio>
#include <cmath>
#include <cstring>
#include <limits>
#include <filesystem>
#include <tuple>
#include <fstream>
#include <thread>
#include <vector>

#include <mrpt/img/CImage.h>
#include <mrpt/io/CFileGZInputStream.h>
#include <mrpt/io/lazy_load_path.h>
#include <opencv2/core.hpp>
#include <sys/stat.h>

#include "support.h"
#include "vofusion/core/deflate.h"
#include "vofusion/core/errors.h"
#include "vofusion/io/external_files.h"
#include "vofusion/io/prefetching_source.h"
#include "vofusion/io/rawlog.h"

using namespace vofusion;
using mrpt::obs::CObservation3DRangeScan;
namespace fs = std::filesystem;

namespace {
// A small frame whose every pixel says which recording and which frame it is. Every recording uses the
// same timestamps, so the same image file names ("KINECT_000007_1.233333_INTENSITY.png").
Frame markedFrame(int recording, std::size_t i) {
  Frame f;
  f.index = i;
  f.timestamp = 1.0 + i / 30.0;
  f.camera = CameraIntrinsics{}.scaled(0.05);  // 32x24
  f.rgb.create(f.camera.height, f.camera.width, CV_8UC3);
  f.depth.create(f.camera.height, f.camera.width, CV_32F);
  for (int r = 0; r < f.rgb.rows; ++r)
    for (int c = 0; c < f.rgb.cols; ++c) {
      f.rgb.at<cv::Vec3b>(r, c) = cv::Vec3b(uchar(40 * recording + r), uchar(i % 256), uchar(i / 256 + c));
      f.depth.at<float>(r, c) = float((5000 + 700 * recording + (i % 600) + r + c) * 2e-4);  // exact in 2e-4 m units
    }
  return f;
}

// Whether a frame read back is exactly frame i of `recording` (depth to its 0.2 mm quantum).
bool isMarkedFrame(const Frame& f, int recording, std::size_t i) {
  const Frame e = markedFrame(recording, i);
  return f.rgb.size() == e.rgb.size() && cv::norm(f.rgb, e.rgb, cv::NORM_INF) == 0 &&
         cv::norm(f.depth, e.depth, cv::NORM_INF) < 1e-4;
}

void writeMarked(const std::string& path, int recording, std::size_t frames) {
  RawlogWriter w(path);
  for (std::size_t i = 0; i < frames; ++i) w.write(markedFrame(recording, i));
  w.commit();
}

// Reads the rawlog `passes` times (through the prefetch thread, as the apps do); counts wrong frames.
// A frame that cannot be read at all (its image looked for in another folder) ends the pass: the frames
// left count as wrong, and `error` keeps the message.
std::size_t readMarked(const std::string& path, int recording, int passes, std::string* error = nullptr) {
  std::size_t wrong = 0;
  for (int p = 0; p < passes; ++p) {
    PrefetchingSource src(std::make_unique<RawlogSource>(path, SourceOptions{}));
    Frame f;
    std::size_t i = 0;
    try {
      for (; src.next(f); ++i) wrong += !isMarkedFrame(f, recording, i);
    } catch (const InputError& e) {
      if (error) *error = e.what();
    }
    wrong += src.size() - i;
  }
  return wrong;
}

// Frame `frame`'s file with extension `ext` (".png" colour, ".bin" range image) in a rawlog's images
// folder written by RawlogWriter; empty when there is none.
std::string imageFile(const std::string& images_dir, std::size_t frame, const std::string& ext) {
  char stem[32];
  std::snprintf(stem, sizeof stem, "KINECT_%06zu_", frame);
  for (const auto& e : fs::directory_iterator(images_dir))
    if (e.path().filename().string().rfind(stem, 0) == 0 && e.path().extension() == ext) return e.path().string();
  return "";
}

std::vector<unsigned char> gunzip(const std::string& path) {
  mrpt::io::CFileGZInputStream in(path);
  std::vector<unsigned char> bytes, buf(1 << 16);
  for (std::size_t n; (n = in.Read(buf.data(), buf.size())) > 0;) bytes.insert(bytes.end(), buf.begin(), buf.begin() + n);
  return bytes;
}
}  // namespace

// Three readers (each with its prefetch thread) and two writers, five recordings in five folders with
// the same image names, 3000 frames in all: every image read is its own recording's, every run.
TEST(RawlogThreads, ReadersAndWritersOfDifferentRawlogsReadOnlyTheirOwnImages) {
  const std::string dir = test::tempDir("rawlog_threads");
  constexpr std::size_t kFrames = 300;
  constexpr int kReaders = 3, kWriters = 2, kPasses = 2;
  auto rawlog = [&](int k) { return dir + "/rec" + std::to_string(k) + "/rec.rawlog"; };
  for (int k = 0; k < kReaders + kWriters; ++k) fs::create_directories(fs::path(rawlog(k)).parent_path());
  for (int k = 0; k < kReaders; ++k) writeMarked(rawlog(k), k, kFrames);

  std::vector<std::size_t> wrong(kReaders, 0);
  std::vector<std::string> errors(kReaders);
  std::vector<std::thread> threads;
  for (int k = 0; k < kReaders; ++k)
    threads.emplace_back([&, k] { wrong[k] = readMarked(rawlog(k), k, kPasses, &errors[k]); });
  for (int k = kReaders; k < kReaders + kWriters; ++k)
    threads.emplace_back([&, k] {
      for (int p = 0; p < kPasses; ++p) writeMarked(rawlog(k), k, kFrames);
    });
  for (auto& t : threads) t.join();

  for (int k = 0; k < kReaders; ++k) EXPECT_EQ(wrong[k], 0u) << "reader " << k << " read other images: " << errors[k];
  for (int k = kReaders; k < kReaders + kWriters; ++k)
    EXPECT_EQ(readMarked(rawlog(k), k, 1), 0u) << "writer " << k << " wrote into another recording's folder";
}

// Reading a rawlog neither needs MRPT's images folder nor changes it.
TEST(RawlogThreads, ReadingLeavesMrptsImagesFolderAlone) {
  const std::string dir = test::tempDir("rawlog_images_folder");
  writeMarked(dir + "/a.rawlog", 1, 5);
  const std::string before = mrpt::img::CImage::getImagesPathBase();
  mrpt::img::CImage::setImagesPathBase(dir + "/no_such_folder");
  const std::size_t wrong = readMarked(dir + "/a.rawlog", 1, 1);
  EXPECT_EQ(mrpt::img::CImage::getImagesPathBase(), dir + "/no_such_folder");
  mrpt::img::CImage::setImagesPathBase(before);
  EXPECT_EQ(wrong, 0u);
}

// The range image file is MRPT's own format: the same bytes as rangeImage_convertToExternalStorage,
// and MRPT's load() reads it back.
TEST(RawlogThreads, RangeImageFileIsMrptsFormat) {
  const std::string dir = test::tempDir("range_image_format");
  auto ours = observationFromFrame(markedFrame(2, 77));
  auto mrpts = observationFromFrame(markedFrame(2, 77));
  const auto expected = ours->rangeImage;
  writeRangeImageExternally(*ours, "ours_DEPTH.bin", dir);
  mrpts->rangeImage_convertToExternalStorage("mrpt_DEPTH.bin", dir + "/");
  EXPECT_TRUE(ours->rangeImage_isExternallyStored());
  EXPECT_EQ(ours->rangeImage_getExternalStorageFile(""), "ours_DEPTH.bin");  // relative: the rawlog can move
  EXPECT_EQ(ours->rangeImage.size(), 0u);
  EXPECT_EQ(gunzip(dir + "/ours_DEPTH.bin"), gunzip(dir + "/mrpt_DEPTH.bin"));

  resolveExternalFiles(*ours, dir);
  EXPECT_EQ(ours->rangeImage_getExternalStorageFile(""), (fs::absolute(dir) / "ours_DEPTH.bin").string());
  ours->load();
  EXPECT_EQ(ours->rangeImage.asEigen(), expected.asEigen());
}

TEST(RawlogThreads, RangeImageThatCannotBeWrittenNamesTheFile) {
  auto obs = observationFromFrame(markedFrame(0, 0));
  try {
    writeRangeImageExternally(*obs, "x_DEPTH.bin", "/nonexistent_folder_vofusion");
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent_folder_vofusion/x_DEPTH.bin: "), std::string::npos) << e.what();
  }
}

// A range image file is read checked whole: the same matrix as MRPT's load() reads from MRPT's own file,
// and one cut short, with a flipped bit, or empty is an InputError naming it.
TEST(RawlogThreads, RangeImageFileIsReadCheckedWhole) {
  const std::string dir = test::tempDir("range_image_checked");
  auto ours = observationFromFrame(markedFrame(3, 41));
  auto mrpts = observationFromFrame(markedFrame(3, 41));
  mrpts->rangeImage_convertToExternalStorage("mrpt_DEPTH.bin", dir + "/");
  resolveExternalFiles(*mrpts, dir);
  *ours = *mrpts;
  mrpts->load();
  loadExternalRangeImage(*ours);
  EXPECT_FALSE(ours->rangeImage_isExternallyStored());
  EXPECT_EQ(ours->rangeImage.asEigen(), mrpts->rangeImage.asEigen());

  const std::string file = dir + "/mrpt_DEPTH.bin";
  std::string bytes;
  {
    std::ifstream in(file, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  std::string flipped = bytes;
  flipped[bytes.size() / 2] ^= 0x10;
  // MRPT reads every name but a .txt as binary: an upper-case .BIN is checked too.
  const std::string upper = dir + "/upper_DEPTH.BIN";
  for (const auto& [name, content, problem] : std::vector<std::tuple<std::string, std::string, std::string>>{
           {file, bytes.substr(0, bytes.size() / 2), "cut short"},
           {file, flipped, "a flipped bit"},
           {upper, flipped, "a flipped bit, named .BIN"}}) {
    std::ofstream(name, std::ios::binary | std::ios::trunc) << content;
    auto obs = observationFromFrame(markedFrame(3, 41));
    useExternalRangeImage(*obs, name);
    try {
      loadExternalRangeImage(*obs);
      ADD_FAILURE() << "no error for a file " << problem;
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()), name + ": corrupt range image file (cut short or damaged: its gzip check fails)");
    }
  }
  // Dimensions whose product wraps in 64 bits to the readings' size (65536 x 2 bytes here): no range
  // image of 2^31 rows, left to MRPT (within the reader's memory limit). Taken as the size, it asked for
  // 2^63 readings, and std::length_error ended the run.
  {
    std::vector<std::uint8_t> crafted(8 + 65536, 0);
    const std::uint32_t dims[2] = {(1u << 31) + 32768u, 0xFFFFFFFFu - 65534u};
    std::memcpy(crafted.data(), dims, sizeof dims);
    const std::vector<std::uint8_t> gz = gzipCompress(crafted.data(), crafted.size());
    std::ofstream(file, std::ios::binary | std::ios::trunc).write(reinterpret_cast<const char*>(gz.data()), std::streamsize(gz.size()));
    auto obs = observationFromFrame(markedFrame(3, 41));
    useExternalRangeImage(*obs, file);
    std::optional<DepthFile> read;
    ASSERT_NO_THROW(read = loadExternalRangeImage(*obs));
    EXPECT_FALSE(read.has_value());
    EXPECT_TRUE(obs->rangeImage_isExternallyStored()) << "left to MRPT's load()";
  }
  std::ofstream(file, std::ios::binary | std::ios::trunc).flush();
  auto empty = observationFromFrame(markedFrame(3, 41));
  useExternalRangeImage(*empty, file);
  EXPECT_THROW(
      {
        try {
          loadExternalRangeImage(*empty);
        } catch (const InputError& e) {
          EXPECT_EQ(std::string(e.what()), file + ": corrupt range image file (empty)");
          throw;
        }
      },
      InputError);
}

// A FIFO named as a text range image (MRPT's EXTERNALS_AS_TEXT) is not handed to MRPT's load(), which
// opens it as it is and waited for a writer for ever: the frame's error names it and says why.
TEST(RawlogThreads, AFifoNamedAsATextRangeImageIsNeverOpened) {
  const std::string fifo = test::tempDir("range_image_fifo") + "/t_DEPTH.txt";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const std::optional<std::string> said = test::resultWithin<std::string>(10, [fifo] {
    auto obs = observationFromFrame(markedFrame(5, 3));
    useExternalRangeImage(*obs, fifo);
    try {
      loadExternalRangeImage(*obs);
      return std::string("no error");
    } catch (const InputError& e) {
      return std::string(e.what());
    }
  });
  ASSERT_TRUE(said.has_value()) << "blocked opening the FIFO";
  EXPECT_EQ(*said, fifo + ": cannot load external range image (not a regular file (a FIFO or a device?))");
}

// What is not MRPT's gzip .bin of rows, cols and readings is left to MRPT's load(): a .txt
// (EXTERNALS_AS_TEXT), a plain .bin, a whole gzip of another layout (older rawlogs hold floats).
TEST(RawlogThreads, OtherRangeImageFilesAreLeftToMrpt) {
  const std::string dir = test::tempDir("range_image_others");
  const auto leftToMrpt = [&](const std::string& name) {
    auto obs = observationFromFrame(markedFrame(5, 3));
    useExternalRangeImage(*obs, (fs::path(dir) / name).string());
    const bool read_here = loadExternalRangeImage(*obs).has_value();  // a frame from it names no file to copy
    return !read_here && obs->rangeImage_isExternallyStored();
  };
  auto text = observationFromFrame(markedFrame(5, 3));
  const auto expected = text->rangeImage;
  CObservation3DRangeScan::EXTERNALS_AS_TEXT(true);
  text->rangeImage_convertToExternalStorage("t_DEPTH.txt", dir + "/");
  CObservation3DRangeScan::EXTERNALS_AS_TEXT(false);
  EXPECT_TRUE(leftToMrpt("t_DEPTH.txt"));
  resolveExternalFiles(*text, dir);
  loadExternalRangeImage(*text);
  text->load();
  EXPECT_EQ(text->rangeImage.asEigen(), expected.asEigen());

  std::ofstream(dir + "/plain_DEPTH.bin", std::ios::binary) << "not gzip";
  EXPECT_TRUE(leftToMrpt("plain_DEPTH.bin"));
  const std::uint32_t dims[2] = {24, 33};  // with 4-byte readings, not 2
  std::vector<unsigned char> raw(sizeof dims + 24 * 33 * 4, 7);
  std::memcpy(raw.data(), dims, sizeof dims);
  const auto packed = gzipCompress(raw.data(), raw.size());
  std::ofstream(dir + "/floats_DEPTH.bin", std::ios::binary).write(reinterpret_cast<const char*>(packed.data()), packed.size());
  EXPECT_TRUE(leftToMrpt("floats_DEPTH.bin"));
}

// Through a rawlog: the frame whose range image file is damaged is skipped as damaged, naming the file;
// the others read as written.
TEST(RawlogThreads, AFrameWithADamagedRangeImageFileIsSkipped) {
  const std::string dir = test::tempDir("range_image_damaged");
  writeMarked(dir + "/a.rawlog", 2, 5);
  const std::string damaged = imageFile(dir + "/a_Images", 2, ".bin");
  ASSERT_FALSE(damaged.empty());
  fs::resize_file(damaged, fs::file_size(damaged) - 9);
  RawlogSource src(dir + "/a.rawlog", SourceOptions{});
  Frame f;
  for (std::size_t i = 0; i < 5; ++i) {
    if (i == 2) {
      try {
        src.next(f);
        ADD_FAILURE() << "frame 2 read";
      } catch (const DamagedFrame& e) {
        EXPECT_NE(std::string(e.what()).find(fs::path(damaged).filename().string() + ": corrupt range image file"),
                  std::string::npos) << e.what();
      }
      continue;
    }
    ASSERT_TRUE(src.next(f));
    EXPECT_TRUE(isMarkedFrame(f, 2, i)) << i;
  }
}

// A reading beyond 16 bits of the range units is written as no reading (0), not clipped to the largest
// value (a surface at the wrong distance); the others are kept to their unit.
TEST(RawlogThreads, AReadingBeyondTheRangeUnitsIsWrittenAsNoReading) {
  const std::string dir = test::tempDir("range_units_reach");
  Frame f = markedFrame(1, 0);
  f.depth.at<float>(3, 4) = 7.0f;  // 70 000 units of 0.1 mm: beyond 6.5535 m
  RawlogWriterOptions options;
  options.range_units = 1e-4;
  {
    RawlogWriter w(dir + "/r.rawlog", options);
    w.write(f);
    testing::internal::CaptureStderr();
    w.commit();
    EXPECT_EQ(testing::internal::GetCapturedStderr(),
              "warning: " + dir + "/r.rawlog: 1 depth readings beyond 6.55 m (65535 range units) written as no " +
                  "reading; a larger --range-units keeps them\n");
  }
  RawlogSource src(dir + "/r.rawlog", SourceOptions{});
  Frame back;
  ASSERT_TRUE(src.next(back));
  EXPECT_EQ(back.depth.at<float>(3, 4), 0.f);
  f.depth.at<float>(3, 4) = 0.f;
  EXPECT_LT(cv::norm(back.depth, f.depth, cv::NORM_INF), 0.6e-4);
}

// Depth to range units rounds as std::round does, halves away from zero, at the edges too: values a
// hair either side of a half, the largest unit, what lies beyond it, and readings that are none.
TEST(RawlogThreads, RangeUnitsRoundAsStdRound) {
  Frame f = markedFrame(1, 0);
  const double scale = 1024.0;  // units of 1/1024 m: every depth below is a float, its units x exact
  std::vector<float> z;
  for (const double units : {0.0, 1.0, 7.0, 1234.0, 5000.0, 65534.0, 65535.0})
    for (const double frac : {0.0, 0.25, 0.5, 0.75}) {
      const float d = float((units + frac) / scale);
      z.insert(z.end(), {d, std::nextafter(d, 0.f), std::nextafter(d, 100.f)});
    }
  const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
  z.insert(z.end(), {65535.5f / 1024, 70000.f / 1024, 1e30f, -0.5f, 0.f, inf, -inf, nan});
  ASSERT_LE(z.size(), std::size_t(f.depth.total()));
  f.depth.setTo(0.f);
  std::copy(z.begin(), z.end(), f.depth.ptr<float>(0));
  const auto obs = observationFromFrame(f, 1.0 / 1024);
  int beyond = 0;
  for (std::size_t i = 0; i < z.size(); ++i) {
    const double x = double(z[i]) * scale;
    double want = (std::isfinite(x) && x > 0) ? std::round(x) : 0.0;
    if (want > 65535.0) want = 0.0, ++beyond;
    EXPECT_EQ(obs->rangeImage(int(i / f.depth.cols), int(i % f.depth.cols)), std::uint16_t(want)) << "depth " << z[i];
  }
  EXPECT_EQ(beyond, 8);  // 65535.5 and above: 2 at 65535.5, 3 at 65535.75, the last three
}

// A colour image cut short is the frame's damage in one line of ours (libpng printed its own line
// before it, "libpng error: PNG input buffer is incomplete").
TEST(RawlogThreads, AColourImageCutShortIsSaidOnceByUs) {
  const std::string dir = test::tempDir("intensity_cut_short");
  writeMarked(dir + "/a.rawlog", 4, 3);
  const std::string damaged = imageFile(dir + "/a_Images", 1, ".png");
  ASSERT_FALSE(damaged.empty());
  fs::resize_file(damaged, fs::file_size(damaged) / 2);
  RawlogSource src(dir + "/a.rawlog", SourceOptions{});
  Frame f;
  ASSERT_TRUE(src.next(f));
  testing::internal::CaptureStderr();
  try {
    src.next(f);
    ADD_FAILURE() << "frame 1 read";
  } catch (const DamagedFrame& e) {
    EXPECT_EQ(std::string(e.what()), damaged + ": cannot load intensity image (truncated PNG)");
  }
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "");
  ASSERT_TRUE(src.next(f));
  EXPECT_TRUE(isMarkedFrame(f, 4, 2));
}
