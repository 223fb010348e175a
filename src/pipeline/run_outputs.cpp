#include "vofusion/pipeline/run_outputs.h"

#include <filesystem>
#include <future>
#include <optional>

#include "mesh_stage.h"
#include "poses_rawlog.h"
#include "run_summary.h"
#include "staged_outputs.h"
#include "vofusion/core/atomic_file.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/heap.h"
#include "vofusion/core/progress.h"  // printWarning
#include "vofusion/core/pose_eigen.h"
#include "vofusion/eval/trajectory_eval.h"
#include "vofusion/io/rawlog.h"
#include "vofusion/scene/scene_export.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace vofusion {

namespace {

constexpr double kFrameRpeDelta = 0.05;  // s

// The picture is rendered beside the scene's writing only for meshes whose two MRPT scenes at once
// cost at most 32 MiB more than one after the other: on rpy_first100 (176 k faces) side by side
// costs +15 MiB of peak RSS, while the long walk's 996 k faces lifted its peak 556 -> 679 MiB
// (~130 B a face; bench/results/2026-12-02-tail.md).
bool pictureBesideScene(std::size_t faces) {
  constexpr double kExtraBytesPerFace = 130.0, kMaxExtraBytes = 32.0 * (1 << 20);
  return kExtraBytesPerFace * double(faces) <= kMaxExtraBytes;
}

// A recording as titles name it: its folder or file name ("rgbd_dataset_freiburg1_xyz", "loop7.rawlog",
// "synthetic:room"), never the absolute path.
std::string recordingName(const std::string& input) {
  fs::path p(input);
  if (!p.has_filename()) p = p.parent_path();  // "folder/" names "folder"
  return p.filename().empty() ? input : p.filename().string();
}

}  // namespace

struct RunRecorder::Impl {
  std::string dir;
  OutputParams params;
  MeshCleanParams mesh_params;
  std::unique_ptr<PosesRawlog> rawlog;
  std::string rawlog_error;  // why poses.rawlog was given up (the run goes on without it)
  Trajectory ground_truth;
  Eigen::Vector3d up_sum = Eigen::Vector3d::Zero();  // accelerometer "up" of the frames, in the map
  CameraIntrinsics camera;
  bool have_camera = false;

  std::string file(const std::string& name) const { return (fs::path(dir) / name).string(); }
  // poses.rawlog could not be written (a full disk): said at once, its temporaries freed, and the run
  // goes on to its other outputs (it lost them all at the end, and kept the temporaries till then).
  void giveUpRawlog(const std::exception& e, const StagedOutputs* out = nullptr) {
    const auto* input = dynamic_cast<const InputError*>(&e);  // MRPT's serialisation throws its own
    const InputError as_input = input ? *input : InputError(file("poses.rawlog"), oneLineMessage(e));
    const InputError named = out ? out->named(as_input) : as_input;
    rawlog_error = named.what();
    printWarning(rawlog_error + " (the run goes on without poses.rawlog)");
    rawlog.reset();
  }
  // The ground truth a run is evaluated against and its rawlog carries: the recording's own, as the
  // benchmark's tools take it (the frames' interpolated one gave xyz_first300 0.011902 m where
  // evaluate_ate.py and rgbd-eval say 0.011927), else the frames'.
  const Trajectory& truth(const RunInfo& info) const {
    return info.recorded_ground_truth.empty() ? ground_truth : info.recorded_ground_truth;
  }

  // trajectory*.txt, trajectory.png, the ATE/RPE and loop entries of s; returns the ground truth in
  // the map's frame (empty without one).
  Trajectory writeTrajectories(const Reconstruction& rec, const RunInfo& info, json& s, StagedOutputs& out) const;
  SceneOptions sceneOptions(const Reconstruction& rec, json& s) const;
  // scene.3Dscene, and mesh.png beside it (a picture that cannot be rendered costs the picture only).
  void writeScene(const TriangleMesh& mesh, const Reconstruction& rec, const Trajectory& gt_in_map, json& s,
                  StagedOutputs& out) const;
  // mesh.ply (or the map released unmeshed), then scene.3Dscene and mesh.png.
  void writeMeshAndScene(Reconstruction& rec, const Trajectory& gt_in_map, json& s, StagedOutputs& out,
                         RegionPremesher* premeshed) const;
  // summary.json (with the run's last figures), then poses.rawlog committed, then every staged file in place.
  void writeSummaryAndCommit(json& s, StagedOutputs& out, std::FILE* log);
};

RunRecorder::RunRecorder(const std::string& dir, const OutputParams& params, const MeshCleanParams& mesh_params)
    : impl_(std::make_unique<Impl>()) {
  ensureWritableDirectory(dir);
  impl_->dir = dir;
  impl_->params = params;
  impl_->mesh_params = mesh_params;
  if (params.write_rawlog) impl_->rawlog = std::make_unique<PosesRawlog>(impl_->file("poses.rawlog"));
}

RunRecorder::~RunRecorder() = default;

void RunRecorder::add(const Frame& frame, const FrameReport& report) {
  if (!impl_->have_camera) impl_->camera = frame.camera, impl_->have_camera = true;
  if (frame.groundTruth) impl_->ground_truth.push_back({frame.timestamp, *frame.groundTruth});
  if (frame.up && report.tracked) impl_->up_sum += report.pose.getRotationMatrix().asEigen() * *frame.up;
  if (impl_->rawlog) {
    impl_->rawlog->push(frame, report);
    if (const std::optional<InputError> err = impl_->rawlog->error()) impl_->giveUpRawlog(*err);
  }
}

Trajectory RunRecorder::Impl::writeTrajectories(const Reconstruction& rec, const RunInfo& info, json& s,
                                                StagedOutputs& out) const {
  writeTumTrajectory(out.path("trajectory.txt"), rec.trajectory());
  out.wrote("trajectory.txt", std::to_string(rec.trajectory().size()) + " poses");
  writeTumTrajectory(out.path("trajectory_fused.txt"), rec.fusedTrajectory());
  out.wrote("trajectory_fused.txt", "where each frame was fused into the map");
  const loop::LoopCloser* loops = rec.loopCloser();
  if (loops) {
    writeTumTrajectory(out.path("trajectory_tracked.txt"), rec.trackedTrajectory());
    out.wrote("trajectory_tracked.txt", "the tracker's poses smoothed, before loop closure");
    s["loop_closure"] = loopClosureJson(*loops, rec, rec.framesProcessed());
    s["loops"] = loopsJson(*loops, ground_truth);
  } else {
    s["loop_closure"] = {{"enabled", false}};
    s["loops"] = json::array();
  }
  const std::string title = "vofusion " + toString(rec.mode()) + ": " + recordingName(info.input);
  // The camera's path alone, where no ATE aligns it with ground truth (none, or too little overlap).
  const auto plotPathAlone = [&](const std::string& why) {
    if (rec.trajectory().empty()) return;
    plotTrajectoriesOverlay(out.path("trajectory.png"), {}, {{"estimate", rec.trajectory()}}, title);
    out.wrote("trajectory.png", "camera path" + why);
  };
  const Trajectory& truth = this->truth(info);
  if (truth.empty()) {
    plotPathAlone("");
    return {};
  }
  const AteResult ate = computeAte(truth, rec.trajectory());
  const RpeResult rpe = computeRpe(truth, rec.trajectory(), params.rpe_delta);
  if (ate.success) s["ate"] = statsJson(ate.trans);
  if (loops) {  // the same run without loop closure, for comparison
    const AteResult tracked = computeAte(truth, rec.trackedTrajectory());
    if (tracked.success) s["ate_tracked"] = statsJson(tracked.trans);
  }
  if (rpe.success) s["rpe"] = {{"delta_s", rpe.delta}, {"trans_m", statsJson(rpe.trans)}, {"rot_deg", statsJson(rpe.rot_deg)}};
  // Over 50 ms, as issue 30 measures it (at 30 Hz the partner is the next frame or the one after, by the
  // stamps' jitter): its p95 is the tail of bad frames, in the written path and (rpe_50ms_fused) in the
  // poses the frames were fused at.
  const auto frameRpe = [&](const Trajectory& path) -> json {
    const RpeResult r = computeRpe(truth, path, kFrameRpeDelta);
    if (!r.success) return nullptr;
    return {{"delta_s", r.delta}, {"trans_m", statsJson(r.trans)}, {"rot_deg", statsJson(r.rot_deg)}};
  };
  if (json j = frameRpe(rec.trajectory()); !j.is_null()) s["rpe_50ms"] = j;
  if (json j = frameRpe(rec.fusedTrajectory()); !j.is_null()) s["rpe_50ms_fused"] = j;
  if (!ate.success) {
    s["ate_error"] = ate.message;
    plotPathAlone(" (no ATE: " + ate.message + ")");
    return {};
  }
  plotAteReport(out.path("trajectory.png"), ate, title);
  out.wrote("trajectory.png", "ATE RMSE " + std::to_string(ate.trans.rmse) + " m");
  // Ground truth drawn in the map's frame (the map is anchored at the first camera): the ATE's rigid
  // alignment (estimate -> ground truth), inverted.
  Trajectory gt_in_map;
  const mrpt::poses::CPose3D to_map = -ate.alignment;
  for (const auto& g : ground_truth.empty() ? truth : ground_truth) gt_in_map.push_back({g.timestamp, to_map + g.pose});
  return gt_in_map;
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

namespace {
// Every file a run may write into its folder, whichever outputs its config asks for.
const std::vector<std::string> kRunOutputs = {
    "trajectory.txt", "trajectory_fused.txt", "trajectory_tracked.txt", "trajectory.png", "mesh.ply", "mesh_raw.ply",
    "mesh_full.ply", "mesh.png", "scene.3Dscene", "summary.json", "poses.rawlog"};
}  // namespace

std::vector<std::string> runOutputPaths(const std::string& out_dir) {
  std::vector<std::string> paths;
  for (const std::string& name : kRunOutputs) paths.push_back((fs::path(out_dir) / name).string());
  const std::string poses = (fs::path(out_dir) / "poses.rawlog").string();
  for (const std::string& more : {RawlogWriter::imagesDirFor(poses), RawlogWriter::groundTruthPathFor(poses),
                                  (fs::path(out_dir) / "checkpoint").string(), (fs::path(out_dir) / ".tmp").string()})
    paths.push_back(more);
  return paths;
}

void refuseWritesOverTheInput(const std::string& input, const std::vector<std::string>& writes,
                              const std::optional<std::string>& save_volume) {
  std::error_code ec;
  const bool folder = fs::is_directory(input, ec);
  // A rawlog is its file, its images folder and its ground truth; a folder (TUM, 7-Scenes) its files.
  const std::vector<std::string> parts =
      folder ? std::vector<std::string>{input}
             : std::vector<std::string>{input, RawlogWriter::imagesDirFor(input), RawlogWriter::groundTruthPathFor(input)};
  for (const std::string& part : parts)
    for (const std::string& w : writes)
      if (isWithin(part, w)) throw InputError(input, "is this run's own output " + w + ": choose another --out");
  if (!save_volume) return;
  for (const std::string& part : parts)
    if (isWithin(*save_volume, part) && (!folder || fs::exists(*save_volume, ec)))  // a new file in a folder replaces nothing
      throw InputError(*save_volume, "is the input recording's (" + input + "): --save-volume would write the map over it");
  for (const std::string& w : writes)
    if (isWithin(*save_volume, w))
      throw InputError(*save_volume, "is one of this run's outputs: --save-volume wants a name of its own");
}

namespace {

// A folder that also holds an earlier run's outputs (this run asked for fewer: mesh = false, no
// ground truth) says so, rather than leave them to pass for this run's.
void warnOfEarlierOutputs(const StagedOutputs& out, const std::string& dir) {
  const std::vector<std::string> left = out.leftFromEarlier(kRunOutputs);
  if (left.empty()) return;
  std::string names;
  for (const std::string& n : left) names += (names.empty() ? "" : ", ") + n;
  printWarning(dir + ": " + names + (left.size() == 1 ? " is" : " are") + " an earlier run's (this run wrote none)");
}
}  // namespace

void RunRecorder::Impl::writeScene(const TriangleMesh& mesh, const Reconstruction& rec, const Trajectory& gt_in_map,
                                   json& s, StagedOutputs& out) const {
  const SceneOptions scene_opts = sceneOptions(rec, s);
  const CameraIntrinsics cam = have_camera ? camera : CameraIntrinsics();
  // The picture rendered beside the scene's building and writing (each took ~0.35 s of rpy_first100's
  // time after its last frame, one after the other) where memory allows, else
  // deferred: rendered by get(), after the scene. The render takes its own copy of the path (reading a
  // CPose3D's angles fills its cache) and its file name. `png` is declared after all it reads: if the
  // scene throws, its destructor waits for a render in flight first.
  const bool beside = !mesh.empty() && pictureBesideScene(mesh.faces.size());
  std::future<void> png;
  if (!mesh.empty())
    png = std::async(beside ? std::launch::async | std::launch::deferred : std::launch::deferred,
                     [&mesh, this, &scene_opts, path = rec.trajectory(), file = out.path("mesh.png")] {
                       renderMeshPng(file, mesh, &path, params.image_width, params.image_height,
                                     scene_opts.up_vector);
                     });
  exportScene(out.path("scene.3Dscene"), mesh, rec.trajectory(), gt_in_map.empty() ? nullptr : &gt_in_map, cam,
              scene_opts);
  out.wrote("scene.3Dscene", "open with SceneViewer3D");
  if (png.valid()) {
    // A picture that cannot be rendered (no OpenGL device on a headless machine) costs the picture:
    // the run's every output was lost with it.
    try {
      png.get();  // rethrows what the render threw
      out.wrote("mesh.png", std::to_string(params.image_width) + "x" + std::to_string(params.image_height) +
                                (beside ? ", rendered beside the scene" : ""));
    } catch (const std::exception& e) {  // InputError, or OpenCV's encoder, or memory
      const auto* input = dynamic_cast<const InputError*>(&e);
      const InputError named = out.named(input ? *input : InputError(out.path("mesh.png"), oneLineMessage(e)));
      printWarning(named.what());
      s["mesh_png_error"] = named.what();
    }
  }
}

void RunRecorder::Impl::writeMeshAndScene(Reconstruction& rec, const Trajectory& gt_in_map, json& s, StagedOutputs& out,
                                          RegionPremesher* premeshed) const {
  TriangleMesh mesh;
  // mesh.png's renderer readied once the map is meshed, on the core the welded mesh's repair leaves
  // idle (~0.1 s of the picture's time after the last frame otherwise), where the picture will be
  // rendered beside the scene: the driver then in memory at the welded repair's peak lifted the
  // 300-frame loop scene's (1.6 M faces) 624-630 -> 666 MiB.
  std::optional<OffscreenRenderWarmUp> renderer_ready;
  const auto readyRenderer = [&](std::size_t faces) {
    if (pictureBesideScene(faces)) renderer_ready.emplace();
  };
  if (params.write_mesh) mesh = writeMeshes(rec, params, mesh_params, s, out, premeshed, readyRenderer);
  else rec.releaseMap();
  renderer_ready.reset();  // before the picture's own render: one EGL start-up at a time
  writeScene(mesh, rec, gt_in_map, s, out);
}

void RunRecorder::Impl::writeSummaryAndCommit(json& s, StagedOutputs& out, std::FILE* log) {
  s["peak_memory_mib"] = peakMemoryMiB();
  s["heap_huge_pages"] = heapAsksForHugePages();  // the run's GLIBC_TUNABLES asks for huge pages (docs/memory.md)
  // Where the time after the last frame went, file by file (mesh.ply's includes the meshing, which
  // mesh_clean's steps break down); summary.json's own and poses.rawlog's come after it.
  for (const auto& [name, seconds] : out.secondsEach())
    s["output_seconds"].push_back({{"file", name}, {"seconds_since_previous", seconds}});
  // A name that is no UTF-8 (a Latin-1 folder) is written with U+FFFD: strict, the writer threw and the run lost every output.
  const auto writeSummary = [&] {
    writeFileAtomically(out.path("summary.json"), s.dump(2, ' ', false, json::error_handler_t::replace) + "\n");
  };
  writeSummary();
  out.wrote("summary.json", "run statistics");
  // The rawlog replaces an earlier run's only once the staged files have their places: a folder where
  // summary.json goes left the new rawlog beside the earlier run's other outputs.
  out.checkPlaces();
  if (rawlog) {
    try {
      rawlog->writer().commit();  // what it throws changed nothing (RawlogWriter::commit)
      out.wrote("poses.rawlog", std::to_string(rawlog->writer().framesWritten()) + " frames", false);
    } catch (const std::exception& e) {  // closing it failed (a full disk): the other outputs stay
      giveUpRawlog(e, &out);
      s["poses_rawlog_error"] = rawlog_error;
      writeSummary();  // still staged: written again, saying why
    }
  }
  out.commit(log);
  warnOfEarlierOutputs(out, dir);
}

json RunRecorder::finish(Reconstruction& rec, const RunInfo& info, std::FILE* log, RegionPremesher* premeshed) {
  Impl& m = *impl_;
  StagedOutputs out([&m](const std::string& name) { return m.file(name); });
  try {
    json s = runSummary(rec, info);
    if (m.rawlog) {
      try {
        m.rawlog->finish(rec, m.truth(info));
      } catch (const std::exception& e) {
        m.giveUpRawlog(e, &out);
      }
    }
    if (!m.rawlog_error.empty()) s["poses_rawlog_error"] = m.rawlog_error;
    const Trajectory gt_in_map = m.writeTrajectories(rec, info, s, out);
    returnFreedHeap();  // the frames are done: what meshing frees goes back to the kernel
    m.writeMeshAndScene(rec, gt_in_map, s, out, premeshed);
    m.writeSummaryAndCommit(s, out, log);
    return s;
  } catch (const InputError& e) {
    throw out.named(e);  // the file as the user will find it, not its staged copy
  }
}

}  // namespace vofusion
