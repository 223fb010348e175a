// The out-of-core world model: bricks spilled to disk come back bit-identical, the RAM cache stays
// within its limit, the region-by-region mesh equals the one-shot one, and a saved map resumes.
#include <sys/mman.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include <csignal>
#include <cstring>
#include <fstream>
#include <random>
#include <set>
#include <unordered_map>
#include <sstream>
#include <algorithm>
#include <array>
#include <atomic>
#include <thread>
#include <tuple>

#include <zlib.h>

#include "support.h"
#include "vofusion/core/deflate.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/spill_file.h"
#include "vofusion/fusion/brick_arena.h"
#include "vofusion/fusion/brick_index.h"
#include "vofusion/fusion/tracked_map.h"
#include "vofusion/fusion/marching_cubes.h"
#include "vofusion/fusion/tsdf_volume.h"
#include "vofusion/fusion/world_model.h"
#include "vofusion/sim/synthetic_sequence.h"

using namespace vofusion;
using namespace vofusion::fusion;

namespace {

std::unique_ptr<Brick> randomBrick(const Eigen::Vector3i& c, std::mt19937& rng) {
  auto b = std::make_unique<Brick>();
  b->coord = c;
  std::uniform_int_distribution<int> d(0, 255);
  for (int i = 0; i < kBrickVoxels; ++i) {
    if (d(rng) < 128) continue;  // half never observed, as in a real brick (compressible)
    Voxel& v = b->voxels[i];
    v.tsdf = static_cast<std::int16_t>(d(rng) * 200 - 25000);
    v.weight = static_cast<std::uint8_t>(1 + d(rng) % 64);
    v.r = static_cast<std::uint8_t>(d(rng)), v.g = static_cast<std::uint8_t>(d(rng)), v.b = static_cast<std::uint8_t>(d(rng));
  }
  return b;
}

bool sameVoxels(const Brick& a, const Brick& b) { return std::memcmp(a.voxels, b.voxels, sizeof(a.voxels)) == 0; }

// Puts n random bricks along x (y = z = 0) one at a time; returns copies of them.
std::vector<std::unique_ptr<Brick>> putRow(WorldModel& wm, int n, std::mt19937& rng) {
  std::vector<std::unique_ptr<Brick>> kept;
  for (int i = 0; i < n; ++i) {
    auto b = randomBrick(Eigen::Vector3i(i, 0, 0), rng);
    kept.push_back(std::make_unique<Brick>(*b));
    wm.put(std::move(b));
  }
  return kept;
}

// KinFu params for a fast synthetic run: a 1.54 m volume following the camera.
KinFuParams smallKinFu(int cache_mib) {
  KinFuParams p;
  p.tsdf.volume_voxels = 256;
  p.tsdf.voxel_size = 0.01f;
  p.tsdf.truncation = 0.04f;
  p.tsdf.world_cache_mib = cache_mib;
  p.tsdf.work_dir = test::tempDir("world_model_spill");
  p.shift_threshold = 0.2f;
  return p;
}

sim::SimOptions corridor(int frames) {
  sim::SimOptions o;
  o.scene = "corridor";
  o.frames = frames;
  o.camera = o.camera.scaled(0.5);
  return o;
}

// Largest distance from a vertex of a to the nearest vertex of b (brute force over a voxel grid hash).
double maxNearest(const TriangleMesh& a, const TriangleMesh& b, float cell) {
  std::unordered_map<std::uint64_t, std::vector<Eigen::Vector3f>> grid;
  const auto key = [cell](const Eigen::Vector3i& c) {
    return (std::uint64_t(std::uint32_t(c.x() + 100000)) << 42) ^ (std::uint64_t(std::uint32_t(c.y() + 100000)) << 21) ^
           std::uint64_t(std::uint32_t(c.z() + 100000));
  };
  for (const auto& v : b.vertices) grid[key((v / cell).array().floor().cast<int>())].push_back(v);
  double worst = 0;
  for (const auto& v : a.vertices) {
    const Eigen::Vector3i c = (v / cell).array().floor().cast<int>();
    double best = 1e9;
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const auto it = grid.find(key(c + Eigen::Vector3i(dx, dy, dz)));
          if (it == grid.end()) continue;
          for (const auto& w : it->second) best = std::min(best, double((v - w).norm()));
        }
    worst = std::max(worst, best);
  }
  return worst;
}

}  // namespace

// The compact index of bricks on disk answers as std::unordered_map does, through many merges and
// erasures (keys revisited, as bricks leave and re-enter the volume).
TEST(WorldModel, BrickIndexAnswersAsAnUnorderedMap) {
  BrickIndex index;
  std::unordered_map<std::uint64_t, std::uint64_t> reference;  // key -> record offset
  std::mt19937_64 rng(7);
  std::uniform_int_distribution<std::uint64_t> key(0, 30000), op(0, 9);
  for (int i = 0; i < 200000; ++i) {
    const std::uint64_t k = key(rng) * 2654435761u;  // spread out, as brick keys are
    const std::uint64_t o = op(rng);
    if (o < 6) {
      const SpillFile::Record r{std::uint64_t(i), std::uint64_t(1 + i % 1000)};
      index.set(k, r);
      reference[k] = r.offset;
    } else if (o < 9) {
      EXPECT_EQ(index.erase(k), reference.erase(k) == 1);
    } else {
      const auto found = index.find(k);
      const auto it = reference.find(k);
      ASSERT_EQ(found.has_value(), it != reference.end());
      if (found) {
        EXPECT_EQ(std::uint64_t(found->offset), it->second);
      }
    }
    ASSERT_EQ(index.size(), reference.size());
  }
  std::set<std::uint64_t> keys;
  index.forEachKey([&](std::uint64_t k) { EXPECT_TRUE(keys.insert(k).second) << "key listed twice"; });
  ASSERT_EQ(keys.size(), reference.size());
  for (const auto& [k, offset] : reference) {
    EXPECT_EQ(keys.count(k), 1u);
    EXPECT_EQ(std::uint64_t(index.find(k)->offset), offset);
  }
  EXPECT_THROW(index.set(1, SpillFile::Record{0, 0}), std::invalid_argument);
  // What it holds, not the address space reserved for a long walk.
  EXPECT_LE(index.bytes(), reference.size() * 16 + 4096 * 40 + 30000 * 16);
}

// The volume's brick storage: ids stay dense (the last brick moves into a removed one's place, and
// its old id is reported), contents survive the moves, and pages past the bricks in use are given back.
TEST(WorldModel, BrickArenaKeepsIdsDenseAndGivesPagesBack) {
  const std::size_t capacity = 8000;
  BrickArena arena(capacity);
  std::vector<std::unique_ptr<Brick>> reference;  // id -> expected brick
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> coord(-1000, 1000), op(0, 9);
  const auto same = [](const Brick& a, const Brick& b) { return std::memcmp(&a, &b, sizeof(Brick)) == 0; };
  for (int i = 0; i < 20000; ++i) {
    if (op(rng) < 6 && reference.size() < capacity) {
      const Eigen::Vector3i c(coord(rng), coord(rng), coord(rng));
      if (op(rng) < 5) {
        reference.push_back(randomBrick(c, rng));
        ASSERT_EQ(arena.add(*reference.back()), std::int32_t(reference.size() - 1));
      } else {
        reference.push_back(std::make_unique<Brick>());
        reference.back()->coord = c;
        ASSERT_EQ(arena.add(c), std::int32_t(reference.size() - 1));
      }
    } else if (!reference.empty()) {
      const auto id = static_cast<std::int32_t>(rng() % reference.size());
      const std::int32_t moved = arena.remove(id);
      const auto last = static_cast<std::int32_t>(reference.size() - 1);
      ASSERT_EQ(moved, id == last ? -1 : last);
      reference[id] = std::move(reference.back());
      reference.pop_back();
    }
    ASSERT_EQ(arena.size(), reference.size());
  }
  for (std::size_t id = 0; id < reference.size(); ++id) ASSERT_TRUE(same(arena[std::int32_t(id)], *reference[id])) << id;
  EXPECT_THROW(BrickArena(0), std::invalid_argument);

  // Fill it, keep 100 bricks: only about those 100 (plus the slack) stay resident.
  const auto page = static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
  const auto resident = [&] {
    const std::size_t bytes = (capacity * sizeof(Brick) + page - 1) / page * page;
    std::vector<unsigned char> in_core(bytes / page);
    EXPECT_EQ(::mincore(static_cast<void*>(&arena[0]), bytes, in_core.data()), 0);
    return page * static_cast<std::size_t>(std::count_if(in_core.begin(), in_core.end(), [](unsigned char v) { return v & 1; }));
  };
  while (arena.size() < capacity) arena.add(Eigen::Vector3i(1, 2, 3));
  EXPECT_THROW(arena.add(Eigen::Vector3i(1, 2, 3)), std::length_error);
  EXPECT_GE(resident(), capacity * sizeof(Brick) - page);
  while (arena.size() > 100) arena.remove(0);
  arena.releaseUnusedPages();
  EXPECT_LE(resident(), 100 * sizeof(Brick) + 2 * page);
  // Written again after the release: zero pages come back, the bricks are as added.
  const std::int32_t id = arena.add(Eigen::Vector3i(4, 5, 6));
  EXPECT_EQ(arena[id].coord, Eigen::Vector3i(4, 5, 6));
  EXPECT_EQ(arena[id].voxels[kBrickVoxels - 1].weight, 0);
}

TEST(WorldModel, SpilledBricksComeBackBitIdenticalAndTheCacheStaysWithinItsLimit) {
  std::mt19937 rng(7);
  const std::size_t limit = 10 * sizeof(Brick) + 100;  // room for 10 bricks
  WorldModel wm(limit, test::tempDir("world_model_cache"));
  std::vector<std::unique_ptr<Brick>> copies;
  for (int i = 0; i < 200; ++i) {
    auto b = randomBrick(Eigen::Vector3i(i % 7 - 3, i / 7, -i), rng);
    copies.push_back(std::make_unique<Brick>(*b));
    wm.put(std::move(b));
    EXPECT_LE(wm.stats().ram_bytes, limit + sizeof(Brick));
  }
  const WorldModelStats st = wm.stats();
  EXPECT_EQ(st.bricks, 200u);
  EXPECT_LE(st.bricks_in_ram, 10u);
  EXPECT_GE(st.spilled, 190u);
  EXPECT_GT(st.spill_file_bytes, 0u);
  EXPECT_LT(st.spill_file_bytes, 190u * sizeof(Brick));  // compressed
  // read() copies without moving anything; take() removes.
  Brick scratch;
  for (const auto& c : copies) {
    ASSERT_TRUE(wm.read(c->coord, scratch));
    EXPECT_TRUE(sameVoxels(scratch, *c));
  }
  EXPECT_EQ(wm.size(), 200u);
  for (const auto& c : copies) {
    const auto b = wm.take(c->coord);
    ASSERT_TRUE(b);
    EXPECT_EQ(b->coord, c->coord);
    EXPECT_TRUE(sameVoxels(*b, *c)) << "brick " << c->coord.transpose();
  }
  EXPECT_EQ(wm.size(), 0u);
  EXPECT_EQ(wm.stats().ram_bytes, 0u);
  EXPECT_FALSE(wm.take(Eigen::Vector3i(0, 0, 0)));
  EXPECT_EQ(wm.coordsInBox(Eigen::Vector3i(-10, -10, -10), 20).size(), 0u);
}

// A box query answers as a walk over every stored brick, in the same order, with bricks in RAM, among
// the latest spilled and merged on disk, boxes cut by the keys' reach included. It looks the rows up
// on disk instead of walking the whole map (a volume shift and every premeshed region ask it).
TEST(WorldModel, BoxQueriesAnswerAsAWalkOverEveryBrick) {
  std::mt19937 rng(11);
  WorldModel wm(20 * sizeof(Brick), test::tempDir("world_model_box"));  // 20 in RAM, the rest on disk
  std::vector<std::unique_ptr<Brick>> batch;
  std::uniform_int_distribution<int> coord(-12, 12);
  for (int i = 0; i < 6000; ++i) {  // more than the index's latest insertions hold: most get merged
    const Eigen::Vector3i c(coord(rng), coord(rng), coord(rng));
    auto b = std::make_unique<Brick>();
    b->coord = c;
    b->voxels[0].weight = 1;
    wm.put(std::move(b));
  }
  wm.put(randomBrick(Eigen::Vector3i(-WorldModel::kKeyReach, 0, 0), rng));   // at the keys' ends
  wm.put(randomBrick(Eigen::Vector3i(WorldModel::kKeyReach - 1, 0, 0), rng));
  ASSERT_GT(wm.stats().spilled, 5000u);
  const std::vector<Eigen::Vector3i> all = wm.coords();
  const auto walk = [&](const Eigen::Vector3i& lo, int n) {
    std::vector<Eigen::Vector3i> out;
    for (const Eigen::Vector3i& c : all)
      if (((c - lo).array() >= 0).all() && ((c - lo).array() < n).all()) out.push_back(c);
    return out;
  };
  std::uniform_int_distribution<int> corner(-16, 10), size(0, 12);
  for (int q = 0; q < 300; ++q) {
    const Eigen::Vector3i lo(corner(rng), corner(rng), corner(rng));
    const int n = size(rng);
    ASSERT_EQ(wm.coordsInBox(lo, n), walk(lo, n)) << "box at " << lo.transpose() << ", " << n;
  }
  for (const Eigen::Vector3i& lo : {Eigen::Vector3i(-WorldModel::kKeyReach - 2, -1, -1), Eigen::Vector3i(WorldModel::kKeyReach - 2, -1, -1)})
    EXPECT_EQ(wm.coordsInBox(lo, 4), walk(lo, 4)) << lo.transpose();
  EXPECT_EQ(wm.coordsInBox(Eigen::Vector3i(-100, -100, -100), 200), walk(Eigen::Vector3i(-100, -100, -100), 200));  // more rows than bricks
}

// A volume shift hands its bricks over at once (putAll / takeAll, the compression and decompression on
// every core): the store ends each shift as handing them over one by one leaves it, down to the spill
// file's size and free places (the same bricks spilled, in the same order, to the same places).
TEST(WorldModel, ShiftsAtOnceLeaveTheStoreAsOneByOne) {
 for (const std::size_t cache_bricks : {std::size_t(10), std::size_t(0)}) {
  SCOPED_TRACE("cache of " + std::to_string(cache_bricks) + " bricks");
  std::mt19937 rng(5);
  WorldModel at_once(cache_bricks * sizeof(Brick), test::tempDir("world_model_at_once"));
  WorldModel one_by_one(cache_bricks * sizeof(Brick), test::tempDir("world_model_one_by_one"));
  std::set<std::array<int, 3>> stored;
  const auto same = [](const WorldModelStats& a, const WorldModelStats& b) {
    return a.bricks == b.bricks && a.bricks_in_ram == b.bricks_in_ram && a.ram_bytes == b.ram_bytes &&
           a.spill_file_bytes == b.spill_file_bytes && a.spill_free_bytes == b.spill_free_bytes &&
           a.spilled == b.spilled && a.reloaded == b.reloaded && a.index_bytes == b.index_bytes;
  };
  for (int shift = 0; shift < 40; ++shift) {
    // Out: new bricks, bricks stored already (replaced) and, now and then, one handed over twice.
    std::vector<std::array<int, 3>> out_coords;
    const int out_n = int(rng() % 30);
    for (int i = 0; i < out_n; ++i) out_coords.push_back({int(rng() % 12), int(rng() % 12), 0});
    std::vector<std::unique_ptr<Brick>> batch;
    for (const auto& c : out_coords) {
      auto b = randomBrick(Eigen::Vector3i(c[0], c[1], c[2]), rng);
      one_by_one.put(std::make_unique<Brick>(*b));
      batch.push_back(std::move(b));
      stored.insert(c);
    }
    at_once.putAll(std::move(batch));
    ASSERT_TRUE(same(at_once.stats(), one_by_one.stats())) << "after putting, shift " << shift;
    // Back: some of the stored ones, in RAM or on disk.
    // A coordinate asked for twice gives null the second time, as a second take does.
    std::vector<Eigen::Vector3i> back;
    for (auto it = stored.begin(); it != stored.end();)
      if (rng() % 3 == 0) back.emplace_back((*it)[0], (*it)[1], (*it)[2]), it = stored.erase(it);
      else ++it;
    if (!back.empty() && shift % 4 == 0) back.push_back(back.front());
    const std::vector<std::unique_ptr<Brick>> taken = at_once.takeAll(back);
    ASSERT_EQ(taken.size(), back.size());
    for (std::size_t i = 0; i < back.size(); ++i) {
      const std::unique_ptr<Brick> b = one_by_one.take(back[i]);
      ASSERT_EQ(bool(b), bool(taken[i])) << "brick " << back[i].transpose();
      if (!b) continue;
      EXPECT_EQ(taken[i]->coord, back[i]);
      EXPECT_TRUE(sameVoxels(*taken[i], *b)) << "brick " << back[i].transpose();
    }
    ASSERT_TRUE(same(at_once.stats(), one_by_one.stats())) << "after taking, shift " << shift;
  }
  EXPECT_GT(one_by_one.stats().reloaded, 20u);  // bricks came back from disk, not only from RAM
  Brick a, b;
  for (const auto& c : stored) {
    const Eigen::Vector3i v(c[0], c[1], c[2]);
    ASSERT_TRUE(at_once.read(v, a) && one_by_one.read(v, b));
    EXPECT_TRUE(sameVoxels(a, b));
  }
 }
}

// A spill that cannot be written (a file size limit, as a full disk) loses no brick and does not stop
// the run: it is reported once (spill_error), every brick handed over stays readable, and from then on
// every brick stays in RAM, over the limit (a run whose work folder fills keeps what it built).
TEST(WorldModel, ASpillThatCannotBeWrittenKeepsEveryBrickInRam) {
  std::mt19937 rng(9);
  WorldModel wm(4 * sizeof(Brick), test::tempDir("world_model_full"));
  std::vector<std::unique_ptr<Brick>> kept = putRow(wm, 20, rng);
  const std::size_t spilled_before = wm.stats().spilled;
  std::vector<std::unique_ptr<Brick>> batch;
  for (int i = 0; i < 30; ++i) {
    auto b = randomBrick(Eigen::Vector3i(i, 1, 0), rng);
    kept.push_back(std::make_unique<Brick>(*b));
    batch.push_back(std::move(b));
  }
  struct rlimit old_limit {};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old_limit), 0);
  const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);  // the write fails with EFBIG instead
  struct rlimit limit = old_limit;
  limit.rlim_cur = rlim_t(wm.stats().spill_file_bytes + 2000);  // a brick or two more
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &limit), 0);
  EXPECT_NO_THROW(wm.putAll(std::move(batch)));
  setrlimit(RLIMIT_FSIZE, &old_limit);
  std::signal(SIGXFSZ, old_handler);
  const WorldModelStats after = wm.stats();
  EXPECT_NE(after.spill_error.find("cannot write the world model's spill file: File too large"), std::string::npos)
      << after.spill_error;
  EXPECT_LE(after.spilled, spilled_before + 2);
  EXPECT_EQ(after.ram_bytes, after.bricks_in_ram * sizeof(Brick));
  EXPECT_EQ(after.bricks, kept.size());
  EXPECT_EQ(wm.size(), kept.size());
  Brick got;
  for (const auto& k : kept) {
    ASSERT_TRUE(wm.read(k->coord, got)) << "brick " << k->coord.transpose();
    EXPECT_TRUE(sameVoxels(got, *k)) << "brick " << k->coord.transpose();
  }
  wm.put(randomBrick(Eigen::Vector3i(0, 2, 0), rng));  // no write is tried again: it stays in RAM
  EXPECT_EQ(wm.stats().spilled, after.spilled);
  EXPECT_EQ(wm.stats().bricks_in_ram, after.bricks_in_ram + 1);
}

// Reads share the store's lock (meshing fetches a region's bricks on every core): four readers, each
// reading every spilled brick three times, get each bit for bit while the owner keeps handing other
// bricks over (each replacement frees a place in the spill file and the next spill reuses it), and
// every read is counted.
TEST(WorldModel, ReadsSideBySideBesideHandOversGiveEveryBrickWhole) {
  std::mt19937 rng(11);
  WorldModel wm(4 * sizeof(Brick), test::tempDir("world_model_shared_reads"));
  std::vector<std::unique_ptr<Brick>> kept = putRow(wm, 120, rng);
  for (int i = 0; i < 4; ++i) wm.put(randomBrick(Eigen::Vector3i(i, 1, 0), rng));  // the last kept ones spill too
  ASSERT_EQ(wm.stats().bricks_in_ram, 4u);
  const std::size_t reloaded_before = wm.stats().reloaded;
  constexpr int kReaders = 4, kRounds = 3;
  std::atomic<int> started{0}, finished{0}, wrong{0}, missing{0};
  std::vector<std::thread> readers;
  for (int t = 0; t < kReaders; ++t)
    readers.emplace_back([&, t] {
      ++started;
      while (started.load() <= kReaders) std::this_thread::yield();  // and the owner
      Brick scratch;
      for (int round = 0; round < kRounds; ++round)
        for (std::size_t k = 0; k < kept.size(); ++k) {
          const Brick& want = *kept[(k + std::size_t(t) * 29) % kept.size()];
          if (!wm.read(want.coord, scratch)) {
            ++missing;
          } else if (!sameVoxels(scratch, want)) {
            ++wrong;
          }
        }
      ++finished;
    });
  ++started;
  int handed = 0;
  while (finished.load() < kReaders || handed < 100) wm.put(randomBrick(Eigen::Vector3i(handed++ % 40, 1, 0), rng));
  for (auto& r : readers) r.join();
  EXPECT_EQ(missing.load(), 0);
  EXPECT_EQ(wrong.load(), 0);
  EXPECT_EQ(wm.stats().reloaded - reloaded_before, std::size_t(kReaders * kRounds) * kept.size());
}

namespace {
bool neverObserved(const Brick& b) {
  for (const Voxel& v : b.voxels)
    if (v.weight != 0) return false;
  return true;
}
}  // namespace

// A spilled brick whose record cannot be read back (bytes damaged on the disk, a file cut short)
// costs that brick, not the run: it comes back as never observed from every way of reading it (the
// camera sees the place anew), is said once and counted; every other brick comes back whole.
TEST(WorldModel, ABrickWhoseRecordIsDamagedIsLostAloneAndSaidOnce) {
  std::mt19937 rng(21);
  const std::string dir = test::tempDir("world_model_damaged");
  WorldModel wm(4 * sizeof(Brick), dir);
  const std::vector<std::unique_ptr<Brick>> kept = putRow(wm, 20, rng);  // bricks 0-15 on disk, oldest first
  const int fd = test::spillFileIn(dir);
  ASSERT_GE(fd, 0);
  const std::vector<std::uint8_t> junk(64, 0xa5);
  ASSERT_EQ(::pwrite(fd, junk.data(), junk.size(), 0), ssize_t(junk.size()));  // brick 0's record starts there
  testing::internal::CaptureStderr();
  Brick got;
  for (int round = 0; round < 2; ++round)
    for (const auto& k : kept) {
      ASSERT_TRUE(wm.read(k->coord, got)) << "brick " << k->coord.transpose();
      if (k->coord.x() == 0) EXPECT_TRUE(neverObserved(got));
      else EXPECT_TRUE(sameVoxels(got, *k)) << "brick " << k->coord.transpose();
    }
  std::vector<std::uint8_t> packed;
  ASSERT_TRUE(wm.readCompressed(kept[0]->coord, packed));
  ASSERT_TRUE(decompressBrick(packed.data(), packed.size(), got));
  EXPECT_TRUE(neverObserved(got));
  const std::string said = testing::internal::GetCapturedStderr();
  EXPECT_EQ(wm.stats().lost, 1u);
  EXPECT_NE(said.find(dir + ": cannot read a brick back from the world model's spill file (damaged record)"), std::string::npos) << said;
  EXPECT_EQ(std::count(said.begin(), said.end(), '\n'), 1) << said;

  // Cut in half (inside brick 7's or 8's record): the bricks from there on are lost too, and taking
  // them all back gives the rest whole.
  struct stat st {};
  ASSERT_EQ(::fstat(fd, &st), 0);
  ASSERT_EQ(::ftruncate(fd, st.st_size / 2), 0);
  std::vector<Eigen::Vector3i> coords;
  for (const auto& k : kept) coords.push_back(k->coord);
  testing::internal::CaptureStderr();
  std::vector<std::unique_ptr<Brick>> back;
  ASSERT_NO_THROW(back = wm.takeAll(coords));
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "");  // said once for the run
  ASSERT_EQ(back.size(), kept.size());
  std::size_t lost = 0;
  for (std::size_t i = 0; i < kept.size(); ++i) {
    ASSERT_TRUE(back[i]) << i;
    EXPECT_EQ(back[i]->coord, kept[i]->coord);
    if (neverObserved(*back[i])) ++lost;
    else EXPECT_TRUE(sameVoxels(*back[i], *kept[i])) << i;
  }
  EXPECT_GT(lost, 2u);
  EXPECT_LT(lost, 16u);
  EXPECT_EQ(wm.stats().lost, lost);
  EXPECT_EQ(wm.size(), 0u);
}

// Bricks and keyframe depths are written by libdeflate as zlib streams: zlib reads what we write
// and we read what zlib wrote (maps saved by earlier builds), and a damaged stream is refused.
TEST(WorldModel, SpillStreamsAreZlibsBothWays) {
  std::mt19937 rng(3);
  const auto brick = randomBrick(Eigen::Vector3i(1, 2, 3), rng);
  const std::size_t n = sizeof(brick->voxels);
  const std::vector<std::uint8_t> ours = zlibCompress(brick->voxels, n);
  ASSERT_FALSE(ours.empty());
  std::vector<std::uint8_t> back(n);
  uLongf len = uLongf(n);
  ASSERT_EQ(uncompress(back.data(), &len, ours.data(), uLong(ours.size())), Z_OK);
  EXPECT_EQ(len, n);
  EXPECT_EQ(std::memcmp(back.data(), brick->voxels, n), 0);

  std::vector<std::uint8_t> theirs(compressBound(uLong(n)));
  uLongf theirs_len = uLongf(theirs.size());
  ASSERT_EQ(compress2(theirs.data(), &theirs_len, reinterpret_cast<const Bytef*>(brick->voxels), uLong(n), 1), Z_OK);
  Brick read;
  ASSERT_TRUE(zlibUncompress(theirs.data(), theirs_len, read.voxels, n));
  EXPECT_TRUE(sameVoxels(read, *brick));

  EXPECT_FALSE(zlibUncompress(theirs.data(), theirs_len / 2, read.voxels, n));  // truncated
  std::vector<std::uint8_t> shorter(compressBound(uLong(n)));
  uLongf shorter_len = uLongf(shorter.size());
  ASSERT_EQ(compress2(shorter.data(), &shorter_len, reinterpret_cast<const Bytef*>(brick->voxels), uLong(n - 6), 1), Z_OK);
  EXPECT_FALSE(zlibUncompress(shorter.data(), shorter_len, read.voxels, n));  // whole, but a voxel short
  EXPECT_FALSE(zlibUncompress(theirs.data(), theirs_len, read.voxels, n - 6));  // not the length expected
  std::vector<std::uint8_t> flipped = ours;
  flipped[flipped.size() - 1] ^= 0x5a;  // the Adler-32 check
  EXPECT_FALSE(zlibUncompress(flipped.data(), flipped.size(), read.voxels, n));
  EXPECT_TRUE(zlibCompress(brick->voxels, 0).empty());
  EXPECT_TRUE(zlibUncompress(nullptr, 0, read.voxels, 0));
}

// A released place is written again: best fit, the rest stays free, neighbours merge.
TEST(WorldModel, SpillFileWritesReleasedPlacesAgain) {
  const std::string dir = test::tempDir("spill_reuse");
  SpillFile f(dir, "a test spill file");
  const auto bytes = [](std::size_t n, std::uint8_t v) { return std::vector<std::uint8_t>(n, v); };
  const SpillFile::Record a = *f.append(bytes(100, 1)), b = *f.append(bytes(50, 2)), c = *f.append(bytes(80, 3));
  const SpillFile::Record d = *f.append(bytes(10, 4));
  EXPECT_EQ(f.bytes(), 240u);
  f.release(c);
  f.release(a);
  EXPECT_EQ(f.freeBytes(), 180u);
  const SpillFile::Record e = *f.append(bytes(70, 5));  // best fit: c's 80, not a's 100
  EXPECT_EQ(e.offset, c.offset);
  EXPECT_EQ(f.freeBytes(), 110u);
  f.release(b);  // merges with a before it (and not with e's rest, which is not next to it)
  const SpillFile::Record g = *f.append(bytes(150, 6));
  EXPECT_EQ(g.offset, a.offset);
  EXPECT_EQ(f.bytes(), 240u);  // nothing appended at the end
  EXPECT_EQ(f.freeBytes(), 10u);
  EXPECT_EQ(f.freePlaces(), 1u);  // e's rest
  EXPECT_EQ(f.read(g), bytes(150, 6));
  EXPECT_EQ(f.read(e), bytes(70, 5));
  EXPECT_EQ(f.read(d), bytes(10, 4));
  const SpillFile::Record h = *f.append(bytes(11, 7));  // larger than any free place: at the end
  EXPECT_EQ(h.offset, 240u);
  // A record the file does not hold (a disk that lost it) is an error naming where the file is.
  try {
    f.read(SpillFile::Record{1000, 10});
    ADD_FAILURE() << "read past the end";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()).rfind(dir + ": cannot read a test spill file: short file", 0), 0u)
        << e.what();
  }
}

// A spill file that cannot be made (or written) answers no place instead of throwing: the first
// failure is kept, and later appends try nothing more.
TEST(WorldModel, SpillFileThatCannotBeMadeAnswersNoPlace) {
  const std::string dir = test::tempDir("spill_file_none");
  std::ofstream(dir + "/a_file") << "not a folder";
  SpillFile f(dir + "/a_file/spill", "the test's spill file");
  EXPECT_FALSE(f.append(std::vector<std::uint8_t>(100, 1)).has_value());
  EXPECT_EQ(f.failure(), dir + "/a_file/spill: cannot create the test's spill file: Not a directory");
  EXPECT_FALSE(f.append(std::vector<std::uint8_t>(10, 2)).has_value());
  EXPECT_EQ(f.bytes(), 0u);
}

// A spill file at the most its records' places can say (1 TiB; 200 bytes here) fails as a full disk
// does: what would go to it stays in RAM. A place past it was cut to 40 bits, and the record written
// over the file's start.
TEST(WorldModel, ASpillFileAtItsMostAnswersNoPlace) {
  const std::string dir = test::tempDir("spill_file_full");
  SpillFile f(dir, "the test's spill file", 200);
  const SpillFile::Record a = *f.append(std::vector<std::uint8_t>(150, 1));
  EXPECT_FALSE(f.append(std::vector<std::uint8_t>(60, 2)).has_value());
  EXPECT_EQ(f.failure(), dir + ": the test's spill file is full: 200 bytes, the most a record's place can say");
  EXPECT_EQ(f.read(a), std::vector<std::uint8_t>(150, 1));
  EXPECT_FALSE(f.append(std::vector<std::uint8_t>(10, 3)).has_value());  // the first failure is kept
  // The default is where a place stops fitting a Record.
  volatile std::uint64_t last = SpillFile::kMaxFileBytes - 1, past = SpillFile::kMaxFileBytes;  // no constant folding
  SpillFile::Record r{};
  r.offset = last;
  EXPECT_EQ(std::uint64_t(r.offset), SpillFile::kMaxFileBytes - 1);
  r.offset = past;
  EXPECT_EQ(std::uint64_t(r.offset), 0u);
}

// Walking back and forth over the same place: every brick taken back frees its place in the spill
// file, so the file stays at the size of one pass instead of growing by a pass each time.
TEST(WorldModel, SpillFileStaysAtTheSizeOfWhatIsStored) {
  std::mt19937 rng(11);
  WorldModel wm(4 * sizeof(Brick), test::tempDir("world_model_back_and_forth"));
  std::size_t after_first = 0;
  for (int pass = 0; pass < 20; ++pass) {
    std::vector<std::unique_ptr<Brick>> copies;
    for (int i = 0; i < 60; ++i) {
      auto b = randomBrick(Eigen::Vector3i(i, pass % 3, 0), rng);  // new contents: other sizes each pass
      copies.push_back(std::make_unique<Brick>(*b));
      wm.put(std::move(b));
    }
    for (const auto& c : copies) {
      const auto b = wm.take(c->coord);
      ASSERT_TRUE(b);
      EXPECT_TRUE(sameVoxels(*b, *c)) << "pass " << pass << ", brick " << c->coord.transpose();
    }
    if (pass == 0) after_first = wm.stats().spill_file_bytes;
  }
  const WorldModelStats st = wm.stats();
  EXPECT_GE(st.spilled, 20u * 56u);
  EXPECT_GT(after_first, 0u);
  EXPECT_LT(st.spill_file_bytes, 2 * after_first);  // append-only: ~20x
  EXPECT_EQ(st.spill_free_bytes, st.spill_file_bytes);  // everything was taken back
}

TEST(WorldModel, StreamedMeshEqualsOneShotMesh) {
  // Bricks of a sphere's TSDF, meshed at once and region by region (regions of 2^3 bricks: many seams).
  std::vector<std::unique_ptr<Brick>> store;
  std::vector<BrickRef> refs;
  std::vector<Eigen::Vector3i> coords;
  const float vs = 0.01f, r = 0.23f;
  for (int bz = -4; bz < 4; ++bz)
    for (int by = -4; by < 4; ++by)
      for (int bx = -4; bx < 4; ++bx) {
        auto b = std::make_unique<Brick>();
        b->coord = Eigen::Vector3i(bx, by, bz);
        bool any = false;
        for (int z = 0; z < 8; ++z)
          for (int y = 0; y < 8; ++y)
            for (int x = 0; x < 8; ++x) {
              const Eigen::Vector3f p = (b->coord * 8 + Eigen::Vector3i(x, y, z)).cast<float>() * vs;
              const float d = (p.norm() - r) / 0.04f;
              if (std::fabs(d) >= 1.f) continue;
              Voxel& v = b->voxels[Brick::index(x, y, z)];
              v.tsdf = static_cast<std::int16_t>(d * kTsdfScale);
              v.weight = 5;
              v.r = static_cast<std::uint8_t>(100 + x);
              any = true;
            }
        if (!any) continue;
        refs.push_back({b->coord, b.get()});
        coords.push_back(b->coord);
        store.push_back(std::move(b));
      }
  const TriangleMesh once = marchingCubes(refs, vs);
  const auto fetch = [&](const Eigen::Vector3i& c, Brick&) -> const Brick* {
    for (const auto& r : refs)
      if (r.coord == c) return r.brick;
    return nullptr;
  };
  const TriangleMesh streamed = marchingCubesStreamed(coords, fetch, vs, 1, 2);
  ASSERT_GT(once.faces.size(), 1000u);
  EXPECT_EQ(streamed.faces.size(), once.faces.size());
  EXPECT_EQ(streamed.vertices.size(), once.vertices.size());  // seams welded: no duplicate vertex
  EXPECT_LE(maxNearest(streamed, once, vs), 1e-6);
  EXPECT_LE(maxNearest(once, streamed, vs), 1e-6);
}

TEST(WorldModel, VolumeWithEverythingOnDiskKeepsItsMapAndSavesIt) {
  // The corridor fused at its true poses with no RAM cache at all: every brick that leaves is on disk.
  const sim::SyntheticSequence seq(corridor(60));
  KinFuParams ram = smallKinFu(1024), disk = smallKinFu(0);
  TrackedMap a(ram, TrackingMode::Odometry, *seq.render(0).groundTruth), b(disk, TrackingMode::Odometry, *seq.render(0).groundTruth);
  for (std::size_t i = 0; i < seq.size(); ++i) {
    const Frame f = seq.render(i);
    a.integrateAt(f, *f.groundTruth);
    b.integrateAt(f, *f.groundTruth);
  }
  const KinFuStats sb = b.stats();
  ASSERT_GT(sb.shifts, 2u);
  ASSERT_GT(sb.world.spilled, 20u);
  EXPECT_EQ(sb.world.ram_bytes, 0u);
  EXPECT_EQ(a.stats().world.spilled, 0u);
  const TriangleMesh ma = a.extractMesh(), mb = b.extractMesh();
  EXPECT_EQ(ma.faces.size(), mb.faces.size());
  EXPECT_EQ(ma.vertices.size(), mb.vertices.size());
  EXPECT_LE(maxNearest(mb, ma, 0.01f), 1e-6);

  // Save and load at the volume level: the same bricks. The bricks on disk go into the save as stored,
  // none read back and compressed again (a long run's checkpoint spent most of its time so), and the
  // save is the one of the map held in RAM.
  std::stringstream ss, ss_ram;
  const std::size_t reloaded = b.stats().world.reloaded;
  b.volume().save(ss);
  EXPECT_EQ(b.stats().world.reloaded, reloaded);
  a.volume().save(ss_ram);
  EXPECT_EQ(ss.str().size(), ss_ram.str().size());
  TsdfVolume back(disk.tsdf, Eigen::Vector3f::Zero());
  back.load(ss);
  EXPECT_EQ(back.bricksInVolume(), b.volume().bricksInVolume());
  EXPECT_EQ(back.bricksInWorldModel(), b.volume().bricksInWorldModel());
  EXPECT_EQ(back.minCorner(), b.volume().minCorner());
  EXPECT_EQ(back.extractMesh().faces.size(), mb.faces.size());
  // A truncated stream is an error, not a partial map.
  const std::string bytes = ss.str();
  std::stringstream cut(bytes.substr(0, bytes.size() / 2));
  TsdfVolume broken(disk.tsdf, Eigen::Vector3f::Zero());
  EXPECT_THROW(broken.load(cut), std::runtime_error);
  // Coordinates the checksums do not cover: the volume's origin (bytes 20-31) and the first brick's
  // (bytes 40-51), each made one the world model's keys cannot hold. Taken, the brick was stored
  // wrapped around (x = 2^20 + 5 read back as -2^20 + 5), the origin overflowed the volume's indices.
  for (const auto& [offset, value, why] : {std::tuple{20, std::int32_t(2147483640), "origin out of range"},
                                           std::tuple{40, std::int32_t((1 << 20) + 5), "coordinates out of range"}}) {
    std::string flipped = bytes;
    std::memcpy(&flipped[offset], &value, sizeof(value));
    std::stringstream in(flipped);
    TsdfVolume corrupt(disk.tsdf, Eigen::Vector3f::Zero());
    try {
      corrupt.load(in);
      ADD_FAILURE() << why << ": loaded";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
    }
  }
}

TEST(WorldModel, SaveThenResumeGivesTheMeshOfOneRun) {
  // 60 corridor frames fused in one run, and as 30 + save + resume + 30 (fusion at the true poses, the
  // world model spilling to disk in both).
  const sim::SyntheticSequence seq(corridor(60));
  const KinFuParams p = smallKinFu(0);
  const auto start = *seq.render(0).groundTruth;
  TrackedMap one(p, TrackingMode::Odometry, start);
  for (std::size_t i = 0; i < seq.size(); ++i) {
    const Frame f = seq.render(i);
    one.integrateAt(f, *f.groundTruth);
  }
  const std::string file = test::tempDir("world_model_resume") + "/map.vfmap";
  {
    TrackedMap first(p, TrackingMode::Odometry, start);
    for (std::size_t i = 0; i < 30; ++i) {
      const Frame f = seq.render(i);
      first.integrateAt(f, *f.groundTruth);
    }
    first.save(file);
  }
  TrackedMap second(p, TrackingMode::Odometry);  // anchored elsewhere: resume() brings map and pose back
  second.resume(file);
  EXPECT_LT(second.pose().distanceTo(*seq.render(29).groundTruth), 1e-9);
  for (std::size_t i = 30; i < seq.size(); ++i) {
    const Frame f = seq.render(i);
    second.integrateAt(f, *f.groundTruth);
  }
  const TriangleMesh m1 = one.extractMesh(), m2 = second.extractMesh();
  ASSERT_GT(m1.faces.size(), 10000u);
  EXPECT_LE(maxNearest(m2, m1, p.tsdf.voxel_size), p.tsdf.voxel_size);
  EXPECT_LE(maxNearest(m1, m2, p.tsdf.voxel_size), p.tsdf.voxel_size);
  EXPECT_NEAR(double(m2.faces.size()), double(m1.faces.size()), 0.01 * m1.faces.size());
}

TEST(WorldModel, CorruptOrTruncatedSaveFileIsAOneLineError) {
  const std::string dir = test::tempDir("world_model_corrupt");
  const std::string bad = dir + "/bad.vfmap";
  std::ofstream(bad) << "VOFUSION-MAP 1\n";  // the magic's start, then nothing
  std::string out;
  const int rc = test::run(test::app("vofusion") + " synthetic --max-frames 2 --out " + dir + "/run --resume " + bad, &out);
  EXPECT_EQ(rc, 2) << out;  // bad input; an abort (an exception no one caught) also wrote two lines
  // One line, the last, naming the file: no usage dump, no stack of messages.
  std::size_t lines = 0;
  for (char c : out) lines += c == '\n';
  EXPECT_LE(lines, 2u) << out;  // the app's start line may precede it
  const std::size_t last = out.rfind('\n', out.size() >= 2 ? out.size() - 2 : 0);
  const std::string last_line = out.substr(last == std::string::npos ? 0 : last + 1);
  EXPECT_EQ(last_line.rfind("vofusion: error: " + bad + ": ", 0), 0u) << out;
  TrackedMap kf(KinFuParams(), TrackingMode::Odometry);
  EXPECT_THROW(kf.resume(bad), InputError);
  EXPECT_THROW(kf.resume(dir + "/missing.vfmap"), InputError);
}

// A flipped bit that every range check lets through: a brick's coordinate (the brick went elsewhere) or
// the camera pose (the camera somewhere). The map ends with its checksum (layout 2) and is refused in one
// line; a map of layout 1 (no checksum) is still read, its pose checked to be a rotation.
TEST(WorldModel, ASavedMapWithAFlippedBitIsRefused) {
  const sim::SyntheticSequence seq(corridor(4));
  const KinFuParams p = smallKinFu(0);
  TrackedMap first(p, TrackingMode::Odometry, *seq.render(0).groundTruth);
  for (std::size_t i = 0; i < seq.size(); ++i) {
    const Frame f = seq.render(i);
    first.integrateAt(f, *f.groundTruth);
  }
  const std::string dir = test::tempDir("world_model_flipped");
  first.save(dir + "/map.vfmap");
  std::ifstream in(dir + "/map.vfmap", std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), {});
  ASSERT_EQ(bytes.compare(0, 15, "VOFUSION-MAP 2\n"), 0);
  ASSERT_EQ(bytes.compare(bytes.size() - 20, 8, "CHECKSUM"), 0);
  const auto refusal = [&](const std::string& name, const std::string& content) {
    std::ofstream(dir + "/" + name, std::ios::binary) << content;
    TrackedMap kf(p, TrackingMode::Odometry);
    try {
      kf.resume(dir + "/" + name);
      return std::string("read");
    } catch (const InputError& e) {
      return std::string(e.what());
    }
  };
  // The first brick's x: after the magic (16), the pose (128), the volume's header (magic 16, 3 numbers
  // 12, origin 12, count 8).
  std::string flipped = bytes;
  flipped[16 + 128 + 16 + 12 + 12 + 8] ^= 0x04;
  EXPECT_EQ(refusal("brick.vfmap", flipped), dir + "/brick.vfmap: truncated or corrupt map: its checksum does not match (a damaged byte)");
  std::string pose = bytes;
  pose[16 + 8 * 1] ^= 0x01;  // a rotation entry, off by an ulp or so
  EXPECT_NE(refusal("pose.vfmap", pose).find("checksum does not match"), std::string::npos);
  // Layout 1: the same without the trailer.
  std::string v1 = bytes.substr(0, bytes.size() - 20);
  v1[13] = '1';
  EXPECT_EQ(refusal("v1.vfmap", v1), "read");
  std::string v1_brick = v1;  // the brick flipped above passes every range check: only the checksum sees it
  v1_brick[16 + 128 + 16 + 12 + 12 + 8] ^= 0x04;
  EXPECT_EQ(refusal("v1brick.vfmap", v1_brick), "read");
  std::string v1_pose = v1;
  v1_pose[16 + 8 * 0 + 7] ^= 0x10;  // R(0,0)'s exponent: no longer a rotation
  EXPECT_EQ(refusal("v1pose.vfmap", v1_pose), dir + "/v1pose.vfmap: truncated or corrupt map (camera pose)");
}
