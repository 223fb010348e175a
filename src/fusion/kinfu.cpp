#include "vofusion/fusion/kinfu.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>

#include <Eigen/Dense>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/file_checksum.h"
#include "vofusion/core/parallel.h"
#include "vofusion/core/pose_eigen.h"
#include "vofusion/core/state_archive.h"

namespace vofusion {

using namespace fusion;

struct KinFu::Impl {
  KinFuParams params;
  Prediction predict;
  std::unique_ptr<TsdfVolume> volume;
  ModelPrediction model;     // ray cast after the last fusion, for the next frame's tracking
  bool have_model = false;   // a frame was fused: the next one is tracked against the map
  bool model_stale = false;  // resumed from a file: the model is ray cast (unhinted) before tracking
  // Resumed from a checkpoint: the world model's bricks lost before it (held there as never observed),
  // and why its spill file could not be written then (the disk that filled before the checkpoint).
  std::size_t bricks_lost_before = 0;
  std::string spill_error_before;

  Eigen::Vector3f focusPoint(const Eigen::Isometry3d& T) const {
    return (T.translation() + T.linear().col(2) * params.focus_distance).cast<float>();
  }
  ShiftObserver on_shift;
  bool shiftIfNeeded(const Eigen::Isometry3d& pose) {
    const Eigen::Vector3i before = volume->originBrick();
    const bool shifted = volume->shiftIfNeeded(focusPoint(pose), params.shift_threshold);
    if (shifted && on_shift) on_shift(*volume, before);
    return shifted;
  }
  // Moves the volume with the camera and fuses the depth at `pose`; true when the volume shifted.
  bool integrate(const cv::Mat& depth, const cv::Mat& rgb, const CameraIntrinsics& cam, const Eigen::Isometry3d& pose,
                 StageTimes& times) {
    auto t0 = std::chrono::steady_clock::now();
    const bool shifted = shiftIfNeeded(pose);
    times.add("shift", secondsSince(t0));
    t0 = std::chrono::steady_clock::now();
    volume->integrate(depth, rgb, cam, pose.cast<float>());
    times.add("integrate", secondsSince(t0));
    return shifted;
  }

  // Depth the last ray cast found per pixel: the hint where the new frame has no reading. The camera
  // moved a little since, so it is only a starting point (the ray cast checks and falls back).
  cv::Mat model_depth;

  void raycastModel(const Eigen::Isometry3d& from, const cv::Mat& frame_depth, const CameraIntrinsics& cam,
                    StageTimes& times, bool hinted = true) {
    const auto t0 = std::chrono::steady_clock::now();
    // Only rays with a hint are cast: ICP pairs the next frame's readings with model pixels next to
    // where this frame had readings (or the last prediction had a surface). Rays without one marched
    // from min_depth through partly observed bricks, three quarters of all ray-cast samples, mostly
    // to find nothing. Hints outside the fused depth range have no surface to find.
    cv::Mat hint(cam.height, cam.width, CV_32F);
    const bool have_frame = frame_depth.size() == hint.size(), have_last = model_depth.size() == hint.size();
    const float lo = params.tsdf.min_depth, hi = params.tsdf.max_depth;
    for (int y = 0; y < hint.rows; ++y) {
      const float* d = have_frame ? frame_depth.ptr<float>(y) : nullptr;
      const float* m = have_last ? model_depth.ptr<float>(y) : nullptr;
      float* h = hint.ptr<float>(y);
      for (int x = 0; x < hint.cols; ++x) {
        const float z = d ? d[x] : 0.f;
        h[x] = z >= lo && z <= hi ? z : (m ? m[x] : 0.f);
      }
    }
    RaycastMaps maps = hinted ? volume->raycast(from.cast<float>(), cam, &hint, false, true)
                              : volume->raycast(from.cast<float>(), cam, nullptr, false, false);
    model_depth = maps.depth;
    const int levels = std::max(1, params.preprocess.levels);
    model.vertices.assign(levels, cv::Mat());
    model.normals.assign(levels, cv::Mat());
    model.vertices[0] = maps.vertices;
    model.normals[0] = maps.normals;
    for (int l = 1; l < levels; ++l)
      downsampleMaps(model.vertices[l - 1], model.normals[l - 1], model.vertices[l], model.normals[l]);
    model.pose = from;
    have_model = true;
    times.add("raycast", secondsSince(t0));
  }
};

KinFu::KinFu(const KinFuParams& params, const Eigen::Isometry3d& initial_pose, Prediction predict)
    : impl_(std::make_unique<Impl>()) {
  impl_->params = params;
  impl_->predict = predict;
  impl_->volume = std::make_unique<TsdfVolume>(params.tsdf, impl_->focusPoint(initial_pose));
}

KinFu::~KinFu() = default;

bool KinFu::hasModel() const { return impl_->have_model; }
std::pair<float, float> KinFu::fusedDepthRange() const { return {impl_->params.tsdf.min_depth, impl_->params.tsdf.max_depth}; }

void KinFu::predictAgain(const Eigen::Isometry3d& pose) {
  if (!impl_->have_model) return;
  impl_->shiftIfNeeded(pose);
  impl_->model_stale = true;
  impl_->model_depth.release();
  impl_->model.intensity.clear();
}
const ModelPrediction& KinFu::model() const { return impl_->model; }

void KinFu::predictIfStale(const Eigen::Isometry3d& pose, const CameraIntrinsics& track_cam, StageTimes& times) {
  if (!impl_->model_stale) return;
  impl_->raycastModel(pose, cv::Mat(), track_cam, times, false);
  impl_->model_stale = false;
}

bool KinFu::fuse(const FrameToFuse& f, StageTimes& times) {
  Impl& s = *impl_;
  s.have_model = true;  // the map exists from the first fused (or tracked) frame on
  bool shifted = false;
  if (f.integrate) {
    shifted = s.integrate(f.depth, f.rgb, f.cam, f.pose, times);
    if (s.predict.surfaces) s.raycastModel(f.pose, f.hint, f.track_cam, times);
  } else if (s.predict.surfaces) {
    // Not fused (fallback or predicted pose): re-predict the model from the new pose so ICP keeps up,
    // looking where this frame has readings (hinted by the last prediction alone, the predicted surface
    // lost a band each frame a pan went unfused: KinFu.PredictionFollowsAPanWhileFramesAreNotFused).
    s.raycastModel(f.pose, f.hint, f.track_cam, times);
  }
  // The ray cast was from this frame's pose: its intensity is the photometric term's reference.
  if (s.predict.intensity) {
    s.model.intensity.clear();
    const std::size_t n = std::min({f.intensity.size(), f.level_cams.size(), s.model.vertices.size()});
    for (std::size_t l = 0; l < n; ++l)
      s.model.intensity.push_back(resampleAtModel(f.intensity[l], s.model.vertices[l], f.colour_pose, f.level_cams[l]));
  }
  return shifted;
}

bool KinFu::integrateAt(const Frame& frame, const Eigen::Isometry3d& cam_to_world, StageTimes& times) {
  CameraIntrinsics cam = frame.camera;
  cam.width = frame.depth.cols;
  cam.height = frame.depth.rows;
  const bool shifted = impl_->integrate(frame.depth, frame.rgb, cam, cam_to_world, times);
  impl_->have_model = true;
  return shifted;
}

TriangleMesh KinFu::extractMesh() const { return impl_->volume->extractMesh(); }

namespace {
// 2: the file ends with its checksum (core/file_checksum.h). A flipped bit in a brick's coordinates or
// the camera pose passed every range check: the brick went elsewhere, the camera somewhere. Maps of
// layout 1 are still read, without it.
constexpr char kMapMagic[16] = {'V', 'O', 'F', 'U', 'S', 'I', 'O', 'N', '-', 'M', 'A', 'P', ' ', '2', '\n', '\0'};
constexpr char kMapMagicV1[16] = {'V', 'O', 'F', 'U', 'S', 'I', 'O', 'N', '-', 'M', 'A', 'P', ' ', '1', '\n', '\0'};

// A camera pose: finite, a rotation (orthonormal, det +1) and the last row 0 0 0 1.
bool isRigid(const Eigen::Matrix4d& T) {
  if (!T.allFinite() || !T.row(3).isApprox(Eigen::RowVector4d(0, 0, 0, 1), 1e-12)) return false;
  const Eigen::Matrix3d R = T.topLeftCorner<3, 3>();
  return (R.transpose() * R - Eigen::Matrix3d::Identity()).norm() < 1e-6 && std::abs(R.determinant() - 1.0) < 1e-6;
}
}  // namespace

void KinFu::save(const std::string& path, const Eigen::Isometry3d& pose) const {
  AtomicPath out(path);
  {
    std::ofstream os(out.tmp(), std::ios::binary);
    if (!os) throw InputError(path, "cannot write the map");
    os.write(kMapMagic, sizeof(kMapMagic));
    const Eigen::Matrix4d T = pose.matrix();
    os.write(reinterpret_cast<const char*>(T.data()), sizeof(double) * 16);
    try {
      impl_->volume->save(os);
    } catch (const std::exception& e) {
      throw InputError(path, std::string("cannot write the map: ") + e.what());
    }
    os.close();
    if (!os) throw InputError(path, "cannot write the map (disk full?)");
  }
  if (std::string why; !appendFileChecksum(out.tmp(), why)) throw InputError(path, "cannot write the map (" + why + ")");
  out.commit();
}

std::string KinFu::savedMapProblem(const std::string& path) {
  std::ifstream is(path, std::ios::binary);
  if (!is) return "cannot open the saved map";
  char magic[sizeof(kMapMagic)];
  if (!is.read(magic, sizeof(magic)) ||
      (std::memcmp(magic, kMapMagic, sizeof(kMapMagic)) != 0 && std::memcmp(magic, kMapMagicV1, sizeof(kMapMagicV1)) != 0))
    return "not a vofusion map (written by --save-volume)";
  if (std::string why; std::memcmp(magic, kMapMagic, sizeof(kMapMagic)) == 0 && !fileChecksumHolds(path, why))
    return "truncated or corrupt map: " + why;
  return {};
}

Eigen::Isometry3d KinFu::resume(const std::string& path) {
  Impl& s = *impl_;
  if (const std::string why = savedMapProblem(path); !why.empty()) throw InputError(path, why);
  std::ifstream is(path, std::ios::binary);
  if (!is || !is.seekg(std::streamoff(sizeof(kMapMagic)))) throw InputError(path, "cannot open the saved map");
  Eigen::Matrix4d T;
  if (!is.read(reinterpret_cast<char*>(T.data()), sizeof(double) * 16) || !isRigid(T))
    throw InputError(path, "truncated or corrupt map (camera pose)");
  try {
    s.volume->load(is);
  } catch (const std::exception& e) {
    throw InputError(path, std::string("bad saved map: ") + e.what());
  }
  s.have_model = true;
  s.model_stale = true;
  s.model_depth.release();
  s.model.intensity.clear();
  if (s.on_shift) s.on_shift(*s.volume, std::nullopt);
  Eigen::Isometry3d pose;
  pose.matrix() = T;
  return pose;
}

void KinFu::saveState(std::ostream& os) const {
  const Impl& s = *impl_;
  {
    auto a = state::archiveOf(os);
    state::tag(a, "map");
    a << s.have_model << s.model_stale;
    state::write(a, s.model.vertices);
    state::write(a, s.model.normals);
    state::write(a, s.model.pose);
    a << uint64_t(s.model.intensity.size());
    for (const IntensityLevel& l : s.model.intensity) {
      state::write(a, l.grey);
      state::write(a, l.dx);
      state::write(a, l.dy);
    }
    state::write(a, s.model_depth);
  }
  s.volume->save(os);  // finds the bricks whose spill records cannot be read any more
  auto a = state::archiveOf(os);
  state::tag(a, "map losses");
  const WorldModelStats world = stats().world;
  a << uint64_t(world.lost) << world.spill_error;
}

void KinFu::loadState(std::istream& is) {
  Impl& s = *impl_;
  {
    auto a = state::archiveOf(is);
    state::expectTag(a, "map");
    a >> s.have_model >> s.model_stale;
    state::read(a, s.model.vertices);
    state::read(a, s.model.normals);
    state::read(a, s.model.pose);
    uint64_t n = 0;
    a >> n;
    if (n > 64) throw std::runtime_error("checkpoint: bad intensity levels");
    s.model.intensity.resize(n);
    for (IntensityLevel& l : s.model.intensity) {
      state::read(a, l.grey);
      state::read(a, l.dx);
      state::read(a, l.dy);
    }
    state::read(a, s.model_depth);
  }
  s.volume->load(is);
  auto a = state::archiveOf(is);
  state::expectTag(a, "map losses");
  uint64_t lost = 0;
  a >> lost >> s.spill_error_before;
  s.bricks_lost_before = lost;
  if (s.on_shift) s.on_shift(*s.volume, std::nullopt);
}

cv::Mat KinFu::renderView(const mrpt::poses::CPose3D& cam_to_world, const CameraIntrinsics& cam, bool coloured) const {
  const Eigen::Isometry3f T = toEigen(cam_to_world).cast<float>();
  const RaycastMaps maps = impl_->volume->raycast(T, cam, nullptr, coloured);
  cv::Mat img(cam.height, cam.width, CV_8UC3, cv::Scalar(0, 0, 0));
  const Eigen::Vector3f c = T.translation();
  parallelFor(0, cam.height, [&](int y) {
    for (int x = 0; x < cam.width; ++x) {
      const cv::Vec3f& v = maps.vertices.ptr<cv::Vec3f>(y)[x];
      const cv::Vec3f& n = maps.normals.ptr<cv::Vec3f>(y)[x];
      if (std::isnan(v[0]) || std::isnan(n[0])) continue;
      const Eigen::Vector3f to_cam = (c - Eigen::Vector3f(v[0], v[1], v[2])).normalized();
      const float lambert = std::max(0.f, to_cam.dot(Eigen::Vector3f(n[0], n[1], n[2])));
      const float shade = 0.2f + 0.8f * lambert;
      if (coloured) {
        const cv::Vec3b& col = maps.colours.ptr<cv::Vec3b>(y)[x];
        img.ptr<cv::Vec3b>(y)[x] = cv::Vec3b(cv::saturate_cast<uchar>(col[0] * shade), cv::saturate_cast<uchar>(col[1] * shade),
                                             cv::saturate_cast<uchar>(col[2] * shade));
      } else {
        const uchar g = cv::saturate_cast<uchar>(255.f * shade);
        img.ptr<cv::Vec3b>(y)[x] = cv::Vec3b(g, g, g);
      }
    }
  });
  return img;
}

MapStats KinFu::stats() const {
  MapStats st;
  st.bricks_in_volume = impl_->volume->bricksInVolume();
  st.bricks_in_world_model = impl_->volume->bricksInWorldModel();
  st.memory_bytes = impl_->volume->memoryBytes();
  st.world = impl_->volume->worldModel().stats();
  st.world.lost += impl_->bricks_lost_before;
  if (st.world.spill_error.empty()) st.world.spill_error = impl_->spill_error_before;
  return st;
}

const TsdfVolume& KinFu::volume() const { return *impl_->volume; }
void KinFu::setShiftObserver(ShiftObserver observer) { impl_->on_shift = std::move(observer); }
const KinFuParams& KinFu::params() const { return impl_->params; }

}  // namespace vofusion
