#include "vofusion/pipeline/reconstruction.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/pose_eigen.h"
#include "vofusion/core/progress.h"  // printWarning
#include "vofusion/core/state_archive.h"
#include "vofusion/core/text_file.h"
#include "vofusion/io/png_decode.h"  // asBgr8

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <utility>

#include <tbb/task_group.h>

namespace vofusion {

namespace {
// The parameter objects are owned here so that reconstructionConfigSections() can hand out
// pointers to their defaults.
const OdometryParams& defaultOdometry() { static const OdometryParams p; return p; }
const KinFuParams& defaultKinFu() { static const KinFuParams p; return p; }
const loop::LoopParams& defaultLoop() { static const loop::LoopParams p; return p; }


// The stages a frame goes through before it is tracked, as its report's times name them.
constexpr const char* kOdometryStage = "odometry";
constexpr const char* kRefitStage = "odometry_refit";

// What fusion is told about the odometry's motion: pose, covariance and inlier matches.
fusion::MotionPrior motionPriorOf(const OdometryResult& o) {
  fusion::MotionPrior p;
  p.reference_index = o.reference_index;
  p.T_ref_cur.matrix() = o.motion.getHomogeneousMatrixVal<mrpt::math::CMatrixDouble44>().asEigen();
  p.covariance = o.covariance.asEigen();
  p.current_points = o.inlier_current;
  p.reference_points = o.inlier_reference;
  p.colour_motion = o.colour_motion;
  return p;
}
}  // namespace

std::vector<ConfigSection> reconstructionConfigSections() {
  return {{"odometry", &defaultOdometry()}, {"kinfu", &defaultKinFu()}, {"loop", &defaultLoop()}};
}

void checkReconstructionValues(const mrpt::config::CConfigFileBase& cfg) {
  OdometryParams().loadFromConfigFile(cfg, "odometry");
  KinFuParams().loadFromConfigFile(cfg, "kinfu");
  loop::LoopParams().loadFromConfigFile(cfg, "loop");
}

namespace {
// The images, copied once for all that keeps them past process(): the caller may refill its frame's
// buffers for the next one (the apps reuse one Frame), while the fusion beside the next frame reads
// both and the odometry's held frames read their depth again (colour time: the current frame's
// depths were read at the reference's pixels).
Frame ownedCopy(const Frame& in) {
  Frame frame = in;
  frame.depth = in.depth.clone();
  // Frame::rgb is 8-bit BGR. A library caller's colour of another pixel type (16 bits a channel, BGRA)
  // is read as the loaders read it, once for every stage: the photometric term dropped it without a
  // word, and the map's colour read its bytes as 8-bit BGR.
  if (in.rgb.empty() || in.rgb.type() == CV_8UC3) {
    frame.rgb = in.rgb.clone();
  } else {
    frame.rgb = asBgr8(in.rgb);
    frame.colour_file.reset();  // not these pixels' file
  }
  return frame;
}
}  // namespace

struct Reconstruction::Impl {
  TrackingMode mode;
  OdometryParams odo_params;
  KinFuParams kinfu_params;
  std::unique_ptr<RgbdOdometry> odometry;  // null in mode kinfu: ICP alone, as KinFu LS
  std::unique_ptr<TrackedMap> kinfu;
  Trajectory trajectory;  // tracked
  loop::LoopParams loop_params;
  std::unique_ptr<loop::LoopCloser> loops;  // null: loop closure off
  Trajectory smoothed;                      // after finish(): the tracked centres smoothed (path_smoother.h)
  PathSmoothing smoothing;                  // what smoothed them, and how far
  Trajectory optimised;                     // after finish(), when loop closure ran: `smoothed` loop-closed
  Trajectory optimised_as_tracked;          // the same corrections on the poses as tracked: reintegrate() fuses there
  double max_correction = 0.0;              // m, largest move of a fused pose by the loops (finish())
  std::string resumed_map;                  // resumeVolume()'s file: reintegrate() fuses into it again,
  std::string resumed_map_stamp;            // if it is still as it was read (fileStamp)
  mutable std::optional<std::optional<std::string>> blocked;  // reintegrationBlocked(), once finished
  std::optional<std::string> resumedMapProblem() const;
  bool finished = false, reintegrated = false;
  KinFuStats tracking_stats;                // of the tracking run, once the map was fused again
  KinFuStats released_stats;                // fusionStats() when releaseMap() freed the map
  std::vector<bool> fused;                  // per frame: fused into the map during tracking
  std::vector<std::uint64_t> indices;       // per frame: its Frame::index (re-fusion finds it by that)
  StageTimes times;
  std::size_t frames = 0, fallbacks = 0, predicted = 0, lost = 0, odo_failures = 0;
  ColourTimeStats colour_time;
  std::map<Rejection, std::size_t> rejections;  // why ICP was rejected
  // Relocalisation: lost after a frame without a pose or kLostAfterPredicted predicted ones in a row;
  // then each frame is matched against the keyframes before it is tracked (loop closure on only).
  static constexpr std::size_t kLostAfterPredicted = 3;  // 0.1 s at constant velocity: a guess beyond
  bool searching = false;
  std::size_t predicted_run = 0;
  std::vector<loop::Relocalisation> relocalisations;
  std::optional<std::size_t> last_index;  // of the frame processed last (this run's)
  // The fusion of the last frame (integrate + ray cast), running beside the next frame's odometry
  // and image loading when overlap_fusion is on; `fusing_frame` keeps its images alive and unchanged.
  tbb::task_group fusing;
  bool fusing_pending = false;
  FusionResult fusing_result;
  Frame fusing_frame;
  // push()'s frame: its odometry has run, and it is tracked once the next frame's has (one frame late),
  // or by flush(). odometry_held: the frames its odometry result may name (RgbdOdometry::heldFrames then).
  // A checkpoint taken while it is held is the state before its odometry (the input gives the frame
  // again): the counts its odometry changed are kept as they were.
  struct Held {
    Frame frame;
    FrameReport report;
    std::vector<std::size_t> odometry_held;
    std::size_t odo_failures_before = 0;
    ColourTimeStats colour_time_before;
  };
  std::optional<Held> held;
  Frame last_tracked;  // trackedFrame(): the frame track() reported last
  // The held frame's motion fitted again now that the next frame's odometry has run (capture mode's
  // refit: RgbdOdometry::refitPrevious).
  void refit(Held& h) {
    OdometryResult& o = h.report.odometry;
    if (!odometry || !o.success) return;
    const auto t0 = std::chrono::steady_clock::now();
    std::optional<OdometryRefit> refit = odometry->refitPrevious(h.frame.index);
    if (!refit) return;
    o.motion = refit->motion;
    o.covariance = refit->covariance;
    o.inlier_current = std::move(refit->inlier_current);
    o.inlier_reference = std::move(refit->inlier_reference);
    o.rms_error = refit->rms_error;
    o.colour_motion = refit->colour_motion;
    h.report.times.add(kRefitStage, secondsSince(t0));
  }
  FrameReport track(Held h);

  TrackedMap& map() const {
    if (!kinfu) throw std::logic_error("Reconstruction: the map was released (releaseMap)");
    return *kinfu;
  }
  // What fuse() threw: the map may be half fused, so every later use of it throws the same (a second
  // wait on the task group returns normally: TBB forgets the exception once rethrown).
  std::exception_ptr fusion_error;
  void waitFusion() {
    if (fusion_error) std::rethrow_exception(fusion_error);
    if (!fusing_pending) return;
    fusing_pending = false;
    try {
      if (fusing.wait() == tbb::canceled) throw std::runtime_error("the map's fusion was cancelled");
    } catch (...) {
      fusion_error = std::current_exception();
      throw;
    }
    times.merge(fusing_result.times);
  }
  ~Impl() {
    // Unwinding from another error, or never asked for the result: what fuse() threw is not rethrown
    // here (it would end the process).
    if (!fusing_pending) return;
    try {
      fusing.wait();
    } catch (...) {
    }
  }
  // The frame tracked against the map and fused (beside the next frame's odometry when overlap_fusion).
  FusionResult track(const Frame& frame, const fusion::MotionPrior* prior, const FrameGeometry* geometry) {
    if (!kinfu_params.overlap_fusion) return kinfu->process(frame, prior, geometry);
    fusing_frame = frame;  // its images process()'s own copies, which the caller cannot refill
    FusionResult f = kinfu->track(fusing_frame, prior, geometry);
    fusing_result = f;
    fusing_result.times = StageTimes();
    fusing_pending = true;
    fusing.run([this] { kinfu->fuse(fusing_result); });
    return f;
  }
  // A frame out of order or without a usable stamp is refused before anything changes.
  void checkNext(const Frame& frame) {
    // The odometry names its reference by index, and the tracker finds that frame's pose by it: frames
    // left at the default index 0 were all "frame 0" (a library caller's), and got wrong poses.
    if (last_index && frame.index <= *last_index)
      throw std::invalid_argument("Reconstruction: frame index " + std::to_string(frame.index) + " after " +
                                  std::to_string(*last_index) + " (Frame::index must grow: its position in the input)");
    // Velocities, the colour-time correction and the trajectory are taken from the stamps: a NaN one
    // would put NaN in the pose and every pose after it.
    if (!std::isfinite(frame.timestamp))
      throw std::invalid_argument("Reconstruction: frame " + std::to_string(frame.index) + " has a timestamp of " +
                                  std::to_string(frame.timestamp) + " (Frame::timestamp must be a number of seconds)");
    last_index = frame.index;
  }
  OdometryResult runOdometry(const Frame& frame) {
    OdometryResult o = odometry->process(frame);
    // The frame the odometry starts from has no motion to estimate: not a failure.
    if (!o.success && !o.started) ++odo_failures;
    if (o.success) colour_time = {true, o.colour_time_capture, o.colour_time_votes, o.colour_time_capture_votes};
    return o;
  }
  // Lost: the frame is tracked only once a keyframe places it (from there, as its prior: not from a
  // frame before the loss), verified against that keyframe as a loop is; until then it stays lost, its
  // pose held, never guessed (ICP from the held pose may converge anywhere once the camera has moved on).
  // ICP against the map then refines the keyframe's pose, or, where it rejects, the frame keeps that
  // pose (a fallback, fused as fallbacks are). Asking the map to agree as well was measured: the brisk
  // blackout's seed 2 resumed 22 frames after the view came back instead of 0 (ATE after it 4.0 against
  // 7.7 mm), over issue 30's 10.
  FusionResult trackOrRelocalise(const Frame& frame, const OdometryResult& odo) {
    if (!searching) {
      fusion::MotionPrior prior;
      if (odo.success) prior = motionPriorOf(odo);
      return track(frame, odo.success ? &prior : nullptr, odo.geometry.get());
    }
    const mrpt::poses::CPose3D held = kinfu->pose();
    const std::optional<loop::Relocalisation> found = loops->relocalise(frame, odo.features);
    FusionResult f;
    if (found) {
      kinfu->relocalise(toMrpt(found->pose), true);
      f = track(frame, nullptr, odo.geometry.get());
      if (f.tracked && !f.predicted) {
        searching = false;
        relocalisations.push_back(*found);
        return f;
      }
      waitFusion();  // the keyframe's pose did not hold: back to the held pose, once the fusion task is done
      kinfu->relocalise(held);
    }
    FusionResult lost;
    lost.rejection = Rejection::NotRelocalised;
    lost.reason = toString(lost.rejection) + (f.reason.empty() ? "" : " (" + f.reason + ")");
    lost.pose = held;
    lost.times = f.times;
    return lost;
  }
  // The frame's outcome into its report, the run's counts and the per-frame lists.
  void record(const Frame& frame, const FusionResult& f, FrameReport& r) {
    r.tracked = f.tracked;  // the first frame with readings in range starts the map; one before it is lost
    r.fell_back = f.fell_back;
    r.predicted = f.predicted;
    r.note = f.reason;
    r.pose = f.pose;
    if (f.rejection != Rejection::None) ++rejections[f.rejection];
    if (f.fell_back) ++fallbacks;
    if (f.predicted) ++predicted;
    if (!r.tracked) ++lost;
    updateLost(r);
    ++frames;
    trajectory.push_back({frame.timestamp, f.pose});
    fused.push_back(r.tracked && !r.predicted && (!r.fell_back || kinfu_params.integrate_on_fallback));
    indices.push_back(frame.index);
  }
  // Lost once a frame had no pose, or kLostAfterPredicted were guessed in a row; found only by
  // relocalisation, so only with loop closure's keyframes (none yet: the frame starts the map).
  void updateLost(const FrameReport& r) {
    predicted_run = r.predicted ? predicted_run + 1 : 0;
    if (loops && loops->keyframesMade() > 0 && (!r.tracked || predicted_run >= kLostAfterPredicted)) searching = true;
  }
};

Reconstruction::Reconstruction(const mrpt::config::CConfigFileBase& cfg, TrackingMode mode)
    : impl_(std::make_unique<Impl>()) {
  impl_->mode = mode;
  impl_->odo_params.loadFromConfigFile(cfg, "odometry");
  impl_->kinfu_params.loadFromConfigFile(cfg, "kinfu");
  impl_->loop_params.loadFromConfigFile(cfg, "loop");
  if (mode != TrackingMode::KinFu) impl_->odometry = std::make_unique<RgbdOdometry>(impl_->odo_params);
  // Place recognition needs the odometry's descriptors: mode kinfu has none.
  if (impl_->loop_params.enabled && impl_->odometry)
    impl_->loops = std::make_unique<loop::LoopCloser>(impl_->loop_params, impl_->kinfu_params.tsdf.work_dir);
  // The map is anchored at the first camera (world = first camera frame). Ground truth never changes
  // what the tracker or the map does; evaluation and pictures align to it afterwards.
  impl_->kinfu = std::make_unique<TrackedMap>(impl_->kinfu_params, mode);
}

Reconstruction::~Reconstruction() = default;

std::optional<FrameReport> Reconstruction::push(const Frame& in) {
  Impl& m = *impl_;
  Impl::Held next{ownedCopy(in), {}, {}, m.odo_failures, m.colour_time};
  m.checkNext(next.frame);
  FrameReport& r = next.report;
  r.index = next.frame.index;
  r.timestamp = next.frame.timestamp;
  if (m.odometry) {
    {
      ScopedStageTimer t(r.times, kOdometryStage);
      r.odometry = m.runOdometry(next.frame);
    }
    next.odometry_held = m.odometry->heldFrames();
  }
  // Held before the previous one is tracked: a failure there costs that frame, not this one too.
  std::optional<Impl::Held> previous = std::exchange(m.held, std::move(next));
  if (!previous) return std::nullopt;
  m.refit(*previous);
  return m.track(std::move(*previous));
}

const Frame& Reconstruction::trackedFrame() const { return impl_->last_tracked; }

std::optional<FrameReport> Reconstruction::flush() {
  std::optional<Impl::Held> h = std::exchange(impl_->held, std::nullopt);
  if (!h) return std::nullopt;
  return impl_->track(std::move(*h));
}

FrameReport Reconstruction::process(const Frame& frame) {
  if (impl_->held) throw std::logic_error("Reconstruction::process while push() holds a frame: flush() it first");
  push(frame);
  return *flush();
}

FrameReport Reconstruction::Impl::track(Held h) {
  const auto start = std::chrono::steady_clock::now();
  FrameReport& r = h.report;
  // What the frame cost before it was tracked: its odometry and refit, already in its report.
  double before = 0.0;
  for (const char* stage : {kOdometryStage, kRefitStage})
    if (const auto it = r.times.seconds.find(stage); it != r.times.seconds.end()) before += it->second;
  waitFusion();
  // The frames a later prior may name keep their poses, however old: the odometry matches against its
  // last good frame after any number of failed ones (ICP tracked a covered lens on; past 32 frames the
  // match that came back had no reference pose, and the frame was guessed). The held frame's own result
  // names one of those its odometry held then; the next frame's, one of those held now.
  if (odometry) {
    std::vector<std::size_t> frames = h.odometry_held;
    for (const std::size_t f : odometry->heldFrames())
      if (std::find(frames.begin(), frames.end(), f) == frames.end()) frames.push_back(f);
    kinfu->holdFrames(std::move(frames));
  }
  const FusionResult f = trackOrRelocalise(h.frame, r.odometry);
  r.times.merge(f.times);
  record(h.frame, f, r);
  if (loops) {
    ScopedStageTimer t(r.times, "keyframes");
    loops->addFrame(h.frame, toEigen(f.pose), r.tracked && !r.fell_back && !r.predicted, f.icp_rms, r.odometry.features);
  }
  r.times.add("total", before + secondsSince(start));
  times.merge(r.times);
  last_tracked = std::move(h.frame);
  return r;
}

TrackingMode Reconstruction::mode() const { return impl_->mode; }
const Trajectory& Reconstruction::trajectory() const {
  if (!impl_->finished) return impl_->trajectory;
  return impl_->loops ? impl_->optimised : impl_->smoothed;
}
const Trajectory& Reconstruction::trackedTrajectory() const {
  return impl_->finished ? impl_->smoothed : impl_->trajectory;
}
const Trajectory& Reconstruction::fusedTrajectory() const {
  return impl_->reintegrated && impl_->loops ? impl_->optimised_as_tracked : impl_->trajectory;
}
const PathSmoothing& Reconstruction::pathSmoothing() const { return impl_->smoothing; }

void Reconstruction::finish() {
  Impl& m = *impl_;
  if (m.finished) return;
  // Its report would be lost to the caller (RunSession queues every report for the outputs).
  if (m.held) throw std::logic_error("Reconstruction::finish while push() holds a frame: flush() it first");
  m.waitFusion();
  // The frames fused into the map are the measurements; lost, predicted and unfused frames end a run.
  m.smoothed = smoothPath(m.trajectory, m.fused, &m.smoothing);
  if (m.loops) {
    m.loops->finish();
    m.optimised = m.loops->correct(m.smoothed);
    m.optimised_as_tracked = m.loops->correct(m.trajectory);
    for (std::size_t i = 0; i < m.trajectory.size(); ++i)
      m.max_correction = std::max(m.max_correction, m.trajectory[i].pose.distanceTo(m.optimised_as_tracked[i].pose));
  }
  m.finished = true;
}

const loop::LoopCloser* Reconstruction::loopCloser() const { return impl_->loops.get(); }

void Reconstruction::setShiftObserver(KinFu::ShiftObserver observer) { impl_->map().setShiftObserver(std::move(observer)); }

double Reconstruction::maxLoopCorrection() const { return impl_->max_correction; }

bool Reconstruction::mapNeedsReintegration() const {
  const Impl& m = *impl_;
  return m.finished && m.loops && m.loops->activeLoops() > 0 && m.max_correction > m.loop_params.reintegrate_min_correction;
}

// reintegrationBlocked()'s judgement, made each time it is called.
std::optional<std::string> Reconstruction::Impl::resumedMapProblem() const {
  if (fileStamp(resumed_map) != resumed_map_stamp)
    return resumed_map + ": changed or gone since the run went on from it (saved over by an interrupted run?): "
                         "fused again without it, the map would lose the sessions before this one";
  // Unreadable now (its disk failing, a byte flipped): found before the tracked map goes, which holds
  // them. Fused without it, the map lost them, and --save-volume wrote that over the file.
  if (const std::string why = KinFu::savedMapProblem(resumed_map); !why.empty())
    return resumed_map + ": " + why + " since the run went on from it: fused again without it, the map would lose the "
                         "sessions before this one";
  return std::nullopt;
}

std::optional<std::string> Reconstruction::reintegrationBlocked() const {
  const Impl& m = *impl_;
  if (m.resumed_map.empty()) return std::nullopt;
  // Judged once at the end (the checksum reads the whole map, and reintegrate() asks again).
  if (m.finished && m.blocked) return *m.blocked;
  const std::optional<std::string> why = m.resumedMapProblem();
  if (m.finished) m.blocked = why;
  return why;
}


std::size_t Reconstruction::reintegrate(const std::function<bool(Frame&)>& next,
                                        const std::function<void(std::size_t)>& progress) {
  Impl& m = *impl_;
  finish();
  if (reintegrationBlocked()) return 0;  // the map stays as tracked (the caller says why)
  // The map follows the loops, not the smoothing: each frame fused again where it was fused, corrected.
  const Trajectory& poses = m.loops ? m.optimised_as_tracked : m.trajectory;
  // The tracking run's statistics stay (guesses, shifts); the map and its memory are the new volume's.
  const KinFuStats tracking = m.map().stats();  // a released map throws, as its contract says
  // The tracking run's map goes before the new one is made: two volumes with their world models at
  // once were the run's peak (loop scene: 820 MiB while re-fusing, 369 MiB while tracking).
  // If reading fails midway, the partly re-fused map is the one left (never none).
  m.kinfu.reset();
  m.kinfu = std::make_unique<TrackedMap>(m.kinfu_params, m.mode, poses.empty() ? mrpt::poses::CPose3D() : poses[0].pose);
  TrackedMap& map = *m.kinfu;
  // A run that went on from a saved map fuses its frames into that map again, not into an empty one:
  // the earlier sessions' surfaces are the map's too (one changed or unreadable since blocked this above;
  // one that fails to load all the same is said, and the frames fused without it).
  if (!m.resumed_map.empty()) {
    try {
      map.resume(m.resumed_map);
    } catch (const InputError& e) {
      printWarning(std::string(e.what()) + ": the frames are fused again without it");
    }
  }
  std::size_t read = 0, fused = 0;
  Frame frame;
  while (read < poses.size() && next(frame)) {
    // A recording may hold frames the run never processed (dropped by the live queue): skipped. It may
    // lack frames the run processed (damaged since): their poses are passed over, not given to the next.
    // By index, not by time: a live clock stepped back between dropped frames put every frame after
    // the step behind a dropped one, and none of them was fused again.
    while (read < poses.size() && frame.index > m.indices[read]) ++read;
    if (read == poses.size()) break;
    if (frame.index < m.indices[read]) continue;
    if (m.fused[read] && map.integrateAt(frame, poses[read].pose)) ++fused;
    ++read;
    if (progress) progress(read);
  }
  m.tracking_stats = tracking;
  m.reintegrated = true;
  return fused;
}

bool Reconstruction::reintegrated() const { return impl_->reintegrated; }
void Reconstruction::saveVolume(const std::string& path) const {
  impl_->waitFusion();
  impl_->map().save(path);
}
void Reconstruction::resumeVolume(const std::string& path) {
  // Checked before the map is replaced: a map replaced under a premesher that reads the world model it
  // holds would be freed under it (its shift observer refuses the load, but only afterwards).
  if (impl_->frames > 0 || impl_->finished) throw std::logic_error("Reconstruction::resumeVolume after the first frame");
  impl_->map().resume(path);
  impl_->resumed_map = std::filesystem::absolute(path).string();
  impl_->resumed_map_stamp = fileStamp(path);
}
void Reconstruction::saveState(std::ostream& os) const {
  Impl& m = *impl_;
  if (m.finished) throw std::logic_error("Reconstruction::saveState after finish()");
  m.waitFusion();
  // A held frame (its odometry run, its tracking not) is not in the checkpoint: it is the state before
  // it, and the frame comes again from the input after loadState.
  const std::size_t odo_failures = m.held ? m.held->odo_failures_before : m.odo_failures;
  const ColourTimeStats colour_time = m.held ? m.held->colour_time_before : m.colour_time;
  {
    auto a = state::archiveOf(os);
    state::tag(a, "reconstruction");
    a << int32_t(m.mode) << uint64_t(m.trajectory.size());
    for (const StampedPose& p : m.trajectory) {
      a << p.timestamp;
      state::write(a, toEigen(p.pose));
    }
    a << m.fused << m.indices;
    for (std::size_t n : {m.frames, m.fallbacks, m.predicted, m.lost, odo_failures}) a << uint64_t(n);
    a << colour_time.known << colour_time.capture << int32_t(colour_time.compared) << int32_t(colour_time.capture_better);
    std::map<int32_t, uint64_t> rejections;
    for (const auto& [why, n] : m.rejections) rejections[int32_t(why)] = n;
    a << rejections;
    state::write(a, m.times);
    a << m.searching << uint64_t(m.predicted_run) << uint64_t(m.relocalisations.size());
    for (const loop::Relocalisation& l : m.relocalisations) {
      a << uint64_t(l.frame) << uint64_t(l.keyframe) << uint64_t(l.keyframe_frame) << int32_t(l.inliers) << l.icp_rms;
      state::write(a, l.pose);
    }
    a << bool(m.odometry) << bool(m.loops) << m.resumed_map << m.resumed_map_stamp;
  }
  if (m.odometry) m.held ? m.odometry->saveStateBeforeLastFrame(os) : m.odometry->saveState(os);
  m.map().saveState(os);
  if (m.loops) m.loops->saveState(os);
}

void Reconstruction::loadState(std::istream& is) {
  Impl& m = *impl_;
  if (m.frames > 0 || m.held || m.finished) throw std::logic_error("Reconstruction::loadState after the first frame");
  {
    auto a = state::archiveOf(is);
    state::expectTag(a, "reconstruction");
    int32_t mode = 0;
    uint64_t n = 0;
    a >> mode >> n;
    if (mode != int32_t(m.mode)) throw std::runtime_error("the checkpoint was made in another tracking mode");
    m.trajectory.resize(n);
    for (StampedPose& p : m.trajectory) {
      Eigen::Isometry3d T;
      a >> p.timestamp;
      state::read(a, T);
      p.pose = toMrpt(T);
    }
    a >> m.fused >> m.indices;
    if (m.fused.size() != m.trajectory.size() || m.indices.size() != m.trajectory.size())
      throw std::runtime_error("checkpoint: per-frame lists of different lengths");
    // The frames after the checkpoint's must go on from its last index, as within one run.
    if (!m.indices.empty()) m.last_index = m.indices.back();
    for (std::size_t* c : {&m.frames, &m.fallbacks, &m.predicted, &m.lost, &m.odo_failures}) {
      a >> n;
      *c = n;
    }
    int32_t compared = 0, better = 0;
    a >> m.colour_time.known >> m.colour_time.capture >> compared >> better;
    m.colour_time.compared = compared, m.colour_time.capture_better = better;
    std::map<int32_t, uint64_t> rejections;
    a >> rejections;
    m.rejections.clear();
    for (const auto& [why, count] : rejections) m.rejections[Rejection(why)] = count;
    state::read(a, m.times);
    uint64_t predicted_run = 0, relocalisations = 0;
    a >> m.searching >> predicted_run >> relocalisations;
    m.predicted_run = predicted_run;
    m.relocalisations.resize(relocalisations);
    for (loop::Relocalisation& l : m.relocalisations) {
      uint64_t frame = 0, keyframe = 0, keyframe_frame = 0;
      int32_t inliers = 0;
      a >> frame >> keyframe >> keyframe_frame >> inliers >> l.icp_rms;
      l.frame = frame, l.keyframe = keyframe, l.keyframe_frame = keyframe_frame, l.inliers = inliers;
      state::read(a, l.pose);
    }
    bool odometry = false, loops = false;
    a >> odometry >> loops;
    if (odometry != bool(m.odometry) || loops != bool(m.loops))
      throw std::runtime_error(std::string("the checkpoint was made with loop closure ") + (loops ? "on" : "off"));
    a >> m.resumed_map >> m.resumed_map_stamp;
  }
  if (m.odometry) m.odometry->loadState(is);
  m.map().loadState(is);
  if (m.loops) m.loops->loadState(is);
}

TriangleMesh Reconstruction::extractMesh() const {
  impl_->waitFusion();
  return impl_->map().extractMesh();
}
void Reconstruction::extractMeshByRegion(int region_bricks, const std::function<void(fusion::RegionMesh&)>& sink) const {
  impl_->waitFusion();
  impl_->map().volume().extractMeshByRegion(region_bricks, sink);
}
cv::Mat Reconstruction::renderView(const CameraIntrinsics& cam) const {
  impl_->waitFusion();
  return impl_->map().renderView(impl_->map().pose(), cam);
}
void Reconstruction::releaseMap() {
  if (!impl_->kinfu) return;
  impl_->released_stats = fusionStats();
  impl_->kinfu.reset();
}
bool Reconstruction::mapReleased() const { return !impl_->kinfu; }
const StageTimes& Reconstruction::totalTimes() const {
  impl_->waitFusion();
  return impl_->times;
}
std::size_t Reconstruction::framesProcessed() const { return impl_->frames; }
std::size_t Reconstruction::framesFused() const {
  return std::size_t(std::count(impl_->fused.begin(), impl_->fused.end(), true));
}
std::size_t Reconstruction::fallbacks() const { return impl_->fallbacks; }
std::size_t Reconstruction::predictedFrames() const { return impl_->predicted; }
const std::map<Rejection, std::size_t>& Reconstruction::icpRejections() const { return impl_->rejections; }
std::size_t Reconstruction::lostFrames() const { return impl_->lost; }
const std::vector<loop::Relocalisation>& Reconstruction::relocalisations() const { return impl_->relocalisations; }
std::size_t Reconstruction::odometryFailures() const { return impl_->odo_failures; }
ColourTimeStats Reconstruction::colourTime() const { return impl_->colour_time; }
KinFuStats Reconstruction::fusionStats() const {
  impl_->waitFusion();
  if (!impl_->kinfu) return impl_->released_stats;
  if (!impl_->reintegrated) return impl_->kinfu->stats();
  KinFuStats s = impl_->tracking_stats;
  const KinFuStats map = impl_->kinfu->stats();
  s.bricks_in_volume = map.bricks_in_volume;
  s.bricks_in_world_model = map.bricks_in_world_model;
  s.memory_bytes = map.memory_bytes;
  if (s.world.spill_error.empty()) s.world.spill_error = map.world.spill_error;  // a disk that filled while re-fusing
  s.world.lost += map.world.lost;  // the re-fused map's own
  return s;
}

}  // namespace vofusion
