#include "support.h"

#include <sys/mount.h>
#include <grp.h>
#include <poll.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>

#include <gtest/gtest.h>

namespace fs = std::filesystem;

namespace vofusion::test {

std::string sourceDir() { return VOFUSION_SOURCE_DIR; }
std::string shareDir() { return (fs::path(VOFUSION_SOURCE_DIR) / "share").string(); }
std::string binDir() { return VOFUSION_BIN_DIR; }

std::string tumFirst300() {
  return (fs::path(VOFUSION_SOURCE_DIR) / ".." / "shared" / "data" / "tum" / "rgbd_dataset_freiburg1_xyz_first300")
      .lexically_normal()
      .string();
}

bool dataPresent(const std::string& path) { return fs::exists(path); }

// As CI systems set it: "true" (GitHub, GitLab), "1", "True"; unset, empty, "0" or "false" is no CI.
bool inCi() {
  const char* ci = std::getenv("CI");
  if (!ci) return false;
  std::string v(ci);
  std::transform(v.begin(), v.end(), v.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return !v.empty() && v != "0" && v != "false";
}

std::string tempDir(const std::string& name) {
  // Under the running test's own folder: ctest runs every test case as its own process, in parallel,
  // and two cases asking for the same name must not empty each other's files.
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const std::string owner = info ? std::string(info->test_suite_name()) + "." + info->name() : "no_test";
  const fs::path p = fs::path(VOFUSION_BIN_DIR) / ".." / "test-tmp" / owner / name;
  fs::remove_all(p);
  fs::create_directories(p);
  return p.lexically_normal().string();
}

std::vector<int> spillFilesIn(const std::string& dir) {
  const std::string prefix = (fs::weakly_canonical(dir) / "vofusion-spill-").string();
  std::vector<int> fds;
  for (int fd = 3; fd < 1024; ++fd) {
    char target[4096];
    const ssize_t n = ::readlink(("/proc/self/fd/" + std::to_string(fd)).c_str(), target, sizeof target);
    if (n > 0 && std::string(target, std::size_t(n)).rfind(prefix, 0) == 0) fds.push_back(fd);
  }
  return fds;
}

int spillFileIn(const std::string& dir) {
  const std::vector<int> fds = spillFilesIn(dir);
  return fds.empty() ? -1 : fds.front();
}

std::string app(const std::string& name) { return (fs::path(VOFUSION_BIN_DIR) / name).string(); }

std::vector<std::string> lines(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);) out.push_back(l);
  return out;
}

int run(const std::string& cmd, std::string* output) {
  std::FILE* p = ::popen((cmd + " 2>&1").c_str(), "r");
  if (!p) return -1;
  std::array<char, 4096> buf;
  std::string out;
  std::size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), p)) > 0) out.append(buf.data(), n);
  const int status = ::pclose(p);
  if (output) *output = out;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

SignalledRun runSignalledMidway(const std::string& command, const std::string& log_path, int total_frames,
                                const std::string& signal, int from, const std::string& watch_path) {
  const std::string watch = watch_path.empty() ? log_path : watch_path;
  const std::string total = std::to_string(total_frames);
  // Counts are read as numbers (grep -o finds each, also in a line of \r-separated updates).
  const std::string count_shows = "grep -o ' [0-9]*/" + total + " frames' '" + watch + "' 2>/dev/null | awk -F/ '$1 >= " +
                                  std::to_string(from) + " && $1 < " + total + " {found = 1} END {exit !found}'";
  std::string said;
  // Signalled only while it runs: one that has ended (its last count shown, or a failure) is not
  // signalled, nor is its pid, which another process may have taken by then.
  run("(" + command + " > '" + log_path + "' 2>&1 & pid=$!; ended= counted=; for i in $(seq 1 600); do kill -0 $pid " +
          "2>/dev/null || { ended=1; break; }; " + count_shows + " && { counted=1; break; }; sleep 0.2; done; " +
          "[ -n \"$ended\" ] || { kill -" + signal + " $pid 2>/dev/null && [ -n \"$counted\" ] && echo signalled-at-a-count; }; " +
          "wait $pid; echo rc=$?)",
      &said);
  SignalledRun r;
  r.signalled_at_a_count = said.find("signalled-at-a-count") != std::string::npos;
  const auto rc = said.rfind("rc=");
  if (rc != std::string::npos) r.exit_code = std::atoi(said.c_str() + rc + 3);
  std::ifstream f(log_path);
  r.log.assign(std::istreambuf_iterator<char>(f), {});
  return r;
}

mrpt::config::CConfigFileMemory quickRoomConfig() {
  mrpt::config::CConfigFileMemory cfg;
  cfg.write("kinfu", "volume_voxels", 256);
  cfg.write("kinfu", "voxel_size", 0.01);
  cfg.write("odometry", "keypoints", "star");
  return cfg;
}

sim::SimOptions quickSim(const std::string& scene, std::size_t frames, const std::string& trajectory) {
  sim::SimOptions o;
  o.scene = scene;
  o.trajectory = trajectory;
  o.frames = frames;
  o.camera = CameraIntrinsics{}.scaled(0.5);
  return o;
}

std::vector<Frame> renderFrames(const sim::SyntheticSequence& seq, std::size_t count) {
  std::vector<Frame> frames;
  count = std::min(count, seq.size());
  frames.reserve(count);
  for (std::size_t i = 0; i < count; ++i) frames.push_back(seq.render(i));
  return frames;
}

Frame deepCopy(const Frame& frame) {
  Frame f = frame;
  f.rgb = frame.rgb.clone();
  f.depth = frame.depth.clone();
  return f;
}

std::string errorWithoutPrivileges(const std::function<void()>& fn) {
  int fds[2];
  if (::pipe(fds) != 0) return {};
  const pid_t pid = ::fork();
  if (pid < 0) return {};
  if (pid == 0) {
    ::close(fds[0]);
    constexpr uid_t kNobody = 65534;
    if (::getuid() == 0 && (::setgroups(0, nullptr) != 0 || ::setgid(kNobody) != 0 || ::setuid(kNobody) != 0)) ::_exit(2);
    std::string said = "no error";
    try {
      fn();
    } catch (const std::exception& e) {
      said = e.what();
    }
    const ssize_t wrote = ::write(fds[1], said.data(), said.size());
    ::_exit(wrote == ssize_t(said.size()) ? 0 : 3);
  }
  ::close(fds[1]);
  // The child is a fork of a process with threads (TBB's, a reader's): a lock one of them held stays
  // held there. Waited for up to a minute, then killed, rather than hanging the test.
  std::string said;
  char buf[4096];
  pollfd p{fds[0], POLLIN, 0};
  bool timed_out = false;
  for (;;) {
    const int ready = ::poll(&p, 1, 60000);
    if (ready < 0 && errno == EINTR) continue;
    if (ready <= 0) {
      timed_out = ready == 0;
      break;
    }
    const ssize_t n = ::read(fds[0], buf, sizeof buf);
    if (n <= 0) break;
    said.append(buf, std::size_t(n));
  }
  ::close(fds[0]);
  if (timed_out) ::kill(pid, SIGKILL);
  int status = 0;
  ::waitpid(pid, &status, 0);
  return !timed_out && WIFEXITED(status) && WEXITSTATUS(status) == 0 ? said : std::string();
}

ScopedTmpfs::ScopedTmpfs(const std::string& dir, const std::string& size) : dir_(dir) {
  mounted_ = ::mount("tmpfs", dir.c_str(), "tmpfs", 0, ("size=" + size).c_str()) == 0;
}

std::size_t jpegScanStart(const std::vector<std::uint8_t>& jpeg) {
  for (std::size_t at = 2; at + 4 <= jpeg.size();) {
    const std::size_t len = (std::size_t(jpeg[at + 2]) << 8) | jpeg[at + 3];
    if (jpeg[at + 1] == 0xDA) return at + 2 + len;
    at += 2 + len;
  }
  return jpeg.size();
}

std::vector<std::uint8_t> jpegWithMarkerInside(std::vector<std::uint8_t> jpeg) {
  const std::size_t scan = jpegScanStart(jpeg), mid = scan + (jpeg.size() - scan) / 2;
  EXPECT_LT(scan + 4, jpeg.size()) << "no scan";
  if (mid + 1 < jpeg.size()) jpeg[mid] = 0xFF, jpeg[mid + 1] = 0xD3;
  return jpeg;
}

ScopedTmpfs::~ScopedTmpfs() {
  if (mounted_) ::umount(dir_.c_str());
}

}  // namespace vofusion::test
