#include "vofusion/loop/loop_closer.h"
#include "vofusion/tracking/residual_monitor.h"

#include <condition_variable>
#include <algorithm>
#include <cmath>
#include <deque>
#include <exception>
#include <mutex>
#include <optional>
#include <thread>

#include <tbb/task_arena.h>

#include "vofusion/loop/keyframe_store.h"
#include "vofusion/core/pose_eigen.h"
#include "vofusion/core/state_archive.h"
#include "vofusion/loop/loop_verifier.h"
#include "vofusion/loop/place_index.h"
#include "vofusion/loop/pose_graph.h"
#include "vofusion/core/thread_name.h"

namespace vofusion::loop {

struct LoopCloser::Impl {
  LoopParams params;
  KeyframeSelector selector;
  ResidualMonitor residuals;
  std::size_t strained_frames = 0;
  // The last well-tracked frame: where and when the camera was last known, for relocalise()'s reach
  // (the newest keyframe may be far older: a camera standing still makes none). Frame loop only.
  // Set with every keyframe too (keyframes are made of well-tracked frames), so always set once one is.
  struct LastKnown {
    double timestamp = 0.0, path_length = 0.0;
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  } last_known;
  std::vector<std::size_t> frame_keyframe;  // per frame added: its keyframe (the last one at or before it)
  std::vector<std::size_t> keyframe_position;  // per keyframe: its frame's position among the frames added
  std::size_t keyframes_made = 0;

  // Owned by the worker thread.
  KeyframeStore keyframes;
  PlaceIndex index;
  std::size_t indexed = 0;  // keyframes[0, indexed) have been considered for the index
  std::optional<Eigen::Isometry3d> last_indexed;  // pose of the newest keyframe in the index
  std::optional<Eigen::Isometry3d> last_queried;  // pose of the newest keyframe looked up in the index
  PoseGraph graph;
  std::size_t loops_unsolved = 0;  // loop edges added since the graph was last solved
  std::size_t solved_at = 0;       // the graph's nodes then
  // ICP pyramids of the last keyframes verified (~2.7 MB each at 320x240): a revisit's consecutive
  // keyframes meet the same older ones.
  PyramidCache pyramids{4};
  std::vector<std::size_t> loop_edge_record;  // graph edge index -> loops[] index (loop edges only)

  // Shared with the frame loop, under `mu`.
  mutable std::mutex mu;
  std::condition_variable wake, idle, taken;
  // Keyframes waiting for the thread. Bounded: beyond kMaxQueued the frame loop waits for the thread
  // (a keyframe holds its depth and features, ~0.3 MB at 640x480), so a loop thread starved of CPU
  // slows the frame loop instead of letting memory grow with the path.
  static constexpr std::size_t kMaxQueued = 16;
  std::deque<Keyframe> queue;
  std::size_t max_queued = 0, frame_loop_waits = 0;
  bool busy = false, stop = false;
  // A keyframe taken but not yet stored and indexed: all relocalise() reads changes only then.
  bool storing = false;
  std::function<void(std::size_t)> after_indexing;  // tests only (setAfterIndexingHook)
  std::vector<LoopRecord> loops;
  std::vector<KeyframePose> poses;
  std::map<std::string, std::size_t> rejections;
  StageTimes times;
  double cpu_seconds = 0.0;  // the thread's CPU time in process()
  KeyframeStoreStats store;
  std::size_t keyframes_lost_before = 0;  // resumed from a checkpoint: those lost before it (held without features)
  std::string spill_error_before;         // and why the spill file could not be written before it
  std::exception_ptr failure;  // what ended the thread (guarded by mu): rethrown on the caller's thread
  std::thread worker;

  Impl(const LoopParams& p, const std::string& spill_dir)
      : params(p), selector(p), residuals(kStrainRmsRatio), keyframes(std::size_t(p.keyframe_cache_mib) << 20, spill_dir), index(p) {
    worker = std::thread([this] { run(); });
  }

  void run() {
    // Our own parallel loops (parallelFor / parallelReduce: ICP sums, depth filters) stay on this
    // thread, in a one-slot arena, instead of taking the pool's workers from the frame loop. Its CPU
    // time (summary.json) then counts that work whole. The cost: a keyframe takes longer in wall time,
    // and relocalise() and finish() wait longer for the thread to be idle. The same results:
    // parallelReduce's split is fixed, whatever the thread count.
    nameThisThread("vof-loop");
    tbb::task_arena alone(1);
    for (;;) {
      Keyframe k;
      {
        std::unique_lock<std::mutex> lock(mu);
        busy = false;
        idle.notify_all();
        wake.wait(lock, [&] { return stop || !queue.empty(); });
        if (queue.empty()) return;
        k = std::move(queue.front());
        queue.pop_front();
        busy = storing = true;
        taken.notify_all();
      }
      try {
        alone.execute([&] { process(std::move(k)); });
      } catch (...) {
        // Memory that ran out, a failure inside OpenCV (a keyframe that cannot be read back is no
        // failure: it comes without features): the thread ends, and the caller's thread rethrows it at
        // its next hand-over (it was std::terminate).
        std::lock_guard<std::mutex> lock(mu);
        failure = std::current_exception();
        queue.clear();
        busy = storing = false;
        idle.notify_all();
        taken.notify_all();
        return;
      }
    }
  }

  // Older keyframes become loop candidates once they are neither among the newest nor nearer along
  // the path than min_travel: nearer revisits are to places the tracker still holds in its volume
  // (or takes back from the world model), where a raw keyframe-to-keyframe loop only adds noise.
  // The path only grows, so the eligible keyframes are a prefix and join the index in order.
  void indexEligible(const Keyframe& cur) {
    while (indexed < cur.id && cur.id - indexed >= std::size_t(params.recent_keyframes) &&
           cur.path_length - keyframes.at(indexed).path_length >= params.min_travel) {
      const std::size_t id = indexed++;
      // Keyframes 0.15 m apart mostly repeat each other's descriptors: the index takes one per
      // index_spacing (or keyframe_rotation), so it grows half as fast along the path.
      const Eigen::Isometry3d& pose = keyframes.at(id).tracked;
      if (!spacedFrom(last_indexed, pose)) continue;
      const Keyframe k = keyframes.load(id);
      // One without descriptors (a blank wall) is no place: it must not take the spacing from the
      // textured keyframes after it.
      if (!k.features || k.features->descriptors.empty()) continue;
      index.add(k.id, k.features->descriptors);
      last_indexed = pose;
    }
  }

  // True when `pose` is index_spacing (or keyframe_rotation) from `last`, or there is no last: keyframes
  // nearer than that see much the same scene. The index takes one keyframe per spacing, and queries are
  // spaced the same way, since a nearer keyframe would find the same places again. On a revisit that
  // halves the loops verified and takes ~40 % off the loop thread's CPU, for the same path (loop scene,
  // 300 frames, seeds 1-5: CPU 2.5-3.4 -> 1.5-2.1 ms a frame, mean ATE 0.0058 m either way;
  // bench/results/2026-12-02-loop-queries.md).
  bool spacedFrom(const std::optional<Eigen::Isometry3d>& last, const Eigen::Isometry3d& pose) const {
    if (!last) return true;
    const auto [moved, turned] = poseDifference(*last, pose);
    return moved >= params.index_spacing || turned >= params.keyframe_rotation;
  }

  // One keyframe: a node chained to the previous one, then place recognition among the keyframes
  // older than the recent ones, verification, and an optimisation when a loop was accepted.
  void process(Keyframe k) {
    const double cpu_start = vofusion::threadCpuSeconds();
    StageTimes t;
    const std::size_t id = graph.addNode(k.tracked);
    if (id > 0) chainToPrevious(k, id);
    keyframes.add(std::move(k));
    const Keyframe& cur = keyframes.back();
    indexEligible(cur);
    std::function<void(std::size_t)> hook;
    {
      std::lock_guard<std::mutex> lock(mu);
      storing = false;
      hook = after_indexing;
    }
    idle.notify_all();
    if (hook) hook(cur.id);
    std::vector<PlaceCandidate> candidates;
    {
      ScopedStageTimer timer(t, "place_recognition");
      if (cur.features && !cur.features->descriptors.empty() && spacedFrom(last_queried, cur.tracked)) {
        candidates = index.query(cur.features->descriptors, [this](std::size_t k) { return !keyframes.lost(k); });
        last_queried = cur.tracked;
      }
    }
    std::vector<LoopRecord> accepted;
    std::map<std::string, std::size_t> rejected;
    {
      ScopedStageTimer timer(t, "loop_verification");
      for (const PlaceCandidate& c : candidates) verifyCandidate(c, cur, accepted, rejected);
    }
    loops_unsolved += accepted.size();
    std::vector<std::size_t> removed;
    bool solved = false;
    {
      ScopedStageTimer timer(t, "pose_graph");
      if (solveDue()) {
        removed = graph.optimise(kMaxLoopChi2, kMaxChainChi2);
        loops_unsolved = 0;
        solved_at = graph.nodes();
        solved = true;
      }
    }
    publish(accepted, removed, rejected, solved, t, vofusion::threadCpuSeconds() - cpu_start);
  }

  // Node id (keyframe k) chained to the previous keyframe by their tracked poses.
  void chainToPrevious(const Keyframe& k, std::size_t id) {
    const Keyframe& prev = keyframes.back();
    GraphEdge e;
    e.from = id - 1;
    e.to = id;
    e.T_from_to = prev.tracked.inverse() * k.tracked;
    e.information = odometryInformation(e.T_from_to, kOdometrySigmaRate, kOdometrySigmaFloor);
    // Across frames the tracker lost, predicted or took from a fallback the chain may hold a jump:
    // a loop should move it there, not spread it over the whole path.
    if (k.after_poor_tracking) e.information /= kPoorTrackingSigmaScale * kPoorTrackingSigmaScale;
    graph.addEdge(e);
    graph.chainNewNode(id);
  }

  // A place candidate verified as a loop with the current keyframe: a loop edge and its record into
  // `accepted`, else its reason counted in `rejected`.
  void verifyCandidate(const PlaceCandidate& c, const Keyframe& cur, std::vector<LoopRecord>& accepted,
                       std::map<std::string, std::size_t>& rejected) {
    const Keyframe old = keyframes.load(c.keyframe);
    if (!old.features) {  // the index takes only keyframes with features: this one's spill record was lost
      ++rejected["keyframe lost (its spill record could not be read back)"];
      return;
    }
    const LoopCheck check = verifyLoop(old, cur, params, pyramids);
    if (!check.accepted) {
      ++rejected[check.reason];
      return;
    }
    GraphEdge e;
    e.from = old.id;
    e.to = cur.id;
    e.T_from_to = check.T_old_new;
    e.information = check.covariance.inverse();
    e.loop = true;
    loop_edge_record.resize(graph.edges().size() + 1, std::size_t(-1));
    loop_edge_record[graph.addEdge(e)] = loops.size() + accepted.size();
    accepted.push_back({old.frame_index, cur.frame_index, old.id, cur.id, check.matches, check.inliers, check.icp_rms,
                        check.icp_condition, check.correction_m, check.correction_deg, true, old.timestamp, cur.timestamp,
                        check.T_old_new});
  }

  // The graph's poses are not used before the end, only its removals of false loops, which
  // finalOptimisation makes again over every loop: on long runs loops are solved in batches
  // (graphSolveDue).
  bool solveDue() const { return graphSolveDue(loops_unsolved, graph.nodes(), solved_at); }

  // At the end of the run, with the thread idle and some loop removed or not yet solved: one
  // optimisation over every loop found (loops removed when they came may fit the ones after them).
  void finalOptimisation() {
    const std::vector<std::size_t> removed = graph.optimiseAll(kMaxLoopChi2, kMaxChainChi2);
    loops_unsolved = 0;
    solved_at = graph.nodes();
    std::lock_guard<std::mutex> lock(mu);
    for (LoopRecord& l : loops) l.active = true;
    rejections.erase("did not fit the graph after optimisation");
    for (const std::size_t e : removed)
      if (e < loop_edge_record.size() && loop_edge_record[e] < loops.size()) loops[loop_edge_record[e]].active = false;
    if (!removed.empty()) rejections["did not fit the graph after optimisation"] = removed.size();
    for (std::size_t i = 0; i < poses.size(); ++i) poses[i].optimised = graph.pose(i);
  }

  // To the thread; beyond kMaxQueued waiting keyframes the caller waits for it (counted when that is
  // the frame loop, not a checkpoint's keyframes being handed over again).
  void enqueue(Keyframe k, bool from_frame_loop = true) {
    std::unique_lock<std::mutex> lock(mu);
    if (failure) std::rethrow_exception(failure);
    if (queue.size() >= kMaxQueued) {
      frame_loop_waits += from_frame_loop;
      taken.wait(lock, [&] { return failure || queue.size() < kMaxQueued; });
      if (failure) std::rethrow_exception(failure);
    }
    queue.push_back(std::move(k));
    if (from_frame_loop) max_queued = std::max(max_queued, queue.size());
    wake.notify_one();
  }
  void waitIdle() {
    std::unique_lock<std::mutex> lock(mu);
    idle.wait(lock, [&] { return queue.empty() && !busy; });
    if (failure) std::rethrow_exception(failure);
  }
  // Until every queued keyframe is stored and indexed (its verification and the graph's solve may go
  // on): the keyframes and the index are then still until the next keyframe, which only the caller's
  // thread hands over.
  void waitStored() {
    std::unique_lock<std::mutex> lock(mu);
    idle.wait(lock, [&] { return failure || (queue.empty() && !storing); });
    if (failure) std::rethrow_exception(failure);
  }

  // solved: the graph was optimised, and every keyframe's pose may have moved; else only the new
  // keyframe's entry is added (rebuilding them all made each keyframe cost the whole run's, under the
  // lock the frame loop takes every frame: 0.25 ms a keyframe at 20 000).
  void publish(const std::vector<LoopRecord>& accepted, const std::vector<std::size_t>& removed,
               const std::map<std::string, std::size_t>& rejected, bool solved, const StageTimes& t, double cpu) {
    std::lock_guard<std::mutex> lock(mu);
    loops.insert(loops.end(), accepted.begin(), accepted.end());
    for (const std::size_t e : removed)
      if (e < loop_edge_record.size() && loop_edge_record[e] < loops.size()) loops[loop_edge_record[e]].active = false;
    for (const auto& [why, n] : rejected) rejections[why] += n;
    if (!removed.empty()) rejections["did not fit the graph after optimisation"] += removed.size();
    const std::size_t from = solved ? 0 : std::min(poses.size(), keyframes.size());
    poses.resize(keyframes.size());
    for (std::size_t i = from; i < keyframes.size(); ++i)
      poses[i] = {keyframes.at(i).frame_index, keyframes.at(i).timestamp, keyframes.at(i).tracked, graph.pose(i)};
    store = keyframes.stats();
    times.merge(t);
    cpu_seconds += cpu;
  }
};

LoopCloser::LoopCloser(const LoopParams& params, const std::string& spill_dir)
    : impl_(std::make_unique<Impl>(params, spill_dir)) {}

LoopCloser::~LoopCloser() {
  {
    std::lock_guard<std::mutex> lock(impl_->mu);
    impl_->stop = true;
    impl_->queue.clear();
  }
  impl_->wake.notify_all();
  if (impl_->worker.joinable()) impl_->worker.join();
}

bool LoopCloser::addFrame(const Frame& frame, const Eigen::Isometry3d& tracked, bool well_tracked, double icp_rms,
                          std::shared_ptr<const DescribedKeypoints> features) {
  Impl& m = *impl_;
  // Only a well-tracked frame's residual is judged and joins the window: a fallback's is that of the
  // ICP refused, large by definition (a stretch of them lifted the median past the jump after it).
  const bool strained = well_tracked && m.residuals.strained(icp_rms);
  m.strained_frames += strained;
  const bool key = m.selector.next(tracked, well_tracked && !frame.depth.empty(), strained);
  if (well_tracked && !frame.depth.empty() && tracked.matrix().allFinite())
    m.last_known = {frame.timestamp, m.selector.pathLength(), tracked};
  if (key) {
    Keyframe k = makeKeyframe(m.keyframes_made, frame, tracked, m.selector.pathLength(), std::move(features),
                              m.params.keyframe_downsample);
    k.after_poor_tracking = m.selector.lastAfterPoorTracking();
    m.enqueue(std::move(k));
    ++m.keyframes_made;
    m.keyframe_position.push_back(m.frame_keyframe.size());
  }
  m.frame_keyframe.push_back(m.keyframes_made == 0 ? 0 : m.keyframes_made - 1);
  return key;
}

void LoopCloser::saveState(std::ostream& os) const {
  Impl& m = *impl_;
  // Only stored keyframes are read, still until the next addFrame: not the thread's verification or
  // solve, which a resumed run makes again (a live run's checkpoint waited for them, its frames dropped).
  m.waitStored();
  auto a = state::archiveOf(os);
  // "v2": the keyframe selector keeps whether strained frames came since the last keyframe (b9be6fb);
  // "v3": the last well-tracked frame and the queue's statistics; "v4": the keyframes lost so far. A
  // checkpoint of an earlier build is refused by name instead of read out of step.
  state::tag(a, "loop v4");
  m.selector.saveState(a);
  m.residuals.saveState(a);
  a << uint64_t(m.strained_frames) << uint64_t(m.keyframes_made);
  a << m.last_known.timestamp << m.last_known.path_length;
  state::write(a, m.last_known.pose);
  {
    std::lock_guard<std::mutex> lock(m.mu);
    a << uint64_t(m.max_queued) << uint64_t(m.frame_loop_waits);
  }
  a << std::vector<uint64_t>(m.frame_keyframe.begin(), m.frame_keyframe.end());
  a << std::vector<uint64_t>(m.keyframe_position.begin(), m.keyframe_position.end());
  a << uint64_t(m.keyframes.size());
  for (std::size_t id = 0; id < m.keyframes.size(); ++id) {
    const Keyframe& k = m.keyframes.at(id);  // its depth and features: data(id), as stored
    a << uint64_t(k.id) << uint64_t(k.frame_index) << k.timestamp << k.path_length << k.after_poor_tracking;
    state::write(a, k.tracked);
    state::write(a, k.camera);
    a << m.keyframes.data(id);
  }
  uint64_t lost = 0;
  std::string spill_error;
  {
    std::lock_guard<std::mutex> lock(m.mu);
    m.store = m.keyframes.stats();  // with the keyframes data() found lost just now
    lost = m.store.lost + m.keyframes_lost_before;
    spill_error = m.store.spill_error.empty() ? m.spill_error_before : m.store.spill_error;
  }
  a << lost << spill_error;  // one lost again after a resume (its new record damaged too) counts again: it lost more
}

void LoopCloser::loadState(std::istream& is) {
  Impl& m = *impl_;
  auto a = state::archiveOf(is);
  state::expectTag(a, "loop v4");
  m.selector.loadState(a);
  m.residuals.loadState(a);
  uint64_t strained = 0, made = 0, count = 0, max_queued = 0, waits = 0;
  a >> strained >> made;
  a >> m.last_known.timestamp >> m.last_known.path_length;
  state::read(a, m.last_known.pose);
  a >> max_queued >> waits;
  m.strained_frames = strained;
  m.keyframes_made = made;
  std::vector<uint64_t> frame_keyframe, keyframe_position;
  a >> frame_keyframe >> keyframe_position;
  m.frame_keyframe.assign(frame_keyframe.begin(), frame_keyframe.end());
  m.keyframe_position.assign(keyframe_position.begin(), keyframe_position.end());
  a >> count;
  if (count != made) throw std::runtime_error("checkpoint: keyframe count does not match");
  std::vector<uint8_t> bytes;
  for (uint64_t i = 0; i < count; ++i) {
    Keyframe k;
    uint64_t id = 0, frame_index = 0;
    a >> id >> frame_index >> k.timestamp >> k.path_length >> k.after_poor_tracking;
    if (id != i) throw std::runtime_error("checkpoint: keyframes out of order");
    k.id = id;
    k.frame_index = frame_index;
    state::read(a, k.tracked);
    state::read(a, k.camera);
    a >> bytes;
    decodeKeyframeData(bytes, k);
    m.enqueue(std::move(k), false);
  }
  uint64_t lost = 0;
  std::string spill_error;
  a >> lost >> spill_error;
  std::lock_guard<std::mutex> lock(m.mu);  // the run's, not the replay's (which does not count them)
  m.max_queued = max_queued;
  m.frame_loop_waits = waits;
  m.keyframes_lost_before = lost;
  m.spill_error_before = spill_error;
}

void LoopCloser::setAfterIndexingHook(std::function<void(std::size_t)> hook) {
  std::lock_guard<std::mutex> lock(impl_->mu);  // read by the thread after a keyframe's hand-over under mu
  impl_->after_indexing = std::move(hook);
}

std::optional<Relocalisation> LoopCloser::relocalise(const Frame& frame, std::shared_ptr<const DescribedKeypoints> features) {
  Impl& m = *impl_;
  if (!features || features->points.empty() || frame.depth.empty()) return std::nullopt;
  // Once the queued keyframes are stored and indexed, the thread changes neither until the next
  // keyframe, which only this (the frame loop's) thread gives it: they are this thread's to read beside
  // the thread's verification and solve (on a long run a solve takes seconds, which waiting for it
  // stalled a lost live camera's frame loop for).
  m.waitStored();
  const std::size_t n = m.keyframes.size();
  if (n == 0) return std::nullopt;
  const Keyframe view = makeKeyframe(n, frame, Eigen::Isometry3d::Identity(), 0.0, features, m.params.keyframe_downsample);
  // The newest keyframes first (a short loss: the camera is near them; the index leaves them out),
  // then those the index has not taken yet (the last min_travel of path: the start of a run, a return
  // to where the camera was a few metres back), newest first, one per index_spacing (or
  // keyframe_rotation) and at most as many as the newest, then the place index's candidates.
  std::vector<std::size_t> candidates;
  const std::size_t recent = std::min<std::size_t>(n, std::size_t(m.params.recent_keyframes));
  for (std::size_t k = 0; k < recent; ++k) candidates.push_back(n - 1 - k);
  std::optional<Eigen::Isometry3d> last_taken;
  for (std::size_t k = n - recent; k-- > m.indexed && candidates.size() < 2 * recent;) {
    const Eigen::Isometry3d& pose = m.keyframes.at(k).tracked;
    if (!m.spacedFrom(last_taken, pose)) continue;
    candidates.push_back(k);
    last_taken = pose;
  }
  for (const PlaceCandidate& c : m.index.query(features->descriptors, [&m](std::size_t k) { return !m.keyframes.lost(k); }))
    if (std::find(candidates.begin(), candidates.end(), c.keyframe) == candidates.end()) candidates.push_back(c.keyframe);
  // Where and when the camera was last known: the last well-tracked frame (the newest keyframe may be
  // much older: a camera standing still, tracked, makes none, and its seconds there widened the reach).
  const Impl::LastKnown& last = m.last_known;  // set: a keyframe exists
  // Stamps that do not go forward (a clock stepped back, recordings joined, no stamps) say nothing
  // of the time lost: no reach bound then.
  const bool timed = std::isfinite(frame.timestamp) && frame.timestamp > last.timestamp;
  const double lost_seconds = timed ? frame.timestamp - last.timestamp : 0.0;
  std::optional<Relocalisation> best;
  PyramidCache pyramids(2);  // the view's, made once for all candidates
  for (const std::size_t id : candidates) {
    const Keyframe known = m.keyframes.load(id);
    if (!known.features) continue;
    const LoopCheck check = verifyRelocalisation(known, view, m.params, pyramids);
    if (!check.accepted) continue;
    const Eigen::Isometry3d placed = known.tracked * check.T_old_new;
    // Both poses are the tracker's, which drifts along the path between the two keyframes.
    const double reach = kMaxCameraSpeed * lost_seconds + m.params.max_drift_translation +
                         m.params.max_drift_rate * std::abs(last.path_length - known.path_length);
    if (timed && (placed.translation() - last.pose.translation()).norm() > reach) continue;
    if (best && check.inliers <= best->inliers) continue;
    best = Relocalisation{frame.index, known.id, known.frame_index, check.inliers, check.icp_rms, placed};
  }
  return best;
}

std::pair<std::size_t, std::size_t> LoopCloser::queueStats() const {
  std::lock_guard<std::mutex> lock(impl_->mu);
  return {impl_->max_queued, impl_->frame_loop_waits};
}

void LoopCloser::finish() {
  bool any_removed = false;
  impl_->waitIdle();
  {
    std::lock_guard<std::mutex> lock(impl_->mu);
    for (const LoopRecord& l : impl_->loops) any_removed |= !l.active;
    impl_->store = impl_->keyframes.stats();  // with relocalise()'s reloads since the last keyframe
  }
  // With every loop in and solved, the last optimisation already was over all of them. Otherwise: the
  // thread waits for keyframes that no longer come, and the graph is the caller's now.
  if (any_removed || impl_->loops_unsolved > 0) impl_->finalOptimisation();
}

std::vector<LoopRecord> LoopCloser::loops() const {
  std::lock_guard<std::mutex> lock(impl_->mu);
  return impl_->loops;
}
std::size_t LoopCloser::activeLoops() const {
  std::lock_guard<std::mutex> lock(impl_->mu);
  std::size_t n = 0;
  for (const auto& l : impl_->loops) n += l.active;
  return n;
}
std::vector<KeyframePose> LoopCloser::keyframes() const {
  std::lock_guard<std::mutex> lock(impl_->mu);
  return impl_->poses;
}
std::map<std::string, std::size_t> LoopCloser::rejections() const {
  std::lock_guard<std::mutex> lock(impl_->mu);
  return impl_->rejections;
}
std::size_t LoopCloser::strainedFrames() const { return impl_->strained_frames; }
std::size_t LoopCloser::keyframesMade() const { return impl_->keyframes_made; }
KeyframeStoreStats LoopCloser::storeStats() const {
  std::lock_guard<std::mutex> lock(impl_->mu);
  KeyframeStoreStats s = impl_->store;
  s.lost += impl_->keyframes_lost_before;
  if (s.spill_error.empty()) s.spill_error = impl_->spill_error_before;
  return s;
}
double LoopCloser::threadCpuSeconds() const {
  std::lock_guard<std::mutex> lock(impl_->mu);
  return impl_->cpu_seconds;
}

StageTimes LoopCloser::times() const {
  std::lock_guard<std::mutex> lock(impl_->mu);
  return impl_->times;
}

namespace {
// The correction a keyframe's optimisation applies to the world: optimised x tracked^-1.
Eigen::Isometry3d correctionOf(const KeyframePose& k) { return k.optimised * k.tracked.inverse(); }

// a and b blended by s in [0, 1]: rotation by slerp, translation linearly.
Eigen::Isometry3d blend(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b, double s) {
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.linear() = Eigen::Quaterniond(a.linear()).slerp(s, Eigen::Quaterniond(b.linear())).toRotationMatrix();
  out.translation() = (1 - s) * a.translation() + s * b.translation();
  return out;
}
}  // namespace

Trajectory LoopCloser::correct(const Trajectory& tracked) const {
  const std::vector<KeyframePose> kf = keyframes();
  Trajectory out = tracked;
  if (kf.empty()) return out;
  const std::vector<std::size_t>& at = impl_->keyframe_position;
  for (std::size_t i = 0; i < out.size() && i < impl_->frame_keyframe.size(); ++i) {
    // Between two keyframes the correction goes from one's to the other's with the frame count, so
    // the corrected path has no jump where a new keyframe begins.
    const std::size_t k = std::min(impl_->frame_keyframe[i], kf.size() - 1);
    Eigen::Isometry3d C = correctionOf(kf[k]);
    if (k + 1 < kf.size() && k + 1 < at.size() && i > at[k])
      C = blend(C, correctionOf(kf[k + 1]), double(i - at[k]) / double(at[k + 1] - at[k]));
    out[i].pose = toMrpt(C * toEigen(tracked[i].pose));
  }
  return out;
}


}  // namespace vofusion::loop
