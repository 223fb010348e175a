#include <Eigen/Dense>
// TUM lists, association, trajectories and the TUM folder source.
#include <sys/stat.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <future>
#include <memory>
#include <thread>
#include <opencv2/imgcodecs.hpp>

#include "support.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/trajectory.h"
#include "vofusion/io/jpeg_decode.h"
#include "vofusion/io/png_decode.h"
#include "vofusion/io/tum_source.h"

using namespace vofusion;
namespace fs = std::filesystem;

TEST(TumList, ParsesCommentsAndEntries) {
  const auto l = parseTumList("# comment\n1.0 rgb/a.png\n\n2.5 rgb/b.png\n", "x");
  ASSERT_EQ(l.size(), 2u);
  EXPECT_DOUBLE_EQ(l[1].timestamp, 2.5);
  EXPECT_EQ(l[1].file, "rgb/b.png");
}

// Lines ended by CR alone (classic Mac OS) are lines: the file read as one comment, "lists no frames".
TEST(TumList, LinesEndedByCarriageReturnsAlone) {
  const auto l = parseTumList("# colour images\r1.0 rgb/a.png\r2.5 rgb/b.png\r", "x");
  ASSERT_EQ(l.size(), 2u);
  EXPECT_EQ(l[1].file, "rgb/b.png");
}

// Comma-separated lists are read as TUM's associate.py reads them: a comma parts the fields. The file
// was ",rgb/a.png", and the error named an image that does not exist instead of the list.
TEST(TumList, CommasPartFieldsAsTumsToolsRead) {
  const auto l = parseTumList("1.0,rgb/a.png\n2.5, rgb/b.png\n", "x");
  ASSERT_EQ(l.size(), 2u);
  EXPECT_EQ(l[0].file, "rgb/a.png");
  EXPECT_DOUBLE_EQ(l[1].timestamp, 2.5);
  EXPECT_EQ(l[1].file, "rgb/b.png");
  // A file name with a comma cannot be listed; the line says why.
  TumListDamage damage;
  parseTumList("1.0 rgb/a,b.png\n2.0 rgb/c.png\n", "x", &damage);
  ASSERT_EQ(damage.problems.size(), 1u);
  EXPECT_NE(damage.problems[0].find("a comma parts fields"), std::string::npos) << damage.problems[0];
}

TEST(TumList, MalformedLineNamesFileAndLine) {
  try {
    parseTumList("1.0 a.png\nnot-a-number b.png\n", "rgb.txt");
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("rgb.txt: line 2"), std::string::npos) << e.what();
  }
}

// Given somewhere to say it, a damaged line is left out and described; the others are read.
TEST(TumList, DamagedLinesAreDescribedWhenAsked) {
  TumListDamage damage;
  const auto l = parseTumList("# c\n1.0 a.png\nx b.png\n2.0 c.png d\n0.5 e.png\n3.0 f.png\n3.5", "rgb.txt", &damage);
  ASSERT_EQ(l.size(), 2u);
  EXPECT_EQ(l[1].file, "f.png");
  EXPECT_EQ(damage.lines, 6u);
  EXPECT_EQ(damage.problems, (std::vector<std::string>{"line 3: expected 'timestamp filename'", "line 4: unexpected extra field 'd'",
                                                       "line 5: timestamp 0.500000 is out of order or duplicated",
                                                       "line 7: expected 'timestamp filename'"}));
}

// One stamp damaged forward (a digit changed) costs its own line: judged against the last line kept,
// every good line after it was "out of order", and the message named the first of them.
TEST(TumList, AStampDamagedForwardCostsOnlyItsOwnLine) {
  TumListDamage damage;
  const auto l = parseTumList("1.0 a.png\n2.0 b.png\n9.0 c.png\n3.0 d.png\n4.0 e.png\n5.0 f.png\n", "rgb.txt", &damage);
  ASSERT_EQ(l.size(), 5u);
  EXPECT_EQ(l[2].file, "d.png");
  EXPECT_EQ(damage.problems, (std::vector<std::string>{"line 3: timestamp 9.000000 is out of order or duplicated"}));
  // Damaged back, and a stamp given twice: the first line of the two is kept.
  TumListDamage back;
  const auto b = parseTumList("1.0 a.png\n2.0 b.png\n0.5 c.png\n2.0 d.png\n3.0 e.png\n", "rgb.txt", &back);
  ASSERT_EQ(b.size(), 3u);
  EXPECT_EQ(b[1].file, "b.png");
  EXPECT_EQ(back.problems, (std::vector<std::string>{"line 3: timestamp 0.500000 is out of order or duplicated",
                                                     "line 4: timestamp 2.000000 is out of order or duplicated"}));
}

TEST(TumList, DuplicateTimestampRejected) {
  EXPECT_THROW(parseTumList("1.0 a.png\n1.0 b.png\n", "rgb.txt"), InputError);
}

// Stamps in nanoseconds (a simulator's or a ROS 2 export's) are refused where they are read: every frame
// interval would be 1e9 times too long, and a rawlog written from them held every frame at 0 s.
TEST(TumList, StampsThatAreNotSecondsAreRefusedWithTheirLine) {
  try {
    parseTumList("# rgb\n1700000000033333333 rgb/1.png\n", "rgb.txt");
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("rgb.txt: line 2: timestamp 1.7e+18 is not in seconds"), std::string::npos)
        << e.what();
  }
  // Seconds before 1970 are seconds: a clock that starts at 0 and a colour image taken just before.
  EXPECT_EQ(parseTumList("-0.008 a.png\n0.0 b.png\n1305031102.175304 c.png\n", "rgb.txt").size(), 3u);
}

TEST(Associate, NearestWithinToleranceEachUsedOnce) {
  std::vector<TumEntry> rgb{{1.00, "a"}, {1.10, "b"}, {1.20, "c"}};
  std::vector<TumEntry> depth{{1.005, "da"}, {1.115, "db"}, {1.50, "dc"}};
  const auto a = associate(rgb, depth, 0.02);
  ASSERT_EQ(a.size(), 2u);
  EXPECT_EQ(a[0].depth.file, "da");
  EXPECT_EQ(a[1].depth.file, "db");
}

// Stamps exactly max_diff apart are no pair, as associate.py (abs(a - b) < max_difference) and the
// evaluation's association have it; binary fractions, so the difference is exact.
TEST(Associate, StampsExactlyTheToleranceApartAreNoPair) {
  const std::vector<TumEntry> rgb{{0.5, "c"}}, depth{{0.515625, "d"}};
  for (const bool one_to_one : {true, false}) EXPECT_TRUE(associate(rgb, depth, 0.015625, one_to_one).empty()) << one_to_one;
  EXPECT_EQ(associate(rgb, depth, 0.0156251).size(), 1u);
}

TEST(Associate, EveryDepthFrameTakesItsNearestColourUnlessOneToOne) {
  std::vector<TumEntry> rgb{{1.000, "a"}, {1.060, "c"}};
  std::vector<TumEntry> depth{{1.010, "d1"}, {1.018, "d2"}, {1.065, "d3"}};
  const auto nearest = associate(rgb, depth, 0.02, false);
  ASSERT_EQ(nearest.size(), 3u);
  EXPECT_EQ(nearest[0].rgb.file, "a");
  EXPECT_EQ(nearest[1].rgb.file, "a");  // 0.018 from a, 0.042 from c: a serves two depth frames
  EXPECT_EQ(nearest[2].rgb.file, "c");
  const auto unique = associate(rgb, depth, 0.02, true);
  ASSERT_EQ(unique.size(), 2u);
  EXPECT_EQ(unique[0].depth.file, "d1");
  EXPECT_EQ(unique[1].depth.file, "d3");
}

// Ties go as associate.py decides them (sorted by difference, then colour, then depth stamp): every
// depth frame halfway between two colour frames pairs with the earlier one, and no pair is lost. An
// unstable sort on the difference alone could pair colour k with depth k - 1 and leave frames out.
TEST(Associate, TiesAreDecidedByTheStampsAsAssociatePyDoes) {
  std::vector<TumEntry> rgb, depth;
  for (int k = 0; k < 40; ++k) {
    rgb.push_back({0.25 * k, "rgb" + std::to_string(k)});
    depth.push_back({0.25 * k + 0.125, "depth" + std::to_string(k)});
  }
  for (const bool one_to_one : {true, false}) {
    const auto pairs = associate(rgb, depth, 0.2, one_to_one);
    ASSERT_EQ(pairs.size(), 40u) << one_to_one;
    for (std::size_t k = 0; k < pairs.size(); ++k) {
      EXPECT_EQ(pairs[k].rgb.file, "rgb" + std::to_string(k)) << one_to_one;
      EXPECT_EQ(pairs[k].depth.file, "depth" + std::to_string(k)) << one_to_one;
    }
  }
}

TEST(TumFolder, FramesAreStampedAtTheirDepthCapture) {
  const std::string dir = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(dir);
  TumFolderSource src(dir, {});
  for (std::size_t i = 0; i < src.pairs().size(); ++i) {
    const auto& a = src.pairs()[i];
    EXPECT_LE(std::abs(a.rgb.timestamp - a.depth.timestamp), 0.02);
    if (i > 0) {
      EXPECT_GT(a.depth.timestamp, src.pairs()[i - 1].depth.timestamp);  // strictly increasing stamps
    }
  }
  const Frame f = src.read(5);
  EXPECT_DOUBLE_EQ(f.timestamp, src.pairs()[5].depth.timestamp);
  // The colour image's own capture time travels along (the odometry's keypoint bearings come from it).
  EXPECT_DOUBLE_EQ(f.timestamp + f.colour_offset, src.pairs()[5].rgb.timestamp);
}

// A JPEG tagged with an EXIF orientation ("rotate 90", as phones write): the size probe reads it as the
// frames are read, on the sensor's grid (it read it turned, 48x64, and every 64x48 frame was refused).
TEST(TumFolder, TheImageSizeIsTheFramesWhateverAnExifOrientationSays) {
  cv::Mat img(48, 64, CV_8UC3);
  cv::RNG(7).fill(img, cv::RNG::UNIFORM, 0, 255);  // its own generator: the data whichever tests ran before
  std::vector<std::uint8_t> jpeg;
  ASSERT_TRUE(cv::imencode(".jpg", img, jpeg));
  // APP1 "Exif", big-endian TIFF, one IFD entry: Orientation (0x0112) SHORT 1 = 6.
  const std::uint8_t exif[] = {0xFF, 0xE1, 0x00, 0x22, 'E', 'x', 'i', 'f', 0, 0, 'M', 'M', 0x00, 0x2A, 0, 0, 0, 8,
                               0x00, 0x01, 0x01, 0x12, 0x00, 0x03, 0, 0, 0, 1, 0x00, 0x06, 0, 0, 0, 0, 0, 0};
  jpeg.insert(jpeg.begin() + 2, std::begin(exif), std::end(exif));
  const std::string path = test::tempDir("exif_orientation") + "/rotated.jpg";
  {
    std::ofstream out(path, std::ios::binary);
    out.write(reinterpret_cast<const char*>(jpeg.data()), std::streamsize(jpeg.size()));
  }
  ASSERT_EQ(cv::imread(path, cv::IMREAD_COLOR).size(), cv::Size(48, 64)) << "OpenCV no longer turns it: the test shows nothing";
  const auto size = recordingImageSize({path});
  ASSERT_TRUE(size.has_value());
  EXPECT_EQ(*size, cv::Size(64, 48));
  EXPECT_EQ(loadColour(path, 64, 48).size(), cv::Size(64, 48));
}

// The recording's image size is the one most of its first PNGs' headers state, nothing decoded: an odd
// first image set the size of the whole recording (each later frame refused as the wrong size), and a
// crafted 30000x30000 one was decoded (1.8 GB) to find its size.
namespace {
// A flat w x h colour image at `path`, in the format its name's extension says; the path back.
std::string writeImage(const std::string& path, int w, int h) {
  EXPECT_TRUE(cv::imwrite(path, cv::Mat(h, w, CV_8UC3, cv::Scalar(10, 120, 200))));
  return path;
}
}  // namespace

TEST(TumFolder, TheImageSizeIsTheOneMostHeadersState) {
  const std::string dir = test::tempDir("image_size_vote");
  const auto png = [&](const std::string& name, int w, int h) { return writeImage(dir + "/" + name, w, h); };
  std::vector<std::uint8_t> bytes;
  ASSERT_TRUE(cv::imencode(".png", cv::Mat(48, 64, CV_8UC3, cv::Scalar(4, 5, 6)), bytes));
  for (const int at : {16, 20}) bytes[at] = 0, bytes[at + 1] = 0, bytes[at + 2] = 0x75, bytes[at + 3] = 0x30;  // 30000
  const std::string crafted = dir + "/crafted.png";
  {
    std::ofstream out(crafted, std::ios::binary);
    out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
  }
  ASSERT_EQ(pngHeaderSize(crafted), cv::Size(30000, 30000));
  const std::vector<std::string> paths{crafted, png("odd.png", 32, 24), png("a.png", 64, 48), png("b.png", 64, 48)};
  const auto size = recordingImageSize(paths);
  ASSERT_TRUE(size.has_value());
  EXPECT_EQ(*size, cv::Size(64, 48));
  // Every one of the size cut short: no size (the recording is refused at once, not frame by frame).
  std::vector<std::string> cut;
  for (const char* name : {"a.png", "b.png"}) {
    std::vector<std::uint8_t> whole;
    ASSERT_TRUE(cv::imencode(".png", cv::Mat(48, 64, CV_8UC3, cv::Scalar(7, 8, 9)), whole));
    cut.push_back(dir + "/cut_" + name);
    std::ofstream(cut.back(), std::ios::binary).write(reinterpret_cast<const char*>(whole.data()), std::streamsize(whole.size() / 2));
  }
  EXPECT_FALSE(recordingImageSize(cut).has_value());
  // A FIFO listed as an image is passed over, never opened (opening it would wait for a writer).
  const std::string fifo = dir + "/fifo.png";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const auto found = test::resultWithin<std::optional<cv::Size>>(10, [fifo, a = paths[2]] { return recordingImageSize({fifo, a}); });
  ASSERT_TRUE(found.has_value()) << "blocked opening the FIFO";
  EXPECT_EQ(*found, std::optional<cv::Size>(cv::Size(64, 48)));
}

// JPEGs vote by their headers too: the first readable JPEG was decoded and set the size, so one odd
// first frame (720x477 before 16x16 ones) made every later frame "the wrong size".
TEST(TumFolder, TheImageSizeIsTheOneMostJpegHeadersState) {
  const std::string dir = test::tempDir("image_size_vote_jpeg");
  const auto jpeg = [&](const std::string& name, int w, int h) { return writeImage(dir + "/" + name, w, h); };
  const std::vector<std::string> paths{jpeg("odd.jpg", 720, 477), jpeg("a.jpg", 16, 16), jpeg("b.jpg", 16, 16)};
  EXPECT_EQ(recordingImageSize(paths), std::optional<cv::Size>(cv::Size(16, 16)));
  // The most stated size whose files are all damaged gives way to the next one with a whole file.
  std::vector<std::uint8_t> whole;
  ASSERT_TRUE(cv::imencode(".jpg", cv::Mat(16, 16, CV_8UC3, cv::Scalar(1, 2, 3)), whole));
  std::vector<std::string> cut{paths[0]};
  for (const char* name : {"cut_a.jpg", "cut_b.jpg"}) {
    cut.push_back(dir + "/" + name);
    // Cut in the image data: its header still votes for 16x16.
    std::ofstream(cut.back(), std::ios::binary).write(reinterpret_cast<const char*>(whole.data()), std::streamsize(whole.size() - 4));
  }
  ASSERT_EQ(readJpeg(cut[1]).header, cv::Size(16, 16)) << "the cut files must vote";
  EXPECT_EQ(recordingImageSize(cut), std::optional<cv::Size>(cv::Size(720, 477)));
}

// An image that exists but cannot be opened (its permissions) says so: it was "cannot decode ...
// (corrupt or truncated PNG?)", sending the user to look for damage in a whole file.
TEST(TumImages, AnUnreadableImageSaysWhyNotCorrupt) {
  const std::string dir = test::tempDir("tum_unreadable");
  const std::string colour = dir + "/c.png", depth = dir + "/d.png";
  cv::imwrite(colour, cv::Mat(48, 64, CV_8UC3, cv::Scalar(10, 20, 30)));
  cv::imwrite(depth, cv::Mat(48, 64, CV_16UC1, cv::Scalar(5000)));
  fs::permissions(colour, fs::perms::none);
  fs::permissions(depth, fs::perms::none);
  const std::string colour_said = test::errorWithoutPrivileges([&] { loadColour(colour, 64, 48); });
  const std::string depth_said = test::errorWithoutPrivileges([&] { loadTumDepth(depth, 64, 48, 5000.0); });
  EXPECT_EQ(colour_said, colour + ": cannot read colour image (Permission denied)");
  EXPECT_EQ(depth_said, depth + ": cannot read depth image (Permission denied)");
}

// A folder that cannot be searched (read but no execute permission): stat fails with EACCES, which
// std::filesystem reports as a file that does not exist, and the image was "missing".
TEST(TumImages, AFolderThatCannotBeSearchedSaysWhyNotMissing) {
  const std::string dir = test::tempDir("tum_unsearchable") + "/rgb";
  fs::create_directories(dir);
  const std::string colour = dir + "/c.png";
  cv::imwrite(colour, cv::Mat(48, 64, CV_8UC3, cv::Scalar(10, 20, 30)));
  fs::permissions(dir, fs::perms::owner_read | fs::perms::group_read | fs::perms::others_read);
  const std::string said = test::errorWithoutPrivileges([&] { loadColour(colour, 64, 48); });
  fs::permissions(dir, fs::perms::owner_all);
  EXPECT_EQ(said, colour + ": cannot read colour image (Permission denied)");
}

// Poses to 1e-9 m and 1e-9 in the quaternion: evaluate_ate.py on trajectory.txt gives summary.json's
// figures (from the poses in memory). At 6 decimals they agreed to 4-5 significant figures only (rpy_first100's
// 50 ms RPE median 1.3e-4 apart; a helper's re-implementation of TUM's scripts).
TEST(Trajectory, WriteReadRoundTrip) {
  Trajectory t{{1.0, mrpt::poses::CPose3D(1.0123456789, 2, 3, 0.1, -0.2, 0.3)}, {2.0, mrpt::poses::CPose3D(-1, 0, 0.5, 1.0, 0.2, -0.1)}};
  const std::string dir = test::tempDir("traj");
  writeTumTrajectory(dir + "/t.txt", t);
  const auto r = readTumTrajectory(dir + "/t.txt");
  ASSERT_EQ(r.size(), 2u);
  for (int i = 0; i < 2; ++i) {
    EXPECT_NEAR(r[i].timestamp, t[i].timestamp, 1e-9);
    EXPECT_LT((r[i].pose.asVectorVal() - t[i].pose.asVectorVal()).norm(), 1e-8);
  }
}

// A run writes its frames in their order, and a recording's clock may step back: such a trajectory
// reads back as written for an estimate (it was refused as "not strictly increasing" by our own
// rgbd-eval and vofusion-mesh --trajectory), and sorted by time it serves the interpolation.
TEST(Trajectory, AnEstimateWithAStampSteppedBackReadsAsWritten) {
  const Trajectory t{{2.0, mrpt::poses::CPose3D(0, 0, 0, 0, 0, 0)},
                     {1.0, mrpt::poses::CPose3D(1, 0, 0, 0, 0, 0)},
                     {3.0, mrpt::poses::CPose3D(3, 0, 0, 0, 0, 0)}};
  const std::string dir = test::tempDir("traj_stepped_back");
  writeTumTrajectory(dir + "/t.txt", t);
  EXPECT_THROW(readTumTrajectory(dir + "/t.txt"), InputError);
  const Trajectory r = readTumTrajectory(dir + "/t.txt", StampOrder::AsWritten);
  ASSERT_EQ(r.size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) EXPECT_NEAR(r[i].timestamp, t[i].timestamp, 1e-9);
  const Trajectory sorted = sortedByTime(r);
  EXPECT_EQ(sorted[0].timestamp, 1.0);
  EXPECT_EQ(sorted[2].timestamp, 3.0);
  mrpt::poses::CPose3D p;
  ASSERT_TRUE(interpolatePose(sorted, 2.5, 1.0, p));
  EXPECT_NEAR(p.x(), 1.5, 1e-9);
}

// A line that is no pose names the file and the line: a huge coordinate (1e300 made rgbd-eval's RMSE
// inf and its JSON invalid), a quaternion off unit length, a field too many.
TEST(Trajectory, ALineThatIsNoPoseNamesTheLine) {
  const auto error = [](const std::string& text) -> std::string {
    try {
      parseTumTrajectory(text, "t.txt");
      return "";
    } catch (const InputError& e) {
      return e.what();
    }
  };
  const std::string ok = "# t tx ty tz qx qy qz qw\n1.0 0 0 0 0 0 0 1\n";
  EXPECT_EQ(error(ok + "2.0 1e300 0 0 0 0 0 1\n"), "t.txt: line 3: position beyond 10 000 km");
  EXPECT_EQ(error(ok + "2.0 0 0 -2e7 0 0 0 1\n"), "t.txt: line 3: position beyond 10 000 km");
  EXPECT_EQ(error(ok + "2.0 0 0 0 0 0 0 2\n"), "t.txt: line 3: quaternion is not unit length (2; a rotation's is 1 within 1 %)");
  EXPECT_EQ(error(ok + "2.0 0 0 0 0 0 0 1 x\n"), "t.txt: line 3: unexpected extra field 'x'");
  EXPECT_EQ(error(ok + "2.0 9e6 0 0 0 0 0 1\n"), "");
  EXPECT_EQ(error(ok + "2.0 0 0 0 0 0 0 1\n0.5 0 0 0 0 0 0 1\n"),
            "t.txt: line 4: timestamps are not strictly increasing (0.500000 after 2.000000)");
  EXPECT_EQ(error(ok + "2.0 nan 0 0 0 0 0 1\n"), "t.txt: line 3: field 2 ('nan') is not a finite number");
  EXPECT_EQ(error(ok + "2.0 0 0 1e999 0 0 0 1\n"), "t.txt: line 3: field 4 ('1e999') is not a finite number");
  EXPECT_EQ(error(ok + "2.0 0 0 0x 0 0 0 1\n"), "t.txt: line 3: expected 'timestamp tx ty tz qx qy qz qw'");
  // Comma-separated, as TUM's associate.py and evaluate_rpe.py read it.
  EXPECT_EQ(parseTumTrajectory("1.0,0,0,0,0,0,0,1\n2.0, 1,0,0, 0,0,0,1\n", "t.txt").size(), 2u);
  // A folder given for a trajectory says so (it read as a file without poses).
  const std::string dir = test::tempDir("traj_folder");
  EXPECT_THROW(
      {
        try {
          readTumTrajectory(dir);
        } catch (const InputError& e) {
          EXPECT_EQ(std::string(e.what()), dir + ": is a folder, expected a file");
          throw;
        }
      },
      InputError);
}

TEST(Trajectory, InterpolatesMidway) {
  Trajectory t{{0.0, mrpt::poses::CPose3D(0, 0, 0, 0, 0, 0)}, {1.0, mrpt::poses::CPose3D(2, 0, 0, 0.2, 0, 0)}};
  mrpt::poses::CPose3D p;
  ASSERT_TRUE(interpolatePose(t, 0.5, 0.6, p));
  EXPECT_NEAR(p.yaw(), 0.1, 1e-9);
  EXPECT_FALSE(interpolatePose(t, 3.0, 0.5, p));
  // Beyond the ends the end pose is held only within the benchmark's 0.02 s, whatever max_gap allows.
  EXPECT_TRUE(interpolatePose(t, 1.015, 0.05, p));
  EXPECT_NEAR(p.x(), 2.0, 1e-12);
  EXPECT_FALSE(interpolatePose(t, 1.04, 0.05, p));
  EXPECT_FALSE(interpolatePose(t, -0.04, 0.05, p));
  EXPECT_TRUE(interpolatePose(t, -0.015, 0.05, p));
  EXPECT_FALSE(interpolatePose(t, -0.015, 0.01, p));
  // A stamp that is no number has no pose (it was given the first one).
  EXPECT_FALSE(interpolatePose(t, std::nan(""), 0.6, p));
}

TEST(TumFolder, ReadsSharedFirst300) {
  const std::string dir = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(dir);
  TumFolderSource src(dir, {});
  EXPECT_EQ(src.size(), 300u);
  Frame f;
  ASSERT_TRUE(src.next(f));
  EXPECT_EQ(f.rgb.type(), CV_8UC3);
  EXPECT_EQ(f.depth.type(), CV_32FC1);
  EXPECT_EQ(f.depth.cols, 640);
  EXPECT_NEAR(f.camera.fx, 517.3, 1e-9);
  ASSERT_TRUE(f.groundTruth.has_value());
  double sum = 0; int n = 0;
  for (int v = 0; v < f.depth.rows; ++v)
    for (int u = 0; u < f.depth.cols; ++u)
      if (f.depth.at<float>(v, u) > 0) sum += f.depth.at<float>(v, u), ++n;
  EXPECT_GT(n, 100000);
  EXPECT_GT(sum / n, 0.5);
  EXPECT_LT(sum / n, 3.0);
}

TEST(TumFolder, MissingFolderIsClearError) {
  try {
    TumFolderSource src("/nonexistent/seq", {});
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), "/nonexistent/seq: no such folder");
  }
}
