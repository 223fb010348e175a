#include "vofusion/core/deflate.h"

#include <libdeflate.h>

#include <memory>
#include <new>
#include <stdexcept>

namespace vofusion {

namespace {
// This thread's compressor (level 1) and decompressor, made when first needed.
libdeflate_compressor& compressor() {
  thread_local std::unique_ptr<libdeflate_compressor, decltype(&libdeflate_free_compressor)> c(
      nullptr, &libdeflate_free_compressor);
  if (!c) c.reset(libdeflate_alloc_compressor(1));
  if (!c) throw std::bad_alloc();
  return *c;
}

libdeflate_decompressor& decompressor() {
  thread_local std::unique_ptr<libdeflate_decompressor, decltype(&libdeflate_free_decompressor)> d(
      nullptr, &libdeflate_free_decompressor);
  if (!d) d.reset(libdeflate_alloc_decompressor());
  if (!d) throw std::bad_alloc();
  return *d;
}

// One deflate container (zlib or gzip) through this thread's compressor, into this thread's scratch
// buffer of the worst-case size; the result is a copy of exactly the compressed bytes (a brick
// compresses to about a third of its bound, and callers keep thousands of them).
template <class Bound, class Compress>
std::vector<std::uint8_t> compressWith(const void* data, std::size_t size, Bound bound, Compress compress) {
  libdeflate_compressor& c = compressor();
  thread_local std::vector<std::uint8_t> scratch;
  scratch.resize(bound(&c, size));
  const std::size_t n = compress(&c, data, size, scratch.data(), scratch.size());
  if (n == 0) throw std::runtime_error("libdeflate: cannot compress");
  return std::vector<std::uint8_t>(scratch.begin(), scratch.begin() + std::ptrdiff_t(n));
}
}  // namespace

std::vector<std::uint8_t> zlibCompress(const void* data, std::size_t size) {
  if (size == 0) return {};
  return compressWith(data, size, libdeflate_zlib_compress_bound, libdeflate_zlib_compress);
}

std::size_t zlibCompressBound(std::size_t size) { return libdeflate_zlib_compress_bound(&compressor(), size); }

std::size_t zlibCompressInto(const void* data, std::size_t size, std::uint8_t* out, std::size_t capacity) {
  if (size == 0) return 0;
  const std::size_t n = libdeflate_zlib_compress(&compressor(), data, size, out, capacity);
  if (n == 0) throw std::runtime_error("libdeflate: cannot compress");
  return n;
}

bool zlibUncompress(const std::uint8_t* data, std::size_t data_size, void* out, std::size_t size) {
  if (size == 0) return data_size == 0;
  return zlibInflate(data, data_size, out, size) == Inflated::Whole;
}

Inflated zlibInflate(const std::uint8_t* data, std::size_t data_size, void* out, std::size_t size) {
  std::size_t got = 0;
  switch (libdeflate_zlib_decompress(&decompressor(), data, data_size, out, size, &got)) {
    case LIBDEFLATE_SUCCESS: return got == size ? Inflated::Whole : Inflated::Short;
    case LIBDEFLATE_INSUFFICIENT_SPACE: return Inflated::Long;
    default: return Inflated::Corrupt;
  }
}

std::vector<std::uint8_t> gzipCompress(const void* data, std::size_t size) {
  return compressWith(data, size, libdeflate_gzip_compress_bound, libdeflate_gzip_compress);
}

bool gzipUncompress(const std::uint8_t* data, std::size_t data_size, std::vector<std::uint8_t>& out, std::size_t max_size) {
  if (data_size < 18) return false;  // a gzip header and trailer
  // What the trailer says is checked by the decompression.
  const std::size_t size = gzipStoredLength(data + data_size);
  if (size > max_size) return false;
  out.resize(size);
  std::size_t in = 0, got = 0;
  return libdeflate_gzip_decompress_ex(&decompressor(), data, data_size, out.data(), size, &in, &got) ==
             LIBDEFLATE_SUCCESS &&
         in == data_size && got == size;
}

std::uint32_t crc32(const void* data, std::size_t size, std::uint32_t crc) {
  return std::uint32_t(libdeflate_crc32(crc, data, size));
}

}  // namespace vofusion
