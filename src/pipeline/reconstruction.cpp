#include "vofusion/pipeline/reconstruction.h"

#include <chrono>

namespace vofusion {

namespace {
// The parameter objects are owned here so that reconstructionConfigSections() can hand out
// pointers to their defaults.
const OdometryParams& defaultOdometry() { static const OdometryParams p; return p; }
const KinFuParams& defaultKinFu() { static const KinFuParams p; return p; }
}  // namespace

std::vector<ConfigSection> reconstructionConfigSections() {
  return {{"odometry", &defaultOdometry()}, {"kinfu", &defaultKinFu()}};
}

struct Reconstruction::Impl {
  TrackingMode mode;
  OdometryParams odo_params;
  KinFuParams kinfu_params;
  std::unique_ptr<RgbdOdometry> odometry;  // null in mode kinfu: ICP alone, as KinFu LS
  std::unique_ptr<KinFu> kinfu;
  Trajectory trajectory;
  StageTimes times;
  std::size_t frames = 0, fallbacks = 0, lost = 0, odo_failures = 0;
};

Reconstruction::Reconstruction(const mrpt::config::CConfigFileBase& cfg, TrackingMode mode)
    : impl_(std::make_unique<Impl>()) {
  impl_->mode = mode;
  impl_->odo_params.loadFromConfigFile(cfg, "odometry");
  impl_->kinfu_params.loadFromConfigFile(cfg, "kinfu");
  if (mode != TrackingMode::KinFu) impl_->odometry = std::make_unique<RgbdOdometry>(impl_->odo_params);
  // The map is anchored at the first frame; when that frame knows its ground-truth pose the map
  // lives in the ground truth's world frame (z up for TUM), so scenes show estimate and truth together.
  impl_->kinfu = std::make_unique<KinFu>(impl_->kinfu_params, mode);
}

Reconstruction::~Reconstruction() = default;

FrameReport Reconstruction::process(const Frame& frame) {
  Impl& m = *impl_;
  const auto start = std::chrono::steady_clock::now();
  FrameReport r;
  r.index = frame.index;
  r.timestamp = frame.timestamp;
  if (m.odometry) {
    ScopedStageTimer t(r.times, "odometry");
    r.odometry = m.odometry->process(frame);
    // The very first frame has no motion to estimate: not a failure.
    if (!r.odometry.success && m.frames > 0) ++m.odo_failures;
  }
  if (m.frames == 0 && frame.groundTruth)
    m.kinfu = std::make_unique<KinFu>(m.kinfu_params, m.mode, *frame.groundTruth);
  const FusionResult f = m.kinfu->process(frame, r.odometry.success ? &r.odometry : nullptr);
  r.times.merge(f.times);
  r.tracked = f.tracked || m.frames == 0;
  r.fell_back = f.fell_back;
  r.note = f.reason;
  r.pose = f.pose;
  if (f.fell_back) ++m.fallbacks;
  if (!r.tracked) ++m.lost;
  ++m.frames;
  m.trajectory.push_back({frame.timestamp, f.pose});
  r.times.add("total", std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  m.times.merge(r.times);
  return r;
}

TrackingMode Reconstruction::mode() const { return impl_->mode; }
const Trajectory& Reconstruction::trajectory() const { return impl_->trajectory; }
TriangleMesh Reconstruction::extractMesh() const { return impl_->kinfu->extractMesh(); }
cv::Mat Reconstruction::renderView(const CameraIntrinsics& cam) const {
  return impl_->kinfu->renderView(impl_->kinfu->pose(), cam);
}
const StageTimes& Reconstruction::totalTimes() const { return impl_->times; }
std::size_t Reconstruction::framesProcessed() const { return impl_->frames; }
std::size_t Reconstruction::fallbacks() const { return impl_->fallbacks; }
std::size_t Reconstruction::lostFrames() const { return impl_->lost; }
std::size_t Reconstruction::odometryFailures() const { return impl_->odo_failures; }
KinFuStats Reconstruction::fusionStats() const { return impl_->kinfu->stats(); }

}  // namespace vofusion
