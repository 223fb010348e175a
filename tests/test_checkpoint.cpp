// Checkpoints (vofusion --checkpoint-every, --resume <checkpoint>): a run saved between any two frames
// and resumed in a fresh process ends exactly as if it had never stopped: every pose bit for bit,
// the same mesh, the same loop closer; a damaged or foreign checkpoint is refused in one line.
#include <sys/resource.h>
#include <atomic>
#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <thread>

#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <mrpt/config/CConfigFileMemory.h>
#include <nlohmann/json.hpp>

#include "support.h"
#include "vofusion/core/state_archive.h"
#include "vofusion/core/allocation_limit.h"
#include "vofusion/core/deflate.h"
#include "vofusion/core/errors.h"
#include "vofusion/loop/loop_closer.h"
#include "vofusion/pipeline/reconstruction.h"
#include "vofusion/pipeline/run_session.h"
#include "vofusion/pipeline/run_outputs.h"
#include "vofusion/sim/synthetic_sequence.h"

using namespace vofusion;
namespace fs = std::filesystem;

namespace {

// quickRoomConfig with loop keyframes every 5 cm, so that the loop closer's state is more than empty.
mrpt::config::CConfigFileMemory roomConfig() {
  mrpt::config::CConfigFileMemory cfg = test::quickRoomConfig();
  cfg.write("loop", "keyframe_translation", 0.05);
  return cfg;
}

struct Ending {
  Trajectory tracked, closed;
  std::size_t faces = 0, fallbacks = 0, keyframes = 0;
};

// Frames [from, to) through rec, each with its own images; finish() and what the run ends with when to is
// the end.
void feed(Reconstruction& rec, const std::vector<Frame>& frames, std::size_t from, std::size_t to) {
  for (std::size_t i = from; i < to; ++i) rec.process(test::deepCopy(frames[i]));
}

Ending finish(Reconstruction& rec) {
  rec.finish();
  Ending e;
  e.tracked = rec.trackedTrajectory();
  e.closed = rec.trajectory();
  e.faces = rec.extractMesh().faces.size();
  e.fallbacks = rec.fallbacks();
  e.keyframes = rec.loopCloser() ? rec.loopCloser()->keyframes().size() : 0;
  return e;
}

void expectIdentical(const Trajectory& a, const Trajectory& b, const std::string& what) {
  ASSERT_EQ(a.size(), b.size()) << what;
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].timestamp, b[i].timestamp) << what << " frame " << i;
    EXPECT_EQ(a[i].pose.asVectorVal(), b[i].pose.asVectorVal()) << what << " frame " << i;
  }
}

}  // namespace

// The fast hand-held shake: fallbacks, colour-time evidence and keyframes all carry state across.
TEST(Checkpoint, AReconstructionResumedAtAnyFrameEndsBitForBitAsAnUninterruptedOne) {
  const std::vector<Frame> frames = test::renderFrames(sim::SyntheticSequence(test::quickSim("room", 30, "shake")));
  const auto cfg = roomConfig();
  Reconstruction whole(cfg, TrackingMode::Joint);
  feed(whole, frames, 0, frames.size());
  const Ending clean = finish(whole);
  ASSERT_GT(clean.faces, 1000u);
  ASSERT_GT(clean.keyframes, 2u) << "the loop closer should hold keyframes to carry over";
  for (const std::size_t at : {std::size_t(1), std::size_t(13), frames.size() - 1}) {
    std::stringstream saved;
    {
      Reconstruction first(cfg, TrackingMode::Joint);
      feed(first, frames, 0, at);
      first.saveState(saved);
    }  // the first half's process-wide state (its loop thread, its spill files) is gone
    Reconstruction second(cfg, TrackingMode::Joint);
    second.loadState(saved);
    feed(second, frames, at, frames.size());
    const Ending resumed = finish(second);
    const std::string what = "resumed at frame " + std::to_string(at);
    expectIdentical(clean.tracked, resumed.tracked, what + ", tracked");
    expectIdentical(clean.closed, resumed.closed, what + ", loop-closed");
    EXPECT_EQ(clean.faces, resumed.faces) << what;
    EXPECT_EQ(clean.fallbacks, resumed.fallbacks) << what;
    EXPECT_EQ(clean.keyframes, resumed.keyframes) << what;
  }
}

// The same one frame late, as the apps run (Reconstruction::push): the checkpoint is taken with a frame
// held, its odometry run, its refit and tracking not. The state saved is the one before that frame, and
// the resumed run is given it again. Capture mode from the first frame: every frame is refitted.
TEST(Checkpoint, AReconstructionResumedWithAFrameHeldEndsBitForBitAsAnUninterruptedOne) {
  const std::vector<Frame> frames = test::renderFrames(sim::SyntheticSequence(test::quickSim("room", 30, "shake")));
  auto cfg = roomConfig();
  cfg.write("odometry", "colour_time_velocity", "capture");
  const auto pushed = [&](Reconstruction& rec, std::size_t from, std::size_t to) {
    for (std::size_t i = from; i < to; ++i) rec.push(test::deepCopy(frames[i]));
  };
  Reconstruction whole(cfg, TrackingMode::Joint);
  pushed(whole, 0, frames.size());
  whole.flush();
  const Ending clean = finish(whole);
  for (const std::size_t at : {std::size_t(1), std::size_t(13), frames.size() - 1}) {
    std::stringstream saved;
    {
      Reconstruction first(cfg, TrackingMode::Joint);
      pushed(first, 0, at);
      ASSERT_EQ(first.framesProcessed(), at - 1);
      first.saveState(saved);
    }
    Reconstruction second(cfg, TrackingMode::Joint);
    second.loadState(saved);
    ASSERT_EQ(second.framesProcessed(), at - 1) << "the held frame is not in the checkpoint";
    pushed(second, at - 1, frames.size());
    second.flush();
    const Ending resumed = finish(second);
    const std::string what = "resumed at frame " + std::to_string(at - 1);
    expectIdentical(clean.tracked, resumed.tracked, what + ", tracked");
    expectIdentical(clean.closed, resumed.closed, what + ", loop-closed");
    EXPECT_EQ(clean.faces, resumed.faces) << what;
  }
}

// A live recording whose clock stepped back by a second while the queue dropped two frames: the run's
// frames are found again by their index (their place in the recording), not by their time. By time,
// resuming threw "the input has no frame at ..." and re-fusing passed over every frame after the step.
TEST(Checkpoint, AClockSteppedBackBetweenDroppedFramesLosesNoFrame) {
  const std::size_t n = 24, dropped_from = 10, resume_at = 16;
  const sim::SyntheticSequence seq(test::quickSim("room", n));
  std::vector<Frame> recording;
  for (std::size_t i = 0; i < n; ++i) {
    Frame f = seq.render(i);
    f.timestamp = 100.0 + double(i) / 30 - (i >= 12 ? 1.0 : 0.0);  // the clock steps back before frame 12
    recording.push_back(f);
  }
  const auto processed = [&](std::size_t i) { return i != dropped_from && i != dropped_from + 1; };
  const auto cfg = test::quickRoomConfig();
  {
    Reconstruction rec(cfg, TrackingMode::Joint);
    for (std::size_t i = 0; i < n; ++i)
      if (processed(i)) rec.process(test::deepCopy(recording[i]));
    std::size_t read = 0;
    const std::size_t fused = rec.reintegrate([&](Frame& f) { return read < n ? (f = test::deepCopy(recording[read++]), true) : false; });
    ASSERT_EQ(rec.lostFrames() + rec.predictedFrames() + rec.fallbacks(), 0u);  // every processed frame was fused
    EXPECT_EQ(fused, n - 2) << "frames fused again of the " << n - 2 << " processed";
  }
  const std::string dir = test::tempDir("checkpoint_clock_back");
  {
    RunSession run(cfg, TrackingMode::Joint, dir + "/out", OutputParams(), MeshCleanParams());
    for (std::size_t i = 0; i < resume_at; ++i)
      if (processed(i)) run.process(test::deepCopy(recording[i]));
    run.flush();  // every frame before resume_at tracked, none held back
    run.saveCheckpoint(dir + "/checkpoint", "input room\n", 1.0);
  }
  RunSession again(cfg, TrackingMode::Joint, dir + "/again", OutputParams(), MeshCleanParams());
  again.resume(dir + "/checkpoint", "input room\n");
  std::size_t replayed = 0, i = 0;
  for (; again.replaying(); ++i) replayed += again.replay(test::deepCopy(recording[i]));
  EXPECT_EQ(i, resume_at);
  EXPECT_EQ(replayed, resume_at - 2);
  // The frames after the checkpoint go on from its last index, as within one run.
  EXPECT_THROW(again.process(test::deepCopy(recording[resume_at - 1])), std::invalid_argument);
  again.process(test::deepCopy(recording[resume_at]));
}

// Memory that runs out while a checkpoint is written costs that checkpoint: the error names it, the
// earlier one stays whole and the run goes on (std::bad_alloc went past the app's catch, and ended it).
TEST(Checkpoint, MemoryRunningOutCostsTheCheckpointOnly) {
  const sim::SyntheticSequence seq(test::quickSim("room", 6));
  const std::string dir = test::tempDir("checkpoint_no_memory");
  const std::string path = dir + "/checkpoint";
  RunSession run(roomConfig(), TrackingMode::Joint, dir + "/out", OutputParams(), MeshCleanParams());
  for (std::size_t i = 0; i < 4; ++i) run.process(seq.render(i));
  run.saveCheckpoint(path, "input room\n", 1.5);
  run.process(seq.render(4));
  try {
    const ScopedAllocationLimit limit(std::size_t(64) << 10, std::size_t(256) << 10);
    run.saveCheckpoint(path, "input room\n", 2.0);
    ADD_FAILURE() << "a checkpoint was written within 256 KiB";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), path);
    EXPECT_EQ(e.problem(), "cannot write the checkpoint: out of memory");
  }
  const auto peek = RunSession::peek(path);
  ASSERT_TRUE(peek.has_value());
  EXPECT_EQ(peek->frames, 3u);  // frames tracked: the one held back is not in a checkpoint
  run.process(seq.render(5));
  run.saveCheckpoint(path, "input room\n", 2.5);
  EXPECT_EQ(RunSession::peek(path)->frames, 5u);
}

namespace {
// A volume that shifts often and spills every brick and keyframe it can into `work_dir`.
mrpt::config::CConfigFileMemory spillingConfig(const std::string& work_dir) {
  auto cfg = roomConfig();
  cfg.write("kinfu", "volume_voxels", 128);
  cfg.write("kinfu", "shift_threshold", 0.05);
  cfg.write("kinfu", "world_cache_mib", 0);
  cfg.write("kinfu", "work_dir", work_dir);
  cfg.write("loop", "keyframe_cache_mib", 0);
  return cfg;
}
}  // namespace

// Bricks and keyframes whose spill records could not be read back are held in the checkpoint as never
// observed / without features: the resumed run still counts them (summary.json's bricks_lost and
// keyframes_lost said 0 after a resume, under a mesh with holes).
TEST(Checkpoint, BricksAndKeyframesLostBeforeACheckpointStayCountedAfterTheResume) {
  const std::vector<Frame> frames = test::renderFrames(sim::SyntheticSequence(test::quickSim("corridor", 30)));
  const std::string dir = test::tempDir("checkpoint_lost_records");
  auto cfg = spillingConfig(dir);
  std::stringstream saved;
  std::size_t bricks_lost = 0, keyframes_lost = 0;
  {
    Reconstruction first(cfg, TrackingMode::Joint);
    feed(first, frames, 0, 20);
    std::stringstream sync;
    first.saveState(sync);  // waits for the loop thread to store its keyframes (storeStats is its last count)
    ASSERT_GT(first.fusionStats().world.spilled, 0u) << "the volume should have left bricks on disk";
    ASSERT_GT(first.loopCloser()->storeStats().spilled, 0u) << "keyframes should be on disk";
    const std::vector<int> files = test::spillFilesIn(dir);
    ASSERT_EQ(files.size(), 2u);
    for (const int fd : files) {  // every record damaged, as a failing disk would
      struct stat st {};
      ASSERT_EQ(::fstat(fd, &st), 0);
      const std::vector<std::uint8_t> junk(std::size_t(st.st_size), 0xa5);
      ASSERT_EQ(::pwrite(fd, junk.data(), junk.size(), 0), ssize_t(junk.size()));
    }
    testing::internal::CaptureStderr();
    first.saveState(saved);  // reads every spilled record: each one is lost there
    testing::internal::GetCapturedStderr();
    bricks_lost = first.fusionStats().world.lost;
    keyframes_lost = first.loopCloser()->storeStats().lost;
    ASSERT_GT(bricks_lost, 0u);
    ASSERT_GT(keyframes_lost, 0u);
  }
  Reconstruction second(cfg, TrackingMode::Joint);
  second.loadState(saved);
  EXPECT_EQ(second.fusionStats().world.lost, bricks_lost);
  EXPECT_EQ(second.loopCloser()->storeStats().lost, keyframes_lost);
  feed(second, frames, 20, 25);
  std::stringstream again;
  second.saveState(again);  // resumed twice: counted once
  Reconstruction third(cfg, TrackingMode::Joint);
  third.loadState(again);
  feed(third, frames, 25, frames.size());
  third.finish();
  EXPECT_EQ(third.fusionStats().world.lost, bricks_lost);
  EXPECT_EQ(third.loopCloser()->storeStats().lost, keyframes_lost);
}

// Why a spill file could not be written before a checkpoint is still said after the resume: it left
// summary.json with the run resumed (a full disk before the checkpoint, bricks kept in RAM since).
TEST(Checkpoint, ASpillErrorBeforeACheckpointIsStillSaidAfterTheResume) {
  const std::vector<Frame> frames = test::renderFrames(sim::SyntheticSequence(test::quickSim("corridor", 24)));
  const std::string dir = test::tempDir("checkpoint_spill_error");
  std::ofstream(dir + "/a_file") << "not a folder";
  auto cfg = spillingConfig(dir + "/a_file/spill");
  std::stringstream saved;
  std::string world_error, keyframe_error;
  {
    testing::internal::CaptureStderr();
    Reconstruction first(cfg, TrackingMode::Joint);
    feed(first, frames, 0, 20);
    first.saveState(saved);
    testing::internal::GetCapturedStderr();
    world_error = first.fusionStats().world.spill_error;
    keyframe_error = first.loopCloser()->storeStats().spill_error;
    ASSERT_NE(world_error.find("cannot create the world model's spill file"), std::string::npos) << world_error;
    ASSERT_NE(keyframe_error.find("cannot create the keyframes' spill file"), std::string::npos) << keyframe_error;
  }
  cfg.write("kinfu", "work_dir", dir);  // the disk usable again
  Reconstruction second(cfg, TrackingMode::Joint);
  second.loadState(saved);
  feed(second, frames, 20, frames.size());
  second.finish();
  EXPECT_EQ(second.fusionStats().world.spill_error, world_error);
  EXPECT_EQ(second.loopCloser()->storeStats().spill_error, keyframe_error);
}

// What a checkpoint writes it reads: a frame's descriptors of over 65536 keypoints (one row each) were
// written whole and refused at --resume ("bad image size"), after the run that made them. Past what a
// checkpoint holds, the write fails (the run goes on without checkpoints), not the resume.
TEST(Checkpoint, AnImageACheckpointWritesItReads) {
  cv::Mat descriptors(70000, 32, CV_8U);
  cv::RNG(7).fill(descriptors, cv::RNG::UNIFORM, 0, 255);  // its own generator: the data whichever tests ran before
  std::stringstream ss;
  {
    auto out = state::archiveOf(static_cast<std::ostream&>(ss));
    state::write(out, descriptors);
  }
  cv::Mat back;
  auto in = state::archiveOf(static_cast<std::istream&>(ss));
  state::read(in, back);
  EXPECT_EQ(cv::norm(back, descriptors, cv::NORM_INF), 0.0);
  std::stringstream none;
  auto out = state::archiveOf(static_cast<std::ostream&>(none));
  EXPECT_THROW(state::write(out, cv::Mat(1, (1 << 24) + 1, CV_8U)), state::NotStorable);  // saveCheckpoint: an InputError
  EXPECT_EQ(none.str().size(), 0u);
}

// A setting that differs past its sixth decimal is another run: the origin wrote both as 0.003000, and
// a run resumed with the other value went on with it.
TEST(Checkpoint, AnOriginTellsSettingsApartPastTheSixthDecimal) {
  mrpt::config::CConfigFileMemory a, b;
  a.write("kinfu", "joint_icp_sigma", std::string("0.0030001"));
  b.write("kinfu", "joint_icp_sigma", std::string("0.0030004"));
  EXPECT_NE(RunSession::checkpointOrigin("synthetic:room", TrackingMode::Joint, a),
            RunSession::checkpointOrigin("synthetic:room", TrackingMode::Joint, b));
}

TEST(Checkpoint, ACheckpointOfAnotherRunOrADamagedOneIsRefusedInOneLine) {
  const sim::SyntheticSequence seq(test::quickSim("room", 6));
  const auto cfg = roomConfig();
  const std::string dir = test::tempDir("checkpoint_refused");
  const std::string path = dir + "/checkpoint";
  {
    RunSession run(cfg, TrackingMode::Joint, dir + "/out", OutputParams(), MeshCleanParams());
    for (std::size_t i = 0; i < 4; ++i) run.process(seq.render(i));
    run.saveCheckpoint(path, "input room\n", 1.5);
  }
  const auto peek = RunSession::peek(path);
  ASSERT_TRUE(peek.has_value());
  EXPECT_EQ(peek->frames, 3u);  // the fourth is held back (Reconstruction::push): read again on resuming
  EXPECT_EQ(peek->seconds, 1.5);

  const auto refusal = [&](const std::string& file, const std::string& origin) -> std::string {
    RunSession run(cfg, TrackingMode::Joint, dir + "/again", OutputParams(), MeshCleanParams());
    try {
      run.resume(file, origin);
    } catch (const InputError& e) {
      EXPECT_EQ(e.file(), file);
      EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
      return e.problem();
    }
    return "";
  };
  EXPECT_EQ(refusal(path, "input corridor\n"),
            "made by another run ('input room' where this run has 'input corridor'): resume with the same input, "
            "--config, --mode and options, or delete it to start over");
  EXPECT_NE(refusal(path, "input room\nmode kinfu\n").find("('(nothing)' where this run has 'mode kinfu')"), std::string::npos);
  // Cut short anywhere past the header, or a map saved with --save-volume instead.
  const std::string bytes = [&] {
    std::ifstream is(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(is), {});
  }();
  for (const double share : {0.01, 0.3, 0.99}) {
    const std::string cut = dir + "/cut";
    std::ofstream(cut, std::ios::binary) << bytes.substr(0, std::size_t(bytes.size() * share));
    const std::string why = refusal(cut, "input room\n");
    EXPECT_NE(why, "") << "cut at " << share;
    if (share > 0.1) {
      EXPECT_NE(why.find("truncated or corrupt checkpoint"), std::string::npos) << why;
    }
  }
  // A length field made huge (the run's origin string, right after the magic), under a checksum that
  // matches (so that the reader's own guard is what is tested): refused, not first zero-filled (4 GiB).
  {
    std::string huge = bytes;
    const std::size_t at = std::string("VOFUSION-CHECKPOINT-8\n").size();
    ASSERT_EQ(huge.compare(0, at, "VOFUSION-CHECKPOINT-8\n"), 0);
    huge.replace(at, 4, "\xff\xff\xff\xff");
    const std::size_t body = huge.size() - 20;  // the trailer: "CHECKSUM", CRC-32, length
    ASSERT_EQ(huge.compare(body, 8, "CHECKSUM"), 0);
    const std::uint32_t crc = crc32(huge.data(), body);
    for (int i = 0; i < 4; ++i) huge[body + 8 + std::size_t(i)] = char((crc >> (8 * i)) & 0xff);
    std::ofstream(dir + "/huge", std::ios::binary) << huge;
    rusage before{}, after{};
    getrusage(RUSAGE_SELF, &before);
    EXPECT_NE(refusal(dir + "/huge", "input room\n").find("truncated or corrupt checkpoint"), std::string::npos);
    getrusage(RUSAGE_SELF, &after);
    EXPECT_LT(after.ru_maxrss - before.ru_maxrss, 1L << 20) << "KiB more at the peak";
  }
  // One byte flipped in the first frame's pose (a double's lowest byte, which no parse notices): the
  // checksum refuses it. It was resumed from, the pose off by 2^-52.
  {
    std::string flipped = bytes;
    const std::size_t pose = flipped.find(std::string("\0\0\0\0\0\0\xf0\x3f", 8));  // 1.0, the first pose's first entry
    ASSERT_NE(pose, std::string::npos);
    flipped[pose] ^= 1;
    std::ofstream(dir + "/flipped", std::ios::binary) << flipped;
    EXPECT_EQ(refusal(dir + "/flipped", "input room\n"), "truncated or corrupt checkpoint: its checksum does not match (a damaged byte)");
  }
  // Ones of earlier layouts (1 had no resumed map's name, 2 no checksum, 3 no frame indices, 4 no loop
  // closer's last well-tracked frame, 5 no last measured frame, 7 no spill errors): said so, not misread
  // as corrupt.
  for (const char* version : {"1", "2", "3", "4", "5", "6", "7"}) {
    std::ofstream(dir + "/old", std::ios::binary) << "VOFUSION-CHECKPOINT-" << version << "\n" << bytes.substr(22);
    EXPECT_TRUE(RunSession::isCheckpoint(dir + "/old"));
    EXPECT_FALSE(RunSession::peek(dir + "/old").has_value());
    EXPECT_EQ(refusal(dir + "/old", "input room\n"), "a checkpoint of an earlier vofusion, which this one cannot read: delete it to start over");
  }
  std::ofstream(dir + "/map", std::ios::binary) << "VOFUSION-MAP";
  EXPECT_FALSE(RunSession::isCheckpoint(dir + "/map"));
  EXPECT_NE(refusal(dir + "/map", "input room\n").find("not a vofusion checkpoint"), std::string::npos);
}

namespace {

std::string slurp(const std::string& path) {
  std::ifstream is(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(is), {});
}

// The test at a tenth of its length: the first 60 frames of xyz_first300, checkpointed after
// every frame; the checkpoints at 50 %, 90 % and 99 % (the first one seen at or past each) are kept as
// a kill would have left them, and each resumed run must write the clean run's trajectory, mesh and
// poses.rawlog byte for byte.
constexpr std::size_t kFrames = 60;

std::string vofusionCommand(const std::string& out, const std::string& extra) {
  return test::app("vofusion") + " " + test::tumFirst300() + " --out " + out + " --max-frames " + std::to_string(kFrames) +
         " --checkpoint-every 0.000001 " + extra;
}

}  // namespace

namespace {

// The run's checkpoints copied as it passes each of `targets` frames (a copy holds the file it opened,
// whole: a checkpoint is replaced by rename), into dir/at<frames>.
std::vector<std::string> watchCheckpoints(const std::string& path, const std::vector<std::size_t>& targets,
                                          const std::string& dir, const std::function<void()>& run) {
  std::vector<std::string> kept;
  std::atomic<bool> done{false};
  std::thread watcher([&] {
    std::size_t next = 0;
    while (next < targets.size() && !done) {
      const auto c = RunSession::peek(path);
      if (c && c->frames >= targets[next]) {
        const std::string copy = dir + "/at" + std::to_string(targets[next]);
        std::error_code ec;
        fs::copy_file(path, copy, fs::copy_options::overwrite_existing, ec);
        const auto copied = RunSession::peek(copy);
        if (!ec && copied && copied->frames >= targets[next]) {
          kept.push_back(copy);
          ++next;
          continue;
        }
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
  });
  run();
  done = true;
  watcher.join();
  return kept;
}

void expectSameOutputs(const std::string& clean, const std::string& out) {
  for (const char* file : {"trajectory.txt", "mesh.ply", "poses.groundtruth.txt", "poses.rawlog"})
    EXPECT_TRUE(slurp(clean + "/" + file) == slurp(out + "/" + file)) << file << " of " << out << " differs from the clean run's";
}

}  // namespace

// Checkpoints kept at 50 %, 90 % and 99 % of a clean run, as a kill would have left them; then a
// run really killed (-9) while checkpointing after every frame. Every resumed run writes the clean
// run's trajectory, mesh and poses.rawlog byte for byte.
TEST(Checkpoint, RunsResumedFromTheirLastCheckpointWriteTheCleanRunsOutputs) {
  VOFUSION_REQUIRE_DATA(test::tumFirst300());
  const std::string dir = test::tempDir("checkpoint_app");
  const std::string clean = dir + "/clean";
  const std::vector<std::size_t> targets = {kFrames / 2, kFrames * 9 / 10, kFrames * 99 / 100};
  const auto kept = watchCheckpoints(clean + "/checkpoint", targets, dir, [&] {
    std::string log;
    ASSERT_EQ(test::run(vofusionCommand(clean, ""), &log), 0) << log;
  });
  EXPECT_FALSE(fs::exists(clean + "/checkpoint")) << "a finished run leaves no checkpoint";
  ASSERT_EQ(kept.size(), targets.size()) << "checkpoints seen at or past frames 30, 54, 59";
  for (const std::string& checkpoint : kept) {
    std::string log;
    ASSERT_EQ(test::run(vofusionCommand(checkpoint + "_out", "--resume " + checkpoint), &log), 0) << log;
    expectSameOutputs(clean, checkpoint + "_out");
  }

  const std::string killed = dir + "/killed";
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    const std::string cmd = "exec " + vofusionCommand(killed, "") + " >/dev/null 2>&1";
    execl("/bin/sh", "sh", "-c", cmd.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  // Once a third of the frames are in, while a checkpoint is being written as likely as not.
  for (int i = 0; i < 60000; ++i) {
    const auto c = RunSession::peek(killed + "/checkpoint");
    if (c && c->frames >= kFrames / 3) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  ::kill(pid, SIGKILL);
  int status = 0;
  ::waitpid(pid, &status, 0);
  ASSERT_TRUE(RunSession::peek(killed + "/checkpoint").has_value());
  std::string log;
  ASSERT_EQ(test::run(vofusionCommand(killed, "--resume " + killed + "/checkpoint"), &log), 0) << log;
  expectSameOutputs(clean, killed);
}

// A checkpoint comes after the last frame too, before the end phase: a run killed while meshing goes
// on from there to the clean run's outputs without tracking a frame again. The last checkpoint was
// the last periodic one (here: none at all, the period being longer than the run).
TEST(Checkpoint, ARunKilledAfterItsLastFrameResumesAtItsEndPhase) {
  const std::string dir = test::tempDir("checkpoint_end_phase");
  const std::string clean = dir + "/clean";
  constexpr std::size_t kRoomFrames = 6;
  const auto command = [&](const std::string& out, const std::string& extra) {
    return test::app("vofusion") + " synthetic:room --max-frames " + std::to_string(kRoomFrames) + " --out " + out +
           " --checkpoint-every 100000 " + extra;
  };
  const auto kept = watchCheckpoints(clean + "/checkpoint", {kRoomFrames}, dir, [&] {
    std::string log;
    ASSERT_EQ(test::run(command(clean, ""), &log), 0) << log;
  });
  const auto summary = nlohmann::json::parse(slurp(clean + "/summary.json"));
  EXPECT_EQ(summary["checkpoints"]["written"].get<int>(), 1) << summary["checkpoints"];
  ASSERT_EQ(kept.size(), 1u) << "no checkpoint after the last frame";
  std::string log;
  ASSERT_EQ(test::run(command(dir + "/resumed", "--resume " + kept[0]), &log), 0) << log;
  expectSameOutputs(clean, dir + "/resumed");
  const auto resumed = nlohmann::json::parse(slurp(dir + "/resumed/summary.json"));
  EXPECT_EQ(resumed["checkpoints"]["resumed_at_frame"].get<std::size_t>(), kRoomFrames);
  EXPECT_EQ(resumed["checkpoints"]["written"].get<int>(), 0) << "the checkpoint it went on from held every frame";
}

namespace {

// The synthetic room as a recording that fails to read from frame `fails_at` on (0: never).
class FailingRoom : public FrameSource {
 public:
  // silent: from `fails_at` on the recording ends without an error, as a skipping reader's cut short.
  FailingRoom(const sim::SyntheticSequence& seq, std::size_t fails_at, bool silent = false)
      : seq_(seq), fails_at_(fails_at), silent_(silent) {}
  bool next(Frame& frame) override {
    if (next_ == seq_.size()) return false;
    if (fails_at_ && next_ >= fails_at_ && silent_) return false;
    if (fails_at_ && next_ >= fails_at_)
      throw InputError("/media/disk/room/depth/" + std::to_string(next_) + ".png", "input/output error");
    frame = seq_.render(next_++);
    return true;
  }
  std::size_t size() const override { return seq_.size(); }
  void rewind() override { next_ = 0; }
  std::string name() const override { return "/media/disk/room"; }

 private:
  const sim::SyntheticSequence& seq_;
  std::size_t fails_at_, next_ = 0;
  bool silent_;
};

// A run of the room whose loops re-fuse the map: loops within its short path, and any correction.
std::unique_ptr<RunSession> roomRunToRefuse(const sim::SyntheticSequence& seq, const std::string& out_dir) {
  mrpt::config::CConfigFileMemory cfg = test::quickRoomConfig();
  cfg.write("loop", "keyframe_translation", 0.05);
  cfg.write("loop", "recent_keyframes", 2);
  cfg.write("loop", "min_travel", 0.1);
  cfg.write("loop", "index_spacing", 0.0);
  cfg.write("loop", "reintegrate_min_correction", 0.0);
  OutputParams out;
  out.write_rawlog = false;
  auto run = std::make_unique<RunSession>(cfg, TrackingMode::Joint, out_dir, out, MeshCleanParams());
  for (std::size_t i = 0; i < seq.size(); ++i) run->process(seq.render(i));
  run->flush();
  run->reconstruction().finish();
  return run;
}

}  // namespace

// An output folder that became unwritable during the run (here a file in its place) fails the end in
// one line naming it: std::filesystem's error named the staging folder inside it.
TEST(RunSessionEnd, AnOutputFolderGoneSinceTheStartIsNamed) {
  const sim::SyntheticSequence seq(test::quickSim("room", 3));
  const std::string dir = test::tempDir("run_session_out_gone");
  OutputParams out;
  out.write_rawlog = false;
  RunSession run(test::quickRoomConfig(), TrackingMode::Joint, dir + "/out", out, MeshCleanParams());
  for (std::size_t i = 0; i < seq.size(); ++i) run.process(seq.render(i));
  fs::remove_all(dir + "/out");
  std::ofstream(dir + "/out") << "a file where the output folder was";
  RunInfo info;
  info.input = "room";
  try {
    run.finish(info, nullptr);
    ADD_FAILURE() << "outputs written into a file";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), dir + "/out");
    EXPECT_EQ(e.problem().rfind("cannot write: ", 0), 0u) << e.what();
  }
}

// poses.rawlog that cannot be written any more (a full disk, here its images' staging folder gone and a
// file in its place) costs poses.rawlog: said, its temporaries freed, the other outputs written and
// summary.json says why. Every output was lost at the end, the frames after the failure run for nothing.
TEST(RunSessionEnd, APosesRawlogThatCannotBeWrittenCostsItOnly) {
  const sim::SyntheticSequence seq(test::quickSim("room", 8));
  const std::string dir = test::tempDir("run_session_rawlog_fails");
  const std::string out = dir + "/out";
  OutputParams params;
  params.write_mesh = false;
  RunSession run(test::quickRoomConfig(), TrackingMode::Joint, out, params, MeshCleanParams());
  for (std::size_t i = 0; i < 3; ++i) run.process(seq.render(i));
  std::string staging;
  for (const auto& e : fs::directory_iterator(out))
    if (e.path().filename().string().rfind("poses_Images.tmp-", 0) == 0) staging = e.path().string();
  ASSERT_FALSE(staging.empty()) << "no staging folder for poses.rawlog's images";
  fs::rename(staging, dir + "/moved_away");  // in one step: the writer thread may be adding an image to it
  std::ofstream(staging) << "a file where the images go";
  testing::internal::CaptureStderr();
  for (std::size_t i = 3; i < seq.size(); ++i) run.process(seq.render(i));
  RunInfo info;
  info.input = "room";
  const nlohmann::json summary = run.finish(info, nullptr);
  const std::string said = testing::internal::GetCapturedStderr();
  EXPECT_NE(said.find("the run goes on without poses.rawlog"), std::string::npos) << said;
  EXPECT_NE(said.find(out + "/poses_Images/"), std::string::npos) << "the file as the user finds it: " << said;
  ASSERT_TRUE(summary.contains("poses_rawlog_error")) << summary.dump();
  for (const char* file : {"trajectory.txt", "summary.json"}) EXPECT_TRUE(fs::exists(out + "/" + file)) << file;
  EXPECT_FALSE(fs::exists(out + "/poses.rawlog"));
  fs::remove(staging);  // the file this test put there
  for (const auto& e : fs::directory_iterator(out))
    EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path() << " left";
}

// A recording that cannot be read again for re-fusion (moved or unmounted since it was tracked) costs
// the re-fusion, not the run: the outputs are written, the mesh of the map fused at the tracked poses
// (or of the frames fused again before a read failed), and summary.json says why. The exception left
// RunSession::finish and every output was lost.
TEST(RunSessionEnd, ARecordingThatCannotBeReadAgainCostsTheRefusionOnly) {
  const sim::SyntheticSequence seq(test::quickSim("room", 90));
  const std::string dir = test::tempDir("run_session_no_reopen");
  RunInfo info;
  info.input = "room";
  {
    const auto run = roomRunToRefuse(seq, dir + "/gone");
    ASSERT_TRUE(run->reconstruction().mapNeedsReintegration()) << "no loop to re-fuse for";
    const nlohmann::json summary =
        run->finish(info, []() -> std::unique_ptr<FrameSource> { throw InputError("/media/disk/room", "no such folder"); });
    EXPECT_EQ(summary["loop_closure_reintegration"]["error"], "/media/disk/room: no such folder") << summary.dump();
    EXPECT_FALSE(summary["loop_closure"]["map_reintegrated"].get<bool>());
    for (const char* file : {"trajectory.txt", "mesh.ply", "summary.json"}) EXPECT_TRUE(fs::exists(dir + "/gone/" + file)) << file;
  }
  {
    const auto run = roomRunToRefuse(seq, dir + "/midway");
    const nlohmann::json summary = run->finish(info, [&] { return std::make_unique<FailingRoom>(seq, 40); });
    EXPECT_EQ(summary["loop_closure_reintegration"]["error"], "/media/disk/room/depth/40.png: input/output error") << summary.dump();
    EXPECT_TRUE(summary["loop_closure"]["map_reintegrated"].get<bool>());
    EXPECT_EQ(summary["loop_closure_reintegration"].value("frames_fused", 0u), 40u) << "the frames fused again before the failure";
    EXPECT_GT(summary["mesh"]["faces"].get<std::size_t>(), 0u);
    for (const char* file : {"trajectory.txt", "mesh.ply", "summary.json"}) EXPECT_TRUE(fs::exists(dir + "/midway/" + file)) << file;
  }
  {
    // Cut short since, with no error (a skipping reader's end): the frames not fused again are counted.
    // They were left out of the map without a word.
    const auto run = roomRunToRefuse(seq, dir + "/cut");
    const std::size_t fused = run->reconstruction().framesFused();
    ASSERT_GT(fused, 40u);
    const nlohmann::json summary = run->finish(info, [&] { return std::make_unique<FailingRoom>(seq, 40, true); });
    const nlohmann::json& about = summary["loop_closure_reintegration"];
    EXPECT_FALSE(about.contains("error")) << summary.dump();
    EXPECT_EQ(about.value("frames_fused", 0u), 40u) << summary.dump();
    EXPECT_EQ(about.value("frames_missing", 0u), fused - 40) << summary.dump();
  }
  {
    // No recording read again (vofusion interrupted: the user asked the run to stop): the mesh keeps the
    // tracked poses while the trajectory is loop-closed, and the summary says why (it did not).
    const auto run = roomRunToRefuse(seq, dir + "/stopped");
    RunInfo stopped = info;
    stopped.interrupted = true;
    stopped.no_rereading = "interrupted";
    const nlohmann::json summary = run->finish(stopped, nullptr);
    EXPECT_EQ(summary["loop_closure_reintegration"].value("skipped", ""), "interrupted") << summary.dump();
    EXPECT_FALSE(summary["loop_closure"]["map_reintegrated"].get<bool>());
  }
}
