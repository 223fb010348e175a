#include "vofusion/core/file_checksum.h"

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <utility>
#include <vector>

#include "vofusion/core/deflate.h"

namespace vofusion {

namespace {

constexpr char kChecksumTag[] = "CHECKSUM";
constexpr std::size_t kTrailerBytes = sizeof(kChecksumTag) - 1 + 4 + 8;

template <typename T>
void putLittleEndian(std::string& out, T v) {
  for (std::size_t i = 0; i < sizeof(T); ++i) out.push_back(char((v >> (8 * i)) & 0xff));
}
template <typename T>
T getLittleEndian(const char* at) {
  T v = 0;
  for (std::size_t i = 0; i < sizeof(T); ++i) v |= T(static_cast<unsigned char>(at[i])) << (8 * i);
  return v;
}

// The CRC-32 of a file's first `bytes` bytes, and whether it had that many.
std::pair<std::uint32_t, bool> crcOfFile(const std::string& path, std::uint64_t bytes) {
  std::ifstream is(path, std::ios::binary);
  std::vector<char> buf(std::size_t(1) << 20);
  std::uint32_t crc = 0;
  std::uint64_t left = bytes;
  while (left > 0 && is.read(buf.data(), std::streamsize(std::min<std::uint64_t>(left, buf.size())))) {
    crc = crc32(buf.data(), std::size_t(is.gcount()), crc);
    left -= std::uint64_t(is.gcount());
  }
  return {crc, left == 0};
}

}  // namespace

bool appendFileChecksum(const std::string& path, std::string& why) {
  std::error_code ec;
  const std::uint64_t bytes = std::filesystem::file_size(path, ec);
  const auto [crc, whole] = crcOfFile(path, bytes);
  if (ec || !whole) return why = "read back failed", false;
  std::string trailer(kChecksumTag);
  putLittleEndian(trailer, crc);
  putLittleEndian(trailer, bytes);
  std::ofstream os(path, std::ios::binary | std::ios::app);
  os.write(trailer.data(), std::streamsize(trailer.size()));
  os.close();
  if (!os) return why = "disk full?", false;
  return true;
}

bool fileChecksumHolds(const std::string& path, std::string& why) {
  std::error_code ec;
  const std::uint64_t size = std::filesystem::file_size(path, ec);
  if (ec || size < kTrailerBytes) return why = "shorter than its checksum", false;
  std::ifstream is(path, std::ios::binary);
  char t[kTrailerBytes];
  is.seekg(std::streamoff(size - kTrailerBytes));
  if (!is.read(t, sizeof t) || std::memcmp(t, kChecksumTag, sizeof(kChecksumTag) - 1) != 0)
    return why = "it does not end with its checksum (cut short?)", false;
  const auto crc = getLittleEndian<std::uint32_t>(t + sizeof(kChecksumTag) - 1);
  const auto bytes = getLittleEndian<std::uint64_t>(t + sizeof(kChecksumTag) - 1 + 4);
  if (bytes != size - kTrailerBytes) return why = "its length is not the one its checksum was made of", false;
  if (crcOfFile(path, bytes) != std::pair<std::uint32_t, bool>{crc, true})
    return why = "its checksum does not match (a damaged byte)", false;
  return true;
}

}  // namespace vofusion
