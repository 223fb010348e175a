#include "vofusion/pipeline/run_session.h"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <limits>
#include <new>
#include <optional>
#include <sstream>
#include <utility>
#include <vector>

#include <mrpt/config/CConfigFileMemory.h>

#include "vofusion/pipeline/region_premesher.h"
#include "vofusion/core/allocation_limit.h"
#include "vofusion/core/atomic_file.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/file_checksum.h"
#include "vofusion/core/pose_eigen.h"
#include "vofusion/core/progress.h"
#include "vofusion/core/state_archive.h"

#include "mesh_stage.h"

namespace vofusion {

namespace {

// 2: the resumed map's name; 3: the checksum; 4: frame indices; 5: the loop closer's last well-tracked frame;
// 6: the tracker's last measured frame; 7: the bricks and keyframes lost so far (their spill records unreadable)
constexpr char kCheckpointMagic[] = "VOFUSION-CHECKPOINT-8\n";

// A checkpoint ends with its own checksum (core/file_checksum.h): a flipped byte in a pose or a
// descriptor is refused, not resumed from.

// The first line where two checkpoint origins differ, as "'<saved>' where this run has '<now>'".
std::string firstDifference(const std::string& saved, const std::string& now) {
  std::istringstream a(saved), b(now);
  std::string la, lb;
  for (;;) {
    const bool more_a = bool(std::getline(a, la)), more_b = bool(std::getline(b, lb));
    if (!more_a) la = "(nothing)";
    if (!more_b) lb = "(nothing)";
    if (la != lb || (!more_a && !more_b)) return "'" + la + "' where this run has '" + lb + "'";
  }
}

using SavedReport = RunSession::SavedReport;

// What poses.rawlog and the summary take from a frame's report, and back.
SavedReport saved(const FrameReport& r) {
  SavedReport s;
  s.index = r.index;
  s.timestamp = r.timestamp;
  s.tracked = r.tracked;
  s.fell_back = r.fell_back;
  s.predicted = r.predicted;
  s.odometry_success = r.odometry.success;
  s.pose = toEigen(r.pose);
  s.motion = toEigen(r.odometry.motion);
  s.covariance = r.odometry.covariance.asEigen();
  return s;
}

FrameReport reportOf(const SavedReport& s) {
  FrameReport r;
  r.index = s.index;
  r.timestamp = s.timestamp;
  r.tracked = s.tracked;
  r.fell_back = s.fell_back;
  r.predicted = s.predicted;
  r.odometry.success = s.odometry_success;
  r.pose = toMrpt(s.pose);
  r.odometry.motion = toMrpt(s.motion);
  r.odometry.covariance = s.covariance;
  return r;
}

void writeReport(state::Archive& a, const SavedReport& r) {
  a << r.index << r.timestamp << r.tracked << r.fell_back << r.predicted << r.odometry_success;
  state::write(a, r.pose);
  state::write(a, r.motion);
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 6; ++j) a << r.covariance(i, j);
}

SavedReport readReport(state::Archive& a) {
  SavedReport r;
  a >> r.index >> r.timestamp >> r.tracked >> r.fell_back >> r.predicted >> r.odometry_success;
  state::read(a, r.pose);
  state::read(a, r.motion);
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 6; ++j) a >> r.covariance(i, j);
  return r;
}

// The bytes one report takes in a checkpoint (all of fixed size).
std::size_t savedReportBytes() {
  std::ostringstream os;
  auto a = state::archiveOf(os);
  writeReport(a, SavedReport());
  return os.str().size();
}

std::uintmax_t fileBytes(const std::string& path) {
  std::error_code ec;
  const std::uintmax_t n = std::filesystem::file_size(path, ec);
  return ec ? 0 : n;
}

}  // namespace

RunSession::RunSession(const mrpt::config::CConfigFileBase& cfg, TrackingMode mode, const std::string& out_dir,
                       const OutputParams& out_params, const MeshCleanParams& mesh_params)
    : rec_(cfg, mode), recorder_(out_dir, out_params, mesh_params), write_mesh_(out_params.write_mesh) {
  // Not with a face budget: it is shared among the regions by their faces, known once all are meshed.
  if (meshesByRegion(out_params, mesh_params) && mesh_params.target_faces == 0) {
    premesher_ = std::make_unique<RegionPremesher>(mesh_params);
    rec_.setShiftObserver([p = premesher_.get()](const fusion::TsdfVolume& volume,
                                                 const std::optional<Eigen::Vector3i>& old_origin) {
      p->volumeShifted(volume, old_origin);
    });
  }
}

RunSession::~RunSession() {
  if (premesher_) premesher_->stop();  // no more reads of the map rec_ is about to free
}

std::optional<FrameReport> RunSession::process(const Frame& frame) {
  if (replaying()) throw std::logic_error("RunSession::process before the checkpoint's frames were replayed");
  std::optional<FrameReport> done = rec_.push(frame);
  if (done) record(*done);
  return done;
}

std::optional<FrameReport> RunSession::flush() {
  std::optional<FrameReport> done = rec_.flush();
  if (done) record(*done);
  return done;
}

void RunSession::record(const FrameReport& report) {
  recorder_.add(rec_.trackedFrame(), report);
  reports_.push_back(saved(report));
}

void RunSession::saveCheckpoint(const std::string& path, const std::string& origin, double seconds) const {
  AtomicPath out(path);
  std::ofstream os(out.tmp(), std::ios::binary);
  try {
    if (!os) throw InputError(path, "cannot write the checkpoint");
    os.write(kCheckpointMagic, sizeof(kCheckpointMagic) - 1);
    {
      auto a = state::archiveOf(os);
      a << origin << uint64_t(reports_.size()) << seconds;
      for (const SavedReport& r : reports_) writeReport(a, r);
    }
    rec_.saveState(os);
    auto a = state::archiveOf(os);
    state::tag(a, "end");
    os.close();
    if (!os) throw InputError(path, "cannot write the checkpoint (disk full?)");
    if (std::string why; !appendFileChecksum(out.tmp(), why)) throw InputError(path, "cannot write the checkpoint (" + why + ")");
  } catch (const InputError&) {
    throw;
  } catch (const state::NotStorable& e) {
    throw InputError(path, std::string("cannot write the checkpoint: ") + e.what());  // the checkpoints', not the run's
  } catch (const std::exception& e) {
    // A write that failed under a part of the state (the map's "write failed (disk full?)", MRPT's
    // archive) or memory that ran out for the copies it is written from is said of the checkpoint,
    // the file the user asked for (memory that ran out on the fusion or loop thread, which the
    // checkpoint waits for, is said so too, and the run meets it again at its next frame); anything
    // else (the loop closer's thread failing) is not the checkpoint's and goes on as it is.
    if (os.good() && !dynamic_cast<const std::bad_alloc*>(&e)) throw;
    throw InputError(path, "cannot write the checkpoint: " + (os.good() ? std::string("out of memory") : oneLineMessage(e)));
  }
  out.commit();  // a power cut leaves the earlier checkpoint or this one, never an empty file
}

namespace {
constexpr char kCheckpointKind[] = "VOFUSION-CHECKPOINT-";  // of any version

// Whether the file starts with `magic` (its first sizeof - 1 bytes).
template <std::size_t N>
bool startsWith(const std::string& path, const char (&magic)[N]) {
  std::ifstream is(path, std::ios::binary);
  char head[N - 1];
  return is.read(head, sizeof(head)) && std::memcmp(head, magic, sizeof(head)) == 0;
}
}  // namespace

bool RunSession::isCheckpoint(const std::string& path) { return startsWith(path, kCheckpointKind); }

std::optional<RunSession::Checkpoint> RunSession::peek(const std::string& path) {
  if (!startsWith(path, kCheckpointMagic)) return std::nullopt;
  std::ifstream is(path, std::ios::binary);
  is.seekg(sizeof(kCheckpointMagic) - 1);
  try {
    auto a = state::archiveOf(is);
    std::string origin;
    uint64_t frames = 0;
    Checkpoint c;
    a >> origin >> frames >> c.seconds;
    c.frames = frames;
    return c;
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

RunSession::Checkpoint RunSession::resume(const std::string& path, const std::string& origin) {
  if (!isCheckpoint(path)) throw InputError(path, "not a vofusion checkpoint (written by --checkpoint-every)");
  if (!startsWith(path, kCheckpointMagic))
    throw InputError(path, "a checkpoint of an earlier vofusion, which this one cannot read: delete it to start over");
  if (std::string why; !fileChecksumHolds(path, why)) throw InputError(path, "truncated or corrupt checkpoint: " + why);
  std::ifstream is(path, std::ios::binary);
  is.seekg(sizeof(kCheckpointMagic) - 1);
  Checkpoint c;
  try {
    // MRPT sizes (and zero-fills) strings and vectors by the length fields it reads: one corrupt field
    // asked for 4 GiB before the read failed. No request of a real checkpoint's comes near 1 GiB (a
    // run's peak is ~700 MiB in all), but for the reports' vector, reserved outside the limit.
    constexpr std::size_t kMaxRequest = std::size_t(1) << 30, kNoTotal = std::numeric_limits<std::size_t>::max();
    uint64_t frames = 0;
    {
      const ScopedAllocationLimit limit(kMaxRequest, kNoTotal);
      auto a = state::archiveOf(is);
      std::string saved_origin;
      a >> saved_origin;
      if (saved_origin != origin)
        throw InputError(path, "made by another run (" + firstDifference(saved_origin, origin) +
                                   "): resume with the same input, --config, --mode and options, or delete it to start over");
      a >> frames >> c.seconds;
    }
    c.frames = frames;
    // Reserved at once, as many as the file can hold whatever its count says: grown by doubling, the
    // vector asked for room for twice the reports past 2^20 frames (a 10-hour live session), over 1 GiB.
    reports_.clear();
    reports_.reserve(std::min<uint64_t>(frames, fileBytes(path) / savedReportBytes()));
    const ScopedAllocationLimit limit(kMaxRequest, kNoTotal);
    {
      auto a = state::archiveOf(is);
      for (uint64_t i = 0; i < frames; ++i) reports_.push_back(readReport(a));
    }
    rec_.loadState(is);
    auto a = state::archiveOf(is);
    state::expectTag(a, "end");
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    throw InputError(path, "truncated or corrupt checkpoint: " + oneLineMessage(e));
  }
  resumed_frames_ = c.frames;
  replayed_ = 0;
  resumed_from_ = path;
  return c;
}

bool RunSession::replay(const Frame& frame) {
  if (!replaying()) throw std::logic_error("RunSession::replay past the checkpoint's frames");
  const SavedReport& r = reports_[replayed_];
  // By index, as the run numbered its input (a live run: the recording's frames in order), not by time:
  // a clock stepped back between dropped frames put the frames after the step behind a dropped one.
  if (frame.index < r.index) return false;  // recorded, not processed (live drops)
  if (frame.index > r.index || std::abs(frame.timestamp - r.timestamp) > 1e-6)
    throw InputError(resumed_from_, "the input has no frame " + std::to_string(r.index) + " at " + std::to_string(r.timestamp) +
                                        " s (frame " + std::to_string(replayed_) + " the checkpoint processed): resume with the same input");
  recorder_.add(frame, reportOf(r));
  ++replayed_;
  return true;
}

std::string RunSession::checkpointOrigin(const std::string& input, TrackingMode mode, const mrpt::config::CConfigFileBase& cfg) {
  std::error_code ec;
  const bool file = std::filesystem::exists(input, ec);
  std::string o = "input " + (file ? std::filesystem::weakly_canonical(input, ec).string() : input) + "\n";
  o += "mode " + toString(mode) + "\n";
  mrpt::config::CConfigFileMemory canonical;
  OdometryParams odometry;
  KinFuParams kinfu;
  loop::LoopParams loop;
  odometry.loadFromConfigFile(cfg, "odometry");
  kinfu.loadFromConfigFile(cfg, "kinfu");
  loop.loadFromConfigFile(cfg, "loop");
  odometry.saveToConfigFile(canonical, "odometry");
  kinfu.saveToConfigFile(canonical, "kinfu");
  loop.saveToConfigFile(canonical, "loop");
  std::istringstream text(canonical.getContent());
  for (std::string line; std::getline(text, line);)
    if (line.find("work_dir") == std::string::npos) o += line + "\n";
  return o;
}

// Loops moved the poses: the map, fused at the tracked ones, is fused again at the corrected ones,
// reading the recording a second time rather than keeping every frame in memory.
namespace {

// The recording read again for the re-fusion; null, said and noted in info, when it cannot be opened
// (moved, unmounted since): then the map fused at the tracked poses is meshed, and the trajectories
// are the loop-closed ones all the same.
std::unique_ptr<FrameSource> openAgain(const RunSession::Reopen& reopen, RunInfo& info) {
  try {
    return reopen();
  } catch (const std::exception& e) {
    const std::string why = oneLineMessage(e);
    printWarning(why + "; the map is not fused again at the loop-closed poses (its mesh is the tracked poses')");
    info.extra["loop_closure_reintegration"] = {{"error", why}};
    return nullptr;
  }
}

}  // namespace

void RunSession::refuse(RunInfo& info, const Reopen& reopen) {
  if (!rec_.mapNeedsReintegration()) return;
  // No recording to read again: the mesh keeps the tracked poses while the trajectories are the
  // loop-closed ones; the summary says why (the app says it to the user).
  if (!reopen) {
    info.extra["loop_closure_reintegration"] = {{"skipped", info.no_rereading}};
    return;
  }
  if (const std::optional<std::string> blocked = rec_.reintegrationBlocked()) {
    printWarning(*blocked + "; the map is not fused again at the loop-closed poses (its mesh is the tracked poses')");
    info.extra["loop_closure_reintegration"] = {{"skipped", *blocked}};
    return;
  }
  const std::unique_ptr<FrameSource> again = openAgain(reopen, info);
  if (!again) return;
  if (premesher_) premesher_->discard();  // made from the map fused at the tracked poses: none is expected to match
  Progress progress(info.app + " [re-fusing at the loop-closed poses]", rec_.framesProcessed());
  std::size_t read = 0;
  std::string failure;  // the recording's, read midway: only the reader's (the map's own go up as they are)
  const auto next = [&](Frame& f) {
    try {
      return again->next(f);
    } catch (const std::exception& e) {
      failure = oneLineMessage(e);
      return false;
    }
  };
  nlohmann::json& about = info.extra["loop_closure_reintegration"];
  about["from"] = std::filesystem::path(again->name()).filename().string();
  const std::size_t fused = rec_.reintegrate(next, [&](std::size_t n) { progress.update(read = n); });
  about["frames_fused"] = fused;
  // Frames the reader no longer gives (damaged or removed since, skipped without --strict; a recording
  // cut short since) are left out of the map without an error: counted, and said.
  const std::size_t fused_while_tracking = rec_.framesFused();
  const std::size_t missing = fused_while_tracking - std::min(fused, fused_while_tracking);
  if (missing > 0) about["frames_missing"] = missing;
  if (!failure.empty()) {
    // An I/O error, a frame damaged since under --strict: the map holds the frames re-fused before it,
    // which is what is left (the tracked map is gone by then).
    about["error"] = failure;
    printWarning(failure + "; re-fusing stopped after " + std::to_string(read) + " of " +
                 std::to_string(rec_.framesProcessed()) + " frames: the mesh holds those");
  } else if (missing > 0) {
    printWarning(again->name() + ": " + std::to_string(missing) + " of the " + std::to_string(fused_while_tracking) +
                 " frames fused while tracking were not there when it was read again (damaged, removed or cut "
                 "short since): the mesh lacks them");
  }
  progress.finish();
  about["seconds"] = progress.elapsedSeconds();
}

nlohmann::json RunSession::finish(RunInfo info, const Reopen& reopen, const std::optional<std::string>& save_volume) {
  if (replaying()) throw std::logic_error("RunSession::finish before the checkpoint's frames were replayed");
  flush();
  rec_.finish();
  if (premesher_) premesher_->stop();  // before the map is fused again or released
  if (write_mesh_ || save_volume) refuse(info, reopen);  // the map is not used otherwise
  // A map that cannot be written costs the map, not the run's other outputs (mapFailure()). It is
  // written before them (the meshing releases the map) but put in place after them: a run whose
  // outputs failed replaced the earlier map, the map it resumed from too.
  std::optional<AtomicPath> map;
  if (save_volume) {
    try {
      map.emplace(*save_volume);
      saveMapTo(*map);
    } catch (const std::exception& e) {
      map.reset();
      map_failure_ = std::current_exception();
      info.extra["save_volume_error"] = oneLineMessage(e);
    }
  }
  nlohmann::json summary = recorder_.finish(rec_, info, stderr, premesher_.get());
  if (map) {
    try {
      map->commit();
    } catch (const std::exception&) {
      map_failure_ = std::current_exception();  // the rename, after summary.json: said on the way out
    }
  }
  return summary;
}

void RunSession::saveMapTo(AtomicPath& map) const {
  try {
    rec_.saveVolume(map.tmp());
    map.prepare();  // on the disk: what is left to the end is the rename
  } catch (const InputError& e) {
    if (e.file() != map.tmp()) throw;
    throw InputError(map.path(), e.problem());  // the file as the user named it
  }
}

}  // namespace vofusion
