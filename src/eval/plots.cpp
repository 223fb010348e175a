// Trajectory and error plots drawn with OpenCV (no plotting library on the target machines).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/errors.h"
#include "vofusion/eval/trajectory_eval.h"

namespace vofusion {

namespace {

const cv::Scalar kBlack(0, 0, 0), kGrey(200, 200, 200), kRed(40, 40, 220), kBlue(200, 90, 20);
const std::vector<cv::Scalar> kPalette{{200, 90, 20}, {40, 160, 40}, {30, 120, 240}, {160, 40, 160}, {20, 180, 200}};

// A "nice" tick step (1, 2 or 5 x 10^k) giving roughly `want` ticks over `range`.
double tickStep(double range, int want) {
  const double raw = std::max(range, 1e-9) / want;
  const double p = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0, 10.0})
    if (m * p >= raw) return m * p;
  return 10 * p;
}

std::string fmt(double v, double step) {
  char b[32];
  const int decimals = std::max(0, int(std::ceil(-std::log10(step) - 1e-9)));
  std::snprintf(b, sizeof b, "%.*f", decimals, std::abs(v) < step * 1e-6 ? 0.0 : v);
  return b;
}

// Maps data (x, y) to pixels inside a plot rectangle; equal_aspect keeps metres square (top views).
struct Axes {
  cv::Rect box;
  double x0, x1, y0, y1;
  Axes(cv::Rect b, double xa, double xb, double ya, double yb, bool equal_aspect) : box(b) {
    if (xb - xa < 1e-6) xa -= 0.5, xb += 0.5;
    if (yb - ya < 1e-6) ya -= 0.5, yb += 0.5;
    const double mx = 0.05 * (xb - xa), my = 0.05 * (yb - ya);
    x0 = xa - mx; x1 = xb + mx; y0 = ya - my; y1 = yb + my;
    if (equal_aspect) {
      const double sx = (x1 - x0) / b.width, sy = (y1 - y0) / b.height, s = std::max(sx, sy);
      const double cx = 0.5 * (x0 + x1), cy = 0.5 * (y0 + y1);
      x0 = cx - 0.5 * s * b.width; x1 = cx + 0.5 * s * b.width;
      y0 = cy - 0.5 * s * b.height; y1 = cy + 0.5 * s * b.height;
    }
  }
  cv::Point px(double x, double y) const {
    return {int(std::lround(box.x + (x - x0) / (x1 - x0) * box.width)),
            int(std::lround(box.y + box.height - (y - y0) / (y1 - y0) * box.height))};
  }
  void draw(cv::Mat& img, const std::string& xlabel, const std::string& ylabel) const {
    const double sx = tickStep(x1 - x0, 6), sy = tickStep(y1 - y0, 6);
    for (double x = std::ceil(x0 / sx) * sx; x <= x1; x += sx) {
      const cv::Point p = px(x, y0);
      cv::line(img, {p.x, box.y}, {p.x, box.y + box.height}, kGrey, 1);
      cv::putText(img, fmt(x, sx), {p.x - 14, box.y + box.height + 18}, cv::FONT_HERSHEY_SIMPLEX, 0.4, kBlack, 1, cv::LINE_AA);
    }
    for (double y = std::ceil(y0 / sy) * sy; y <= y1; y += sy) {
      const cv::Point p = px(x0, y);
      cv::line(img, {box.x, p.y}, {box.x + box.width, p.y}, kGrey, 1);
      cv::putText(img, fmt(y, sy), {box.x - 48, p.y + 4}, cv::FONT_HERSHEY_SIMPLEX, 0.4, kBlack, 1, cv::LINE_AA);
    }
    cv::rectangle(img, box, kBlack, 1);
    cv::putText(img, xlabel, {box.x + box.width / 2 - 40, box.y + box.height + 38}, cv::FONT_HERSHEY_SIMPLEX, 0.5,
                kBlack, 1, cv::LINE_AA);
    // Vertical label, drawn horizontally then rotated.
    int base = 0;
    const cv::Size ts = cv::getTextSize(ylabel, cv::FONT_HERSHEY_SIMPLEX, 0.5, 1, &base);
    cv::Mat lab(ts.height + base + 4, ts.width + 4, CV_8UC3, cv::Scalar(255, 255, 255));
    cv::putText(lab, ylabel, {2, ts.height + 2}, cv::FONT_HERSHEY_SIMPLEX, 0.5, kBlack, 1, cv::LINE_AA);
    cv::rotate(lab, lab, cv::ROTATE_90_COUNTERCLOCKWISE);
    const int lx = std::max(0, box.x - 75), ly = std::max(0, box.y + box.height / 2 - lab.rows / 2);
    if (lx + lab.cols <= img.cols && ly + lab.rows <= img.rows) lab.copyTo(img(cv::Rect(lx, ly, lab.cols, lab.rows)));
  }
};

void title(cv::Mat& img, const std::string& t) {
  cv::putText(img, t, {20, 28}, cv::FONT_HERSHEY_SIMPLEX, 0.65, kBlack, 1, cv::LINE_AA);
}

void legend(cv::Mat& img, cv::Point at, const std::vector<std::pair<std::string, cv::Scalar>>& entries) {
  int w = 0;
  for (const auto& e : entries) w = std::max(w, cv::getTextSize(e.first, cv::FONT_HERSHEY_SIMPLEX, 0.45, 1, nullptr).width);
  const cv::Rect r(at.x, at.y, w + 50, 8 + 20 * int(entries.size()));
  cv::rectangle(img, r, cv::Scalar(255, 255, 255), cv::FILLED);
  cv::rectangle(img, r, kBlack, 1);
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const int y = at.y + 16 + 20 * int(i);
    cv::line(img, {at.x + 6, y - 4}, {at.x + 34, y - 4}, entries[i].second, 2, cv::LINE_AA);
    cv::putText(img, entries[i].first, {at.x + 40, y}, cv::FONT_HERSHEY_SIMPLEX, 0.45, kBlack, 1, cv::LINE_AA);
  }
}

void savePng(const std::string& path, const cv::Mat& img) {
  std::vector<uchar> buf;
  if (!cv::imencode(".png", img, buf)) throw InputError(path, "cannot encode PNG");
  writeFileAtomically(path, std::string(buf.begin(), buf.end()));
}

// Whether samples taken at ta and tb are joined by a line: not across a gap of more than 3 of the
// usual spacing (frames lost, a blackout), which a line drew as a smooth ramp or a straight chord.
class Gaps {
 public:
  explicit Gaps(std::vector<double> times) {
    std::vector<double> steps;  // the positive ones: repeated stamps are no spacing
    for (std::size_t i = 1; i < times.size(); ++i)
      if (times[i] > times[i - 1]) steps.push_back(times[i] - times[i - 1]);
    if (steps.empty()) return;
    std::nth_element(steps.begin(), steps.begin() + steps.size() / 2, steps.end());
    longest_joined_ = 3.0 * steps[steps.size() / 2];
  }
  bool joined(double ta, double tb) const { return !(tb - ta > longest_joined_); }
  // Sample i of n, joined to neither neighbour: drawn as a dot, or it would not show at all.
  bool alone(const std::vector<double>& t, std::size_t i) const {
    return (i == 0 || !joined(t[i - 1], t[i])) && (i + 1 >= t.size() || !joined(t[i], t[i + 1]));
  }

 private:
  double longest_joined_ = 0.0;
};

std::vector<double> stampsOf(const Trajectory& t) {
  std::vector<double> s;
  for (const auto& p : t) s.push_back(p.timestamp);
  return s;
}

// The two coordinate axes along which the ground truth (or, lacking it, all poses) spreads most.
std::pair<int, int> topAxes(const std::vector<const Trajectory*>& trajs) {
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  for (const Trajectory* t : trajs)
    for (const auto& p : *t)
      for (int k = 0; k < 3; ++k) lo[k] = std::min(lo[k], p.pose[k]), hi[k] = std::max(hi[k], p.pose[k]);
  int order[3] = {0, 1, 2};
  std::sort(order, order + 3, [&](int a, int b) { return hi[a] - lo[a] > hi[b] - lo[b]; });
  return {std::min(order[0], order[1]), std::max(order[0], order[1])};
}

cv::Mat renderTopView(const Trajectory& gt, const std::vector<std::pair<std::string, Trajectory>>& ests,
                      bool error_vectors, const std::string& t) {
  cv::Mat img(700, 700, CV_8UC3, cv::Scalar(255, 255, 255));
  title(img, t);
  std::vector<const Trajectory*> all{&gt};
  for (const auto& e : ests) all.push_back(&e.second);
  const auto [a, b] = topAxes(gt.empty() ? all : std::vector<const Trajectory*>{&gt});
  double xa = 1e300, xb = -1e300, ya = 1e300, yb = -1e300;
  for (const Trajectory* tr : all)
    for (const auto& p : *tr)
      xa = std::min(xa, p.pose[a]), xb = std::max(xb, p.pose[a]), ya = std::min(ya, p.pose[b]), yb = std::max(yb, p.pose[b]);
  if (xa > xb) xa = xb = ya = yb = 0;
  const Axes ax(cv::Rect(90, 50, 580, 580), xa, xb, ya, yb, true);
  static const char* kAxis[] = {"x", "y", "z"};
  ax.draw(img, std::string(kAxis[a]) + " [m]", std::string(kAxis[b]) + " [m]");
  cv::Mat plot = img(ax.box);  // clip drawing to the plot area
  const cv::Point off(ax.box.x, ax.box.y);
  auto P = [&](const mrpt::poses::CPose3D& p) { return ax.px(p[a], p[b]) - off; };
  if (error_vectors && ests.size() == 1 && ests[0].second.size() == gt.size())
    for (std::size_t i = 0; i < gt.size(); ++i) cv::line(plot, P(gt[i].pose), P(ests[0].second[i].pose), kRed, 1, cv::LINE_AA);
  const auto path = [&](const Trajectory& tr, const cv::Scalar& c) {
    const std::vector<double> stamps = stampsOf(tr);
    const Gaps gaps(stamps);
    for (std::size_t i = 0; i < tr.size(); ++i) {
      if (i > 0 && gaps.joined(stamps[i - 1], stamps[i])) cv::line(plot, P(tr[i - 1].pose), P(tr[i].pose), c, 2, cv::LINE_AA);
      if (tr.size() > 1 && gaps.alone(stamps, i)) cv::circle(plot, P(tr[i].pose), 2, c, cv::FILLED, cv::LINE_AA);
    }
  };
  path(gt, kBlack);
  std::vector<std::pair<std::string, cv::Scalar>> entries;
  if (!gt.empty()) entries.push_back({"ground truth", kBlack});
  for (std::size_t k = 0; k < ests.size(); ++k) {
    const cv::Scalar c = ests.size() == 1 ? kBlue : kPalette[k % kPalette.size()];
    const Trajectory& e = ests[k].second;
    path(e, c);
    if (!e.empty()) cv::circle(plot, P(e.front().pose), 4, c, cv::FILLED, cv::LINE_AA);  // where it starts (a path of one pose: all of it)
    entries.push_back({ests[k].first, c});
  }
  if (error_vectors && ests.size() == 1) entries.push_back({"difference", kRed});
  legend(img, {ax.box.x + 8, ax.box.y + 8}, entries);
  return img;
}

cv::Mat renderErrorOverTime(const std::vector<double>& times, const std::vector<double>& errors, const std::string& t,
                            const std::string& ylabel) {
  cv::Mat img(700, 900, CV_8UC3, cv::Scalar(255, 255, 255));
  title(img, t);
  const double t0 = times.empty() ? 0 : times.front();
  const double t1 = times.empty() ? 1 : times.back();
  const double emax = errors.empty() ? 1 : *std::max_element(errors.begin(), errors.end());
  Axes ax(cv::Rect(90, 50, 780, 580), 0, std::max(t1 - t0, 1e-3), 0, std::max(emax, 1e-6), false);
  ax.y0 = 0;  // errors start at zero
  ax.x0 = 0;
  ax.draw(img, "time [s]", ylabel);
  cv::Mat plot = img(ax.box);
  const cv::Point off(ax.box.x, ax.box.y);
  const Gaps gaps(times);
  for (std::size_t i = 0; i < times.size() && i < errors.size(); ++i) {
    if (gaps.alone(times, i))
      cv::circle(plot, ax.px(times[i] - t0, errors[i]) - off, 2, kRed, cv::FILLED, cv::LINE_AA);
    if (i > 0 && gaps.joined(times[i - 1], times[i]))
      cv::line(plot, ax.px(times[i - 1] - t0, errors[i - 1]) - off, ax.px(times[i] - t0, errors[i]) - off, kRed, 2, cv::LINE_AA);
  }
  return img;
}

}  // namespace

void plotTrajectoryTopView(const std::string& png, const Trajectory& gt, const Trajectory& est_aligned,
                           const std::string& t) {
  savePng(png, renderTopView(gt, {{"estimated", est_aligned}}, true, t));
}

void plotErrorOverTime(const std::string& png, const std::vector<double>& times, const std::vector<double>& errors,
                       const std::string& t, const std::string& y_label) {
  savePng(png, renderErrorOverTime(times, errors, t, y_label));
}

void plotTrajectoriesOverlay(const std::string& png, const Trajectory& gt,
                             const std::vector<std::pair<std::string, Trajectory>>& estimates, const std::string& t) {
  savePng(png, renderTopView(gt, estimates, false, t));
}

void plotAteReport(const std::string& png, const AteResult& ate, const std::string& t) {
  cv::Mat left = renderTopView(ate.gt, {{"estimated", ate.est_aligned}}, true, t + " (top view)");
  cv::Mat right = renderErrorOverTime(ate.times, ate.errors, "translational error (ATE)", "translational error [m]");
  cv::Mat both;
  cv::hconcat(left, right, both);
  savePng(png, both);
}

}  // namespace vofusion
