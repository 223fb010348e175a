#pragma once
// Everything a reconstruction run leaves in its output folder, each file whole or not at all:
//   trajectory.txt   TUM format, one pose per processed frame
//   poses.rawlog     input observations + odometry actions (CActionRobotMovement3D, emVisualOdometry)
//                    + fused poses (CObservationRobotPose "VOFUSION_POSE"), for RawLogViewer / MRPT tools
//   mesh.ply         CGAL post-processed coloured mesh, simplified (mesh_raw.ply, mesh_full.ply too when asked)
//   scene.3Dscene    mesh, camera path, frustums, grid for SceneViewer3D
//   trajectory.png   path (and ground truth + error when known); mesh.png an off-screen rendering
//   summary.json     frames, failures, fps per stage, peak memory, mesh statistics, ATE/RPE
// Used by the offline app and the live one alike; the config sections by every app that reads a vofusion config.
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <mrpt/config/CLoadableOptions.h>
#include <nlohmann/json.hpp>

#include "vofusion/core/config.h"
#include "vofusion/core/trajectory.h"
#include "vofusion/mesh/mesh_clean.h"
#include "vofusion/pipeline/reconstruction.h"

namespace vofusion {

class RegionPremesher;
class SkippingSource;

// INI section [output].
struct OutputParams : public mrpt::config::CLoadableOptions {
  bool write_rawlog = true;      // poses.rawlog (costs PNG encoding per frame, on a writer thread)
  // mesh.ply, mesh.png and the mesh in scene.3Dscene (and the re-fusion after loops that feeds them);
  // false: the path and the statistics only, for trajectory benchmarks
  bool write_mesh = true;
  bool save_raw_mesh = false;    // also mesh_raw.ply, the marching-cubes mesh before post-processing
  bool clean_mesh = true;        // CGAL post-processing with the [mesh] parameters
  bool save_full_mesh = false;   // also mesh_full.ply, post-processed but not simplified
  int frustum_every = 30;        // frames between camera frustums drawn in scene.3Dscene
  int image_width = 1280;        // px, mesh.png and trajectory.png
  int image_height = 960;        // px
  double rpe_delta = 1.0;        // s, pose-pair spacing of the relative pose error

  void loadFromConfigFile(const mrpt::config::CConfigFileBase& cfg, const std::string& section) override;
  void saveToConfigFile(mrpt::config::CConfigFileBase& cfg, const std::string& section) const override;
};

struct RunInfo {
  std::string app = "vofusion";  // names the run in messages
  std::string input;           // what was reconstructed
  std::string config;          // the config file used ("" = defaults)
  bool interrupted = false;    // stopped early (Ctrl-C, sensor lost): outputs hold what was built
  double seconds = 0.0;        // wall time of the frame loop
  nlohmann::json extra;        // caller-specific facts (e.g. live: played/dropped), merged into summary
  // Why RunSession::finish is given no recording to read again (summary.json's
  // loop_closure_reintegration.skipped when loops moved the poses; the caller says it to the user).
  std::string no_rereading = "no recording to read again";
  // The recording's ground truth as it lists it (FrameSource::recordedGroundTruth): the ATE and RPE are
  // taken against it, as TUM's evaluate_ate.py and rgbd-eval take them (the nearest stamp within
  // 20 ms); empty: against the frames' own (Frame::groundTruth: exact for synthetic and 7-Scenes).
  Trajectory recorded_ground_truth;
};

// Every path a run may write into its folder out_dir, whichever outputs its config asks for: its
// files, poses.rawlog's images folder and ground truth, its checkpoint and its default work folder.
std::vector<std::string> runOutputPaths(const std::string& out_dir);
// Nothing a run writes lands on its input recording: throws InputError when the input is (or is inside)
// one of `writes` (--out the folder of the poses.rawlog read), or when `save_volume` (--save-volume) is
// a rawlog input, its images or ground truth, a file already in a folder input, or one of `writes`.
// Each was replaced without a word.
void refuseWritesOverTheInput(const std::string& input, const std::vector<std::string>& writes,
                              const std::optional<std::string>& save_volume);

// Every section of a vofusion config, at its defaults: the reconstruction's, [mesh] and [output]
// (vofusion's --dump-config; the sections any app taking that file checks for typos).
std::vector<ConfigSection> vofusionConfigSections();

// Adds the recording's damaged frames to info.extra: `frames_skipped` (how many), `skipped_frames` (frame,
// file, problem each) and, when the recording ends in a damaged record, `recording_cut_short`.
// `stopped_at`: the position of the frame an interrupted run read but did not process; frames the read
// ahead skipped past it are not the run's (the summary listed them, and a cut short it never reached).
void reportSkipped(const SkippingSource& frames, RunInfo& info, std::optional<std::size_t> stopped_at = std::nullopt);

class RunRecorder {
 public:
  // Throws InputError(dir, ...) when the folder cannot be created or written.
  RunRecorder(const std::string& dir, const OutputParams& params, const MeshCleanParams& mesh_params);
  ~RunRecorder();  // without finish(): poses.rawlog is discarded, earlier outputs stay as they were

  // Queues the frame for poses.rawlog (written by a background thread) and keeps its ground truth. A
  // poses.rawlog that cannot be written (a full disk) is given up, said at once; the run goes on, and
  // finish() writes the other outputs, summary.json's poses_rawlog_error saying why.
  void add(const Frame& frame, const FrameReport& report);
  // Writes every output and returns the summary that went into summary.json. `log` gets one line
  // per file written (may be null). Frees rec's map once it is meshed (Reconstruction::releaseMap).
  // `premeshed`: the regions meshed while tracking (stopped), handed over where they are still the map's,
  // the rest freed once the regions are done.
  nlohmann::json finish(Reconstruction& rec, const RunInfo& info, std::FILE* log = stderr,
                        RegionPremesher* premeshed = nullptr);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Peak resident memory of this process so far, in MiB.
double peakMemoryMiB();

}  // namespace vofusion
