// Rawlogs whose length fields ask for gigabytes: the reader must fail with its one-line InputError
// before MRPT allocates (and zero-fills) the buffer, for each way MRPT's deserialisation allocates:
// std::string and std::vector (global operator new, called inside libmrpt-*.so and libstdc++.so) and
// matrices (mrpt::aligned_malloc). Peak RSS is checked, so a replacement that MRPT's libraries do not
// call makes these tests fail. Also: ScopedAllocationLimit itself, and a 4K frame (with a point
// cloud) that must still read.
#include <sys/resource.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <new>
#include <thread>
#include <vector>

#include <mrpt/core/aligned_allocator.h>
#include <mrpt/obs/CActionCollection.h>
#include <mrpt/io/CMemoryStream.h>
#include <mrpt/serialization/CArchive.h>

#include "support.h"
#include "vofusion/core/allocation_limit.h"
#include "vofusion/core/errors.h"
#include "vofusion/io/rawlog.h"

using namespace vofusion;

namespace {

constexpr std::size_t kMiB = std::size_t(1) << 20;

long peakRssKiB() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss;
}

Frame smallFrame(int w, int h) {
  Frame f;
  f.timestamp = 1.5;
  f.rgb = cv::Mat(h, w, CV_8UC3, cv::Scalar(10, 20, 30));
  f.depth = cv::Mat(h, w, CV_32F, cv::Scalar(1.25f));
  f.camera = CameraIntrinsics{}.scaled(w / 640.0);
  return f;
}

// A rawlog at `path` holding obs alone, its images inside.
void writeOneObservation(const std::string& path, const mrpt::obs::CObservation3DRangeScan& obs) {
  RawlogWriterOptions o;
  o.external_images = false;
  RawlogWriter writer(path, o);
  writer.writeObservation(obs);
  writer.commit();
}

// One observation as MRPT writes it (class header, version, fields), uncompressed: MRPT reads plain
// archives as well, and the bytes can be patched.
std::string serialize(const mrpt::obs::CObservation3DRangeScan& obs) {
  mrpt::io::CMemoryStream mem;
  auto arch = mrpt::serialization::archiveFrom(mem);
  arch << obs;
  return std::string(static_cast<const char*>(mem.getRawBufferData()), mem.getTotalBytesCount());
}

template <typename T>
std::string bytesOf(T v) {
  return std::string(reinterpret_cast<const char*>(&v), sizeof v);
}

uint32_t readU32(const std::string& s, std::size_t at) {
  uint32_t v;
  std::memcpy(&v, s.data() + at, 4);
  return v;
}

void patchU32(std::string& s, std::size_t at, uint32_t v) { std::memcpy(&s[at], &v, 4); }

void p_unused(void* p) { ::operator delete(p); }

std::string writeFile(const std::string& name, const std::string& bytes) {
  const std::string path = test::tempDir("rawlog_corrupt") + "/" + name;
  std::ofstream(path, std::ios::binary) << bytes;
  return path;
}

// Reading `path` must end in one InputError line containing `needle`; peak RSS may rise by at most
// max_growth (MRPT zero-fills what it is granted).
void expectBoundedFailure(const std::string& path, const std::string& needle, std::size_t max_growth = 64 * kMiB) {
  const long before = peakRssKiB();
  try {
    RawlogSource src(path, {});
    Frame f;
    while (src.next(f)) {
    }
    ADD_FAILURE() << "no error for " << path;
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(needle), std::string::npos) << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  }
  const long grew_kib = peakRssKiB() - before;
  EXPECT_LT(grew_kib, long(max_growth / 1024)) << "peak RSS rose by " << grew_kib / 1024 << " MiB";
}

}  // namespace

TEST(AllocationLimit, RefusesLargerRequestsOnThisThreadOnly) {
  void* p = nullptr;
  {
    const ScopedAllocationLimit limit(kMiB, 64 * kMiB);
    EXPECT_THROW(p = ::operator new(2 * kMiB), std::bad_alloc);
    EXPECT_EQ(limit.refusedRequest(), 2 * kMiB);
    EXPECT_EQ(::operator new[](3 * kMiB, std::nothrow), nullptr);
    EXPECT_EQ(limit.refusedRequest(), 3 * kMiB);
    EXPECT_THROW(p = mrpt::aligned_malloc(2 * kMiB, 16), std::bad_alloc);
    EXPECT_THROW(p = mrpt::aligned_calloc(2 * kMiB, 16), std::bad_alloc);  // MRPT's own, via aligned_malloc
    EXPECT_FALSE(limit.totalExceeded());
    p = ::operator new(kMiB);  // at the limit: allowed
    ::operator delete(p);
    p = mrpt::aligned_malloc(kMiB / 2, 64);
    ASSERT_NE(p, nullptr);
    EXPECT_EQ(reinterpret_cast<uintptr_t>(p) % 64, 0u);
    mrpt::aligned_free(p);

    bool other_thread_ok = false;
    std::thread([&] {
      void* q = ::operator new(8 * kMiB);
      other_thread_ok = q != nullptr;
      ::operator delete(q);
    }).join();
    EXPECT_TRUE(other_thread_ok);

    {
      const ScopedAllocationLimit looser(16 * kMiB, 64 * kMiB);  // cannot loosen the enclosing limit
      EXPECT_THROW(p = ::operator new(2 * kMiB), std::bad_alloc);
      const ScopedAllocationLimit tighter(kMiB / 4, 64 * kMiB);
      EXPECT_THROW(p = ::operator new(kMiB / 2), std::bad_alloc);
    }
    EXPECT_THROW(p = ::operator new(2 * kMiB), std::bad_alloc);
    p = ::operator new(kMiB / 2);  // the inner limits are gone
    ::operator delete(p);
  }
  p = ::operator new(8 * kMiB);
  ::operator delete(p);
}

TEST(AllocationLimit, TotalCountsEveryRequestButNotCleanup) {
  std::vector<void*> blocks;
  blocks.reserve(8192);  // so that only the blocks count
  {
    const ScopedAllocationLimit limit(kMiB, 4 * kMiB);
    try {
      for (;;) blocks.push_back(::operator new(1000));  // small blocks, freed or not, add up
    } catch (const std::bad_alloc&) {
      EXPECT_TRUE(limit.totalExceeded());
      EXPECT_EQ(limit.refusedRequest(), 0u);
      void* in_handler = ::operator new(1000);  // while an exception is handled: granted
      ::operator delete(in_handler);
    }
    EXPECT_EQ(blocks.size(), 4 * kMiB / 1000);
    for (void* b : blocks) ::operator delete(b);
    EXPECT_THROW(p_unused(::operator new(1000)), std::bad_alloc);  // frees are not credited

    struct AllocatesWhenDestroyed {
      ~AllocatesWhenDestroyed() { ::operator delete(::operator new(100)); }  // like MRPT's buffer pool
    };
    EXPECT_THROW(
        {
          AllocatesWhenDestroyed a;
          throw std::bad_alloc();
        },
        std::bad_alloc);  // the destructor runs while unwinding: granted, no std::terminate
    {
      const ScopedAllocationLimit inner(kMiB, 64 * kMiB);  // nested: bounded by what the outer has left
      EXPECT_THROW(p_unused(::operator new(1000)), std::bad_alloc);
    }
  }
  {
    const ScopedAllocationLimit outer(kMiB, 3 * kMiB + kMiB / 2);
    {
      const ScopedAllocationLimit inner(kMiB, 64 * kMiB);
      for (int i = 0; i < 3; ++i) ::operator delete(::operator new(kMiB));
    }
    EXPECT_THROW(p_unused(::operator new(kMiB)), std::bad_alloc);  // the inner scope's use counts
  }
}

// sensorLabel's length (std::string: operator>> in libmrpt-serialization, _M_mutate in libstdc++).
TEST(RawlogCorrupt, HugeStringLength) {
  auto obs = observationFromFrame(smallFrame(64, 48), 2e-4, "LABEL_TO_PATCH");
  std::string bytes = serialize(*obs);
  const std::size_t at = bytes.find("LABEL_TO_PATCH");
  ASSERT_NE(at, std::string::npos);
  ASSERT_EQ(readU32(bytes, at - 4), 14u);  // MRPT: uint32 length, then the characters
  patchU32(bytes, at - 4, 0xF0000000u);    // 3840 MiB
  expectBoundedFailure(writeFile("string.rawlog", bytes), "corrupt or truncated rawlog at entry 1 (asks for a buffer of 3841 MiB");
}

// The point count (five std::vectors, resized in libmrpt-obs before any point is read).
TEST(RawlogCorrupt, HugePointCount) {
  auto obs = observationFromFrame(smallFrame(64, 48));
  obs->hasPoints3D = true;
  obs->resizePoints3DVectors(3);
  obs->points3D_x = {1234.5f, -98.25f, 7.125f};
  std::string bytes = serialize(*obs);
  const std::size_t at = bytes.find(bytesOf(1234.5f) + bytesOf(-98.25f));
  ASSERT_NE(at, std::string::npos);
  ASSERT_EQ(readU32(bytes, at - 4), 3u);
  patchU32(bytes, at - 4, 0x40000000u);  // 4 GiB per float vector
  expectBoundedFailure(writeFile("points.rawlog", bytes), "asks for a buffer of 4096 MiB");
}

// The range image's rows and cols (CMatrix_u16: mrpt::aligned_malloc, zero-filled).
TEST(RawlogCorrupt, HugeRangeImage) {
  const float units = 1.2345e-4f;
  auto obs = observationFromFrame(smallFrame(64, 48), units);
  std::string bytes = serialize(*obs);
  const std::size_t at = bytes.find(bytesOf(obs->rangeUnits));
  ASSERT_NE(at, std::string::npos);
  ASSERT_EQ(readU32(bytes, at + 4), 48u);  // rows, cols follow rangeUnits
  ASSERT_EQ(readU32(bytes, at + 8), 64u);
  patchU32(bytes, at + 4, 49152);
  patchU32(bytes, at + 8, 49152);  // 4.5 GiB of uint16
  expectBoundedFailure(writeFile("range.rawlog", bytes), "asks for a buffer of 4608 MiB");
}

// The action count of a CActionCollection (a std::deque: 512-byte blocks, each below any per-buffer
// limit; only the total stops it).
TEST(RawlogCorrupt, HugeActionCount) {
  mrpt::obs::CActionCollection actions;
  actions.insert(makeOdometryAction(mrpt::poses::CPose3D(0.1, 0, 0, 0, 0, 0), 1.0));
  mrpt::io::CMemoryStream mem;
  auto arch = mrpt::serialization::archiveFrom(mem);
  arch << actions;
  std::string bytes(static_cast<const char*>(mem.getRawBufferData()), mem.getTotalBytesCount());
  const std::string name = "CActionCollection";
  const std::size_t at = bytes.find(name);
  ASSERT_NE(at, std::string::npos);
  const std::size_t count_at = at + name.size() + 1;  // class name, version byte, uint32 count
  ASSERT_EQ(readU32(bytes, count_at), 1u);
  patchU32(bytes, count_at, 0x0F000000u);  // 252 M actions: 4 GiB of deque blocks, a 63 MiB block map
  expectBoundedFailure(writeFile("actions.rawlog", bytes), "(needs more than the 256 MiB an entry may use)",
                       320 * kMiB);
}

// The limit leaves real frames alone: a 4K depth frame with its point cloud (33 MB per vector).
TEST(RawlogCorrupt, FourKFrameWithPointsStillReads) {
  const int w = 3840, h = 2160;
  const std::string path = test::tempDir("rawlog_corrupt_4k") + "/4k.rawlog";
  {
    auto obs = observationFromFrame(smallFrame(w, h));
    obs->hasPoints3D = true;
    obs->resizePoints3DVectors(std::size_t(w) * h);
    writeOneObservation(path, *obs);
  }
  RawlogSource src(path, {});
  ASSERT_EQ(src.size(), 1u);
  Frame f;
  ASSERT_TRUE(src.next(f));
  EXPECT_EQ(f.depth.cols, w);
  EXPECT_EQ(f.depth.rows, h);
  EXPECT_FLOAT_EQ(f.depth.at<float>(h / 2, w / 2), 1.25f);
}

// A record whose depth units are no scale (NaN, 0, negative, infinite) costs that frame in one line: it
// made every reading NaN or 0, a frame the tracker took for one with depth.
TEST(RawlogCorrupt, DepthUnitsThatAreNoScaleCostTheirFrame) {
  const std::string path = test::tempDir("rawlog_corrupt_units") + "/units.rawlog";
  for (const float units : {std::numeric_limits<float>::quiet_NaN(), 0.f, -1e-3f, std::numeric_limits<float>::infinity()}) {
    {
      auto obs = observationFromFrame(smallFrame(64, 48));
      obs->rangeUnits = units;
      writeOneObservation(path, *obs);
    }
    RawlogSource src(path, {});
    Frame f;
    try {
      src.next(f);
      ADD_FAILURE() << "units " << units << " read as a frame";
    } catch (const DamagedFrame& e) {
      EXPECT_NE(std::string(e.what()).find("depth units of"), std::string::npos) << e.what();
    }
  }
}

// A point cloud stored beside the rawlog (rawlog-edit --externalize: <name>_3D.bin), which no frame
// uses, is not loaded: missing, it cost its frame as a "missing or corrupt" range image (and present,
// was decoded for nothing, 3.7 MB a frame).
TEST(RawlogCorrupt, AnExternalPointCloudIsNotLoaded) {
  const std::string dir = test::tempDir("rawlog_external_points");
  const std::string path = dir + "/points.rawlog";
  {
    auto obs = observationFromFrame(smallFrame(64, 48));
    obs->hasPoints3D = true;
    obs->resizePoints3DVectors(3);
    std::filesystem::create_directories(dir + "/points_Images");
    obs->points3D_convertToExternalStorage("gone_3D.bin", dir + "/points_Images/");
    ASSERT_TRUE(obs->points3D_isExternallyStored());
    writeOneObservation(path, *obs);
  }
  std::filesystem::remove(dir + "/points_Images/gone_3D.bin");
  RawlogSource src(path, {});
  Frame f;
  try {
    ASSERT_TRUE(src.next(f));
  } catch (const std::exception& e) {
    FAIL() << e.what();
  }
  EXPECT_EQ(f.depth.cols, 64);
  EXPECT_FLOAT_EQ(f.depth.at<float>(24, 32), 1.25f);
}
