// core/text_file.h: whole-file reads and the data lines of '#'-commented text formats.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "support.h"
#include "vofusion/core/allocation_limit.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/text_file.h"

using namespace vofusion;

TEST(TextFile, DataLinesSkipBlankAndCommentLinesAndKeepLineNumbers) {
  const auto lines = dataLines("# header\n\n1 a\n   # indented comment\n \t\r\n2 b\r\n  3 c # not a comment\nlast");
  ASSERT_EQ(lines.size(), 4u);
  EXPECT_EQ(lines[0].number, 3);
  EXPECT_EQ(lines[0].text, "1 a");
  EXPECT_EQ(lines[1].number, 6);
  EXPECT_EQ(lines[1].text, "2 b\r");
  EXPECT_EQ(lines[2].number, 7);
  EXPECT_EQ(lines[2].text, "  3 c # not a comment");
  EXPECT_EQ(lines[3].number, 8);  // no final newline
  EXPECT_EQ(lines[3].text, "last");
  EXPECT_TRUE(dataLines("").empty());
  EXPECT_TRUE(dataLines("#\n\n").empty());
  // A UTF-8 byte order mark before a header comment: still a comment (it was line 1's data).
  const auto bom = dataLines("\xEF\xBB\xBF# timestamp filename\n1 a\n");
  ASSERT_EQ(bom.size(), 1u);
  EXPECT_EQ(bom[0].number, 2);
  EXPECT_EQ(bom[0].text, "1 a");
}

TEST(TextFile, ReadsWholeFileOrNamesIt) {
  const std::string dir = test::tempDir("text_file");
  const std::string bytes = std::string("a\nb\0c\r\n", 7);
  std::ofstream(dir + "/f.txt", std::ios::binary) << bytes;
  EXPECT_EQ(readTextFile(dir + "/f.txt"), bytes);
  try {
    readTextFile(dir + "/missing.txt");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), dir + "/missing.txt: cannot open file (No such file or directory)");
  }
  // A file far larger than any list (a sparse 300 MiB here) is refused before it is read.
  std::ofstream(dir + "/huge.txt") << "1 2 3\n";
  std::filesystem::resize_file(dir + "/huge.txt", std::uintmax_t(300) << 20);
  try {
    readTextFile(dir + "/huge.txt");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), dir + "/huge.txt: is 300 MiB: too large for a text file here (256 MiB at most)");
  }
}

// A stream with no size to check first (a device, a pipe) is read up to the cap and refused there: a
// list given as /dev/zero grew without bound until the machine ran out of memory.
TEST(TextFile, AnEndlessStreamIsRefusedAtTheCap) {
  const ScopedAllocationLimit limit(std::size_t(1) << 30, std::size_t(2) << 30);  // without the cap: bad_alloc, not the machine
  try {
    readTextFile("/dev/zero");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), "/dev/zero: goes on past 256 MiB: too large for a text file here");
  }
}
