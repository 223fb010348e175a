#include "vofusion/pipeline/run_session.h"

#include <cstdio>
#include <filesystem>

#include "vofusion/core/progress.h"

namespace vofusion {

RunSession::RunSession(const mrpt::config::CConfigFileBase& cfg, TrackingMode mode, const std::string& out_dir,
                       const OutputParams& out_params, const MeshCleanParams& mesh_params)
    : rec_(cfg, mode), recorder_(out_dir, out_params, mesh_params), write_mesh_(out_params.write_mesh) {}

RunSession::~RunSession() = default;

FrameReport RunSession::process(const Frame& frame) {
  const FrameReport report = rec_.process(frame);
  recorder_.add(frame, report);
  return report;
}

// Loops moved the poses: the map, fused at the tracked ones, is fused again at the corrected ones,
// reading the recording a second time rather than keeping every frame in memory.
void RunSession::refuse(RunInfo& info, const Reopen& reopen) {
  // No recording to read again (vofusion interrupted, vofusion-grab without one): the app says why.
  if (!rec_.mapNeedsReintegration() || !reopen) return;
  auto again = reopen();
  Progress progress(info.app + " [re-fusing at the loop-closed poses]", rec_.framesProcessed());
  const std::size_t fused =
      rec_.reintegrate([&](Frame& f) { return again->next(f); }, [&](std::size_t n) { progress.update(n); });
  progress.finish();
  info.extra["loop_closure_reintegration"] = {
      {"frames_fused", fused}, {"seconds", progress.elapsedSeconds()}, {"from", std::filesystem::path(again->name()).filename().string()}};
}

nlohmann::json RunSession::finish(RunInfo info, const Reopen& reopen, const std::optional<std::string>& save_volume) {
  rec_.finish();
  if (write_mesh_ || save_volume) refuse(info, reopen);  // the map is not used otherwise
  if (save_volume) rec_.saveVolume(*save_volume);
  return recorder_.finish(rec_, info);
}

}  // namespace vofusion
