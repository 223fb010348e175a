// [kinfu] INI section. One table lists every key, so loading and saving can never disagree.
#include <mrpt/config/CConfigFileBase.h>

#include "vofusion/core/config.h"
#include "vofusion/core/errors.h"
#include "vofusion/fusion/kinfu.h"

namespace vofusion {

namespace {

std::vector<ConfigKey> keys(KinFuParams& p) {
  return {
      {"volume_voxels", &p.tsdf.volume_voxels, "voxels per volume edge (multiple of 8)", 8.0, 1024.0},
      {"voxel_size", &p.tsdf.voxel_size, "m", 0.001, 1.0},
      {"truncation", &p.tsdf.truncation, "m, TSDF band half width", 0.002, 10.0},
      {"max_weight", &p.tsdf.max_weight, "frames, weight cap of the running average (<= 255)", 1.0, 255.0},
      {"integrate_min_depth", &p.tsdf.min_depth, "m, depth readings fused (above 0: a 0 is no reading)", 0.001, 20.0},
      {"integrate_max_depth", &p.tsdf.max_depth, "m", 0.1, 20.0},
      {"world_cache_mib", &p.tsdf.world_cache_mib, "MiB of bricks that left the volume kept in RAM; the rest are spilled compressed to disk", 0.0, 65536.0},
      {"work_dir", &p.tsdf.work_dir, "folder of the world model's spill file (auto: vofusion uses <out>/.tmp, --work-dir overrides; elsewhere the system's temporary folder)"},
      {"bilateral_sigma_depth", &p.preprocess.sigma_depth, "m", 0.001, 1.0},
      {"bilateral_sigma_spatial", &p.preprocess.sigma_spatial, "pixels; mode kinfu or [brand] use_geometry = false (as bilateral_kernel)", 0.1, 50.0},
      {"bilateral_kernel", &p.preprocess.kernel, "pixels (window edge; 0 = no filter); mode kinfu or [brand] use_geometry = false (else tracking averages the odometry's point and normal maps down)", 0.0, 31.0},
      {"min_depth", &p.preprocess.min_depth, "m, readings used for tracking (above 0: a 0 is no reading)", 0.001, 20.0},
      {"max_depth", &p.preprocess.max_depth, "m", 0.1, 20.0},
      {"max_normal_jump", &p.preprocess.max_normal_jump, "fraction of depth: larger neighbour jumps give no normal; mode kinfu or [brand] use_geometry = false (else the odometry's normals)", 0.001, 10.0},
      {"icp_iterations_l0", &p.icp.iterations[0], "ICP iterations at the finest tracking level (its statistics judge the fit)", 1.0, 100.0},
      {"icp_iterations_l1", &p.icp.iterations[1], "ICP iterations at 1/2 of it", 0.0, 100.0},
      {"icp_iterations_l2", &p.icp.iterations[2], "ICP iterations at 1/4 of it", 0.0, 100.0},
      {"icp_max_distance", &p.icp.max_distance, "m, correspondence distance threshold", 0.001, 10.0},
      {"icp_max_angle", &p.icp.max_angle, "degrees, correspondence normal angle threshold", 0.0, 180.0},
      {"shift_threshold", &p.shift_threshold, "m, focus point to volume centre distance that shifts the volume", 0.0, 100.0},
      {"focus_distance", &p.focus_distance, "m, the volume follows the point this far along the optical axis", 0.0, 10.0},
      {"min_inlier_ratio", &p.min_inlier_ratio, "ICP inliers / pixels that land on the model (mode joint) or / valid pixels (other modes) below which ICP is rejected", 0.0, 1.0},
      {"icp_degenerate_ratio", &p.icp.degenerate_ratio, "eigenvalue / largest (rotation scaled by depth) below which an ICP direction keeps the prediction (an ICP seeded by the odometry, or mode joint's with its prior: decided once per ICP, gradual from half to twice it; any other ICP at most 1e-6)", 0.0, 1.0},
      {"max_jump_translation", &p.max_jump_translation, "m, ICP vs odometry prediction beyond which ICP is rejected", 0.0, 100.0},
      {"max_jump_rotation", &p.max_jump_rotation, "degrees, same for rotation", 0.0, 180.0},
      {"integrate_on_fallback", &p.integrate_on_fallback, "fuse frames posed by the odometry fallback"},
      {"overlap_fusion", &p.overlap_fusion, "fuse frame k beside the odometry of frame k+1 (same results, faster)"},
      {"joint_icp_sigma", &p.joint_icp_sigma, "m, mode joint: noise of one point-to-plane residual (smaller: geometry outweighs the matches more)", 0.0001, 1.0},
      {"joint_rolling_shutter", &p.joint_rolling_shutter, "s, mode joint: depth readout time; ICP noise grows by it x turn rate x depth", 0.0, 0.1},
      {"motion_sigma_translation", &p.motion_sigma_translation, "m per 1/30 s, mode joint: camera centre vs the constant-velocity prediction (0 = no motion model)", 0.0, 10.0},
      {"motion_sigma_rotation", &p.motion_sigma_rotation, "degrees per 1/30 s, mode joint: rotation vs the constant-velocity prediction (0 = none)", 0.0, 180.0},
      {"joint_photometric_sigma", &p.joint_photometric_sigma, "grey levels, mode joint: noise of one photometric residual (last frame's intensity at the model point; 0 = no photometric term)", 0.0, 255.0},
      {"joint_photometric_rotation_only", &p.joint_photometric_rotation_only, "mode joint: the photometric term informs the rotation only (its translation part marginalised out)"},
      {"joint_photometric_colour_time", &p.joint_photometric_colour_time, "mode joint: the photometric term places each colour image at its capture time (constant velocity)"},
  };
}

}  // namespace

void KinFuParams::loadFromConfigFile(const mrpt::config::CConfigFileBase& cfg, const std::string& section) {
  loadKeys(cfg, section, keys(*this));
  const std::string where = "[" + section + "]";
  if (tsdf.volume_voxels < 8 || tsdf.volume_voxels % 8 != 0)
    throw InputError(where, "volume_voxels must be a positive multiple of 8");
  if (!(tsdf.voxel_size > 0.f) || !(tsdf.truncation > tsdf.voxel_size))
    throw InputError(where, "voxel_size must be positive and truncation larger than it");
  if (tsdf.max_weight < 1 || tsdf.max_weight > 255) throw InputError(where, "max_weight must be in 1..255");
  if (!(preprocess.min_depth < preprocess.max_depth)) throw InputError(where, "min_depth must be below max_depth");
  if (!(tsdf.min_depth < tsdf.max_depth)) throw InputError(where, "integrate_min_depth must be below integrate_max_depth");
}

void KinFuParams::saveToConfigFile(mrpt::config::CConfigFileBase& cfg, const std::string& section) const {
  saveKeys(cfg, section, keys(const_cast<KinFuParams&>(*this)));
}

}  // namespace vofusion
