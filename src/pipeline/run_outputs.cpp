#include "vofusion/pipeline/run_outputs.h"

#include <sys/resource.h>

#include <chrono>
#include <condition_variable>
#include <deque>
#include <filesystem>
#include <mutex>
#include <thread>

#include <mrpt/core/bits_math.h>
#include <mrpt/obs/CObservationRobotPose.h>
#include <mrpt/poses/Lie/SO.h>
#include <mrpt/config/CConfigFileBase.h>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/config.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/heap.h"
#include "vofusion/core/pose_eigen.h"
#include "vofusion/core/progress.h"
#include "vofusion/eval/trajectory_eval.h"
#include "vofusion/io/rawlog.h"
#include "vofusion/mesh/mesh_io.h"
#include "vofusion/pipeline/mesh_by_region.h"
#include "vofusion/scene/scene_export.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace vofusion {

namespace {
// Every [output] key, once: loading and saving both walk this list.
std::vector<ConfigKey> outputKeys(OutputParams& p) {
  return {
      {"write_rawlog", &p.write_rawlog, "poses.rawlog: observations + odometry actions + fused poses"},
      {"save_raw_mesh", &p.save_raw_mesh, "also mesh_raw.ply (marching cubes before CGAL post-processing)"},
      {"clean_mesh", &p.clean_mesh, "CGAL post-processing with the [mesh] parameters"},
      {"save_full_mesh", &p.save_full_mesh, "also mesh_full.ply (post-processed but not simplified)"},
      {"frustum_every", &p.frustum_every, "frames between camera frustums in scene.3Dscene", 0.0, 100000.0},
      {"image_width", &p.image_width, "px, mesh.png and trajectory.png", 16.0, 8192.0},
      {"image_height", &p.image_height, "px", 16.0, 8192.0},
      {"rpe_delta", &p.rpe_delta, "s, pose-pair spacing of the relative pose error in summary.json", 0.01, 100.0},
  };
}
}  // namespace

void OutputParams::loadFromConfigFile(const mrpt::config::CConfigFileBase& c, const std::string& s) {
  loadKeys(c, s, outputKeys(*this));
  if (frustum_every < 1 || image_width < 64 || image_height < 64 || !(rpe_delta > 0))
    throw InputError("[" + s + "]", "out-of-range value (frustum_every >= 1, image size >= 64 px, rpe_delta > 0)");
}

void OutputParams::saveToConfigFile(mrpt::config::CConfigFileBase& c, const std::string& s) const {
  saveKeys(c, s, outputKeys(const_cast<OutputParams&>(*this)));
}

double peakMemoryMiB() {
  rusage u{};
  ::getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;  // Linux reports KiB
}

namespace {

// A recording as titles name it: its folder or file name ("rgbd_dataset_freiburg1_xyz", "loop7.rawlog",
// "synthetic:room"), never the absolute path.
std::string recordingName(const std::string& input) {
  fs::path p(input);
  if (!p.has_filename()) p = p.parent_path();  // "folder/" names "folder"
  return p.filename().empty() ? input : p.filename().string();
}

// poses.rawlog is written on its own thread: PNG encoding must not slow the frame loop down.
class RawlogThread {
 public:
  explicit RawlogThread(const std::string& path)
      : writer_(path, rawlogOptions()), thread_([this] { loop(); }) {}
  ~RawlogThread() { stop(); }

  void push(const Frame& f, const FrameReport& r) {
    std::unique_lock<std::mutex> lock(mu_);
    // Bounded: the offline loop waits rather than piling frames up in memory.
    space_.wait(lock, [&] { return queue_.size() < 8 || !error_.empty(); });
    if (!error_.empty()) return;
    queue_.push_back({f, r});
    ready_.notify_one();
  }
  // Waits for the queue to drain; returns the writer's error, if any.
  std::string stop() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      done_ = true;
    }
    ready_.notify_all();
    if (thread_.joinable()) thread_.join();
    return error_;
  }
  RawlogWriter& writer() { return writer_; }

 private:
  static RawlogWriterOptions rawlogOptions() {
    RawlogWriterOptions o;
    o.format = RawlogWriterOptions::Format::ActionsSensoryFrames;  // odometry actions need it
    return o;
  }
  void loop() {
    for (;;) {
      std::pair<Frame, FrameReport> item;
      {
        std::unique_lock<std::mutex> lock(mu_);
        ready_.wait(lock, [&] { return !queue_.empty() || done_; });
        if (queue_.empty()) return;
        item = std::move(queue_.front());
        queue_.pop_front();
      }
      space_.notify_one();
      try {
        write(item.first, item.second);
      } catch (const std::exception& e) {
        std::lock_guard<std::mutex> lock(mu_);
        error_ = e.what();
        queue_.clear();
        space_.notify_all();
        return;
      }
    }
  }
  void write(const Frame& f, const FrameReport& r) {
    if (r.odometry.success)
      writer_.writeAction(makeOdometryAction(r.odometry.motion, f.timestamp, &r.odometry.covariance));
    mrpt::obs::CObservationRobotPose pose;
    pose.sensorLabel = "VOFUSION_POSE";
    pose.timestamp = mrpt::Clock::fromDouble(f.timestamp);
    pose.pose.mean = r.pose;
    writer_.writeObservation(pose);
    writer_.write(f);
  }

  RawlogWriter writer_;
  std::mutex mu_;
  std::condition_variable ready_, space_;
  std::deque<std::pair<Frame, FrameReport>> queue_;
  bool done_ = false;
  std::string error_;
  std::thread thread_;
};

json statsJson(const ErrorStats& s) {
  return {{"rmse", s.rmse}, {"mean", s.mean}, {"median", s.median}, {"std", s.std}, {"max", s.max}, {"count", s.count}};
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

// summary.json "loops": one entry per accepted loop; with ground truth, how far the loop's measured
// relative pose is from the truth's (what a loop is worth, whatever the tracker did).
json loopsJson(const loop::LoopCloser& lc, const Trajectory& ground_truth) {
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
  return {{"enabled", true},
          {"max_queued_keyframes", max_queued},
          {"frame_loop_waits_for_thread", frame_loop_waits},
          {"keyframes", lc.keyframes().size()},
          {"frames_strained", lc.strainedFrames()},
          {"keyframes_in_ram", store.in_ram},
          {"keyframes_spilled", store.spilled},
          {"keyframe_spill_mib", double(store.spill_file_bytes) / (1 << 20)},
          {"loops_accepted", active},
          {"loops_removed_after_optimisation", removed},
          {"candidates_rejected", lc.rejections()},
          {"max_pose_correction_m", rec.maxLoopCorrection()},
          {"map_reintegrated", rec.reintegrated()},
          {"frame_loop_ms_per_frame", frames ? front * 1e3 / frames : 0.0},
          {"thread_ms_per_frame", frames ? back * 1e3 / frames : 0.0},
          {"stages", timesJson(t, frames)}};
}

// Faces against the marching-cubes mesh; distances against the mesh just before simplification.
json simplificationJson(const MeshSimplification& s, std::size_t raw_faces) {
  return {{"faces_raw", raw_faces}, {"faces_before", s.faces_before}, {"faces_after", s.faces_after},
          {"ratio_to_raw", raw_faces ? double(s.faces_after) / double(raw_faces) : 0.0},
          {"mean_distance_m", s.distance.mean}, {"max_distance_m", s.distance.max},
          {"distance_samples", s.distance.samples}, {"seconds", s.seconds}};
}

// Output files written into a staging folder and moved into place together, only once all of them
// were written: a failure (disk full) leaves an earlier run's outputs intact. Each is logged with the
// time since the previous one.
class StagedOutputs {
 public:
  explicit StagedOutputs(std::function<std::string(const std::string&)> final_path)
      : final_path_(std::move(final_path)), staging_(final_path_(".staging")), last_(std::chrono::steady_clock::now()) {
    fs::create_directories(staging_.tmp());
  }
  std::string path(const std::string& name) const { return (fs::path(staging_.tmp()) / name).string(); }
  // `name` is done; staged = false: it was written in place (the rawlog, committed by its writer).
  void wrote(const std::string& name, const std::string& what, bool staged = true) {
    const auto now = std::chrono::steady_clock::now();
    char line[1024];
    std::snprintf(line, sizeof line, "  wrote %s  (%s; %.1f s)\n", final_path_(name).c_str(), what.c_str(),
                  std::chrono::duration<double>(now - last_).count());
    log_lines_.push_back(line);
    if (staged) names_.push_back(name);
    last_ = now;
  }
  void commit(std::FILE* log) {
    for (const std::string& name : names_) {
      std::error_code ec;
      fs::rename(path(name), final_path_(name), ec);
      if (ec) throw InputError(final_path_(name), "cannot write: " + ec.message());
    }
    if (log)
      for (const std::string& l : log_lines_) std::fputs(l.c_str(), log);
  }

 private:
  std::function<std::string(const std::string&)> final_path_;
  AtomicPath staging_;
  std::chrono::steady_clock::time_point last_;
  std::vector<std::string> names_, log_lines_;
};

// The run's counts, times and fusion statistics (the start of summary.json).
json runSummary(const Reconstruction& rec, const RunInfo& info) {
  const std::size_t frames = rec.framesProcessed();
  json s;
  s["input"] = info.input;
  s["config"] = info.config;
  s["mode"] = toString(rec.mode());
  s["interrupted"] = info.interrupted;
  s["frames"] = frames;
  s["lost_frames"] = rec.lostFrames();
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
  const KinFuStats ks = rec.fusionStats();
  s["fusion"] = {{"volume_shifts", ks.shifts}, {"icp_degenerate_frames", ks.degenerate},
                 {"initial_guess", {{"odometry", ks.guess_prior}, {"constant_velocity", ks.guess_velocity}, {"last_pose", ks.guess_last}}},
                 {"bricks_in_volume", ks.bricks_in_volume},
                 {"bricks_in_world_model", ks.bricks_in_world_model}, {"tsdf_memory_mib", ks.memory_bytes / 1048576.0},
                 {"world_model", {{"cache_mib", ks.world.ram_bytes / 1048576.0}, {"bricks_spilled", ks.world.spilled},
                                  {"bricks_reloaded", ks.world.reloaded}, {"spill_file_mib", ks.world.spill_file_bytes / 1048576.0},
                                  {"spill_free_mib", ks.world.spill_free_bytes / 1048576.0}, {"spill_seconds", ks.world.spill_seconds}}}};
  if (!info.extra.is_null()) s.update(info.extra);
  return s;
}

}  // namespace

struct RunRecorder::Impl {
  std::string dir;
  OutputParams params;
  MeshCleanParams mesh_params;
  std::unique_ptr<RawlogThread> rawlog;
  Trajectory ground_truth;
  Eigen::Vector3d up_sum = Eigen::Vector3d::Zero();  // accelerometer "up" of the frames, in the map
  CameraIntrinsics camera;
  bool have_camera = false;

  std::string file(const std::string& name) const { return (fs::path(dir) / name).string(); }

  void finishRawlog(const Reconstruction& rec);
  // trajectory*.txt, trajectory.png, the ATE/RPE and loop entries of s; returns the ground truth in
  // the map's frame (empty without one).
  Trajectory writeTrajectories(const Reconstruction& rec, const RunInfo& info, json& s, StagedOutputs& out) const;
  // Meshes the map (region by region unless mesh_full.ply is asked for), releases it, and writes
  // mesh_raw.ply / mesh_full.ply / mesh.ply as asked; fills the mesh entries of s.
  TriangleMesh writeMeshes(Reconstruction& rec, json& s, StagedOutputs& out) const;
  SceneOptions sceneOptions(const Reconstruction& rec, json& s) const;
};

RunRecorder::RunRecorder(const std::string& dir, const OutputParams& params, const MeshCleanParams& mesh_params)
    : impl_(std::make_unique<Impl>()) {
  ensureWritableDirectory(dir);
  impl_->dir = dir;
  impl_->params = params;
  impl_->mesh_params = mesh_params;
  if (params.write_rawlog) impl_->rawlog = std::make_unique<RawlogThread>(impl_->file("poses.rawlog"));
}

RunRecorder::~RunRecorder() = default;

void RunRecorder::add(const Frame& frame, const FrameReport& report) {
  if (!impl_->have_camera) impl_->camera = frame.camera, impl_->have_camera = true;
  if (frame.groundTruth) impl_->ground_truth.push_back({frame.timestamp, *frame.groundTruth});
  if (frame.up && report.tracked) impl_->up_sum += report.pose.getRotationMatrix().asEigen() * *frame.up;
  if (impl_->rawlog) impl_->rawlog->push(frame, report);
}

void RunRecorder::Impl::finishRawlog(const Reconstruction& rec) {
  const std::string err = rawlog->stop();
  if (!err.empty()) throw InputError(file("poses.rawlog"), err);
  if (!ground_truth.empty()) rawlog->writer().writeGroundTruth(ground_truth);
  // Loop closure: the corrected poses follow the frames as "VOFUSION_POSE_OPTIMISED" (the tracked
  // ones went in with each frame as "VOFUSION_POSE"), one per frame in one last sensory frame.
  if (rec.loopCloser())
    for (const StampedPose& sp : rec.trajectory()) {
      mrpt::obs::CObservationRobotPose pose;
      pose.sensorLabel = "VOFUSION_POSE_OPTIMISED";
      pose.timestamp = mrpt::Clock::fromDouble(sp.timestamp);
      pose.pose.mean = sp.pose;
      rawlog->writer().writeObservation(pose);
    }
}

Trajectory RunRecorder::Impl::writeTrajectories(const Reconstruction& rec, const RunInfo& info, json& s,
                                                StagedOutputs& out) const {
  writeTumTrajectory(out.path("trajectory.txt"), rec.trajectory());
  out.wrote("trajectory.txt", std::to_string(rec.trajectory().size()) + " poses");
  const loop::LoopCloser* loops = rec.loopCloser();
  if (loops) {
    writeTumTrajectory(out.path("trajectory_tracked.txt"), rec.trackedTrajectory());
    out.wrote("trajectory_tracked.txt", "the tracker's poses, before loop closure");
    s["loop_closure"] = loopClosureJson(*loops, rec, rec.framesProcessed());
    s["loops"] = loopsJson(*loops, ground_truth);
  } else {
    s["loop_closure"] = {{"enabled", false}};
    s["loops"] = json::array();
  }
  const std::string title = "vofusion " + toString(rec.mode()) + ": " + recordingName(info.input);
  if (ground_truth.empty()) {
    if (!rec.trajectory().empty()) {
      plotTrajectoriesOverlay(out.path("trajectory.png"), {}, {{"estimate", rec.trajectory()}}, title);
      out.wrote("trajectory.png", "camera path");
    }
    return {};
  }
  const AteResult ate = computeAte(ground_truth, rec.trajectory());
  const RpeResult rpe = computeRpe(ground_truth, rec.trajectory(), params.rpe_delta);
  if (ate.success) s["ate"] = statsJson(ate.trans);
  if (loops) {  // the same run without loop closure, for comparison
    const AteResult tracked = computeAte(ground_truth, rec.trackedTrajectory());
    if (tracked.success) s["ate_tracked"] = statsJson(tracked.trans);
  }
  if (rpe.success) s["rpe"] = {{"delta_s", rpe.delta}, {"trans_m", statsJson(rpe.trans)}, {"rot_deg", statsJson(rpe.rot_deg)}};
  if (!ate.success) return {};
  plotAteReport(out.path("trajectory.png"), ate, title);
  out.wrote("trajectory.png", "ATE RMSE " + std::to_string(ate.trans.rmse) + " m");
  // Ground truth drawn in the map's frame (the map is anchored at the first camera): the ATE's rigid
  // alignment (estimate -> ground truth), inverted.
  Trajectory gt_in_map;
  const mrpt::poses::CPose3D to_map = -ate.alignment;
  for (const auto& g : ground_truth) gt_in_map.push_back({g.timestamp, to_map + g.pose});
  return gt_in_map;
}

TriangleMesh RunRecorder::Impl::writeMeshes(Reconstruction& rec, json& s, StagedOutputs& out) const {
  const OutputParams& p = params;
  // Once meshed the map goes, before the welded mesh's repair, the scene and the pictures.
  const auto release_map = [&] {
    if (rec.mapReleased()) return;
    rec.releaseMap();
    returnFreedHeap();
  };
  TriangleMesh mesh;
  std::string streamed_raw;  // logged after mesh.ply, whose line then carries the meshing time
  // Region by region unless the unsimplified whole (mesh_full.ply) is asked for.
  const bool by_region = p.clean_mesh && mesh_params.region_bricks > 0 && !p.save_full_mesh;
  if (by_region) {
    const auto source = [&](const std::function<void(fusion::RegionMesh&)>& sink) {
      rec.extractMeshByRegion(mesh_params.region_bricks, sink);
    };
    std::unique_ptr<Progress> shown;
    int shown_pass = 0;
    const auto progress = [&](int pass, std::size_t done, std::size_t regions) {
      if (pass != shown_pass) {
        if (shown) shown->finish();
        shown = std::make_unique<Progress>(pass == 1 ? "meshing [finding fragments]" : "meshing [repair, simplify]",
                                           regions, "regions");
        shown_pass = pass;
      }
      shown->update(done);
    };
    RegionMeshResult r =
        meshByRegion(source, mesh_params, p.save_raw_mesh ? out.path("mesh_raw.ply") : "", progress, release_map);
    if (shown) shown->finish();
    mesh = std::move(r.mesh);
    s["mesh_raw"] = {{"vertices", r.raw_vertices}, {"faces", r.raw_faces}, {"regions", r.regions}};
    if (p.save_raw_mesh) streamed_raw = std::to_string(r.raw_faces) + " faces, streamed region by region";
    s["mesh_clean"] = json::parse(r.report.toJson());
    if (r.report.simplification.ran) s["mesh_simplification"] = simplificationJson(r.report.simplification, r.raw_faces);
  } else {
    mesh = rec.extractMesh();
    s["mesh_raw"] = meshJson(mesh);
  }
  release_map();
  if (!by_region && p.save_raw_mesh) {
    writePly(out.path("mesh_raw.ply"), mesh);
    out.wrote("mesh_raw.ply", std::to_string(mesh.faces.size()) + " faces");
  }
  if (!by_region && p.clean_mesh && !mesh.empty()) {
    const std::size_t raw_faces = mesh.faces.size();
    TriangleMesh full;
    const MeshCleanReport report = cleanMesh(mesh, mesh_params, p.save_full_mesh ? &full : nullptr);
    s["mesh_clean"] = json::parse(report.toJson());
    if (report.simplification.ran) s["mesh_simplification"] = simplificationJson(report.simplification, raw_faces);
    if (p.save_full_mesh) {
      writePly(out.path("mesh_full.ply"), full);
      out.wrote("mesh_full.ply", std::to_string(full.faces.size()) + " faces");
    }
  }
  s["mesh"] = meshJson(mesh);
  writePly(out.path("mesh.ply"), mesh);
  out.wrote("mesh.ply", std::to_string(mesh.faces.size()) + " faces");
  if (!streamed_raw.empty()) out.wrote("mesh_raw.ply", streamed_raw);
  return mesh;
}

SceneOptions RunRecorder::Impl::sceneOptions(const Reconstruction& rec, json& s) const {
  SceneOptions o;
  o.frustum_every_k = params.frustum_every;
  if (const loop::LoopCloser* loops = rec.loopCloser()) {
    const std::vector<loop::KeyframePose> kf = loops->keyframes();
    auto at = [&](std::size_t id) { return toMrpt(kf[id].optimised); };
    for (const auto& k : kf) o.keyframes.push_back(toMrpt(k.optimised));
    for (const loop::LoopRecord& l : loops->loops())
      if (l.active && l.from_keyframe < kf.size() && l.to_keyframe < kf.size())
        o.loop_edges.push_back({at(l.from_keyframe), at(l.to_keyframe)});
  }
  // Up: the accelerometer's where the recording has one, else the scene finds the floor.
  if (up_sum.norm() > 0) {
    o.up_vector = up_sum.normalized();
    s["up_from_accelerometer"] = {o.up_vector->x(), o.up_vector->y(), o.up_vector->z()};
  }
  return o;
}

json RunRecorder::finish(Reconstruction& rec, const RunInfo& info, std::FILE* log) {
  Impl& m = *impl_;
  StagedOutputs out([&m](const std::string& name) { return m.file(name); });
  json s = runSummary(rec, info);
  if (m.rawlog) m.finishRawlog(rec);
  const Trajectory gt_in_map = m.writeTrajectories(rec, info, s, out);

  returnFreedHeap();  // the frames are done: what meshing frees goes back to the kernel
  const TriangleMesh mesh = m.writeMeshes(rec, s, out);

  const SceneOptions scene_opts = m.sceneOptions(rec, s);
  const CameraIntrinsics cam = m.have_camera ? m.camera : CameraIntrinsics();
  exportScene(out.path("scene.3Dscene"), mesh, rec.trajectory(), gt_in_map.empty() ? nullptr : &gt_in_map, cam, scene_opts);
  out.wrote("scene.3Dscene", "open with SceneViewer3D");
  if (!mesh.empty()) {
    renderMeshPng(out.path("mesh.png"), mesh, &rec.trajectory(), m.params.image_width, m.params.image_height,
                  scene_opts.up_vector);
    out.wrote("mesh.png", std::to_string(m.params.image_width) + "x" + std::to_string(m.params.image_height));
  }

  s["peak_memory_mib"] = peakMemoryMiB();
  writeFileAtomically(out.path("summary.json"), s.dump(2) + "\n");
  out.wrote("summary.json", "run statistics");
  if (m.rawlog) {
    m.rawlog->writer().commit();
    out.wrote("poses.rawlog", std::to_string(m.rawlog->writer().framesWritten()) + " frames", false);
  }
  out.commit(log);
  return s;
}

}  // namespace vofusion
