#include "vofusion/loop/loop_params.h"

#include "vofusion/core/config.h"

namespace vofusion::loop {

namespace {
// Every [loop] key, once: loading and saving both walk this list.
std::vector<ConfigKey> loopKeys(LoopParams& p) {
  return {
      {"enabled", &p.enabled, "loop closure (--no-loop-closure = false)"},
      {"keyframe_translation", &p.keyframe_translation, "m moved since the last keyframe", 0.01, 10.0},
      {"keyframe_rotation", &p.keyframe_rotation, "degrees turned since the last keyframe", 0.5, 180.0},
      {"keyframe_downsample", &p.keyframe_downsample, "keyframe depth kept at 1/n resolution (ICP)", 1.0, 16.0},
      {"keyframe_cache_mib", &p.keyframe_cache_mib, "MiB of keyframe features and depth kept in RAM; older ones spilled to disk", 0.0, 65536.0},
      {"recent_keyframes", &p.recent_keyframes, "newest keyframes never loop candidates", 1.0, 10000.0},
      {"min_travel", &p.min_travel, "m of camera path between a loop's keyframes, at least", 0.0, 10000.0},
      {"place_descriptors", &p.place_descriptors, "descriptors per keyframe indexed and queried", 10.0, 100000.0},
      {"index_spacing", &p.index_spacing, "m (or keyframe_rotation) from the last indexed keyframe to index another, and from the last queried one to query again; 0 = every one", 0.0, 100.0},
      {"candidates", &p.candidates, "best-voted places verified per keyframe", 1.0, 100.0},
      {"min_votes", &p.min_votes, "descriptor votes a place (an indexed keyframe and its two neighbours) needs", 1.0, 100000.0},
      {"max_hamming", &p.max_hamming, "bits of 256, a vote's distance at most", 1.0, 256.0},
      {"lsh_tables", &p.lsh_tables, "LSH hash tables (the place index's own, FLANN's scheme)", 1.0, 64.0},
      {"lsh_key_bits", &p.lsh_key_bits, "LSH key size, bits", 4.0, 30.0},
      {"lsh_probe_level", &p.lsh_probe_level, "LSH multi-probe level", 0.0, 4.0},
      {"min_inliers", &p.min_inliers, "3D inliers of the loop's rigid motion", 6.0, 100000.0},
      {"inlier_threshold", &p.inlier_threshold, "m at 1 m depth, grows with z^2", 0.0005, 0.5},
      {"min_icp_overlap", &p.min_icp_overlap, "ICP inliers / valid pixels of the keyframe", 0.0, 1.0},
      {"max_icp_rms", &p.max_icp_rms, "m, point-to-plane RMS of the loop's ICP", 0.0005, 1.0},
      {"max_icp_change_translation", &p.max_icp_change_translation, "m, ICP vs RANSAC pose", 0.001, 10.0},
      {"max_icp_change_rotation", &p.max_icp_change_rotation, "degrees, ICP vs RANSAC pose", 0.01, 180.0},
      {"max_drift_translation", &p.max_drift_translation, "m, correction allowed without travel", 0.0, 100.0},
      {"max_drift_rate", &p.max_drift_rate, "m of correction per m travelled", 0.0, 10.0},
      {"max_drift_rotation", &p.max_drift_rotation, "degrees, correction allowed without travel", 0.0, 180.0},
      {"max_drift_rotation_rate", &p.max_drift_rotation_rate, "degrees of correction per m travelled", 0.0, 180.0},
      {"reintegrate_min_correction", &p.reintegrate_min_correction, "m; larger corrections re-fuse the map", 0.0, 100.0},
  };
}
}  // namespace

void LoopParams::loadFromConfigFile(const mrpt::config::CConfigFileBase& c, const std::string& s) { loadKeys(c, s, loopKeys(*this)); }

void LoopParams::saveToConfigFile(mrpt::config::CConfigFileBase& c, const std::string& s) const {
  saveKeys(c, s, loopKeys(const_cast<LoopParams&>(*this)));
}

}  // namespace vofusion::loop
