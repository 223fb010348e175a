#include "vofusion/core/camera.h"

#include <cmath>
#include <filesystem>
#include <limits>
#include <sstream>
#include <vector>

#include "vofusion/core/errors.h"

namespace vofusion {

namespace {
CameraIntrinsics make(double fx, double fy, double cx, double cy, std::array<double, 5> d = {}) {
  CameraIntrinsics c;
  c.fx = fx; c.fy = fy; c.cx = cx; c.cy = cy; c.dist = d;
  return c;
}
}  // namespace

CameraIntrinsics CameraIntrinsics::parse(const std::string& spec, const std::string& origin) {
  // Calibrations published with the TUM RGB-D benchmark (depth registered to colour).
  if (spec == "fr1") return make(517.3, 516.5, 318.6, 255.3, {0.2624, -0.9531, -0.0054, 0.0026, 1.1633});
  if (spec == "fr2") return make(520.9, 521.0, 325.1, 249.7, {0.2312, -0.7849, -0.0033, -0.0001, 0.9172});
  if (spec == "fr3") return make(535.4, 539.2, 320.1, 247.6);
  if (spec == "ros" || spec == "default") return make(525.0, 525.0, 319.5, 239.5);
  std::vector<double> v;
  std::stringstream ss(spec);
  std::string tok;
  while (std::getline(ss, tok, ',')) {
    try {
      std::size_t used = 0;
      v.push_back(std::stod(tok, &used));
      if (used != tok.size() || !std::isfinite(v.back())) v.clear(), v.resize(99);  // "inf,inf,..." passed fx > 0
    } catch (const std::exception&) {
      v.resize(99);
      break;
    }
  }
  if (!spec.empty() && spec.back() == ',') v.resize(99);  // "1,2,3,4," (getline drops the empty last field)
  if (v.size() != 4)
    throw InputError(origin, "unknown intrinsics '" + spec + "' (expected fr1, fr2, fr3, ros or fx,fy,cx,cy)");
  CameraIntrinsics c = make(v[0], v[1], v[2], v[3]);
  c.width = c.height = 0;  // the recording's: forImage() sets it and validates the centre against it
  // What the four numbers say alone: checked here against 640x480, a 1280x720 camera's centre was refused.
  CameraIntrinsics unsized = c;
  unsized.width = unsized.height = std::numeric_limits<int>::max();
  unsized.validate(origin);
  return c;
}

CameraIntrinsics CameraIntrinsics::forImage(int cols, int rows, const std::string& origin) const {
  CameraIntrinsics c = *this;
  if (width > 0 && height > 0 && (width != cols || height != rows)) {
    // Scaled unasked only where nothing else can be meant: a 640x480 preset given a 320x240 recording
    // would put its centre in the image's corner (ATE 0.146 m against 0.013 on a synthetic shake).
    if (!fitsShapeOf(cols, rows))
      throw InputError(origin, "a calibration of " + std::to_string(width) + "x" + std::to_string(height) +
                                   " images, this recording's are " + std::to_string(cols) + "x" + std::to_string(rows) +
                                   " (another shape): give its camera as fx,fy,cx,cy");
    c = resizedTo(cols, rows);
  }
  c.width = cols;
  c.height = rows;
  c.validate(origin);
  return c;
}

namespace {
// The folder's own name, whatever its parents are called and however it was written ("." or "x/").
std::string ownName(const std::string& folder) {
  std::filesystem::path p = std::filesystem::absolute(folder).lexically_normal();
  if (p.filename().empty()) p = p.parent_path();
  return p.filename().string();
}

// The TUM preset its own name names ("fr1" for ...freiburg1...), empty for none: "freiburg" alone
// (my_freiburg_take) names no camera.
std::string freiburgPresetOf(const std::string& folder) {
  const std::string name = ownName(folder);
  for (const char* fr : {"freiburg1", "freiburg2", "freiburg3"})
    if (name.find(fr) != std::string::npos) return std::string("fr") + fr[8];
  return {};
}
}  // namespace

CameraIntrinsics CameraIntrinsics::forTumFolder(const std::string& folder) {
  const std::string preset = freiburgPresetOf(folder);
  return parse(preset.empty() ? "ros" : preset);
}

bool CameraIntrinsics::namesAFreiburgCamera(const std::string& folder) { return !freiburgPresetOf(folder).empty(); }

CameraIntrinsics CameraIntrinsics::scaled(double s) const {
  CameraIntrinsics c = *this;
  c.width = static_cast<int>(width * s + 0.5);
  c.height = static_cast<int>(height * s + 0.5);
  // Pixel centres: a pixel at u in the full image maps to (u + 0.5) * s - 0.5.
  c.fx = fx * s; c.fy = fy * s;
  c.cx = (cx + 0.5) * s - 0.5; c.cy = (cy + 0.5) * s - 0.5;
  return c;
}

CameraIntrinsics CameraIntrinsics::resizedTo(int cols, int rows) const {
  CameraIntrinsics c = *this;
  const double sx = double(cols) / width, sy = double(rows) / height;
  c.width = cols;
  c.height = rows;
  c.fx = fx * sx;
  c.fy = fy * sy;
  c.cx = (cx + 0.5) * sx - 0.5;
  c.cy = (cy + 0.5) * sy - 0.5;
  return c;
}

bool CameraIntrinsics::writtenFor(int cols, int rows) const {
  if (width <= 0 || height <= 0 || (width == cols && height == rows)) return true;
  const auto offCentre = [&](int w, int h) { return std::abs((cx + 0.5) / w - 0.5) + std::abs((cy + 0.5) / h - 0.5); };
  return offCentre(cols, rows) <= offCentre(width, height);
}

void CameraIntrinsics::validate(const std::string& origin) const {
  std::ostringstream why;
  // A focal length under a pixel is 0 in the float maths (1e-50: the ray cast never ended), one past
  // kMaxFocalInImages image sizes a field of view under 0.6 degrees (1e300: every pose the identity).
  const double longest = std::max(width, height);
  if (!(fx > 0 && fy > 0)) why << "focal length must be positive (fx=" << fx << ", fy=" << fy << ")";
  else if (width <= 0 || height <= 0) why << "image size must be positive (" << width << "x" << height << ")";
  else if (!(fx >= 1 && fy >= 1 && fx <= kMaxFocalInImages * longest && fy <= kMaxFocalInImages * longest))
    why << "focal length must be between 1 and " << kMaxFocalInImages * longest << " pixels, " << kMaxFocalInImages
        << " times the image's side (fx=" << fx << ", fy=" << fy << ")";
  else if (!(cx >= 0 && cx < width && cy >= 0 && cy < height))
    why << "principal point (" << cx << ", " << cy << ") lies outside the " << width << "x" << height << " image";
  else if (fx / fy > 1.5 || fy / fx > 1.5) why << "fx/fy ratio is implausible (fx=" << fx << ", fy=" << fy << ")";
  if (!why.str().empty()) throw InputError(origin, "inconsistent intrinsics: " + why.str());
}

mrpt::img::TCamera CameraIntrinsics::toMrpt() const {
  mrpt::img::TCamera c;
  c.ncols = static_cast<uint32_t>(width);
  c.nrows = static_cast<uint32_t>(height);
  c.fx(fx); c.fy(fy); c.cx(cx); c.cy(cy);
  for (int i = 0; i < 5; ++i) c.dist[i] = dist[i];
  return c;
}

CameraIntrinsics CameraIntrinsics::fromMrpt(const mrpt::img::TCamera& m) {
  CameraIntrinsics c = make(m.fx(), m.fy(), m.cx(), m.cy());
  c.width = static_cast<int>(m.ncols);
  c.height = static_cast<int>(m.nrows);
  for (int i = 0; i < 5; ++i) c.dist[i] = m.dist[i];
  return c;
}

}  // namespace vofusion
