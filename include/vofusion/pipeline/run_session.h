#pragma once
// One reconstruction run, as both apps drive it (vofusion over a recording, vofusion-grab --live over a
// sensor or a replay): each frame through the Reconstruction and into the outputs' queue, then one
// end-of-run flow: the loop closer's last corrections, the map fused again at the loop-closed poses
// from the recording read a second time, the map saved when asked, every output written.
//
//   RunSession run(cfg, TrackingMode::Joint, "out", out_params, mesh_params);
//   while (source.next(frame)) run.process(frame);
//   json summary = run.finish(info, [&] { return openFrameSource(input); });
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include <mrpt/config/CConfigFileBase.h>
#include <nlohmann/json.hpp>

#include "vofusion/io/frame_source.h"
#include "vofusion/pipeline/reconstruction.h"
#include "vofusion/pipeline/run_outputs.h"

namespace vofusion {

class RunSession {
 public:
  // Opens the recording again from its first frame, for re-fusion; empty: there is none to read.
  using Reopen = std::function<std::unique_ptr<FrameSource>()>;

  // Throws InputError for a bad configuration or an output folder that cannot be written.
  RunSession(const mrpt::config::CConfigFileBase& cfg, TrackingMode mode, const std::string& out_dir,
             const OutputParams& out_params, const MeshCleanParams& mesh_params);
  ~RunSession();  // without finish(): no outputs replaced

  Reconstruction& reconstruction() { return rec_; }
  // The frame through the reconstruction, then queued for poses.rawlog.
  FrameReport process(const Frame& frame);
  // The end of the run, once: loop closure finished, the map fused again at the corrected poses when
  // loops moved them (from reopen(); without one the mesh keeps the tracked poses),
  // saved to save_volume when given, and every output written. Returns summary.json's content.
  nlohmann::json finish(RunInfo info, const Reopen& reopen, const std::optional<std::string>& save_volume = std::nullopt);

 private:
  void refuse(RunInfo& info, const Reopen& reopen);

  Reconstruction rec_;
  RunRecorder recorder_;
  bool write_mesh_;  // the map is used at all after the frame loop
};

}  // namespace vofusion
