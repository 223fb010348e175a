// NARF's interest image and interest points as pcl::NarfKeypoint computes them with its defaults
// (PCL 1.13: sparse interest image, non-maximum suppression, no polynomial refinement), on one
// thread with buffers reused across seeds. Operations keep PCL's order so the floats come out the same.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>

#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include <pcl/common/angles.h>
#include <pcl/common/eigen.h>

#include "vofusion/features/narf_fast.h"

namespace vofusion::narf {

namespace {
constexpr int kBins = kDirectionCells;       // angle_histogram_size: directions over 180 degrees
constexpr float kOptimalDistance = 0.25f;    // optimal_distance_to_high_surface_change, factor on the radius
constexpr float kMinPointDistance = 0.25f;   // min_distance_between_interest_points, factor on support size
constexpr float kUnset = 2.0f;               // PCL's marker of a pixel whose interest is still to compute

// Eigen's squaredNorm() of a 3-vector sums x^2 + (y^2 + z^2); PCL's distances through Eigen do, so
// ours must too for the same floats.
inline float eigenSquaredNorm(float dx, float dy, float dz) { return dx * dx + (dy * dy + dz * dz); }

// The seed's histogram cell of a direction (nkdGetDirectionAngle's angle): its x in the seed's viewer
// frame, normalised in the plane, through DirectionCells.
inline int directionCell(const Eigen::Vector3f& direction, const Eigen::Affine3f& rotation, const DirectionCells& cells) {
  const Eigen::Vector3f rotated = rotation * direction;
  Eigen::Vector2f v(rotated[0], rotated[1]);
  v.normalize();
  return cells.cellOf(v[0]);
}

// The cells' steps, found once per process (about 550 acos).
const DirectionCells& directionCells() {
  static const DirectionCells cells;
  return cells;
}

// Floats as unsigned keys in their order (-0 just below +0), for bisection.
std::uint32_t orderKey(float f) {
  std::uint32_t b;
  std::memcpy(&b, &f, sizeof b);
  return (b & 0x80000000u) ? ~b : (b | 0x80000000u);
}
float fromOrderKey(std::uint32_t k) {
  const std::uint32_t b = (k & 0x80000000u) ? (k & 0x7fffffffu) : ~k;
  float f;
  std::memcpy(&f, &b, sizeof f);
  return f;
}

// The strongest change between two direction cells, weighted by their angle apart (PCL's loop over
// all cell pairs, here over the non-empty cells only: the same products, the same maximum).
float angleChange(const std::array<float, kBins>& hist) {
  int cells[kBins], n = 0;
  for (int c = 0; c < kBins; ++c)
    if (hist[c] != 0.0f) cells[n++] = c;
  float change = 0.0f;
  for (int a = 0; a + 1 < n; ++a)
    for (int b = a + 1; b < n; ++b) {
      const int c1 = cells[a], c2 = cells[b];
      float diff = 2.0f * float(c2 - c1) / float(kBins);
      diff = diff <= 1.0f ? diff : 2.0f - diff;
      change = std::max(hist[c1] * hist[c2] * diff, change);
    }
  return std::sqrt(change);
}

// A seed's surface changes, cell after cell ([begin[c], begin[c + 1])), as flat arrays.
struct Changes {
  std::array<int, kBins + 1> begin;
  std::vector<float> x, y, z, score, px, py;  // m; [0,1]; pixel coordinates (floats for SIMD)
  void clear() {
    for (auto* v : {&x, &y, &z, &score, &px, &py}) v->clear();
  }
  void push(const Eigen::Vector3f& p, float s, int u, int v) {
    x.push_back(p.x()), y.push_back(p.y()), z.push_back(p.z());
    score.push_back(s), px.push_back(float(u)), py.push_back(float(v));
  }
  void move(int from, int to) {
    for (auto* v : {&x, &y, &z, &score, &px, &py}) (*v)[to] = (*v)[from];
  }
  void resize(int n) {
    for (auto* v : {&x, &y, &z, &score, &px, &py}) v->resize(n);
  }
};

// The buffers of the sparse interest image, allocated once per image.
struct Workspace {
  std::vector<std::uint8_t> usable;     // valid and neither shadow border nor veil point
  std::vector<std::uint8_t> touched;    // on the image padded by one pixel, the padding always touched
  std::vector<int> to_check;            // the seed's region in growing order, at most every pixel once
  std::vector<short> check_x, check_y;  // its pixel coordinates (no division per visit)
  std::vector<int> near;                // the region's pixels close enough to get a value from this seed
  std::array<std::vector<std::pair<int, float>>, kBins> relevant;  // (pixel, change) per direction cell
  Changes changes;                      // the same, thinned
  std::vector<std::uint8_t> still_valid;
};

// Thins the sorted changes [first, first + n): drops those within `limit` of a stronger one, where
// PCL compares the distance (not its square) with the squared limit (kept: the keypoints must be
// PCL's). Almost no pair is that close, so a test on the squared distance, 4 at a time, goes first.
void thin(Changes& c, int first, int n, float limit, std::vector<std::uint8_t>& valid) {
  const float pre = limit * limit * 1.001f;  // above it, the distance is surely above `limit`
  const float *x = c.x.data() + first, *y = c.y.data() + first, *z = c.z.data() + first;
  valid.assign(n, 1);
  auto check = [&](int k1, int k2) {
    const float d2 = eigenSquaredNorm(x[k1] - x[k2], y[k1] - y[k2], z[k1] - z[k2]);
    if (d2 <= pre && std::sqrt(d2) <= limit) valid[k2] = 0;  // PCL's norm()
  };
  for (int k1 = 0; k1 < n - 1; ++k1) {
    if (!valid[k1]) continue;
    int k2 = k1 + 1;
#ifdef __SSE2__
    const __m128 X = _mm_set1_ps(x[k1]), Y = _mm_set1_ps(y[k1]), Z = _mm_set1_ps(z[k1]), PRE = _mm_set1_ps(pre);
    for (; k2 + 4 <= n; k2 += 4) {
      const __m128 dx = _mm_sub_ps(X, _mm_loadu_ps(x + k2)), dy = _mm_sub_ps(Y, _mm_loadu_ps(y + k2)),
                   dz = _mm_sub_ps(Z, _mm_loadu_ps(z + k2));
      const __m128 d2 = _mm_add_ps(_mm_mul_ps(dx, dx), _mm_add_ps(_mm_mul_ps(dy, dy), _mm_mul_ps(dz, dz)));
      if (_mm_movemask_ps(_mm_cmple_ps(d2, PRE)))
        for (int l = 0; l < 4; ++l) check(k1, k2 + l);
    }
#endif
    for (; k2 < n; ++k2) check(k1, k2);
  }
  int kept = first;
  for (int k = 0; k < n; ++k)
    if (valid[k]) c.move(first + k, kept++);
  c.resize(kept);
}

// nkdGetScores of every change in [k0, k1) for the point p at pixel (u, v): the cell's value (largest
// positive score) is returned, `negative` lowered to the smallest negative score. A change close by
// lowers the score (negative); one at the right distance raises its cell (positive). All pairs are
// scored, as in PCL: a far change leaves both as they were, so no branch is needed.
float cellScore(const Changes& c, int k0, int k1, const Eigen::Vector3f& p, float u, float v, float radius_inv,
                float& negative) {
  float best = 0.0f;
  int k = k0;
  auto score = [&](int i) {
    const float pixel_distance = std::max(std::abs(c.px[i] - u), std::abs(c.py[i] - v));
    const float df = radius_inv * std::sqrt(eigenSquaredNorm(c.x[i] - p.x(), c.y[i] - p.y(), c.z[i] - p.z()));
    float neg = 1.0f - 0.5f * c.score[i] * std::max(1.0f - df / kOptimalDistance, 0.0f);
    neg = neg * neg;  // powf(neg, 2), which compilers fold to this
    const float pos = pixel_distance < 2.0f ? c.score[i] : c.score[i] * (1.0f - df);
    best = std::max(best, pos);
    negative = std::min(negative, neg);
  };
#ifdef __SSE2__
  // Four at a time, the same operations lane by lane. max/min may differ from std::max/min only in
  // the sign of a zero, which no later step sees (a cell is skipped when == 0).
  const __m128 U = _mm_set1_ps(u), V = _mm_set1_ps(v), PX = _mm_set1_ps(p.x()), PY = _mm_set1_ps(p.y()),
               PZ = _mm_set1_ps(p.z()), RI = _mm_set1_ps(radius_inv), ONE = _mm_set1_ps(1.0f),
               HALF = _mm_set1_ps(0.5f), OPT = _mm_set1_ps(kOptimalDistance), TWO = _mm_set1_ps(2.0f),
               ABS = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
  __m128 vbest = _mm_setzero_ps(), vneg = _mm_set1_ps(negative);
  for (; k + 4 <= k1; k += 4) {
    const __m128 du = _mm_and_ps(_mm_sub_ps(_mm_loadu_ps(&c.px[k]), U), ABS),
                 dv = _mm_and_ps(_mm_sub_ps(_mm_loadu_ps(&c.py[k]), V), ABS);
    const __m128 dx = _mm_sub_ps(_mm_loadu_ps(&c.x[k]), PX), dy = _mm_sub_ps(_mm_loadu_ps(&c.y[k]), PY),
                 dz = _mm_sub_ps(_mm_loadu_ps(&c.z[k]), PZ);
    const __m128 d2 = _mm_add_ps(_mm_mul_ps(dx, dx), _mm_add_ps(_mm_mul_ps(dy, dy), _mm_mul_ps(dz, dz)));
    const __m128 df = _mm_mul_ps(RI, _mm_sqrt_ps(d2)), s = _mm_loadu_ps(&c.score[k]);
    __m128 neg = _mm_sub_ps(ONE, _mm_mul_ps(_mm_mul_ps(HALF, s), _mm_max_ps(_mm_sub_ps(ONE, _mm_div_ps(df, OPT)), _mm_setzero_ps())));
    neg = _mm_mul_ps(neg, neg);
    const __m128 adjacent = _mm_cmplt_ps(_mm_max_ps(du, dv), TWO);
    const __m128 pos = _mm_or_ps(_mm_and_ps(adjacent, s), _mm_andnot_ps(adjacent, _mm_mul_ps(s, _mm_sub_ps(ONE, df))));
    vbest = _mm_max_ps(vbest, pos);
    vneg = _mm_min_ps(vneg, neg);
  }
  alignas(16) float lanes_best[4], lanes_neg[4];
  _mm_store_ps(lanes_best, vbest);
  _mm_store_ps(lanes_neg, vneg);
  for (int l = 0; l < 4; ++l) best = std::max(best, lanes_best[l]), negative = std::min(negative, lanes_neg[l]);
#endif
  for (; k < k1; ++k) score(k);
  return best;
}

// calculateSparseInterestImage, one seed: grow the region within 1.5 support radii, histogram its
// surface changes by direction; if no pixel nearby can reach the minimum, zero them all, else compute
// the pixels within the overhead radius from a thinned list of the changes.
void seedInterest(const RangeImage& im, const Borders& b, float support_size, float min_interest, int index,
                  Workspace& ws, std::vector<float>& interest) {
  const DirectionCells& cells = directionCells();
  const int w = im.width;
  const float radius = 0.5f * support_size, radius_inv = 1.0f / radius, increased = 1.5f * radius,
              increased2 = increased * increased, overhead = increased - radius, overhead2 = overhead * overhead;
  const int x = index % w, y = index / w;
  const Eigen::Vector3f& point = im.points[index];
  Eigen::Affine3f rotation;
  pcl::getTransformationFromTwoUnitVectors(Eigen::Vector3f(0.0f, -1.0f, 0.0f), point.normalized(), rotation);

  int n_check = 0;
  auto touch = [&](int i, int xi, int yi) {
    ws.touched[(yi + 1) * (w + 2) + xi + 1] = 1;
    ws.to_check[n_check] = i, ws.check_x[n_check] = short(xi), ws.check_y[n_check] = short(yi);
    ++n_check;
  };
  touch(index, x, y);
  ws.near.clear();
  std::array<float, kBins> hist{};
  for (auto& r : ws.relevant) r.clear();
  for (int k = 0; k < n_check; ++k) {
    const int i2 = ws.to_check[k];
    if (!ws.usable[i2]) continue;
    const int x2 = ws.check_x[k], y2 = ws.check_y[k];
    const int pixel_distance = std::max(std::abs(x2 - x), std::abs(y2 - y));
    const Eigen::Vector3f& p2 = im.points[i2];
    const float dx = p2.x() - point.x(), dy = p2.y() - point.y(), dz = p2.z() - point.z();
    const float d2 = dx * dx + dy * dy + dz * dz;  // pcl::squaredEuclideanDistance's order
    if (d2 <= overhead2) ws.near.push_back(i2);
    if (pixel_distance > 2 && d2 > increased2) continue;  // immediate neighbours always count
    // The 3x3 neighbours in PCL's order; the padding stands for PCL's clamping to the image.
    const std::uint8_t* t = &ws.touched[y2 * (w + 2) + x2];  // padded (x2 - 1, y2 - 1)
    for (int dy = 0; dy < 3; ++dy, t += w + 2)
      for (int dx = 0; dx < 3; ++dx)
        if (!t[dx]) touch(i2 + (dy - 1) * w + dx - 1, x2 + dx - 1, y2 + dy - 1);
    const float change = b.change_score[i2];
    if (change < kMinSurfaceChange) continue;
    const int cell = directionCell(b.change_dir[i2], rotation, cells);
    hist[cell] = std::max(hist[cell], change);
    ws.relevant[cell].emplace_back(i2, change);
  }
  for (int k = 0; k < n_check; ++k) ws.touched[(ws.check_y[k] + 1) * (w + 2) + ws.check_x[k] + 1] = 0;

  if (angleChange(hist) < min_interest) {  // no pixel within the overhead radius can do better
    for (int i : ws.near) interest[i] = 0.0f;
    return;
  }
  Changes& c = ws.changes;
  c.clear();
  for (int cell = 0; cell < kBins; ++cell) {
    auto& rel = ws.relevant[cell];
    std::sort(rel.begin(), rel.end(), [](const auto& a1, const auto& a2) { return a1.second > a2.second; });
    c.begin[cell] = int(c.x.size());
    for (const auto& [i3, change] : rel) c.push(im.points[i3], change, i3 % w, i3 / w);
    thin(c, c.begin[cell], int(rel.size()), powf(0.25f * radius, 2), ws.still_valid);
  }
  c.begin[kBins] = int(c.x.size());

  for (int i2 : ws.near) {
    if (interest[i2] <= 1.0f) continue;  // already computed by an earlier seed
    float negative = 1.0f;
    for (int cell = 0; cell < kBins; ++cell)
      hist[cell] = cellScore(c, c.begin[cell], c.begin[cell + 1], im.points[i2], float(i2 % w), float(i2 / w),
                             radius_inv, negative);
    interest[i2] = negative * angleChange(hist);
  }
}
}  // namespace

int cellOfX(float x) {
  // pcl::normAngle(a) for a = 2 acos in [0, 2 pi]: fmod(a + pi, 2 pi) - pi, where the fmod is one
  // exact subtraction (Sterbenz), so this is the same float without the libm call.
  const float pi = float(M_PI), two_pi = 2.0f * pi, deg90 = pcl::deg2rad(90.0f), deg180 = pcl::deg2rad(180.0f);
  float t = 2.0f * std::acos(x) + pi;
  if (t >= two_pi) t -= two_pi;
  const float angle = 0.5f * (t - pi);
  return std::min(kBins - 1, int(std::lrint(double(std::floor((angle + deg90) / deg180 * kBins)))));
}

DirectionCells::DirectionCells() {
  std::uint32_t at = orderKey(-1.0f);
  const std::uint32_t end = orderKey(1.0f);
  int steps = 0;
  cell_[0] = cellOfX(-1.0f);
  // Each step: the first float after `at` whose cell differs (each cell holds one run of floats).
  while (steps < kDirectionCells - 1 && cellOfX(1.0f) != cell_[steps]) {
    std::uint32_t lo = at, hi = end;  // cellOfX(lo) == cell_[steps] != cellOfX(hi)
    while (hi - lo > 1) {
      const std::uint32_t mid = lo + (hi - lo) / 2;
      (cellOfX(fromOrderKey(mid)) == cell_[steps] ? lo : hi) = mid;
    }
    step_[steps] = fromOrderKey(hi);
    cell_[steps + 1] = cellOfX(step_[steps]);
    at = hi;
    ++steps;
  }
  for (int i = steps; i < kDirectionCells - 1; ++i) step_[i] = std::numeric_limits<float>::infinity(), cell_[i + 1] = cell_[i];
}

std::vector<int> interestPoints(const RangeImage& im, const Borders& b, const KeypointParams& p,
                                std::vector<float>& interest) {
  const int w = im.width, h = im.height, size = w * h;
  Workspace ws;
  ws.usable.resize(size);
  for (int i = 0; i < size; ++i) ws.usable[i] = im.valid(i) && !(b.traits[i] & (kShadow | kVeil));
  interest.assign(size, 0.0f);
  for (int i = 0; i < size; ++i)
    if (ws.usable[i]) interest[i] = kUnset;
  ws.touched.assign(std::size_t(w + 2) * (h + 2), 1);
  for (int y = 0; y < h; ++y) std::fill_n(&ws.touched[(y + 1) * (w + 2) + 1], w, 0);
  ws.to_check.resize(size), ws.check_x.resize(size), ws.check_y.resize(size);
  // Seeds in raster order: each computes itself and its still unset neighbours, so later pixels
  // take the value the first seed near them gave (PCL's order, hence PCL's values).
  for (int i = 0; i < size; ++i)
    if (interest[i] > 1.0f) seedInterest(im, b, p.support_size, p.min_interest_value, i, ws, interest);

  // Local maxima above the minimum, strongest first, none within 0.25 support sizes of a stronger one.
  struct Candidate {
    float strength;
    int index;
  };
  std::vector<Candidate> candidates;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const int i = y * w + x;
      const float v = interest[i];
      if (!im.valid(i) || v < p.min_interest_value) continue;
      bool is_max = true;
      for (int y2 = y - 1; y2 <= y + 1 && is_max; ++y2)
        for (int x2 = x - 1; x2 <= x + 1; ++x2)
          if (im.inImage(x2, y2) && interest[y2 * w + x2] > v) {
            is_max = false;
            break;
          }
      if (is_max) candidates.push_back({v, i});
    }
  std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& c) { return a.strength > c.strength; });
  const float min_d2 = powf(kMinPointDistance * p.support_size, 2);
  std::vector<int> kept;
  for (const Candidate& c : candidates) {
    if (p.max_points > 0 && int(kept.size()) >= p.max_points) break;
    bool too_close = false;
    for (int k : kept)
      if ((im.points[c.index] - im.points[k]).squaredNorm() < min_d2) {
        too_close = true;
        break;
      }
    if (!too_close) kept.push_back(c.index);
  }
  std::sort(kept.begin(), kept.end());  // raster order, as NarfKeypoint::compute lists them
  return kept;
}

}  // namespace vofusion::narf
