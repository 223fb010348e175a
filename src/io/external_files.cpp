#include "vofusion/io/external_files.h"

#include <fcntl.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <vector>

#include "vofusion/core/deflate.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/text_file.h"
#include "vofusion/io/png_decode.h"  // readWholeFile, isRgb8Png

namespace fs = std::filesystem;
using mrpt::obs::CObservation3DRangeScan;

namespace vofusion {

namespace {
// The range image's and 3D points' file names are protected members with no setter but
// rangeImage_convertToExternalStorage (which swaps the global folder). A derived class may name them
// as pointers to members of the base, which is how they are reached here.
struct ExternalNames : CObservation3DRangeScan {
  static constexpr auto range_file = &ExternalNames::m_rangeImage_external_file;
  static constexpr auto range_stored = &ExternalNames::m_rangeImage_external_stored;
  static constexpr auto points_file = &ExternalNames::m_points3D_external_file;
  static constexpr auto points_stored = &ExternalNames::m_points3D_external_stored;
};

// MRPT's own test of an absolute name (mrpt::io::lazy_load_absolute_path).
bool isAbsolute(const std::string& f) {
  return !f.empty() && (f[0] == '/' || (f.size() > 2 && f[1] == ':' && (f[2] == '\\' || f[2] == '/')));
}

// A hard link at `to` to `from`; false where the file system refuses (another device, no hard links)
// or `from` is gone. Whatever was at `to` is removed first, so that a file written there instead never
// writes through a link into the recording.
bool linkFile(const std::string& from, const std::string& to) {
  std::error_code ec;
  fs::remove(to, ec);
  fs::create_hard_link(from, to, ec);
  return !ec;
}

std::string resolved(const std::string& name, const fs::path& dir) {
  return isAbsolute(name) ? name : (dir / name).string();
}

void resolveImage(mrpt::img::CImage& img, const fs::path& dir) {
  if (img.isExternallyStored()) img.setExternalStorage(resolved(img.getExternalStorageFile(), dir));
}
}  // namespace

void resolveExternalFiles(CObservation3DRangeScan& obs, const std::string& images_dir) {
  const fs::path dir = fs::absolute(images_dir);
  resolveImage(obs.intensityImage, dir);
  resolveImage(obs.confidenceImage, dir);
  if (obs.*ExternalNames::range_stored) obs.*ExternalNames::range_file = resolved(obs.*ExternalNames::range_file, dir);
  if (obs.*ExternalNames::points_stored)
    obs.*ExternalNames::points_file = resolved(obs.*ExternalNames::points_file, dir);
}

std::optional<DepthFile> loadExternalRangeImage(CObservation3DRangeScan& obs) {
  if (!(obs.*ExternalNames::range_stored)) return std::nullopt;
  const std::string path = obs.*ExternalNames::range_file;
  // Only MRPT's gzip binary file is read here. A .txt (EXTERNALS_AS_TEXT; MRPT reads any other name as
  // binary), a plain binary file, or a whole gzip of another layout (rawlogs older than MRPT's
  // serialisation v9 hold floats) is left to MRPT's load().
  std::string extension = fs::path(path).extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(), [](unsigned char c) { return std::tolower(c); });
  if (extension == ".txt") {
    // MRPT's load() opens it as it is: a FIFO there waited for a writer for ever (openRegularFile's check).
    if (const std::string why = whyUnreadable(path); !why.empty())
      throw InputError(path, "cannot load external range image (" + why + ")");
    return std::nullopt;
  }
  constexpr std::uint32_t kLargestSide = 8192;
  constexpr std::size_t kLargest = 8 + std::size_t(kLargestSide) * kLargestSide * 2;  // rows, cols and 8192 x 8192 readings
  std::error_code ec;
  const std::uintmax_t stored = fs::file_size(path, ec);
  if (ec) throw InputError(path, "cannot load external range image (" + ec.message() + ")");
  if (stored > kLargest) throw InputError(path, "corrupt range image file (larger than any range image)");
  thread_local std::vector<std::uint8_t> packed, raw;  // a frame's worth, kept for the reader's next frames
  if (!readWholeFile(path, packed)) {
    const std::string why = whyUnreadable(path);
    throw InputError(path, "cannot load external range image (" + (why.empty() ? std::string("unreadable") : why) + ")");
  }
  if (packed.empty()) throw InputError(path, "corrupt range image file (empty)");
  if (packed.size() < 2 || packed[0] != 0x1f || packed[1] != 0x8b) return std::nullopt;  // not gzip
  if (!gzipUncompress(packed.data(), packed.size(), raw, kLargest))
    throw InputError(path, "corrupt range image file (cut short or damaged: its gzip check fails)");
  std::uint32_t dims[2] = {0, 0};
  if (raw.size() >= sizeof dims) std::memcpy(dims, raw.data(), sizeof dims);
  // Each side at most kLargestSide first: a product of two 32-bit sides wraps in 64 bits (a crafted
  // file's came to its size, and the range image asked for 2^63 readings).
  if (dims[0] == 0 || dims[1] == 0 || dims[0] > kLargestSide || dims[1] > kLargestSide ||
      raw.size() != sizeof dims + std::size_t(dims[0]) * dims[1] * 2)
    return std::nullopt;
  auto& ri = obs.rangeImage;
  ri.setSize(dims[0], dims[1]);
  static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "the range image's bytes are read as they are in memory");
  std::memcpy(ri.data(), raw.data() + sizeof dims, raw.size() - sizeof dims);
  obs.*ExternalNames::range_stored = false;
  (obs.*ExternalNames::range_file).clear();
  return DepthFile{path, double(obs.rangeUnits), packed.size(), gzipTrailer(packed.data() + packed.size()), false};
}

std::optional<DepthFile> reuseRangeImageFile(const DepthFile& file, double units, const std::string& path,
                                             const std::string& shown) {
  if (float(file.units) != float(units)) return std::nullopt;  // MRPT keeps rangeUnits as a float
  const DepthFile reused{path, file.units, file.size, file.trailer, false};
  if (file.recorded) {
    std::uint8_t tail[8];
    std::error_code ec;
    if (file.size < sizeof tail || fs::file_size(file.path, ec) != file.size || ec) return std::nullopt;
    std::FILE* f = std::fopen(file.path.c_str(), "rb");
    const bool read = f && std::fseek(f, -long(sizeof tail), SEEK_END) == 0 && std::fread(tail, 1, sizeof tail, f) == sizeof tail;
    if (f) std::fclose(f);
    if (!read || gzipTrailer(tail + sizeof tail) != file.trailer || !linkFile(file.path, path)) return std::nullopt;
    return reused;
  }
  thread_local std::vector<std::uint8_t> bytes;
  if (!readWholeFile(file.path, bytes) || bytes.size() != file.size || bytes.size() < 18 ||
      gzipTrailer(bytes.data() + bytes.size()) != file.trailer)
    return std::nullopt;
  writeExternalFile(path, bytes, shown, "range image");
  return reused;
}

bool reuseColourFile(const ColourFile& file, int width, int height, const std::string& path, const std::string& shown) {
  if (file.recorded) return linkFile(file.path, path);
  thread_local std::vector<std::uint8_t> bytes;
  if (!readWholeFile(file.path, bytes) || !isRgb8Png(bytes, width, height)) return false;
  writeExternalFile(path, bytes, shown, "image");
  return true;
}

DepthFile writeRangeImageExternally(CObservation3DRangeScan& obs, const std::string& file_name, const std::string& dir,
                                    const std::string& shown) {
  const std::string path = (fs::path(dir) / file_name).string();
  if (obs.rangeImage_isExternallyStored()) throw std::logic_error(path + ": range image is already external");
  // What MRPT's CFileGZOutputStream + CArchive wrote (and its load() reads): a gzip file of rows and
  // cols as little-endian uint32, then the readings as little-endian uint16 in memory order. Made by
  // libdeflate at level 1: 2.6 instead of zlib's 4.2 ms a 640x480 TUM frame, 86 instead of 99 KB.
  const auto& ri = obs.rangeImage;
  static_assert(sizeof(*ri.data()) == 2);
  const std::uint32_t dims[2] = {std::uint32_t(ri.rows()), std::uint32_t(ri.cols())};
  std::vector<unsigned char> raw(sizeof dims + std::size_t(ri.size()) * 2);
  static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "the range image's bytes are written as they are in memory");
  std::memcpy(raw.data(), dims, sizeof dims);
  if (ri.size() != 0) std::memcpy(raw.data() + sizeof dims, ri.data(), std::size_t(ri.size()) * 2);
  const std::vector<std::uint8_t> packed = gzipCompress(raw.data(), raw.size());
  writeExternalFile(path, packed, shown.empty() ? path : shown, "range image");
  useExternalRangeImage(obs, file_name);
  return DepthFile{path, double(obs.rangeUnits), packed.size(), gzipTrailer(packed.data() + packed.size()), false};
}

void writeExternalFile(const std::string& path, const std::vector<std::uint8_t>& bytes, const std::string& shown,
                       const std::string& what) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  const bool ok = f && std::fwrite(bytes.data(), 1, bytes.size(), f) == bytes.size() && std::fflush(f) == 0;
  const int err = errno;
  // Its writeback started now, without waiting: the recording's end syncs every image (a power cut
  // must not leave a record naming an empty file), and finds most of them on the disk already.
  if (ok) ::sync_file_range(::fileno(f), 0, 0, SYNC_FILE_RANGE_WRITE);
  if (!f || std::fclose(f) != 0 || !ok) {
    const std::string why = std::strerror(f && ok ? errno : err);
    std::remove(path.c_str());  // no half-written file that names itself an image
    throw InputError(shown, "cannot write " + what + ": " + why);
  }
}

void useExternalRangeImage(CObservation3DRangeScan& obs, const std::string& file_name) {
  obs.*ExternalNames::range_file = file_name;
  obs.*ExternalNames::range_stored = true;
  obs.rangeImage.setSize(0, 0);
}

}  // namespace vofusion
