// Writes tiny rawlog seeds for fuzz_rawlog: both MRPT rawlog formats, images embedded, 16x12 pixels,
// gzip-compressed as written and uncompressed (so mutations reach the serialization, not just zlib).
//   make_rawlog_seeds <dir>
#include <cstdio>
#include <string>

#include <mrpt/io/CFileGZInputStream.h>

#include "vofusion/io/rawlog.h"

using namespace vofusion;

static Frame tinyFrame(int i) {
  Frame f;
  f.index = std::size_t(i);
  f.timestamp = 1000.0 + 0.033 * i;
  f.camera = f.camera.scaled(16.0 / 640.0);
  f.rgb = cv::Mat(12, 16, CV_8UC3, cv::Scalar(10 * i, 100, 200));
  f.depth = cv::Mat(12, 16, CV_32F, cv::Scalar(1.0 + 0.1 * i));
  f.depth.at<float>(0, 0) = 0;
  f.groundTruth = mrpt::poses::CPose3D(0.01 * i, 0, 0, 0, 0, 0);
  return f;
}

static void gunzip(const std::string& in, const std::string& out) {
  mrpt::io::CFileGZInputStream gz(in);
  std::FILE* o = std::fopen(out.c_str(), "wb");
  char buf[4096];
  size_t n;
  while ((n = gz.Read(buf, sizeof buf)) > 0) std::fwrite(buf, 1, n, o);
  std::fclose(o);
}

int main(int argc, char** argv) {
  if (argc != 2) return 2;
  const std::string dir = argv[1];
  for (bool sf : {false, true}) {
    RawlogWriterOptions o;
    o.external_images = false;
    o.format = sf ? RawlogWriterOptions::Format::ActionsSensoryFrames : RawlogWriterOptions::Format::Observations;
    const std::string path = dir + (sf ? "/sf" : "/obs") + ".rawlog";
    {
      RawlogWriter w(path, o);
      for (int i = 0; i < 2; ++i) {
        if (sf && i > 0) w.writeAction(makeOdometryAction(mrpt::poses::CPose3D(0.01, 0, 0, 0, 0, 0), 1000.0 + 0.033 * i));
        w.write(tinyFrame(i));
      }
      w.commit();
    }
    gunzip(path, dir + (sf ? "/sf_plain" : "/obs_plain") + ".rawlog");
  }
  return 0;
}
