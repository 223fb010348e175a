#pragma once
// Meshing while tracking (issue 31): the regions the moving volume has left are marched and
// simplified on a thread of their own at the lowest priority, so that meshing at the end finds them
// done (meshByRegion's PremeshedLookup). A region is simplified once its 26 neighbours have left the
// volume too, because its fragments that cross a seam are judged whole ([mesh] min_component_faces),
// with the neighbours' pieces. Nothing is assumed final: the end takes a region made during the run
// only when what it would simplify is the same, bit for bit (regionInputHash), so a region the camera
// came back to or a map fused again after loop closure is simply simplified again there, and the mesh
// is the one meshing at the end alone gives.
//
//   RegionPremesher pre(mesh_params);
//   rec.setShiftObserver([&](const fusion::TsdfVolume& v, const std::optional<Eigen::Vector3i>& o) { pre.volumeShifted(v, o); });
//   ... frames ...
//   rec.finish(); pre.stop();          // before the map is fused again, released or replaced
//   meshByRegion(..., pre.lookup());
#include <array>
#include <atomic>
#include <condition_variable>
#include <deque>
#include <exception>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <thread>

#include "vofusion/fusion/tsdf_volume.h"
#include "vofusion/pipeline/mesh_by_region.h"

namespace vofusion {

class RegionPremesher {
 public:
  explicit RegionPremesher(const MeshCleanParams& params);  // params.region_bricks > 0
  ~RegionPremesher();                                       // stop()
  RegionPremesher(const RegionPremesher&) = delete;
  RegionPremesher& operator=(const RegionPremesher&) = delete;

  // On the fusion thread, after a shift: the regions whose bricks (and the +1 bricks their cells
  // read) were inside the volume's box before and are all outside it now are queued; those it reaches
  // again are forgotten, and so are their neighbours' simplified meshes (judged with their pieces). Without an old origin (a map just loaded: a checkpoint, a saved map) every
  // region of the world model outside the box is queued; a load after a shift or another load throws
  // std::logic_error (what was made and what is being read belong to the map it replaced). The volume's
  // world model is read from this object's thread until stop(): the map must not be replaced before.
  // Without memory for its lists it stops meshing (said once) instead of failing the caller.
  void volumeShifted(const fusion::TsdfVolume& volume, const std::optional<Eigen::Vector3i>& old_origin);
  // Returns once every region queued so far has been summarised and, where ready, simplified (tests:
  // the thread's share of CPU is whatever the frame loop leaves).
  void waitIdle();
  // Ends the thread once the region in hand is done (no other is started); idempotent.
  void stop();

  // After stop() (throws std::logic_error before): the regions made, for a meshByRegion with the
  // same MeshCleanParams as this. Each region is handed over (moved out) once, when its input matches;
  // one that does not match stays until discard().
  PremeshedLookup lookup();
  // After stop(): frees the regions not handed over (the end's meshing is done, or the map is about to
  // be fused again, which no region made during the run matches).
  void discard();
  std::size_t regionsMeshed() const;  // simplified during the run (a region made again counts again)
  std::size_t regionsHeld() const;    // simplified and not yet handed over or discarded
  std::size_t regionsFailed() const;  // attempts whose work failed here (no memory): left to the end
  bool stoppedWithoutMemory() const;  // it had no memory to follow a shift, and stopped

 private:
  using Key = std::array<int, 3>;
  // A region's raw components that touch a seam: what its neighbours need to judge theirs.
  struct SeamPieces {
    std::vector<std::uint64_t> faces;
    std::vector<double> area;
    std::vector<std::pair<std::array<float, 3>, std::uint32_t>> seam_vertices;  // exact position, component
  };

  void run();
  static void warnOfFailure(const std::exception_ptr& failure) noexcept;  // once, on this object's thread
  void followShift(const fusion::TsdfVolume& volume, const std::optional<Eigen::Vector3i>& old_origin);  // volumeShifted's work
  bool halt(bool out_of_memory);  // stops taking regions and wakes the thread; false when already stopping
  void summarise(const Key& region);
  void simplifyIfReady(const Key& region);
  bool finalNow(const Key& region) const;  // under mutex_
  bool reaches(const Key& region, const Eigen::Vector3i& origin) const;
  fusion::RegionMesh march(const Key& region, bool& ok);
  std::vector<std::uint64_t> generationsAround(const Key& region) const;  // under mutex_: its own, then its neighbours'

  // Which of the region's components are fragments, those on seams judged with the neighbours'
  // pieces; false when one cannot be judged here (then the end does it).
  bool judge(const fusion::RegionMesh& r, const RegionComponents& c,
             const std::vector<std::shared_ptr<const SeamPieces>>& neighbours, std::vector<std::uint8_t>& drop) const;

  const MeshCleanParams params_;
  const MeshCleanParams region_params_;
  mutable std::mutex mutex_;
  std::condition_variable wake_, idle_;
  std::deque<Key> queue_;                   // regions to summarise
  std::set<Key> queued_;                    // those in queue_
  bool in_hand_ = false;                    // the thread is working on a region taken from queue_
  bool stopping_ = false;
  bool out_of_memory_ = false;  // why it stopped before stop()
  const fusion::WorldModel* world_ = nullptr;
  float voxel_size_ = 0.f;
  Eigen::Vector3i origin_ = Eigen::Vector3i::Zero();  // the volume's box now
  int box_bricks_ = 0;
  std::map<Key, std::uint64_t> generation_;  // bumped when the volume reaches a region again
  std::map<Key, std::shared_ptr<const SeamPieces>> pieces_;  // final regions summarised (with bricks)
  std::set<Key> empty_;                      // final regions without bricks
  std::map<Key, PremeshedRegion> done_;
  std::size_t meshed_ = 0;
  std::atomic<std::size_t> failed_{0};
  std::vector<fusion::Brick> scratch_;       // the thread's, kept from region to region
  std::thread thread_;
};

}  // namespace vofusion
