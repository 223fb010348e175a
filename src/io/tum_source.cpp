#include "vofusion/io/tum_source.h"

#include <algorithm>
#include <tuple>
#include <cmath>
#include <cstdio>
#include <optional>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <opencv2/core/persistence.hpp>
#include <opencv2/imgcodecs.hpp>

#include "vofusion/core/errors.h"
#include "vofusion/core/progress.h"
#include "vofusion/io/jpeg_decode.h"
#include "vofusion/io/rawlog_time.h"
#include "vofusion/io/png_decode.h"
#include "vofusion/core/text_file.h"

namespace fs = std::filesystem;

namespace vofusion {

namespace {
// What is wrong with a list line on its own ("" when nothing is); e parsed from it.
std::string listLineProblem(std::string line, TumEntry& e) {
  const bool commas = line.find(',') != std::string::npos;
  std::replace(line.begin(), line.end(), ',', ' ');  // as TUM's associate.py reads a list (and our trajectories)
  std::istringstream ls(line);
  if (!(ls >> e.timestamp) || !std::isfinite(e.timestamp) || !(ls >> e.file)) return "expected 'timestamp filename'";
  std::string extra;
  if (ls >> extra)
    return "unexpected extra field '" + extra + "'" + (commas ? " (a comma parts fields, as in TUM's tools: a file name cannot hold one)" : "");
  // Seconds past any clock's end are another unit: every frame interval would be a billion times too
  // long (the motion model's velocities), and no rawlog could hold the stamp.
  if (!rawlogCanHold(e.timestamp))
    return "timestamp " + cv::format("%.10g", e.timestamp) +
           " is not in seconds (TUM lists give Unix time in seconds; nanoseconds?)";
  return {};
}

// Which entries keep the list in time order: the longest run of rising stamps, of equal runs the one of
// the earliest lines (a duplicated stamp keeps its first line). Judged against the last line kept, one
// stamp damaged forward (a digit changed) put every good line after it "out of order".
std::vector<bool> inTimeOrder(const std::vector<TumEntry>& entries) {
  // Longest rising run starting at each entry, walked from the end: tails[k] is the entry that starts a
  // run of k + 1 with the latest first stamp; next[i] the entry after i in its run.
  std::vector<std::size_t> tails;
  std::vector<long> next(entries.size(), -1);
  for (std::size_t i = entries.size(); i-- > 0;) {
    const double t = entries[i].timestamp;
    // The first run whose start is not later than t: i cannot start it, but replaces its start.
    const auto at = std::lower_bound(tails.begin(), tails.end(), t,
                                     [&](std::size_t k, double v) { return entries[k].timestamp > v; });
    if (at != tails.begin()) next[i] = long(*std::prev(at));
    if (at == tails.end()) tails.push_back(i);
    else *at = i;
  }
  std::vector<bool> keep(entries.size(), false);
  for (long i = tails.empty() ? -1 : long(tails.back()); i >= 0; i = next[std::size_t(i)]) keep[std::size_t(i)] = true;
  return keep;
}
}  // namespace

std::vector<TumEntry> parseTumList(const std::string& text, const std::string& origin, TumListDamage* damage) {
  std::vector<TumEntry> parsed;
  std::vector<std::size_t> line_of;
  std::vector<std::pair<std::size_t, std::string>> problems;  // (line, why), in line order at the end
  for (const auto& [n, line] : dataLines(text)) {
    if (damage) ++damage->lines;
    TumEntry e;
    if (const std::string why = listLineProblem(line, e); !why.empty()) {
      problems.emplace_back(n, why);
      continue;
    }
    parsed.push_back(std::move(e));
    line_of.push_back(n);
  }
  const std::vector<bool> keep = inTimeOrder(parsed);
  std::vector<TumEntry> out;
  out.reserve(parsed.size());
  for (std::size_t i = 0; i < parsed.size(); ++i) {
    if (keep[i]) out.push_back(std::move(parsed[i]));
    else problems.emplace_back(line_of[i], "timestamp " + std::to_string(parsed[i].timestamp) + " is out of order or duplicated");
  }
  std::sort(problems.begin(), problems.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  for (const auto& [n, why] : problems) {
    if (!damage) throw InputError(origin, "line " + std::to_string(n) + ": " + why);
    damage->problems.push_back("line " + std::to_string(n) + ": " + why);
  }
  return out;
}

std::vector<TumEntry> readTumList(const std::string& path) { return parseTumList(readTextFile(path), path); }

std::vector<TumAssociation> associate(const std::vector<TumEntry>& rgb, const std::vector<TumEntry>& depth,
                                      double max_diff, bool one_to_one) {
  // Candidate pairs less than max_diff apart, best first; each stamp used once (as associate.py does:
  // abs(a - b) < max_difference, as the evaluation's association).
  struct Cand { double dt; std::size_t i, j; };
  std::vector<Cand> cands;
  for (std::size_t i = 0; i < rgb.size(); ++i) {
    auto lo = std::lower_bound(depth.begin(), depth.end(), rgb[i].timestamp - max_diff,
                               [](const TumEntry& e, double t) { return e.timestamp < t; });
    for (auto it = lo; it != depth.end() && it->timestamp <= rgb[i].timestamp + max_diff; ++it)
      if (const double dt = std::abs(it->timestamp - rgb[i].timestamp); dt < max_diff)
        cands.push_back({dt, i, std::size_t(it - depth.begin())});
  }
  // Ties by the stamps, as associate.py sorts (difference, colour stamp, depth stamp) tuples.
  std::sort(cands.begin(), cands.end(),
            [](const Cand& a, const Cand& b) { return std::tie(a.dt, a.i, a.j) < std::tie(b.dt, b.i, b.j); });
  if (!one_to_one) {
    // Best first, so the first candidate seen for a depth frame is its nearest colour frame.
    std::vector<long> nearest(depth.size(), -1);
    for (const Cand& c : cands)
      if (nearest[c.j] < 0) nearest[c.j] = long(c.i);
    std::vector<TumAssociation> out;
    for (std::size_t j = 0; j < depth.size(); ++j)
      if (nearest[j] >= 0) out.push_back({rgb[std::size_t(nearest[j])], depth[j]});
    return out;
  }
  std::vector<char> used_rgb(rgb.size(), 0), used_depth(depth.size(), 0);
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  for (const Cand& c : cands) {
    if (used_rgb[c.i] || used_depth[c.j]) continue;
    used_rgb[c.i] = used_depth[c.j] = 1;
    pairs.emplace_back(c.i, c.j);
  }
  std::sort(pairs.begin(), pairs.end());
  std::vector<TumAssociation> out;
  out.reserve(pairs.size());
  for (auto [i, j] : pairs) out.push_back({rgb[i], depth[j]});
  return out;
}

namespace {
// accelerometer.txt: "timestamp ax ay az" per line, as the "up" the sensor feels (the reaction to
// gravity), in the optical frame.
std::vector<std::pair<double, Eigen::Vector3d>> readAccelerometer(const std::string& path) {
  std::vector<std::pair<double, Eigen::Vector3d>> ups;
  for (const auto& l : dataLines(readTextFile(path))) {
    std::istringstream ls(l.text);
    double t, a[3];
    std::string extra;
    if (!(ls >> t >> a[0] >> a[1] >> a[2]) || (ls >> extra) || !std::isfinite(t))
      throw InputError(path, "line " + std::to_string(l.number) + ": expected 'timestamp ax ay az'");
    const Eigen::Vector3d up(-a[0], -a[1], a[2]);
    if (up.allFinite() && up.norm() > 1.0) ups.emplace_back(t, up);  // m/s^2; ~0 = no reading
  }
  return ups;
}

// cv::imread, with OpenCV's refusal of a header's size (past its pixel limit: an exception, not an
// empty image) as the file's damage.
cv::Mat readImage(const std::string& path, int flags, const char* what) {
  try {
    return cv::imread(path, flags);
  } catch (const cv::Exception& e) {
    throw InputError(path, std::string("cannot decode ") + what + " image (OpenCV: " + e.err + ")");
  }
}

// An image file named by a list: missing, or a folder (a list line naming "rgb/"), is the frame's
// damage in one line.
void requireImageFile(const std::string& path, const char* what) {
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  // A folder on the way that cannot be searched (no x permission) is no missing image: say why.
  if (ec && ec != std::errc::no_such_file_or_directory && ec != std::errc::not_a_directory)
    throw InputError(path, std::string("cannot read ") + what + " image (" + ec.message() + ")");
  if (!fs::exists(st)) throw InputError(path, std::string(what) + " image is missing");
  if (!fs::is_regular_file(st)) throw InputError(path, std::string(what) + " image is not a file (a folder?)");
}

// Where the plain decoder got nothing: a file that cannot be opened says why (it was "corrupt or
// truncated"). Only then: a second open of every image every frame is what the plain decoder saves.
void requireReadable(const std::string& path, const char* what) {
  if (const std::string why = whyUnreadable(path); !why.empty())
    throw InputError(path, std::string("cannot read ") + what + " image (" + why + ")");
}

std::string sizeMismatch(const char* what, cv::Size got, int expect_w, int expect_h) {
  return std::string(what) + " image is " + std::to_string(got.width) + "x" + std::to_string(got.height) +
         ", expected " + std::to_string(expect_w) + "x" + std::to_string(expect_h);
}

// The image as readPlainPng decodes it; a PNG whose header states another size is refused before any
// decoder allocates its pixels (a crafted 30000x30000 depth PNG of 1 KB reached libpng, its own line
// printed and 1.8 GB allocated). Empty for anything readPlainPng leaves to OpenCV.
cv::Mat readPlainPngOfSize(const std::string& path, const char* what, int expect_w, int expect_h) {
  cv::Size header;
  cv::Mat image = readPlainPng(path, cv::Size(expect_w, expect_h), &header);
  if (!header.empty() && header != cv::Size(expect_w, expect_h))
    throw InputError(path, sizeMismatch(what, header, expect_w, expect_h));
  return image;
}

// The same for a JPEG, whose corrupt data (a hole in the middle, flipped bytes) is the file's damage:
// cv::imread returns such a picture with grey or smeared blocks. Empty for what is no JPEG.
cv::Mat readJpegOfSize(const std::string& path, const char* what, int expect_w, int expect_h) {
  const JpegDecode jpeg = readJpeg(path, cv::Size(expect_w, expect_h));
  if (!jpeg.damage.empty()) throw InputError(path, std::string("cannot decode ") + what + " image (" + jpeg.damage + ")");
  if (!jpeg.header.empty() && jpeg.header != cv::Size(expect_w, expect_h))
    throw InputError(path, sizeMismatch(what, jpeg.header, expect_w, expect_h));
  return jpeg.image;
}
}  // namespace

cv::Mat loadRawDepthPng(const std::string& path, int expect_w, int expect_h, const std::string& unit_note) {
  requireImageFile(path, "depth");
  // A 16-bit grey PNG in about half OpenCV's time; only a whole file decodes (IEND, CRCs), so the
  // truncation check is needed (and the file opened again) only for what OpenCV gets.
  cv::Mat raw = readPlainPngOfSize(path, "depth", expect_w, expect_h);
  if (raw.empty()) {
    requireReadable(path, "depth");
    if (const std::string damage = imageFileDamage(path); !damage.empty())
      throw InputError(path, "cannot decode depth image (" + damage + ")");
    // The sensor's pixel grid, whatever an EXIF orientation says: depth and colour pair pixel by pixel.
    raw = readImage(path, cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR | cv::IMREAD_IGNORE_ORIENTATION, "depth");
  }
  if (raw.empty()) throw InputError(path, "cannot decode depth image (corrupt or truncated PNG?)");
  if (raw.type() != CV_16UC1) throw InputError(path, "depth image must be 16-bit single channel" + unit_note);
  if (raw.cols != expect_w || raw.rows != expect_h)
    throw InputError(path, sizeMismatch("depth", raw.size(), expect_w, expect_h));
  return raw;
}

cv::Mat loadTumDepth(const std::string& path, int expect_w, int expect_h, double scale) {
  cv::Mat depth;
  loadRawDepthPng(path, expect_w, expect_h).convertTo(depth, CV_32F, 1.0 / scale);  // 0 = no reading
  return depth;
}

cv::Mat loadColour(const std::string& path, int expect_w, int expect_h) {
  requireImageFile(path, "colour");
  cv::Mat img = readPlainPngOfSize(path, "colour", expect_w, expect_h);  // an 8-bit RGB PNG, as loadRawDepthPng does
  if (img.type() != CV_8UC3) {
    requireReadable(path, "colour");
    if (const std::string damage = imageFileDamage(path); !damage.empty())
      throw InputError(path, "cannot decode colour image (" + damage + ")");
    img = readJpegOfSize(path, "colour", expect_w, expect_h);
    if (img.empty()) img = readImage(path, cv::IMREAD_UNCHANGED, "colour");
    // A depth map read as colour gave a grey picture of the depths, tracked as if it were colour.
    if (img.type() == CV_16UC1)
      throw InputError(path, "colour image is 16-bit single channel, as depth images are (a depth file in rgb.txt?)");
  }
  if (img.empty()) throw InputError(path, "cannot decode colour image (corrupt or truncated?)");
  // The size before any conversion: an image of another size is not converted to be refused.
  if (img.cols != expect_w || img.rows != expect_h)
    throw InputError(path, sizeMismatch("colour", img.size(), expect_w, expect_h));
  return img.type() == CV_8UC3 ? img : asBgr8(img);
}

CameraFile readIntrinsicsFile(const std::string& path) {
  const auto lines = dataLines(readTextFile(path));
  if (lines.empty()) throw InputError(path, "no 'fx fy cx cy' line");
  auto bad = [&](std::size_t k, const std::string& what) {
    return InputError(path, "line " + std::to_string(lines[k].number) + ": expected " + what);
  };
  std::istringstream ls(lines[0].text);
  std::vector<double> v;
  for (double x; ls >> x;) v.push_back(x);
  if (!ls.eof() || (v.size() != 4 && v.size() != 9)) throw bad(0, "'fx fy cx cy [k1 k2 p1 p2 k3]'");
  CameraFile f;
  f.camera.fx = v[0]; f.camera.fy = v[1]; f.camera.cx = v[2]; f.camera.cy = v[3];
  f.camera.dist = {};
  for (std::size_t i = 4; i < v.size(); ++i) f.camera.dist[i - 4] = v[i];
  for (std::size_t k = 1; k < lines.size(); ++k) {
    std::istringstream kv(lines[k].text);
    std::string key, extra;
    kv >> key;
    if (key == "size") {
      if (!(kv >> f.camera.width >> f.camera.height) || (kv >> extra) || f.camera.width < 1 || f.camera.height < 1)
        throw bad(k, "'size W H' (pixels)");
      f.has_size = true;
    } else if (key == "depth_scale") {
      if (!(kv >> f.depth_scale) || (kv >> extra) || !(f.depth_scale > 0 && f.depth_scale <= 1e6))
        throw bad(k, "'depth_scale S' with S in (0, 1e6] depth units per metre");
    } else {
      throw bad(k, "'size W H' or 'depth_scale S' (unknown key '" + key + "')");
    }
  }
  return f;
}

namespace {
// A matrix of the YAML file as doubles, one row: OpenCV's (!!opencv-matrix: rows, cols, dt, data) or
// ROS camera_info's (rows, cols, data, as camera_calibration writes it); empty when the key is absent.
cv::Mat yamlMatrix(const cv::FileNode& node, const std::string& path, const std::string& key) {
  if (node.empty()) return {};
  const std::string expected = key + " must be a matrix (OpenCV's rows, cols, dt, data or ROS's rows, cols, data)";
  std::vector<double> values;
  try {
    if (node.isMap() && node["dt"].empty() && node["data"].isSeq()) {
      node["data"] >> values;
    } else {
      cv::Mat m, row;
      node >> m;
      if (!m.empty()) m.reshape(1, 1).convertTo(row, CV_64F);
      values.assign(row.begin<double>(), row.end<double>());
    }
  } catch (const cv::Exception&) {
    throw InputError(path, expected);
  }
  if (values.empty()) throw InputError(path, expected);
  return cv::Mat(values, true).reshape(1, 1);
}
}  // namespace

CameraFile readCameraYaml(const std::string& path) {
  // Capped as every text file (--intrinsics /dev/zero grew without bound).
  std::string yaml = readTextFile(path);
  if (yaml.empty()) throw InputError(path, "cannot read (empty)");
  // OpenCV reads YAML only after its "%YAML:1.0" line, which ROS's files do not have.
  if (yaml.rfind("%YAML", 0) != 0) yaml = "%YAML:1.0\n---\n" + yaml;
  cv::FileStorage fsr;
  try {
    if (!fsr.open(yaml, cv::FileStorage::READ | cv::FileStorage::MEMORY | cv::FileStorage::FORMAT_YAML))
      throw InputError(path, "cannot read");
  } catch (const cv::Exception&) {
    throw InputError(path, "not an OpenCV YAML file (camera_matrix, distortion_coefficients, image_width, ...)");
  }
  const cv::Mat K = yamlMatrix(fsr["camera_matrix"], path, "camera_matrix"),
                d = yamlMatrix(fsr["distortion_coefficients"], path, "distortion_coefficients");
  if (K.rows * K.cols != 9) throw InputError(path, "camera_matrix must be a 3x3 matrix");
  CameraFile f;
  f.camera.fx = K.at<double>(0); f.camera.fy = K.at<double>(4);
  f.camera.cx = K.at<double>(2); f.camera.cy = K.at<double>(5);
  f.camera.dist = {};
  // k1 k2 p1 p2 k3 (OpenCV's and ROS's plumb_bob); ROS's rational_polynomial adds k4..k6, which only
  // fit this model at zero, and equidistant is another model altogether.
  const bool named = !fsr["distortion_model"].empty();
  const std::string model = named ? std::string(fsr["distortion_model"]) : "plumb_bob";
  // (no distortion_coefficients: an empty matrix, whose iterators OpenCV cannot make: SIGFPE)
  const bool beyond_five = d.total() > 5 && std::any_of(d.begin<double>() + 5, d.end<double>(), [](double k) { return k != 0.0; });
  if ((model != "plumb_bob" && model != "rational_polynomial") || beyond_five)
    throw InputError(path, (named ? "distortion '" + model + "' with " : "distortion with ") + std::to_string(d.total()) +
                               " coefficients" + (beyond_five ? ", some beyond k3 not zero" : "") +
                               ": only k1 k2 p1 p2 k3 (plumb_bob) can be used");
  for (int i = 0; i < std::min<int>(5, int(d.total())); ++i) f.camera.dist[i] = d.at<double>(i);
  if (!fsr["image_width"].empty() && !fsr["image_height"].empty()) {
    f.camera.width = int(fsr["image_width"]);
    f.camera.height = int(fsr["image_height"]);
    f.has_size = true;
  }
  if (!fsr["depth_scale"].empty()) {
    f.depth_scale = double(fsr["depth_scale"]);
    if (!(f.depth_scale > 0 && f.depth_scale <= 1e6)) throw InputError(path, "depth_scale must be in (0, 1e6] units per metre");
  }
  return f;
}

namespace {

void warn(const std::string& origin, const std::string& what) { printWarning(origin + ": " + what); }

// The median reading of a depth PNG in its own units (0 when it has none).
double medianRaw(const cv::Mat& raw) {
  std::vector<uint16_t> v;
  v.reserve(raw.total());
  for (int y = 0; y < raw.rows; y += 2)
    for (int x = 0; x < raw.cols; x += 2)
      if (const uint16_t d = raw.at<uint16_t>(y, x)) v.push_back(d);
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

}  // namespace

namespace {
// The size a colour file's header states, without decoding it: a PNG's IHDR, a JPEG's frame header
// (empty for neither, or an unreadable header).
cv::Size headerSize(const std::string& path) {
  const cv::Size png = pngHeaderSize(path);
  if (!png.empty()) return png;
  return readJpeg(path, {}, 1.0).header;  // more than one pixel: not decoded, its header said
}

// Whether the file decodes whole at `size`, as loadColour would read it.
bool wholeAt(const std::string& path, cv::Size size) {
  if (!imageFileDamage(path).empty()) return false;
  if (!pngHeaderSize(path).empty()) return true;  // a PNG's data is checked whole by imageFileDamage
  // A crafted header that won the vote (a short list) is not decoded past any colour camera's size.
  constexpr double kMostColourPixels = 64e6;  // 16x a Kinect v2's 2 megapixels, 4x a 4K camera's
  const JpegDecode jpeg = readJpeg(path, size, kMostColourPixels);
  if (jpeg.image.empty() && double(size.area()) > kMostColourPixels) return false;
  if (!jpeg.damage.empty()) return false;
  if (!jpeg.image.empty()) return true;
  try {  // a colour space libjpeg leaves to OpenCV (CMYK)
    return readImage(path, cv::IMREAD_UNCHANGED, "colour").size() == size;
  } catch (const InputError&) {
    return false;
  }
}
}  // namespace

std::optional<cv::Size> recordingImageSize(const std::vector<std::string>& paths) {
  const auto regular = [](const std::string& path) {
    std::error_code ec;  // a file that cannot be stat'ed (a symlink loop) is its own frame's damage, not the run's
    return !path.empty() && fs::is_regular_file(path, ec);  // and no FIFO is opened (it would block)
  };
  // PNGs and JPEGs vote by their headers, nothing decoded: one odd or crafted first frame (a JPEG
  // stating 32768 x 32767 was decoded whole to learn its size) sets no recording's size.
  std::vector<cv::Size> headers;  // each path's, empty for neither
  std::vector<std::pair<cv::Size, int>> votes;  // in the order first seen: a tie goes to the earlier
  for (const std::string& path : paths) {
    const cv::Size header = headers.emplace_back(regular(path) ? headerSize(path) : cv::Size());
    if (header.empty()) continue;
    const auto it = std::find_if(votes.begin(), votes.end(), [&](const auto& v) { return v.first == header; });
    if (it == votes.end()) votes.emplace_back(header, 1);
    else ++it->second;
  }
  if (!votes.empty()) {
    // The most voted size with a file of it that is whole; with none whole the recording is refused
    // at once (as when none decodes), not frame by frame.
    std::stable_sort(votes.begin(), votes.end(), [](const auto& a, const auto& b) { return a.second > b.second; });
    for (const auto& [size, count] : votes)
      for (std::size_t i = 0; i < paths.size(); ++i)
        if (headers[i] == size && wholeAt(paths[i], size)) return size;
    return std::nullopt;
  }
  // Other formats (BMP, TIFF): OpenCV decodes the first readable one.
  for (const std::string& path : paths) {
    if (!regular(path) || !imageFileDamage(path).empty()) continue;
    try {
      // As loadColour reads it (IMREAD_UNCHANGED ignores an EXIF orientation): IMREAD_COLOR turned a
      // JPEG tagged "rotate 90" to 480x640, and every 640x480 frame was then refused as the wrong size.
      const cv::Mat image = readImage(path, cv::IMREAD_UNCHANGED, "colour");
      if (!image.empty()) return image.size();
    } catch (const InputError&) {  // the next one may give the size; this one is its own frame's damage
    }
  }
  return std::nullopt;
}

namespace {
// The image size comes from the data itself: the first frames' colour images set it for the whole
// sequence (recordingImageSize); an error naming the first when none of them can be read.
cv::Size colourImageSize(const std::string& folder, const std::vector<TumAssociation>& pairs) {
  std::vector<std::string> paths;
  for (std::size_t i = 0; i < std::min(pairs.size(), kFramesForImageSize); ++i)
    paths.push_back((fs::path(folder) / pairs[i].rgb.file).string());
  if (const auto size = recordingImageSize(paths)) return *size;
  throw InputError(paths.front(), "colour image cannot be read, nor can any of the first " + std::to_string(paths.size()) +
                                      " listed in rgb.txt");
}

// Depth frames no colour frame pairs with are not used: said when they are more than one in ten (a colour
// camera at half the depth's rate halved the frames tracked without a word; TUM's lists leave one or two).
// associate() uses each depth line at most once, so the pairs count the lines used (by file name, a
// file listed at two stamps, as a driver repeating a frame writes, was one used and one not).
void warnOfUnpairedDepth(const std::string& depth_list, const std::vector<TumEntry>& depth,
                         const std::vector<TumAssociation>& pairs, double max_diff) {
  const std::size_t unpaired = depth.size() - std::min(depth.size(), pairs.size());
  if (unpaired * 10 <= depth.size()) return;
  char within[32];
  std::snprintf(within, sizeof within, "%g", max_diff);
  warn(depth_list, std::to_string(unpaired) + " of its " + std::to_string(depth.size()) +
                       " depth frames have no colour frame within " + within + " s and are not used (colour at a lower rate?)");
}

// The folder's camera file, intrinsics.txt before camera.yaml (`origin` set to the one read); none: nullopt.
std::optional<CameraFile> cameraFileIn(const std::string& txt, const std::string& yaml, std::string& origin) {
  if (entryExists(txt)) {
    origin = txt;
    return readIntrinsicsFile(txt);
  }
  if (entryExists(yaml)) {
    origin = yaml;
    return readCameraYaml(yaml);
  }
  return std::nullopt;
}
}  // namespace

namespace {
// A frame list whose damaged lines cost those frames, as a damaged image does (warnOfDamagedLines says
// them); more than one in five stops the run (the file itself is then in doubt). strict: the first
// stops it. A recording cut short mid-line (a crash while it was written) lost its run to its last line.
std::vector<TumEntry> readFrameList(const std::string& path, bool strict, TumListDamage& damage) {
  if (strict) return readTumList(path);
  std::vector<TumEntry> list = parseTumList(readTextFile(path), path, &damage);
  const std::size_t bad = damage.problems.size();
  if (bad * 5 > damage.lines)
    throw InputError(path, damage.problems.front() + " (" + std::to_string(bad) + " of its " + std::to_string(damage.lines) +
                               " lines damaged: more than one in five)");
  return list;
}

// The first three damaged lines, and how many there were beyond them.
void warnOfDamagedLines(const std::string& path, const TumListDamage& damage) {
  const std::size_t bad = damage.problems.size();
  for (std::size_t i = 0; i < std::min<std::size_t>(bad, 3); ++i) warn(path, damage.problems[i] + " (its frame skipped)");
  if (bad > 3) warn(path, std::to_string(bad) + " damaged lines skipped in all");
}

// rgb.txt and depth.txt paired by time (at most opts.max_frames pairs).
std::vector<TumAssociation> framePairsIn(const std::string& folder, const SourceOptions& opts) {
  const std::string rgb_list = (fs::path(folder) / "rgb.txt").string();
  const std::string depth_list = (fs::path(folder) / "depth.txt").string();
  for (const auto& f : {rgb_list, depth_list})
    if (!entryExists(f)) throw InputError(f, "missing (not a TUM RGB-D folder?)");
  TumListDamage rgb_damage, depth_damage;
  const auto rgb = readFrameList(rgb_list, opts.strict, rgb_damage);
  const auto depth = readFrameList(depth_list, opts.strict, depth_damage);
  warnOfDamagedLines(rgb_list, rgb_damage);  // once both lists are taken: nothing said before a refusal
  warnOfDamagedLines(depth_list, depth_damage);
  if (rgb.empty()) throw InputError(rgb_list, "lists no frames");
  if (depth.empty()) throw InputError(depth_list, "lists no frames");
  std::vector<TumAssociation> pairs = associate(rgb, depth, opts.max_time_diff, opts.unique_depth);
  if (pairs.empty())
    throw InputError(folder, "no colour frame has a depth frame within " + std::to_string(opts.max_time_diff) + " s");
  warnOfUnpairedDepth(depth_list, depth, pairs, opts.max_time_diff);
  if (opts.max_frames > 0 && pairs.size() > opts.max_frames) pairs.resize(opts.max_frames);
  return pairs;
}

// The folder's camera file as the options let it be read (`origin` set to the one read, else the folder).
std::optional<CameraFile> cameraFileFor(const std::string& folder, const SourceOptions& opts, std::string& origin) {
  const std::string txt = (fs::path(folder) / "intrinsics.txt").string(), yaml = (fs::path(folder) / "camera.yaml").string();
  origin = folder;
  if (!opts.intrinsics) return cameraFileIn(txt, yaml, origin);
  if (opts.depth_scale > 0) return std::nullopt;
  // Given --intrinsics, the file is read for its depth unit only: one this reader cannot take (another
  // tool's camera.yaml) is said and left, where it made the folder unusable without editing it.
  try {
    return cameraFileIn(txt, yaml, origin);
  } catch (const InputError& e) {
    if (opts.strict) throw;
    warn(e.file(), e.problem() + " (left: --intrinsics gives the camera; depth in 1/5000 m unless --depth-scale)");
    return std::nullopt;
  }
}

// The camera for `image`-sized frames: the command line, else the folder's camera file, else a guess
// (TUM's fr1 default, 640x480 only).
CameraIntrinsics cameraOf(const std::string& folder, const SourceOptions& opts, const std::optional<CameraFile>& file,
                          std::string origin, const cv::Size& image) {
  const std::string size = std::to_string(image.width) + "x" + std::to_string(image.height);
  CameraIntrinsics camera;
  if (opts.intrinsics) {
    origin = "--intrinsics";
    camera = CameraIntrinsics::parse(*opts.intrinsics).forImage(image.width, image.height, origin);
  } else if (file) {
    camera = file->camera;
    if (file->has_size && (camera.width != image.width || camera.height != image.height))
      throw InputError(origin, "intrinsics are for " + std::to_string(camera.width) + "x" + std::to_string(camera.height) +
                                   " images, this recording's are " + size);
  } else {
    camera = CameraIntrinsics::forTumFolder(folder);
    const bool tum = CameraIntrinsics::namesAFreiburgCamera(folder);
    // A TUM recording's own camera fits a copy of another size and the same shape, as its preset given
    // by hand does; the ROS default is a guess only at the size it was made for.
    if (tum && camera.fitsShapeOf(image.width, image.height))
      camera = camera.forImage(image.width, image.height, folder);
    else if (image.width != 640 || image.height != 480)
      throw InputError(folder, "no intrinsics for its " + size + " images: give --intrinsics fx,fy,cx,cy or put an "
                               "intrinsics.txt ('fx fy cx cy') or camera.yaml beside rgb.txt");
    if (!tum)
      warn(folder, "no intrinsics.txt or camera.yaml and no --intrinsics: assuming fx = fy = 525, cx = 319.5, cy = 239.5");
  }
  camera.width = image.width;
  camera.height = image.height;
  camera.validate(origin);
  return camera;
}

// A unit mix-up shows in the first frame's median reading (indoor RGB-D: 0.4-5 m; millimetres read
// as TUM's units land at a fifth, TUM's read as millimetres at five times). The first depth image that
// loads: a damaged one is the reader's to report, frame by frame.
void warnOfAnotherDepthUnit(const std::string& folder, const std::vector<TumAssociation>& pairs, const cv::Size& image,
                            double depth_scale) {
  for (std::size_t i = 0; i < std::min<std::size_t>(pairs.size(), 10); ++i) {
    const std::string d = (fs::path(folder) / pairs[i].depth.file).string();
    cv::Mat raw;
    try {
      raw = loadRawDepthPng(d, image.width, image.height);
    } catch (const InputError&) {
      continue;
    }
    const double median = medianRaw(raw) / depth_scale;
    if (median > 5.0 || (median > 0 && median < 0.4))
      warn(d, cv::format("median depth %.2f m at %g depth units per metre: another unit? (--depth-scale: 1000 for "
                         "millimetres, 5000 for TUM)", median, depth_scale));
    return;
  }
}

// The Kinect's accelerometer reads the reaction to gravity ("up") with its x and y axes opposite to
// the optical frame's (checked on fr1 xyz and rpy against their ground truth). Like the ground truth
// it only goes along with the frames: damaged, it costs the pictures' measured "up" (they are then
// oriented as for a recording without one), not the run, unless --strict. Sorted by time.
std::vector<std::pair<double, Eigen::Vector3d>> accelerometerIn(const std::string& folder, bool strict) {
  const std::string accel = (fs::path(folder) / "accelerometer.txt").string();
  std::vector<std::pair<double, Eigen::Vector3d>> readings;
  if (!entryExists(accel)) return readings;
  try {
    readings = readAccelerometer(accel);
  } catch (const InputError& e) {
    if (strict) throw;
    printWarning(std::string(e.what()) + " (read without the accelerometer's up)");
  }
  std::sort(readings.begin(), readings.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  return readings;
}
}  // namespace

TumFolderSource::TumFolderSource(const std::string& folder, const SourceOptions& opts) : folder_(folder) {
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) throw InputError(folder, "no such folder");
  pairs_ = framePairsIn(folder, opts);
  // The camera and the depth unit: the command line, else the folder's camera file, else a guess.
  std::string origin;
  const std::optional<CameraFile> file = cameraFileFor(folder, opts, origin);
  const cv::Size image = colourImageSize(folder, pairs_);
  camera_ = cameraOf(folder, opts, file, origin, image);
  depth_scale_ = opts.depth_scale > 0 ? opts.depth_scale : file && file->depth_scale > 0 ? file->depth_scale : 5000.0;
  warnOfAnotherDepthUnit(folder, pairs_, image, depth_scale_);
  const std::string gt = (fs::path(folder) / "groundtruth.txt").string();
  if (entryExists(gt)) gt_ = readGroundTruthFile(gt, opts);
  accel_ = accelerometerIn(folder, opts.strict);
}

Frame TumFolderSource::read(std::size_t i) const {
  const TumAssociation& a = pairs_.at(i);
  Frame f;
  f.index = i;
  // The pose a frame yields is where the camera was when the depth image was taken: ICP and the TSDF
  // see only depth, and colour may be up to max_time_diff away.
  f.timestamp = a.depth.timestamp;
  f.colour_offset = a.rgb.timestamp - a.depth.timestamp;  // the odometry's keypoint bearings come from colour
  f.camera = camera_;
  f.colour_file = ColourFile{(fs::path(folder_) / a.rgb.file).string()};
  f.rgb = loadColour(f.colour_file->path, camera_.width, camera_.height);
  f.depth = loadTumDepth((fs::path(folder_) / a.depth.file).string(), camera_.width, camera_.height, depth_scale_);
  mrpt::poses::CPose3D gt;
  if (interpolatePose(gt_, f.timestamp, 0.05, gt)) f.groundTruth = gt;
  // The mean of the readings within 0.1 s: the camera's own accelerations average out a little.
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  auto it = std::lower_bound(accel_.begin(), accel_.end(), f.timestamp - 0.1,
                             [](const auto& a, double t) { return a.first < t; });
  for (; it != accel_.end() && it->first <= f.timestamp + 0.1; ++it) sum += it->second;
  if (sum.norm() > 0) f.up = sum.normalized();
  return f;
}

}  // namespace vofusion
