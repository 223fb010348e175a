#pragma once
// Deflate streams through libdeflate, one compressor and decompressor per thread: the zlib streams of
// spilled and saved TSDF bricks, keyframe depths and PNG image data, and the gzip files of the range
// images we write and read. The same bytes zlib reads and writes, in less time.
#include <cstddef>
#include <cstdint>
#include <vector>

namespace vofusion {

// A zlib stream of `size` bytes at `data`, at level 1 (fast, ~3x on TSDF bricks and depth); empty for size 0.
std::vector<std::uint8_t> zlibCompress(const void* data, std::size_t size);
// The same stream written into `out` (capacity at least zlibCompressBound(size)); returns its length.
// For callers on worker threads: the buffer is the caller's, so nothing is allocated there (glibc keeps
// what a worker thread frees in that thread's own heap).
std::size_t zlibCompressBound(std::size_t size);
std::size_t zlibCompressInto(const void* data, std::size_t size, std::uint8_t* out, std::size_t capacity);
// Fills exactly `size` bytes at `out`; false when `data` is not a zlib stream of that length.
bool zlibUncompress(const std::uint8_t* data, std::size_t data_size, void* out, std::size_t size);
// The same, telling a failure's kind: a stream that inflates to fewer bytes, to more (only its first
// `size` are inflated), or that is no whole zlib stream.
enum class Inflated { Whole, Short, Long, Corrupt };
Inflated zlibInflate(const std::uint8_t* data, std::size_t data_size, void* out, std::size_t size);
// A gzip file's bytes (one member) of `size` bytes at `data`, at level 1.
std::vector<std::uint8_t> gzipCompress(const void* data, std::size_t size);
// What a gzip member's trailer says its data's length is, modulo 2^32 (RFC 1952's ISIZE): the
// little-endian 32 bits of its last four bytes, at `trailer_end - 4`.
inline std::uint32_t gzipStoredLength(const std::uint8_t* trailer_end) {
  return std::uint32_t(trailer_end[-4]) | std::uint32_t(trailer_end[-3]) << 8 | std::uint32_t(trailer_end[-2]) << 16 |
         std::uint32_t(trailer_end[-1]) << 24;
}
// A gzip member's whole trailer (its data's CRC-32 and length) as one number, from its last eight
// bytes at `trailer_end - 8`: what tells one file's content from another's of the same size without
// inflating either.
inline std::uint64_t gzipTrailer(const std::uint8_t* trailer_end) {
  return std::uint64_t(gzipStoredLength(trailer_end - 4)) << 32 | gzipStoredLength(trailer_end);
}
// A gzip file of one member, checked whole (its CRC-32 and length), into `out`; false when it is cut
// short, damaged, not gzip, followed by more bytes, or longer than max_size (at most 4 GiB - 1: the
// length field holds the size modulo 2^32).
bool gzipUncompress(const std::uint8_t* data, std::size_t data_size, std::vector<std::uint8_t>& out, std::size_t max_size);
// The CRC-32 (zlib's, gzip's) of `size` bytes at `data`, going on from `crc` (0 to start).
std::uint32_t crc32(const void* data, std::size_t size, std::uint32_t crc = 0);
// All of these throw std::bad_alloc when libdeflate cannot allocate its state.

}  // namespace vofusion
