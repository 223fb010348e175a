#include "vofusion/sim/synthetic_sequence.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>

#include "vofusion/core/errors.h"

#include "vofusion/core/parallel.h"

namespace vofusion::sim {

namespace {

// ---- Counter-based randomness: every value is a hash of its coordinates, so frames render
// identically whatever the thread count or the order frames are requested in.
inline std::uint64_t mix(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}
inline std::uint64_t hash(std::uint64_t a, std::uint64_t b, std::uint64_t c = 0, std::uint64_t d = 0,
                          std::uint64_t e = 0) {
  return mix(mix(mix(mix(mix(a) ^ b) ^ c) ^ d) ^ e);
}
inline double unit(std::uint64_t h) { return double(h >> 11) * (1.0 / 9007199254740992.0); }  // [0,1)
inline double gaussian(std::uint64_t h) {
  const double u1 = std::max(unit(mix(h)), 1e-300), u2 = unit(mix(h ^ 0x5bd1e995ull));
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * u2);
}

using Vec3 = Eigen::Vector3d;

struct Hit {
  double s = std::numeric_limits<double>::infinity();  // ray parameter = depth (ray has unit z in camera)
  int surface = -1;                                     // texture id
  double tu = 0, tv = 0;                                // texture coordinates on the surface, m
  Vec3 n = Vec3::Zero();                                // surface normal, facing the camera
};

struct Box {
  Vec3 lo, hi;
  bool inside;  // true: the camera is inside (room walls), false: a solid box seen from outside
  int texture = -1;  // texture id (-1: the box's index); look-alike copies share one
};

struct Plane {
  Vec3 n;  // unit normal; plane n.x = d
  double d;
  Vec3 u, v;  // texture axes
};

// Smooth hand-held motion: per coordinate c0 + rate*t + sum of two sinusoids.
struct Wave {
  double c0 = 0, rate = 0;
  std::array<double, 2> amp{}, freq{}, phase{};
  double at(double t) const {
    return c0 + rate * t + amp[0] * std::sin(freq[0] * t + phase[0]) + amp[1] * std::sin(freq[1] * t + phase[1]);
  }
};

// BGR colour from hue, saturation, value in [0,1].
std::array<double, 3> hsvToBgr(double h, double s, double v) {
  const double c = v * s, hp = std::fmod(h, 1.0) * 6.0, x = c * (1 - std::abs(std::fmod(hp, 2.0) - 1));
  double r = 0, g = 0, b = 0;
  if (hp < 1) r = c, g = x;
  else if (hp < 2) r = x, g = c;
  else if (hp < 3) g = c, b = x;
  else if (hp < 4) g = x, b = c;
  else if (hp < 5) r = x, b = c;
  else r = c, b = x;
  const double m = v - c;
  return {b + m, g + m, r + m};
}

// One cell of one texture layer (SyntheticSequence::Impl::texture): whether it holds a pattern,
// which one, its shape's four random numbers and its colours (the alternate one for a checker's
// dark squares), all drawn from the cell's hash.
struct TextureCell {
  bool empty = true;
  int kind = 0;  // 0 rectangle, 1 disc, 2 checker patch
  double r1 = 0, r2 = 0, r3 = 0, r4 = 0;
  std::array<double, 3> colour{}, alt_colour{};
};

TextureCell textureCell(std::uint64_t surface_id, int level, double iu, double iv) {
  TextureCell c;
  const std::uint64_t h = hash(surface_id, std::uint64_t(level), std::uint64_t(std::int64_t(iu)), std::uint64_t(std::int64_t(iv)));
  if (unit(h) > 0.55) return c;  // empty cell
  c.empty = false;
  c.r1 = unit(mix(h + 11)), c.r2 = unit(mix(h + 12)), c.r3 = unit(mix(h + 13)), c.r4 = unit(mix(h + 14));
  c.kind = int(unit(mix(h + 15)) * 3);
  const double hue = unit(mix(h + 16)), sat = 0.5 + 0.5 * unit(mix(h + 17));
  c.colour = hsvToBgr(hue, sat, 0.55 + 0.45 * unit(mix(h + 19)));
  if (c.kind == 2) c.alt_colour = hsvToBgr(hue, 0.2, 0.1 + 0.15 * unit(mix(h + 18)));
  return c;
}

constexpr int kTextureLevels = 4;

// A surface's texture seed (from --seed and the surface's id) and its own colour under the layers.
struct SurfaceLook {
  std::uint64_t id = 0;
  std::array<double, 3> colour{};
};

// The surface and the cells a row of pixels last looked up: neighbours mostly fall in the same cells
// (a 9 cm cell is ~12 pixels wide at 2 m in a 320x240 frame), whose hashes and colours are then not
// drawn again. The texture was 55 % of rgbd-simulate's CPU on a 320x240 shake recording (perf), most of
// it these draws; the values are the same.
class TextureMemo {
 public:
  // The surface's look, drawn (draw()) when the surface differs from the last one.
  template <typename Draw>
  const SurfaceLook& surface(int surface, Draw draw) {
    if (surface != surface_) {
      surface_ = surface;
      look_ = draw();
      for (Slot& s : slots_) s.valid = false;
    }
    return look_;
  }
  // The cell (iu, iv) of layer `level` on the last surface.
  const TextureCell& cell(int level, double iu, double iv) {
    Slot& s = slots_[level];
    if (!s.valid || iu != s.iu || iv != s.iv) s = {true, iu, iv, textureCell(look_.id, level, iu, iv)};
    return s.cell;
  }

 private:
  struct Slot {
    bool valid = false;
    double iu = 0, iv = 0;
    TextureCell cell;
  };
  std::optional<int> surface_;
  SurfaceLook look_;
  std::array<Slot, kTextureLevels> slots_;
};

}  // namespace

struct SyntheticSequence::Impl {
  SimOptions opts;
  std::vector<Box> boxes;
  std::vector<Plane> planes;
  Wave x, y, z, yaw, pitch, roll;
  std::vector<Wave> shake;  // trajectory "shake": added to yaw, pitch, roll
  double texture_period_x = 0.0;  // m; > 0: textures repeat along x with this period (look-alike places)
  // Scene "loop": the camera walks a rounded rectangle (half sizes a x b, corner radius r) `laps`
  // times over the sequence, facing along it.
  double ring_a = 0.0, ring_b = 0.0, ring_r = 0.0, laps = 0.0, duration = 1.0;
  // --blackout: frames [blackout_first, blackout_end) covered, decided once by index (a sum of decimal
  // times compared with i / fps covered 0.1:0.2 at 10 fps three frames, 0.2:0.3 two).
  std::size_t blackout_first = 0, blackout_end = 0;

  // Position on the ring at arc length s (wrapped), and the heading (rad) of the path there.
  std::pair<Eigen::Vector2d, double> ringAt(double s) const {
    const double lx = 2 * (ring_a - ring_r), ly = 2 * (ring_b - ring_r), arc = M_PI / 2 * ring_r;
    const double perimeter = 2 * lx + 2 * ly + 4 * arc;
    s -= perimeter * std::floor(s / perimeter);
    // Counter-clockwise from the middle of the bottom side (0, -b), heading +x: half a side, then
    // corner, side, corner, ... each corner a quarter circle.
    const double sides[4] = {lx, ly, lx, ly};
    const Eigen::Vector2d centres[4] = {{ring_a - ring_r, -(ring_b - ring_r)}, {ring_a - ring_r, ring_b - ring_r},
                                        {-(ring_a - ring_r), ring_b - ring_r}, {-(ring_a - ring_r), -(ring_b - ring_r)}};
    double start = -lx / 2;  // the first side starts half a side before s = 0
    for (int k = 0; k < 8; ++k) {
      const int side = k % 4;
      const double heading0 = side * M_PI / 2;
      const Eigen::Vector2d dir(std::cos(heading0), std::sin(heading0));
      const Eigen::Vector2d normal(std::sin(heading0), -std::cos(heading0));  // outwards (right of travel)
      // Straight part along `side`, ending where corner `side` starts.
      const Eigen::Vector2d end = centres[side] + ring_r * normal;
      if (s < start + sides[side]) return {end - (start + sides[side] - s) * dir, heading0};
      start += sides[side];
      if (s < start + arc) {
        const double a = (s - start) / ring_r;  // angle turned into the corner
        const double phi = heading0 - M_PI / 2 + a;  // direction from the corner's centre
        return {centres[side] + ring_r * Eigen::Vector2d(std::cos(phi), std::sin(phi)), heading0 + a};
      }
      start += arc;
    }
    return {Eigen::Vector2d(0, -ring_b), 0.0};
  }
  double ringPerimeter() const { return 4 * (ring_a - ring_r) + 4 * (ring_b - ring_r) + 2 * M_PI * ring_r; }

  mrpt::poses::CPose3D pose(double t) const {
    t *= opts.pace;
    // Body frame (x forward, y left, z up) then the optical frame (z forward, x right, y down).
    const double dyaw = shake.empty() ? 0 : shake[0].at(t), dpitch = shake.empty() ? 0 : shake[1].at(t),
                 droll = shake.empty() ? 0 : shake[2].at(t);
    double px = x.at(t), py = y.at(t), heading = yaw.at(t);
    if (laps > 0) {  // on the ring: the waves add wobble around it
      const auto [p, h] = ringAt(laps * ringPerimeter() * t / duration);
      px += p.x();
      py += p.y();
      heading += h;
    }
    const mrpt::poses::CPose3D body(px, py, z.at(t), heading + dyaw, pitch.at(t) + dpitch, roll.at(t) + droll);
    static const mrpt::poses::CPose3D optical(0, 0, 0, -M_PI / 2, 0, -M_PI / 2);
    return body + optical;
  }

  Hit cast(const Vec3& o, const Vec3& d) const {
    Hit best;
    for (std::size_t b = 0; b < boxes.size(); ++b) {
      const Box& bx = boxes[b];
      double tnear = -std::numeric_limits<double>::infinity(), tfar = std::numeric_limits<double>::infinity();
      int anear = -1, afar = -1;
      for (int a = 0; a < 3; ++a) {
        if (std::abs(d[a]) < 1e-12) {
          if (o[a] < bx.lo[a] || o[a] > bx.hi[a]) { tnear = 1; tfar = 0; break; }
          continue;
        }
        double t0 = (bx.lo[a] - o[a]) / d[a], t1 = (bx.hi[a] - o[a]) / d[a];
        if (t0 > t1) std::swap(t0, t1);
        if (t0 > tnear) tnear = t0, anear = a;
        if (t1 < tfar) tfar = t1, afar = a;
      }
      if (tnear > tfar) continue;
      const double s = bx.inside ? tfar : tnear;
      const int axis = bx.inside ? afar : anear;
      if (axis < 0 || !(s > 1e-9) || s >= best.s) continue;
      best.s = s;
      Vec3 p = o + s * d;
      Vec3 n = Vec3::Zero();
      n[axis] = d[axis] > 0 ? -1 : 1;  // facing the ray
      const int side = (std::abs(p[axis] - bx.lo[axis]) < std::abs(p[axis] - bx.hi[axis])) ? 0 : 1;
      best.surface = (bx.texture >= 0 ? bx.texture : int(b)) * 6 + axis * 2 + side;
      if (texture_period_x > 0) p.x() -= texture_period_x * std::floor(p.x() / texture_period_x);
      best.n = n;
      best.tu = p[(axis + 1) % 3];
      best.tv = p[(axis + 2) % 3];
    }
    for (std::size_t k = 0; k < planes.size(); ++k) {
      const Plane& pl = planes[k];
      const double den = pl.n.dot(d);
      if (std::abs(den) < 1e-12) continue;
      const double s = (pl.d - pl.n.dot(o)) / den;
      if (!(s > 1e-9) || s >= best.s) continue;
      best.s = s;
      const Vec3 p = o + s * d;
      best.surface = 1000 + int(k);
      best.n = den < 0 ? pl.n : Vec3(-pl.n);
      best.tu = pl.u.dot(p);
      best.tv = pl.v.dot(p);
    }
    return best;
  }

  // The shaded colour seen along a ray (black where nothing is hit).
  cv::Vec3d colourAlong(const Vec3& org, const Vec3& dw, TextureMemo& memo) const {
    static const Vec3 light = Vec3(0.3, 0.5, 0.8).normalized();
    const Hit h = cast(org, dw);
    if (!std::isfinite(h.s)) return cv::Vec3d(0, 0, 0);
    const double shade = 0.72 + 0.28 * std::abs(h.n.dot(light));
    const auto col = texture(h.surface, h.tu, h.tv, memo);
    return cv::Vec3d(255.0 * col[0] * shade, 255.0 * col[1] * shade, 255.0 * col[2] * shade);
  }
  // Colour exposed from t - exposure/2 to t + exposure/2: the mean of sub-frames (motion blur).
  cv::Mat blurredColour(double t) const {
    const CameraIntrinsics& c = opts.camera;
    const int samples = opts.exposure > 0 ? 7 : 1;
    cv::Mat sum(c.height, c.width, CV_64FC3, cv::Scalar::all(0));
    for (int k = 0; k < samples; ++k) {
      const double tk = samples > 1 ? t + opts.exposure * (double(k) / (samples - 1) - 0.5) : t;
      const mrpt::poses::CPose3D p = pose(tk);
      const Eigen::Matrix3d R = p.getRotationMatrix().asEigen();
      const Vec3 org(p.x(), p.y(), p.z());
      parallelFor(0, c.height, [&](int v) {
        cv::Vec3d* row = sum.ptr<cv::Vec3d>(v);
        TextureMemo memo;
        for (int u = 0; u < c.width; ++u) row[u] += colourAlong(org, R * Vec3((u - c.cx) / c.fx, (v - c.cy) / c.fy, 1.0), memo);
      }, 4);
    }
    cv::Mat out;
    sum.convertTo(out, CV_8UC3, 1.0 / samples);
    return out;
  }

  // Layered procedural texture: at each scale the surface is tiled in cells, a hashed share of which
  // hold a rectangle, a disc or a checker patch of a random colour; finer layers paint over coarser.
  std::array<double, 3> texture(int surface, double tu, double tv, TextureMemo& memo) const {
    if (!opts.textured) return {0.72, 0.74, 0.76};  // painted walls: a light grey, the same everywhere
    std::array<double, 3> col = memo.surface(surface, [&] {
      const std::uint64_t sid = hash(opts.seed, 77, std::uint64_t(surface));
      return SurfaceLook{sid, hsvToBgr(unit(mix(sid)), 0.25 + 0.3 * unit(mix(sid + 1)), 0.45 + 0.3 * unit(mix(sid + 2)))};
    }).colour;
    static const double kCell[kTextureLevels] = {0.9, 0.42, 0.2, 0.09};
    for (int level = 0; level < kTextureLevels; ++level) {
      const double cell = kCell[level];
      const double fu = tu / cell, fv = tv / cell;
      const double iu = std::floor(fu), iv = std::floor(fv);
      const double lu = fu - iu, lv = fv - iv;  // position inside the cell, [0,1)
      const TextureCell& c = memo.cell(level, iu, iv);
      if (c.empty) continue;
      bool inside = false, alt = false;
      if (c.kind == 0) {  // rectangle
        const double w = 0.3 + 0.55 * c.r1, hgt = 0.3 + 0.55 * c.r2;
        const double u0 = c.r3 * (1 - w), v0 = c.r4 * (1 - hgt);
        inside = lu >= u0 && lu < u0 + w && lv >= v0 && lv < v0 + hgt;
      } else if (c.kind == 1) {  // disc
        const double rad = 0.18 + 0.27 * c.r1;
        const double cu = rad + c.r2 * (1 - 2 * rad), cv = rad + c.r3 * (1 - 2 * rad);
        inside = (lu - cu) * (lu - cu) + (lv - cv) * (lv - cv) < rad * rad;
      } else {  // checker patch, 2..4 squares a side, in an inset square
        const int n = 2 + int(c.r1 * 3);
        const double m = 0.1 + 0.1 * c.r2;
        inside = lu >= m && lu < 1 - m && lv >= m && lv < 1 - m;
        if (inside) alt = ((int((lu - m) / (1 - 2 * m) * n) + int((lv - m) / (1 - 2 * m) * n)) & 1) != 0;
      }
      if (inside) col = alt ? c.alt_colour : c.colour;
    }
    return col;
  }

  // Scene set-up, one per --scene value: geometry and the hand-held path (waves) through it.
  void buildWorld(const std::string& scene, std::uint32_t s, double duration, double walked);
  void buildRoom(std::uint32_t s);
  void buildCorridor(std::uint32_t s, double duration);
  void buildBareWall(std::uint32_t s);
  void buildLoop(std::uint32_t s, double duration);
  void buildLookalike(std::uint32_t s, double duration);
  void buildLongwalk(std::uint32_t s, double duration);
  void buildTrajectory(const std::string& trajectory, std::uint32_t s);

  // Ray-casts the frame at time t seen from `camera` (its pose at t): colour, exact depth (truth,
  // 0 = nothing hit) and the grazing-angle mask (1 = the depth camera reads nothing there).
  void trace(double t, const mrpt::poses::CPose3D& camera, cv::Mat& rgb, cv::Mat& truth, cv::Mat& grazing) const;
};

static Wave wave(double c0, double rate, double a0, double f0, double a1, double f1, std::uint32_t seed, int k) {
  Wave w;
  w.c0 = c0;
  w.rate = rate;
  w.amp = {a0, a1};
  w.freq = {f0, f1};
  w.phase = {2 * M_PI * unit(hash(seed, 500, k, 0)), 2 * M_PI * unit(hash(seed, 500, k, 1))};
  return w;
}

void SyntheticSequence::Impl::buildWorld(const std::string& scene, std::uint32_t s, double duration, double walked) {
  // Velocity bounds (sum of amp*freq per axis) keep speed <= ~0.45 m/s and turn rate <= ~30 deg/s.
  // `walked`: the path's time at its pace. The corridors are built for it (their speed capped: at a
  // pace the corridor cannot hold, the walk is slower than pace x); the loop's ring is closed, so it is
  // built for the recording's time and a pace walks it more times (1.15 laps at pace 1).
  if (scene == "room") buildRoom(s);
  else if (scene == "corridor") buildCorridor(s, walked);
  else if (scene == "bare_wall") buildBareWall(s);
  else if (scene == "loop") buildLoop(s, duration);
  else if (scene == "lookalike") buildLookalike(s, walked);
  else if (scene == "longwalk") buildLongwalk(s, walked);
  else
    throw InputError("--scene",
                     "unknown scene '" + scene + "' (expected room, corridor, bare_wall, loop, lookalike or longwalk)");
}

void SyntheticSequence::Impl::buildRoom(std::uint32_t s) {
  boxes = {{{-2.5, -2.0, 0.0}, {2.5, 2.0, 3.0}, true},
           {{1.2, -1.5, 0.0}, {2.2, -0.6, 0.8}, false},
           {{1.6, 0.5, 0.0}, {2.5, 1.4, 1.2}, false},
           {{-0.5, 1.3, 0.0}, {0.3, 2.0, 0.6}, false},
           {{0.9, -0.3, 0.0}, {1.4, 0.3, 0.45}, false},
           {{-2.5, -1.0, 0.0}, {-1.8, 0.0, 1.8}, false}};
  x = wave(-0.2, 0, 0.5, 0.45, 0.1, 1.1, s, 0);
  y = wave(0, 0, 0.35, 0.35, 0.08, 1.3, s, 1);
  z = wave(1.4, 0, 0.1, 0.6, 0.03, 1.7, s, 2);
  yaw = wave(0, 0, 0.9, 0.25, 0.08, 1.2, s, 3);
  pitch = wave(-0.12, 0, 0.12, 0.4, 0.04, 1.5, s, 4);
  roll = wave(0, 0, 0.06, 0.5, 0.03, 1.9, s, 5);
}

void SyntheticSequence::Impl::buildCorridor(std::uint32_t s, double duration) {
  boxes = {{{-1.0, -1.1, 0.0}, {12.0, 1.1, 2.6}, true},
           {{2.0, 0.6, 0.0}, {2.6, 1.1, 1.0}, false},
           {{4.0, -1.1, 0.0}, {4.5, -0.5, 1.4}, false},
           {{6.5, 0.5, 0.0}, {7.2, 1.1, 0.7}, false},
           {{8.5, -1.1, 0.0}, {9.0, -0.6, 1.8}, false},
           {{10.5, 0.7, 0.0}, {11.0, 1.1, 1.2}, false}};
  const double speed = std::min(0.4, 9.5 / duration);
  x = wave(0, speed, 0.05, 0.9, 0.0, 1.0, s, 0);
  y = wave(0, 0, 0.2, 0.4, 0.04, 1.3, s, 1);
  z = wave(1.3, 0, 0.08, 0.5, 0.02, 1.6, s, 2);
  yaw = wave(0, 0, 0.35, 0.3, 0.06, 1.1, s, 3);
  pitch = wave(-0.05, 0, 0.08, 0.4, 0.03, 1.4, s, 4);
  roll = wave(0, 0, 0.05, 0.5, 0.02, 1.8, s, 5);
}

void SyntheticSequence::Impl::buildBareWall(std::uint32_t s) {
  planes = {{Vec3(0, 1, 0), kBareWallY, Vec3(1, 0, 0), Vec3(0, 0, 1)}};
  x = wave(0, 0.2, 0.3, 0.5, 0.03, 1.3, s, 0);
  y = wave(0, 0, 0.1, 0.4, 0.02, 1.1, s, 1);
  z = wave(1.4, 0, 0.15, 0.45, 0.02, 1.5, s, 2);
  yaw = wave(M_PI / 2, 0, 0.1, 0.35, 0.02, 1.2, s, 3);
  pitch = wave(0, 0, 0.06, 0.5, 0.02, 1.4, s, 4);
  roll = wave(0, 0, 0.04, 0.6, 0.02, 1.7, s, 5);
}

void SyntheticSequence::Impl::buildLoop(std::uint32_t s, double duration) {
  // A corridor 2 m wide around a 6 x 4 m block (outer walls 10 x 8 m), walked once around and on
  // for another 15 % of a lap, facing along it: the end sees again what the start saw, after a
  // 26 m loop's drift.
  boxes = {{{-5.0, -4.0, 0.0}, {5.0, 4.0, 2.6}, true},
           {{-3.0, -2.0, 0.0}, {3.0, 2.0, 2.6}, false},
           {{1.0, -4.0, 0.0}, {1.6, -3.5, 1.2}, false},
           {{4.4, -1.0, 0.0}, {5.0, 0.2, 0.9}, false},
           {{-0.5, 3.4, 0.0}, {0.5, 4.0, 1.5}, false},
           {{-5.0, 1.0, 0.0}, {-4.5, 1.8, 0.7}, false},
           {{-2.0, -2.5, 0.0}, {-1.4, -2.0, 1.0}, false}};
  ring_a = 4.0;
  ring_b = 3.0;
  ring_r = 1.0;
  laps = 1.15;
  this->duration = duration;
  x = wave(0, 0, 0.06, 0.7, 0.02, 1.9, s, 0);
  y = wave(0, 0, 0.06, 0.6, 0.02, 1.7, s, 1);
  z = wave(1.4, 0, 0.08, 0.5, 0.02, 1.6, s, 2);
  yaw = wave(0, 0, 0.12, 0.5, 0.03, 1.3, s, 3);
  pitch = wave(-0.1, 0, 0.06, 0.45, 0.03, 1.4, s, 4);
  roll = wave(0, 0, 0.04, 0.5, 0.02, 1.8, s, 5);
}

void SyntheticSequence::Impl::buildLookalike(std::uint32_t s, double duration) {
  // A corridor whose walls and furniture repeat every 3 m (same texture, same boxes): the camera
  // slides along one wall for more than a period, so it sees a place that looks exactly like
  // one 3 m behind. Joining the two would be a false loop.
  const double P = 3.0;
  texture_period_x = P;
  boxes = {{{-1.0, -1.5, 0.0}, {3 * P + 1.0, 1.5, 2.6}, true}};
  for (int k = 0; k < 4; ++k) {
    boxes.push_back({{0.4 + k * P, 0.9, 0.0}, {1.1 + k * P, 1.5, 0.8}, false, 1});
    boxes.push_back({{1.9 + k * P, 1.1, 0.0}, {2.3 + k * P, 1.5, 1.6}, false, 2});
  }
  const double speed = std::min(0.4, 1.6 * P / duration);
  x = wave(0, speed, 0.05, 0.9, 0.0, 1.0, s, 0);
  y = wave(-0.3, 0, 0.1, 0.4, 0.03, 1.3, s, 1);
  z = wave(1.3, 0, 0.08, 0.5, 0.02, 1.6, s, 2);
  yaw = wave(M_PI / 2, 0, 0.25, 0.35, 0.05, 1.1, s, 3);  // facing the +y wall
  pitch = wave(-0.1, 0, 0.08, 0.4, 0.03, 1.4, s, 4);
  roll = wave(0, 0, 0.04, 0.5, 0.02, 1.8, s, 5);
}

void SyntheticSequence::Impl::buildLongwalk(std::uint32_t s, double duration) {
  // A straight corridor 2.2 m wide walked at 1 m/s for the whole sequence (30 m per 900 frames at
  // 30 fps: 100 m = 3000 frames), furniture every ~1.5 m on alternating sides: a map that only grows,
  // for memory bounded by the volume rather than by the area walked (bench/longrun).
  const double speed = 1.0, length = speed * duration + 6.0;
  boxes = {{{-1.0, -1.1, 0.0}, {length, 1.1, 2.6}, true}};
  for (int k = 0; 1.0 + 1.5 * k < length - 1.0; ++k) {
    const double x0 = 1.0 + 1.5 * k + 0.6 * unit(hash(s, 600, k, 0)), w = 0.3 + 0.4 * unit(hash(s, 600, k, 1));
    const double d = 0.3 + 0.3 * unit(hash(s, 600, k, 2)), h = 0.4 + 1.4 * unit(hash(s, 600, k, 3));
    if (k % 2 == 0) boxes.push_back({{x0, 1.1 - d, 0.0}, {x0 + w, 1.1, h}, false});
    else boxes.push_back({{x0, -1.1, 0.0}, {x0 + w, -1.1 + d, h}, false});
  }
  x = wave(0, speed, 0.05, 0.9, 0.0, 1.0, s, 0);
  y = wave(0, 0, 0.2, 0.4, 0.04, 1.3, s, 1);
  z = wave(1.3, 0, 0.08, 0.5, 0.02, 1.6, s, 2);
  yaw = wave(0, 0, 0.35, 0.3, 0.06, 1.1, s, 3);
  pitch = wave(-0.05, 0, 0.08, 0.4, 0.03, 1.4, s, 4);
  roll = wave(0, 0, 0.05, 0.5, 0.02, 1.8, s, 5);
}

void SyntheticSequence::Impl::buildTrajectory(const std::string& trajectory, std::uint32_t s) {
  if (trajectory == "shake") {
    // Hand shake on top of the path: each angle gets two faster sinusoids (rad, rad/s); with the
    // path's own turns the camera turns at ~80 deg/s on average and up to ~150 deg/s.
    shake = {wave(0, 0, 0.19, 6.0, 0.06, 13.0, s, 10),   // yaw
             wave(0, 0, 0.12, 7.5, 0.05, 15.0, s, 11),   // pitch
             wave(0, 0, 0.085, 9.0, 0.035, 17.0, s, 12)};  // roll
  } else if (trajectory != "smooth") {
    throw InputError("--trajectory", "unknown trajectory '" + trajectory + "' (expected smooth or shake)");
  }
}

SyntheticSequence::SyntheticSequence(const SimOptions& o) {
  auto impl = std::make_shared<Impl>();
  impl->opts = o;
  o.camera.validate("--intrinsics");
  if (!(o.fps > 0)) throw InputError("--fps", "must be positive");
  if (!(o.pace > 0 && o.pace <= 4)) throw InputError("--pace", "must be in (0, 4]");
  if (!(o.max_range > kKinectMinRange)) throw InputError("--max-range", "must exceed 0.4 m");
  const std::uint32_t s = o.seed;
  // The path covers frames / fps seconds at pace 1, `pace` times that faster: a corridor sized by the
  // time walked (corridor, lookalike, longwalk) is built for the time the path covers, or the camera
  // walked out through its end wall.
  const double duration = std::max(1.0, double(o.frames) / o.fps);
  impl->buildWorld(o.scene, s, duration, duration * o.pace);
  impl->buildTrajectory(o.trajectory, s);
  if (!(o.exposure >= 0 && o.exposure <= 0.1)) throw InputError("--exposure", "must be in [0, 0.1] s");
  if (!(o.colour_offset_max >= 0 && o.colour_offset_max <= 0.05)) throw InputError("--colour-offset", "must be in [0, 0.05] s");
  if (!(o.depth_readout >= 0 && o.depth_readout <= 0.1)) throw InputError("--depth-readout", "must be in [0, 0.1] s");
  if (!(o.blackout_start >= 0 && o.blackout_seconds >= 0)) throw InputError("--blackout", "T:S must be two non-negative times in s");
  // The first frame at or after T, and the first at or after T + S (each time rounded to a frame within
  // 1e-9): the frames covered, decided once, by one rule.
  const auto firstFrameFrom = [&](double t) {
    return std::size_t(std::clamp(std::ceil(t * o.fps - 1e-9), 0.0, double(o.frames)));  // past the last: frames
  };
  if (o.blackout_seconds > 0) {
    impl->blackout_first = firstFrameFrom(o.blackout_start);
    impl->blackout_end = firstFrameFrom(o.blackout_start + o.blackout_seconds);
  }
  // A cover that holds no frame (frame i is at i / fps) would change nothing: refused, not ignored,
  // whether it starts after the last frame or falls between two.
  const double last_frame_time = (double(o.frames) - 1) / o.fps;
  if (o.blackout_seconds > 0 && impl->blackout_first >= o.frames) {
    char why[160];
    std::snprintf(why, sizeof why, "starts at %g s, after the last frame (at %g s: %zu frames at %g fps)",
                  o.blackout_start, last_frame_time, std::size_t(o.frames), o.fps);
    throw InputError("--blackout", why);
  }
  if (o.blackout_seconds > 0 && impl->blackout_first >= impl->blackout_end) {
    char why[160];
    std::snprintf(why, sizeof why, "%g:%g covers no frame (frames are %g s apart)", o.blackout_start, o.blackout_seconds,
                  1.0 / o.fps);
    throw InputError("--blackout", why);
  }
  impl_ = impl;
}

std::size_t SyntheticSequence::size() const { return impl_->opts.frames; }
const SimOptions& SyntheticSequence::options() const { return impl_->opts; }

mrpt::poses::CPose3D SyntheticSequence::groundTruth(std::size_t i) const {
  return impl_->pose(double(i) / impl_->opts.fps);
}

double SyntheticSequence::exactDepth(const mrpt::poses::CPose3D& pose, double u, double v) const {
  const CameraIntrinsics& c = impl_->opts.camera;
  const Eigen::Matrix3d R = pose.getRotationMatrix().asEigen();
  const Vec3 o(pose.x(), pose.y(), pose.z());
  const Hit h = impl_->cast(o, R * Vec3((u - c.cx) / c.fx, (v - c.cy) / c.fy, 1.0));
  return std::isfinite(h.s) ? h.s : 0.0;
}

double SyntheticSequence::distanceToSurface(const Eigen::Vector3d& p) const {
  double best = std::numeric_limits<double>::infinity();
  for (const Box& b : impl_->boxes) {
    const Vec3 below = b.lo - p, above = p - b.hi;
    const Vec3 outside = below.cwiseMax(above).cwiseMax(0.0);
    // Outside: the distance to the box; inside: to its nearest face.
    const double inside = std::min(below.cwiseMax(above).maxCoeff(), 0.0);
    best = std::min(best, outside.norm() + std::abs(inside));
  }
  for (const Plane& pl : impl_->planes) best = std::min(best, std::abs(pl.n.dot(p) - pl.d));
  return best;
}

void SyntheticSequence::Impl::trace(double t, const mrpt::poses::CPose3D& camera, cv::Mat& rgb, cv::Mat& truth,
                                    cv::Mat& grazing) const {
  const SimOptions& o = opts;
  const CameraIntrinsics& c = o.camera;
  const Eigen::Matrix3d R = camera.getRotationMatrix().asEigen();
  const Vec3 org(camera.x(), camera.y(), camera.z());
  const Vec3 light = Vec3(0.3, 0.5, 0.8).normalized();

  truth.create(c.height, c.width, CV_64F);
  grazing.create(c.height, c.width, CV_8U);
  rgb.create(c.height, c.width, CV_8UC3);
  parallelFor(0, c.height, [&](int v) {
    double* zrow = truth.ptr<double>(v);
    unsigned char* grow = grazing.ptr<unsigned char>(v);
    cv::Vec3b* crow = rgb.ptr<cv::Vec3b>(v);
    // A rolling-shutter depth camera reads this row at its own time; the ground truth is the pose at
    // the middle row's. The colour stays at the frame's time.
    Eigen::Matrix3d R_row = R;
    Vec3 org_row = org;
    TextureMemo memo;
    if (o.depth_readout > 0) {
      const mrpt::poses::CPose3D p = pose(t + o.depth_readout * ((v + 0.5) / c.height - 0.5));
      R_row = p.getRotationMatrix().asEigen();
      org_row = Vec3(p.x(), p.y(), p.z());
    }
    for (int u = 0; u < c.width; ++u) {
      const Vec3 dc((u - c.cx) / c.fx, (v - c.cy) / c.fy, 1.0);
      const Vec3 dw = R * dc;
      const Hit h = cast(org, dw);
      if (!std::isfinite(h.s)) {
        crow[u] = cv::Vec3b(0, 0, 0);
      } else {
        // Lambert-like shading with a fixed light: depends on the surface only, not on the view.
        const double shade = 0.72 + 0.28 * std::abs(h.n.dot(light));
        const auto col = texture(h.surface, h.tu, h.tv, memo);
        for (int k = 0; k < 3; ++k) crow[u][k] = cv::saturate_cast<unsigned char>(255.0 * col[k] * shade);
      }
      const Vec3 dw_row = R_row * dc;
      const Hit hd = o.depth_readout > 0 ? cast(org_row, dw_row) : h;
      if (!std::isfinite(hd.s)) {
        zrow[u] = 0;
        grow[u] = 1;
        continue;
      }
      zrow[u] = hd.s;
      grow[u] = std::abs(hd.n.dot(dw_row.normalized())) < 0.12;
    }
  }, 4);
}

namespace {

// Shadow of a depth discontinuity at pixel (u, v) of exact depth z: a neighbour with no surface, or
// one more than 3 % nearer, hides it from the projector (projector/camera parallax).
bool inDepthShadow(const cv::Mat& truth, const CameraIntrinsics& c, int u, int v, double z) {
  bool edge = false;
  for (int dv = -1; dv <= 1 && !edge; ++dv)
    for (int du = -1; du <= 1; ++du) {
      const int uu = u + du, vv = v + dv;
      if (uu < 0 || vv < 0 || uu >= c.width || vv >= c.height) continue;
      const double zn = truth.at<double>(vv, uu);
      if (zn <= 0 || z - zn > 0.03 * z) { edge = true; break; }
    }
  return edge;
}

// Frame i's depth image as a Kinect v1 reads the exact depth `truth` (see the header): range limits,
// and with noise on, dropout, holes, Gaussian noise and disparity quantisation.
cv::Mat kinectDepth(const SimOptions& o, std::size_t i, const cv::Mat& truth, const cv::Mat& grazing) {
  const CameraIntrinsics& c = o.camera;
  cv::Mat depth(c.height, c.width, CV_32F);
  const double kinect_f = c.fx * 640.0 / c.width;  // disparity measured on a 640 px wide sensor
  const std::uint64_t frame_key = hash(o.seed, 901, i);
  parallelFor(0, c.height, [&](int v) {
    const double* zrow = truth.ptr<double>(v);
    float* out = depth.ptr<float>(v);
    for (int u = 0; u < c.width; ++u) {
      const double z = zrow[u];
      out[u] = 0.f;
      if (z < kKinectMinRange || z > o.max_range) continue;
      if (!o.noise) {
        out[u] = float(z);
        continue;
      }
      const std::uint64_t key = hash(frame_key, std::uint64_t(v), std::uint64_t(u));
      if (unit(key) < 0.02 || grazing.at<unsigned char>(v, u)) continue;  // random dropout, grazing angles
      if (inDepthShadow(truth, c, u, v, z)) continue;
      const double noisy = z + kinectNoiseSigma(z) * gaussian(key);
      const double disparity = kinect_f * kKinectBaseline / noisy;
      const double quantised = std::round(disparity * kDisparitySubpixel) / kDisparitySubpixel;
      const double zq = kinect_f * kKinectBaseline / quantised;
      if (zq >= kKinectMinRange && zq <= o.max_range) out[u] = float(zq);
    }
  });
  return depth;
}

}  // namespace

Frame SyntheticSequence::render(std::size_t i) const {
  const Impl& m = *impl_;
  const SimOptions& o = m.opts;
  const CameraIntrinsics& c = o.camera;
  Frame f;
  f.index = i;
  f.timestamp = double(i) / o.fps;
  f.camera = c;
  const mrpt::poses::CPose3D pose = m.pose(f.timestamp);
  f.groundTruth = pose;
  if (i >= m.blackout_first && i < m.blackout_end) {
    f.rgb = cv::Mat::zeros(c.height, c.width, CV_8UC3);  // covered: the sensor sees nothing, the path goes on
    f.depth = cv::Mat::zeros(c.height, c.width, CV_32FC1);
    return f;
  }
  cv::Mat truth, grazing;
  m.trace(f.timestamp, pose, f.rgb, truth, grazing);
  // Shake: the colour camera's own capture time and exposure (the depth and the pose stay at the
  // depth capture).
  if (!m.shake.empty()) {
    f.colour_offset = o.colour_offset_max * (2.0 * unit(hash(o.seed, 902, i)) - 1.0);
    f.rgb = m.blurredColour(f.timestamp + f.colour_offset);
  }
  // Slight optical blur as a real lens has; also tames aliasing of the sharp texture edges.
  cv::GaussianBlur(f.rgb, f.rgb, cv::Size(3, 3), 0.6);
  f.depth = kinectDepth(o, i, truth, grazing);
  return f;
}

}  // namespace vofusion::sim
