// GzipMembersFile against the reader every MRPT load uses (CFileGZInputStream, zlib's gzread): the
// bytes written, across several members and in pieces of every size, are the bytes read back.
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <vector>

#include <mrpt/io/CFileGZInputStream.h>
#include <mrpt/io/CFileGZOutputStream.h>

#include "support.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/gzip_members.h"

using namespace vofusion;

namespace {

std::vector<std::uint8_t> readBack(const std::string& path) {
  mrpt::io::CFileGZInputStream in(path);
  std::vector<std::uint8_t> out;
  std::uint8_t buf[65536];
  for (std::size_t n; (n = in.Read(buf, sizeof buf)) > 0;) out.insert(out.end(), buf, buf + n);
  return out;
}

// Half compressible (a repeating ramp), half noise, so members differ in size.
std::vector<std::uint8_t> content(std::size_t size) {
  std::mt19937 rng(7);
  std::vector<std::uint8_t> v(size);
  for (std::size_t i = 0; i < size; ++i) v[i] = (i / 4096) % 2 ? std::uint8_t(rng()) : std::uint8_t(i % 251);
  return v;
}

// The number of gzip members: each starts with the magic 1f 8b 08 (a member's own compressed bytes
// could hold it too, so this is an upper bound; at least the count written).
std::size_t magicCount(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  const std::vector<char> b((std::istreambuf_iterator<char>(f)), {});
  std::size_t n = 0;
  for (std::size_t i = 0; i + 2 < b.size(); ++i) n += b[i] == '\x1f' && b[i + 1] == '\x8b' && b[i + 2] == '\x08';
  return n;
}

}  // namespace

TEST(GzipMembers, ReadsBackAsOneStreamAcrossMembers) {
  const std::string dir = test::tempDir("gzip_members");
  const std::size_t size = 5 * GzipMembersFile::kMemberBytes + 12345;  // 6 members, the last short
  const std::vector<std::uint8_t> data = content(size);
  const std::string path = dir + "/pieces.gz";
  {
    GzipMembersFile f(path);
    // Pieces of 1 byte up to two members at once, so writes end inside, at and across members' ends.
    std::mt19937 rng(3);
    std::size_t at = 0;
    for (std::size_t piece = 1; at < size; piece = piece * 7 % (2 * GzipMembersFile::kMemberBytes + 13) + rng() % 3) {
      const std::size_t n = std::min(piece, size - at);
      ASSERT_EQ(f.Write(data.data() + at, n), n);
      at += n;
      EXPECT_EQ(f.getPosition(), at);
    }
    f.close();
    f.close();  // idempotent
  }
  EXPECT_GE(magicCount(path), 6u);
  EXPECT_EQ(readBack(path), data);
}

TEST(GzipMembers, ExactMultipleAndEmpty) {
  const std::string dir = test::tempDir("gzip_members_edges");
  const std::vector<std::uint8_t> data = content(2 * GzipMembersFile::kMemberBytes);
  {
    GzipMembersFile f(dir + "/two.gz");
    f.Write(data.data(), data.size());
    f.close();
  }
  EXPECT_EQ(readBack(dir + "/two.gz"), data);
  {
    GzipMembersFile f(dir + "/empty.gz");
    f.close();
  }
  EXPECT_TRUE(readBack(dir + "/empty.gz").empty());
  EXPECT_EQ(magicCount(dir + "/empty.gz"), 1u);  // a gzip file, as `gzip` makes of nothing
}

TEST(GzipMembers, UnwritablePathNamesTheFile) {
  const std::string path = test::tempDir("gzip_members_bad") + "/no/such/dir/x.gz";
  try {
    GzipMembersFile f(path);
    FAIL() << "opened " << path;
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
}

TEST(GzipMembers, IsWriteOnly) {
  GzipMembersFile f(test::tempDir("gzip_members_ro") + "/x.gz");
  std::uint8_t b;
  EXPECT_THROW(f.Read(&b, 1), std::logic_error);
  EXPECT_THROW(f.Seek(0), std::logic_error);
}

TEST(GzipMembers, AFullDiskIsAnInputErrorNamingTheFile) {
  const std::vector<std::uint8_t> data = content(3 * GzipMembersFile::kMemberBytes);
  try {
    GzipMembersFile f("/dev/full");
    f.Write(data.data(), data.size());
    f.close();
    FAIL() << "wrote 3 MiB to /dev/full";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), "/dev/full");
  }
}

TEST(GzipMembers, DestroyedWithMembersInFlightWaitsForThem) {
  const std::string path = test::tempDir("gzip_members_unclosed") + "/x.gz";
  const std::vector<std::uint8_t> data = content(6 * GzipMembersFile::kMemberBytes);
  {
    GzipMembersFile f(path);
    f.Write(data.data(), data.size());
  }  // as when serialising throws: no close(); the members in flight finish before theirs are freed
  EXPECT_TRUE(std::filesystem::exists(path));
  GzipMembersFile f(path);
  f.close();
  EXPECT_THROW(f.Write(data.data(), 1), std::logic_error);
}

// A rawlog MRPT's gzip stream wrote is whole when its trailer gives the length written; one cut short
// is not (MRPT's close() does not say when the last flush failed).
TEST(GzipMembers, TrailerTellsAWholeFileFromOneCutShort) {
  const std::string path = test::tempDir("gzip_trailer") + "/x.gz";
  const std::vector<std::uint8_t> data = content(300000);
  std::uint64_t written = 0;
  {
    mrpt::io::CFileGZOutputStream gz(path);
    gz.Write(data.data(), data.size());
    written = gz.getPosition();
  }
  EXPECT_EQ(written, data.size());
  EXPECT_TRUE(gzipTrailerSays(path, written));
  EXPECT_FALSE(gzipTrailerSays(path, written + 1));
  const auto size = std::filesystem::file_size(path);
  std::filesystem::resize_file(path, size - 1);
  EXPECT_FALSE(gzipTrailerSays(path, written));
  std::filesystem::resize_file(path, size / 2);
  EXPECT_FALSE(gzipTrailerSays(path, written));
  EXPECT_FALSE(gzipTrailerSays(path + ".missing", written));
}
