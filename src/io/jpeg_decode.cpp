#include "vofusion/io/jpeg_decode.h"

#include <algorithm>
#include <csetjmp>
#include <exception>
#include <vector>

#include <jpeglib.h>
#include <jerror.h>
#ifndef JCS_EXTENSIONS
#error "io/jpeg_decode needs libjpeg-turbo (its JCS_EXT_BGR output): Debian's libjpeg-dev is it"
#endif

#include "vofusion/io/png_decode.h"

namespace vofusion {

namespace {

constexpr double kMaxPixels = double(1 << 30);  // OpenCV's OPENCV_IO_MAX_IMAGE_PIXELS default

// libjpeg reports through its error manager: a fatal error ends in error_exit (which must not return:
// it jumps back to the decoding function), a warning goes to emit_message at level -1.
struct ErrorManager {
  jpeg_error_mgr pub;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX] = "";
  bool damaged = false;
  bool in_scan = false;  // past the header: extraneous bytes before a marker are the image data's
  const std::uint8_t* data = nullptr;  // the file's bytes, which libjpeg reads in place
};

// The warnings that mean the pixels are not the file's: the entropy-coded data did not decode as it
// was written. Not among them: an unknown JFIF revision or Adobe transform, a bad ICC marker
// (metadata), and a scan's parameters libjpeg corrects (baseline files with zero spectral bytes
// decode to their pixels, "Invalid SOS parameters for sequential JPEG").
bool isCorruptData(int code) {
  switch (code) {
    case JWRN_ARITH_BAD_CODE:
    case JWRN_EXTRANEOUS_DATA:
    case JWRN_HIT_MARKER:
    case JWRN_HUFF_BAD_CODE:
    case JWRN_JPEG_EOF:
    case JWRN_MUST_RESYNC:
      return true;
    default:
      return false;
  }
}

// Extraneous bytes that say nothing of the pixels. In the header: padding between segments, whatever
// they hold. Before a restart marker: libjpeg resynchronises there, and MJPEG webcams leave a byte or
// two before one in every frame, whose pixels are whole (the warning may name a later restart marker
// than the one the bytes sit before, so their place is not checked). Before the end marker: zeros
// alone, a camera's padding; they are the bytes just before the source's position (libjpeg has
// synchronised it to the marker's first 0xFF, in the memory it reads).
bool isPadding(j_common_ptr cinfo, const ErrorManager& err) {
  const int marker = cinfo->err->msg_parm.i[1];
  if (!err.in_scan || (marker >= 0xD0 && marker <= 0xD7)) return true;
  const std::uint8_t* end = reinterpret_cast<j_decompress_ptr>(cinfo)->src->next_input_byte;
  if (end < err.data) return false;  // libjpeg's own buffer (past the file's end): no place to check
  const long count = std::min<long>(cinfo->err->msg_parm.i[0], end - err.data);
  for (long k = 1; k <= count; ++k)
    if (end[-k] != 0) return false;
  return true;
}

void onError(j_common_ptr cinfo) {
  auto* err = reinterpret_cast<ErrorManager*>(cinfo->err);
  (*cinfo->err->format_message)(cinfo, err->message);
  err->damaged = true;
  std::longjmp(err->jump, 1);
}

// Nothing is printed: the damage is the caller's one line. The first corrupt-data warning is kept.
void onMessage(j_common_ptr cinfo, int level) {
  auto* err = reinterpret_cast<ErrorManager*>(cinfo->err);
  const int code = cinfo->err->msg_code;
  if (level >= 0 || err->damaged || !isCorruptData(code)) return;
  if (code == JWRN_EXTRANEOUS_DATA && isPadding(cinfo, *err)) return;
  (*cinfo->err->format_message)(cinfo, err->message);
  err->damaged = true;
}

// The decompressor's life, with the two steps libjpeg may jump out of (its creation is in the first).
// Between setjmp and a jump no object with a destructor is made: the Mat is allocated between them.
class Decompressor {
 public:
  Decompressor() {
    cinfo_.err = jpeg_std_error(&err_.pub);
    err_.pub.error_exit = onError;
    err_.pub.emit_message = onMessage;
  }
  ~Decompressor() { jpeg_destroy_decompress(&cinfo_); }  // nothing to free before it was created (mem NULL)
  Decompressor(const Decompressor&) = delete;
  Decompressor& operator=(const Decompressor&) = delete;

  // The header read and the output set: BGR for colour, grey for grey; false for another colour space.
  bool readHeader(const std::uint8_t* data, std::size_t size) {
    err_.data = data;
    if (setjmp(err_.jump)) return false;
    jpeg_create_decompress(&cinfo_);
    jpeg_mem_src(&cinfo_, data, static_cast<unsigned long>(size));
    jpeg_read_header(&cinfo_, TRUE);
    header_read_ = true;
    if (cinfo_.jpeg_color_space == JCS_GRAYSCALE) cinfo_.out_color_space = JCS_GRAYSCALE;
    else if (cinfo_.jpeg_color_space == JCS_YCbCr || cinfo_.jpeg_color_space == JCS_RGB) cinfo_.out_color_space = JCS_EXT_BGR;
    else return false;
    return true;
  }
  int rows() const { return header_read_ ? int(cinfo_.image_height) : 0; }
  int cols() const { return header_read_ ? int(cinfo_.image_width) : 0; }
  int channels() const { return cinfo_.out_color_space == JCS_GRAYSCALE ? 1 : 3; }

  // The rows decoded into `image`, which has the header's size; false when libjpeg gave up.
  bool decodeInto(cv::Mat& image) {
    err_.in_scan = true;
    if (setjmp(err_.jump)) return false;
    jpeg_start_decompress(&cinfo_);
    while (cinfo_.output_scanline < cinfo_.output_height) {
      if (err_.damaged) return false;  // the rest would be decoded for nothing
      JSAMPROW row = image.ptr<JSAMPLE>(int(cinfo_.output_scanline));
      jpeg_read_scanlines(&cinfo_, &row, 1);
    }
    jpeg_finish_decompress(&cinfo_);  // reads to the end-of-image marker: warnings past the last row
    return true;
  }

  bool damaged() const { return err_.damaged; }
  std::string message() const { return err_.message; }

 private:
  ErrorManager err_;
  jpeg_decompress_struct cinfo_{};
  bool header_read_ = false;
};

bool startsAsJpeg(const std::uint8_t* p, std::size_t n) { return n >= 3 && p[0] == 0xFF && p[1] == 0xD8 && p[2] == 0xFF; }

}  // namespace

JpegDecode decodeJpeg(const std::uint8_t* data, std::size_t size, cv::Size expect, double most_pixels) {
  JpegDecode out;
  if (!startsAsJpeg(data, size)) return out;
  Decompressor d;
  const bool supported = d.readHeader(data, size);
  if (d.damaged()) {
    out.damage = d.message();
    return out;
  }
  out.header = cv::Size(d.cols(), d.rows());
  if (!expect.empty() && out.header != expect) return out;
  if (most_pixels > 0 && double(out.header.area()) > most_pixels) return out;
  if (expect.empty() && double(d.cols()) * d.rows() > kMaxPixels) {
    out.damage = "its header states " + std::to_string(d.cols()) + "x" + std::to_string(d.rows()) + " pixels, more than any image";
    return out;
  }
  if (!supported) return out;
  cv::Mat image;
  try {
    image.create(d.rows(), d.cols(), d.channels() == 1 ? CV_8UC1 : CV_8UC3);
  } catch (const std::exception&) {  // cv::Exception or std::bad_alloc: the file's size is the problem
    out.damage = "its header states " + std::to_string(d.cols()) + "x" + std::to_string(d.rows()) + " pixels, more than memory holds";
    return out;
  }
  if (!d.decodeInto(image) || d.damaged()) {
    out.damage = d.damaged() ? d.message() : "libjpeg stopped";
    return out;
  }
  out.image = image;
  return out;
}

JpegDecode readJpeg(const std::string& path, cv::Size expect, double most_pixels) {
  // Its first bytes first: a PNG is not read whole again to be told apart.
  std::uint8_t head[3];
  if (!readFileStart(path, head, sizeof head) || !startsAsJpeg(head, sizeof head)) return {};
  thread_local std::vector<std::uint8_t> bytes;
  if (!readWholeFile(path, bytes)) return {};
  return decodeJpeg(bytes.data(), bytes.size(), expect, most_pixels);
}

}  // namespace vofusion
