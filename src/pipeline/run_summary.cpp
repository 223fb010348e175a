#include "run_summary.h"

#include <sys/resource.h>

#include <mrpt/core/bits_math.h>
#include <mrpt/poses/Lie/SO.h>

#include "vofusion/core/pose_eigen.h"
#include "vofusion/io/skipping_source.h"

using nlohmann::json;

namespace vofusion {

double peakMemoryMiB() {
  rusage u{};
  ::getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;  // Linux reports KiB
}

json statsJson(const ErrorStats& s) {
  return {{"rmse", s.rmse}, {"mean", s.mean}, {"median", s.median}, {"std", s.std}, {"min", s.min}, {"max", s.max},
          {"p95", s.p95}, {"count", s.count}};  // rgbd-eval --json's fields
}

json timesJson(const StageTimes& t, std::size_t frames) {
  json j = json::object();
  for (const auto& [stage, sec] : t.seconds) {
    const double per_frame = frames ? sec / frames : 0.0;
    j[stage] = {{"total_s", sec}, {"ms_per_frame", per_frame * 1e3}, {"fps", per_frame > 0 ? 1.0 / per_frame : 0.0}};
  }
  return j;
}

json meshJson(const TriangleMesh& m) { return {{"vertices", m.vertices.size()}, {"faces", m.faces.size()}}; }

json loopsJson(const loop::LoopCloser& lc, const Trajectory& frames_ground_truth) {
  // The frames' ground truth comes in frame order, out of time order where the recording's clock
  // stepped back; the interpolation searches it by time.
  const Trajectory ground_truth = sortedByTime(frames_ground_truth);
  json a = json::array();
  for (const loop::LoopRecord& l : lc.loops()) {
    json j = {{"from_frame", l.from_frame}, {"to_frame", l.to_frame}, {"from_keyframe", l.from_keyframe},
              {"to_keyframe", l.to_keyframe}, {"matches", l.matches}, {"inliers", l.inliers}, {"icp_rms_m", l.icp_rms},
              {"icp_condition", l.icp_condition},
              {"correction_m", l.correction_m}, {"correction_deg", l.correction_deg}, {"active", l.active}};
    mrpt::poses::CPose3D a_gt, b_gt;
    if (interpolatePose(ground_truth, l.from_timestamp, 0.02, a_gt) && interpolatePose(ground_truth, l.to_timestamp, 0.02, b_gt)) {
      const mrpt::poses::CPose3D error = toMrpt(l.measured) - (b_gt - a_gt);
      j["error_vs_ground_truth_m"] = error.norm();
      j["error_vs_ground_truth_deg"] = mrpt::RAD2DEG(mrpt::poses::Lie::SO<3>::log(error.getRotationMatrix()).norm());
    }
    a.push_back(j);
  }
  return a;
}

// The noise levels that smoothed the tracked path and how far its centres moved from where the frames
// were tracked (and fused) (tracking/path_smoother.h).
json pathSmoothingJson(const Reconstruction& rec) {
  const PathSmoothing& s = rec.pathSmoothing();
  return {{"measurement_sigma_m", s.noise.measurement}, {"acceleration_sigma_m", s.noise.acceleration},
          {"frame_interval_s", s.noise.interval}, {"pairs", s.noise.pairs}, {"mean_shift_m", s.mean_shift},
          {"max_shift_m", s.max_shift}};
}

json loopClosureJson(const loop::LoopCloser& lc, const Reconstruction& rec, std::size_t frames) {
  std::size_t active = 0, removed = 0;
  for (const loop::LoopRecord& l : lc.loops()) (l.active ? active : removed)++;
  const StageTimes t = lc.times();
  // Keyframing runs on the frame loop (the pipeline's stage); recognition, verification and the graph
  // on their own thread.
  const auto keyframing = rec.totalTimes().seconds.find("keyframes");
  const double front = keyframing == rec.totalTimes().seconds.end() ? 0.0 : keyframing->second;
  double back = 0.0;
  for (const auto& [stage, sec] : t.seconds) back += sec;
  const loop::KeyframeStoreStats store = lc.storeStats();
  const auto [max_queued, frame_loop_waits] = lc.queueStats();
  json j = {{"enabled", true},
            {"max_queued_keyframes", max_queued},
            {"frame_loop_waits_for_thread", frame_loop_waits},
            {"keyframes", lc.keyframes().size()},
            {"frames_strained", lc.strainedFrames()},
            {"keyframes_in_ram", store.in_ram},
            {"keyframes_spilled", store.spilled},
            {"keyframe_spill_mib", double(store.spill_file_bytes) / (1 << 20)},
            {"keyframes_lost", store.lost},
            {"loops_accepted", active},
            {"loops_removed_after_optimisation", removed},
            {"candidates_rejected", lc.rejections()},
            {"max_pose_correction_m", rec.maxLoopCorrection()},
            {"map_reintegrated", rec.reintegrated()},
            {"frame_loop_ms_per_frame", frames ? front * 1e3 / frames : 0.0},
            {"thread_ms_per_frame", frames ? back * 1e3 / frames : 0.0},
            {"thread_cpu_ms_per_frame", frames ? lc.threadCpuSeconds() * 1e3 / frames : 0.0},
            {"stages", timesJson(t, frames)}};
  if (!store.spill_error.empty()) j["keyframe_spill_error"] = store.spill_error;
  return j;
}

json simplificationJson(const MeshSimplification& s, std::size_t raw_faces) {
  return {{"faces_raw", raw_faces}, {"faces_before", s.faces_before}, {"faces_after", s.faces_after},
          {"ratio_to_raw", raw_faces ? double(s.faces_after) / double(raw_faces) : 0.0},
          {"mean_distance_m", s.distance.mean}, {"max_distance_m", s.distance.max},
          {"distance_samples", s.distance.samples}, {"seconds", s.seconds}};
}

json runSummary(const Reconstruction& rec, const RunInfo& info) {
  const std::size_t frames = rec.framesProcessed();
  json s;
  s["input"] = info.input;
  s["config"] = info.config;
  s["mode"] = toString(rec.mode());
  s["interrupted"] = info.interrupted;
  s["frames"] = frames;
  s["lost_frames"] = rec.lostFrames();
  s["relocalisations"] = nlohmann::json::array();
  for (const loop::Relocalisation& l : rec.relocalisations())
    s["relocalisations"].push_back({{"frame", l.frame}, {"keyframe", l.keyframe}, {"keyframe_frame", l.keyframe_frame},
                                    {"inliers", l.inliers}, {"icp_rms_m", l.icp_rms}});
  s["icp_fallbacks_to_odometry"] = rec.fallbacks();
  s["predicted_frames"] = rec.predictedFrames();
  json rejections = json::object();
  for (const auto& [why, n] : rec.icpRejections()) rejections[toString(why)] = n;
  s["icp_rejections"] = rejections;
  s["odometry_failures"] = rec.odometryFailures();
  const ColourTimeStats ct = rec.colourTime();
  if (ct.known)
    s["colour_time"] = {{"velocity", ct.capture ? "capture" : "interval"}, {"frames_compared", ct.compared},
                        {"capture_fitted_better", ct.capture_better}};
  s["seconds"] = info.seconds;
  s["fps"] = info.seconds > 0 ? frames / info.seconds : 0.0;
  s["stages"] = timesJson(rec.totalTimes(), frames);
  s["path_smoothing"] = pathSmoothingJson(rec);
  const KinFuStats ks = rec.fusionStats();
  s["fusion"] = {{"volume_shifts", ks.shifts}, {"icp_degenerate_frames", ks.degenerate},
                 {"model_overruled_frames", ks.model_overruled},
                 {"initial_guess", {{"odometry", ks.guess_prior}, {"constant_velocity", ks.guess_velocity}, {"last_pose", ks.guess_last}}},
                 {"bricks_in_volume", ks.bricks_in_volume},
                 {"bricks_in_world_model", ks.bricks_in_world_model}, {"tsdf_memory_mib", ks.memory_bytes / 1048576.0},
                 {"world_model", {{"cache_mib", ks.world.ram_bytes / 1048576.0}, {"bricks_spilled", ks.world.spilled},
                                  {"bricks_reloaded", ks.world.reloaded}, {"bricks_lost", ks.world.lost}, {"spill_file_mib", ks.world.spill_file_bytes / 1048576.0},
                                  {"spill_free_mib", ks.world.spill_free_bytes / 1048576.0}, {"spill_seconds", ks.world.spill_seconds}}}};
  if (!ks.world.spill_error.empty()) s["fusion"]["world_model"]["spill_error"] = ks.world.spill_error;
  if (!info.extra.is_null()) s.update(info.extra);
  return s;
}

void reportSkipped(const SkippingSource& frames, RunInfo& info, std::optional<std::size_t> stopped_at) {
  json list = json::array();
  for (const SkippedFrame& f : frames.skipped())
    if (!stopped_at || f.position < *stopped_at)
      list.push_back({{"frame", f.position}, {"file", f.file}, {"problem", f.problem}});
  info.extra["frames_skipped"] = list.size();
  info.extra["skipped_frames"] = list;
  if (!frames.cutShort().empty() && !stopped_at) info.extra["recording_cut_short"] = frames.cutShort();
}

}  // namespace vofusion
