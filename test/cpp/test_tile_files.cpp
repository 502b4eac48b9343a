// Tiles by reference: the map worker reads tile files itself and folds them into the NDT target. The truth is a
// from-scratch build of the same window's points.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "grid_puzzle_localization/map_update_worker.hpp"
#include "synthetic_world.hpp"
#include "tile_files.hpp"

namespace gpl = grid_puzzle_localization;

namespace {

class TempDir {
 public:
  TempDir() {
    char name[] = "/tmp/gpl_tiles_XXXXXX";
    if (!mkdtemp(name)) throw std::runtime_error("mkdtemp failed");
    path = name;
  }
  ~TempDir() { std::system(("rm -rf '" + path + "'").c_str()); }
  std::string path;
};

gpl::PointCloud concat(const std::map<std::string, gpl::PointCloud>& tiles, const std::vector<std::string>& ids) {
  gpl::PointCloud out;
  for (const auto& id : ids) out.insert(out.end(), tiles.at(id).begin(), tiles.at(id).end());
  return out;
}

// Same voxels with bit-identical statistics and Gaussians.
void expectExactlyEqual(const gpl::VoxelMap& a, const gpl::VoxelMap& b) {
  ASSERT_EQ(a.voxelCount(), b.voxelCount());
  ASSERT_EQ(a.gaussianCount(), b.gaussianCount());
  ASSERT_EQ(a.pointCount(), b.pointCount());
  a.forEach([&](const gpl::VoxelKey& key, const gpl::VoxelStats& st, const gpl::VoxelGaussian& g) {
    const gpl::VoxelStats* o = b.stats(key);
    ASSERT_NE(o, nullptr);
    EXPECT_EQ(o->count, st.count);
    for (int i = 0; i < 3; ++i) EXPECT_EQ(o->sum[i], st.sum[i]);
    for (int i = 0; i < 6; ++i) EXPECT_EQ(o->sum_sq[i], st.sum_sq[i]);
    const gpl::VoxelGaussian* h = b.find(key);
    ASSERT_EQ(h != nullptr, g.valid != 0);
    if (h) {
      EXPECT_EQ(h->mean, g.mean);
    }
  });
}

gpl::MapChange change(const std::string& dir, bool reset, std::vector<std::string> added,
                      std::vector<std::string> removed, double s, std::string revision = "r1",
                      std::vector<std::string> prefetch = {}) {
  gpl::TileFileChange f;
  f.dir = dir;
  f.index_revision = std::move(revision);
  f.reset = reset;
  f.added = std::move(added);
  f.removed = std::move(removed);
  f.prefetch = std::move(prefetch);
  return gpl::MapChange::tileFiles(s, std::move(f));
}

struct TiledWorld {
  explicit TiledWorld(double s) : s(s), tiles(gpl::test::cutTileStems(gpl::test::makeWorld(), s)) {
    gpl::test::writeTiles(dir.path, tiles);
    for (const auto& [id, cloud] : tiles) ids.push_back(id);
  }
  double s;
  TempDir dir;
  std::map<std::string, gpl::PointCloud> tiles;
  std::vector<std::string> ids;
};

}  // namespace

TEST(TileFiles, VoxelsPerTileSide) {
  EXPECT_EQ(gpl::voxelsPerTileSide(2.0, 1.0), 2);
  EXPECT_EQ(gpl::voxelsPerTileSide(2.0, 0.5), 4);
  EXPECT_EQ(gpl::voxelsPerTileSide(3.0, 1.5), 2);
  EXPECT_EQ(gpl::voxelsPerTileSide(0.6, 0.2), 3);  // 0.6 / 0.2 is 2.9999999999999996 in double
  EXPECT_EQ(gpl::voxelsPerTileSide(2.5, 1.0), 0);
  EXPECT_EQ(gpl::voxelsPerTileSide(1.0, 2.0), 0);
  EXPECT_EQ(gpl::voxelsPerTileSide(0.0, 1.0), 0);
}

TEST(TileFiles, TileKeyOfStem) {
  const gpl::TileKey k = gpl::tileKeyOfStem("-3.0_5.0", 2.0);
  EXPECT_EQ(k.i, -2);
  EXPECT_EQ(k.j, 2);
  EXPECT_THROW(gpl::tileKeyOfStem("3.0", 2.0), std::invalid_argument);
  EXPECT_THROW(gpl::tileKeyOfStem("a_b", 2.0), std::invalid_argument);
  EXPECT_THROW(gpl::tileKeyOfStem("1.0_2.0x", 2.0), std::invalid_argument);
}

TEST(TileFiles, AddAndRemoveByReferenceEqualsAFromScratchBuildExactly) {
  for (const double resolution : {1.0, 0.5}) {
    SCOPED_TRACE(resolution);
    TiledWorld w(2.0);
    ASSERT_GE(w.ids.size(), 100u);
    gpl::VoxelMapParams params;
    params.resolution = resolution;
    gpl::MapUpdateWorker worker(params);
    const std::vector<std::string> first(w.ids.begin(), w.ids.begin() + 60);
    worker.submit(change(w.dir.path, true, first, {}, w.s));
    worker.waitIdle();  // the slide would otherwise join the first change, and its leaving tiles go unread
    // Slide: 20 leave, 25 enter, one is read again in place, an unknown id leaves.
    std::vector<std::string> enter(w.ids.begin() + 60, w.ids.begin() + 85);
    enter.push_back(w.ids[30]);
    std::vector<std::string> leave(w.ids.begin(), w.ids.begin() + 20);
    leave.push_back("999.0_999.0");
    worker.submit(change(w.dir.path, false, enter, leave, w.s));
    worker.waitIdle();
    EXPECT_TRUE(worker.takeErrors().empty());
    const auto incremental = worker.takeReady();
    ASSERT_NE(incremental, nullptr);
    const gpl::MapUpdateStats st = worker.stats();
    EXPECT_TRUE(st.tile_aligned);
    EXPECT_EQ(st.tiles, 65u);
    EXPECT_EQ(st.tiles_read, 86u);
    EXPECT_EQ(st.points_outside, 0u);

    gpl::NdtTarget reference(params);
    reference.setTarget(concat(w.tiles, std::vector<std::string>(w.ids.begin() + 20, w.ids.begin() + 85)));
    expectExactlyEqual(*incremental, *reference.snapshot());
    // Memory per voxel is the pcd mode's: the same storage, nothing per tile.
    EXPECT_EQ(incremental->voxelCount(), reference.snapshot()->voxelCount());
  }
}

TEST(TileFiles, SideNotAMultipleOfTheResolutionFallsBackToKeptStatistics) {
  TiledWorld w(2.5);  // resolution 1 m: voxels straddle tile borders
  gpl::MapUpdateWorker worker{gpl::VoxelMapParams()};
  worker.submit(change(w.dir.path, true, std::vector<std::string>(w.ids.begin(), w.ids.begin() + 40), {}, w.s));
  worker.submit(change(w.dir.path, false, {}, std::vector<std::string>(w.ids.begin(), w.ids.begin() + 10), w.s));
  worker.waitIdle();
  EXPECT_TRUE(worker.takeErrors().empty());
  EXPECT_FALSE(worker.stats().tile_aligned);
  const auto incremental = worker.takeReady();
  gpl::NdtTarget reference{gpl::VoxelMapParams()};
  reference.setTarget(concat(w.tiles, std::vector<std::string>(w.ids.begin() + 10, w.ids.begin() + 40)));
  const auto ref = reference.snapshot();
  ASSERT_EQ(incremental->voxelCount(), ref->voxelCount());
  ASSERT_EQ(incremental->pointCount(), ref->pointCount());
  // Subtraction leaves double round-off in straddling voxels: equal to far below the float Gaussians.
  incremental->forEach([&](const gpl::VoxelKey& key, const gpl::VoxelStats& st, const gpl::VoxelGaussian&) {
    const gpl::VoxelStats* o = ref->stats(key);
    ASSERT_NE(o, nullptr);
    EXPECT_EQ(o->count, st.count);
    EXPECT_LT((o->sum - st.sum).norm(), 1e-9);
  });
}

TEST(NdtTarget, AddTileDropsPointsWhoseVoxelLiesInAnotherTile) {
  gpl::NdtTarget target{gpl::VoxelMapParams()};
  const gpl::PointCloud pts = {{0.5f, 0.5f, 0.0f}, {1.5f, 1.9f, 0.0f}, {2.1f, 0.5f, 0.0f}, {-0.1f, 0.5f, 0.0f}};
  EXPECT_EQ(target.addTile({0, 0}, 2.0, pts), 2u);
  EXPECT_EQ(target.snapshot()->pointCount(), 2u);
  EXPECT_THROW(target.addTile({0, 0}, 2.5, pts), std::invalid_argument);
  target.removeTiles({{0, 0}}, 2.0);
  EXPECT_EQ(target.snapshot()->voxelCount(), 0u);
}

TEST(TileVoxels, EqualTheStatisticsOfAFromScratchBuildOfTheTilesOwnPoints) {
  // Tile (1, -2) of side 2 m covers [2, 4) x [-4, -2); the points spill 0.5 m over each border and one is NaN. They
  // span 40 m in height: 160 voxels, more than the first voxel table of tileVoxels holds.
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> x(1.5f, 4.5f), y(-4.5f, -1.5f), z(-20.0f, 20.0f);
  gpl::PointCloud points, own;
  for (int i = 0; i < 3000; ++i) {
    const gpl::Point p(x(rng), y(rng), z(rng));
    points.push_back(p);
    if (p.x() >= 2.0f && p.x() < 4.0f && p.y() >= -4.0f && p.y() < -2.0f) own.push_back(p);
  }
  points.push_back(gpl::Point(NAN, 3.0f, 0.0f));
  const gpl::TileVoxels tile = gpl::tileVoxels({1, -2}, 2.0, 1.0, points);
  EXPECT_EQ(tile.outside, points.size() - 1 - own.size());
  const auto reference = gpl::voxelStatistics(own, 1.0, 1);
  ASSERT_EQ(tile.voxels.size(), reference.size());
  std::map<std::tuple<int, int, int>, gpl::VoxelStats> by_key;
  for (const auto& [k, st] : reference) by_key[{k.x, k.y, k.z}] = st;
  for (std::size_t i = 0; i < tile.voxels.size(); ++i) {
    const auto& [k, st] = tile.voxels[i];
    if (i > 0) {
      EXPECT_LT(std::make_tuple(tile.voxels[i - 1].first.x, tile.voxels[i - 1].first.y, tile.voxels[i - 1].first.z),
                std::make_tuple(k.x, k.y, k.z));
    }
    const gpl::VoxelStats& o = by_key.at({k.x, k.y, k.z});
    EXPECT_EQ(o.count, st.count);
    for (int a = 0; a < 3; ++a) EXPECT_EQ(o.sum[a], st.sum[a]);
    for (int a = 0; a < 6; ++a) EXPECT_EQ(o.sum_sq[a], st.sum_sq[a]);
  }
  EXPECT_THROW(gpl::tileVoxels({0, 0}, 2.5, 1.0, points), std::invalid_argument);
}

TEST(TileFiles, MissingAndCorruptTilesAreReportedByFileAndTheRestIsLoaded) {
  TiledWorld w(2.0);
  const std::string missing = w.ids[3], truncated = w.ids[4], garbage = w.ids[5];
  std::remove((w.dir.path + "/" + missing + ".pcd").c_str());
  truncate((w.dir.path + "/" + truncated + ".pcd").c_str(), 150);
  std::ofstream(w.dir.path + "/" + garbage + ".pcd") << "not a pcd file\n";
  gpl::MapUpdateWorker worker{gpl::VoxelMapParams()};
  worker.submit(change(w.dir.path, true, std::vector<std::string>(w.ids.begin(), w.ids.begin() + 10), {}, w.s));
  worker.waitIdle();
  const auto errors = worker.takeErrors();
  ASSERT_EQ(errors.size(), 3u);
  for (const std::string& id : {missing, truncated, garbage}) {
    bool named = false;
    for (const auto& e : errors) named |= e.find(w.dir.path + "/" + id + ".pcd") != std::string::npos;
    EXPECT_TRUE(named) << id;
  }
  EXPECT_EQ(worker.stats().tiles, 7u);
  std::vector<std::string> good(w.ids.begin(), w.ids.begin() + 10);
  good.erase(good.begin() + 3, good.begin() + 6);
  gpl::NdtTarget reference{gpl::VoxelMapParams()};
  reference.setTarget(concat(w.tiles, good));
  expectExactlyEqual(*worker.takeReady(), *reference.snapshot());
}

TEST(TileFiles, AMissingDirectoryOrAnUnannouncedNewRevisionKeepsTheLoadedMap) {
  TiledWorld w(2.0);
  gpl::MapUpdateWorker worker{gpl::VoxelMapParams()};
  worker.submit(change(w.dir.path, true, std::vector<std::string>(w.ids.begin(), w.ids.begin() + 10), {}, w.s));
  worker.waitIdle();
  const std::size_t points = worker.takeReady()->pointCount();
  ASSERT_GT(points, 0u);

  worker.submit(change("/nonexistent/tiles", true, {w.ids[20]}, {}, w.s));
  worker.submit(change(w.dir.path, false, {w.ids[21]}, {w.ids[0]}, w.s, "r2"));
  worker.waitIdle();
  const auto errors = worker.takeErrors();
  ASSERT_EQ(errors.size(), 2u);
  EXPECT_NE(errors[0].find("/nonexistent/tiles"), std::string::npos);
  EXPECT_NE(errors[0].find("does not exist"), std::string::npos);
  EXPECT_NE(errors[1].find("r2"), std::string::npos);
  EXPECT_EQ(worker.takeReady()->pointCount(), points);
  EXPECT_EQ(worker.stats().tiles, 10u);

  // The directory is rewritten (new index revision) and announced by a reset: the new tiles are loaded.
  gpl::PointCloud moved = w.tiles.at(w.ids[0]);
  for (auto& p : moved) p.z() += 1.0f;
  gpl::test::writeBinaryPcd(w.dir.path + "/" + w.ids[0] + ".pcd", moved);
  worker.submit(change(w.dir.path, true, {w.ids[0]}, {}, w.s, "r2"));
  worker.waitIdle();
  EXPECT_TRUE(worker.takeErrors().empty());
  gpl::NdtTarget reference{gpl::VoxelMapParams()};
  reference.setTarget(moved);
  expectExactlyEqual(*worker.takeReady(), *reference.snapshot());
}

TEST(TileFiles, AResetOfTheSameSourceReadsOnlyTheTilesNotHeldAndAnnouncesOnlyThem) {
  // A respawned provider sends its whole window again as a reset. The held tiles stay (and are not in flight: the
  // track goes on matching on them), those it no longer names leave, and a tile that failed before is read again.
  TiledWorld w(2.0);
  gpl::MapUpdateWorker worker{gpl::VoxelMapParams()};
  const std::string missing = w.dir.path + "/" + w.ids[3] + ".pcd";
  ASSERT_EQ(std::rename(missing.c_str(), (missing + ".away").c_str()), 0);
  worker.submit(change(w.dir.path, true, std::vector<std::string>(w.ids.begin(), w.ids.begin() + 10), {}, w.s));
  worker.waitIdle();
  ASSERT_EQ(worker.takeErrors().size(), 1u);  // the missing tile
  ASSERT_EQ(worker.stats().tiles, 9u);
  while (worker.takeSnapshot()) {
  }
  const std::size_t read_before = worker.stats().tiles_read;

  // The missing tile is back; the last tile of the new window comes through a FIFO, so the change stays in progress
  // until this test writes it.
  ASSERT_EQ(std::rename((missing + ".away").c_str(), missing.c_str()), 0);
  const std::string fifo = w.dir.path + "/" + w.ids[12] + ".pcd";
  ASSERT_EQ(std::remove(fifo.c_str()), 0);
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  const std::vector<std::string> window(w.ids.begin() + 2, w.ids.begin() + 13);
  worker.submit(change(w.dir.path, true, window, {}, w.s));
  std::optional<gpl::MapSnapshot> announced;
  for (int i = 0; i < 1000 && !announced; ++i) {
    announced = worker.takeSnapshot();
    if (!announced) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_TRUE(announced.has_value()) << "no snapshot while the change waits on the FIFO";
  std::vector<gpl::TileKey> expected;
  for (const int i : {3, 10, 11, 12}) expected.push_back(gpl::tileKeyOfStem(w.ids[i], w.s));
  std::vector<gpl::TileKey> in_flight = announced->in_flight.keys;
  const auto order = [](const gpl::TileKey& a, const gpl::TileKey& b) {
    return std::tie(a.i, a.j) < std::tie(b.i, b.j);
  };
  std::sort(expected.begin(), expected.end(), order);
  std::sort(in_flight.begin(), in_flight.end(), order);
  EXPECT_EQ(in_flight, expected);
  gpl::test::writeBinaryPcd(fifo, w.tiles.at(w.ids[12]));
  worker.waitIdle();
  EXPECT_TRUE(worker.takeErrors().empty());
  EXPECT_EQ(worker.stats().tiles, window.size());
  EXPECT_EQ(worker.stats().tiles_read - read_before, 4u);
  gpl::NdtTarget reference{gpl::VoxelMapParams()};
  reference.setTarget(concat(w.tiles, window));
  expectExactlyEqual(*worker.takeReady(), *reference.snapshot());
}

TEST(TileFiles, PrefetchedTilesAreServedFromTheCacheWithinTheBudget) {
  TiledWorld w(2.0);
  gpl::MapUpdateWorker worker{gpl::VoxelMapParams()};
  const std::vector<std::string> ahead(w.ids.begin() + 10, w.ids.begin() + 20);
  worker.submit(
      change(w.dir.path, true, std::vector<std::string>(w.ids.begin(), w.ids.begin() + 10), {}, w.s, "r1", ahead));
  worker.waitIdle();
  gpl::MapUpdateStats st = worker.stats();
  EXPECT_EQ(st.tiles_read, 20u);
  EXPECT_GT(st.cache_bytes, 0u);
  EXPECT_LE(st.cache_bytes, static_cast<std::size_t>(gpl::MapUpdateWorker::kDefaultTileCacheMb * 1024 * 1024));
  // They enter: no file is read again, and the cache no longer holds them (no second copy).
  worker.submit(change(w.dir.path, false, ahead, {}, w.s));
  worker.waitIdle();
  st = worker.stats();
  EXPECT_EQ(st.tiles_read, 20u);
  EXPECT_EQ(st.cache_hits, 10u);
  EXPECT_EQ(st.cache_bytes, 0u);
  gpl::NdtTarget reference{gpl::VoxelMapParams()};
  reference.setTarget(concat(w.tiles, std::vector<std::string>(w.ids.begin(), w.ids.begin() + 20)));
  expectExactlyEqual(*worker.takeReady(), *reference.snapshot());

  // A budget of 0 turns prefetch off.
  worker.setTileCacheMb(0.0);
  worker.submit(change(w.dir.path, false, {}, {}, w.s, "r1", {w.ids[30]}));
  worker.waitIdle();
  EXPECT_EQ(worker.stats().tiles_read, 20u);
  EXPECT_THROW(worker.setTileCacheMb(-1.0), std::invalid_argument);
}

TEST(TileCache, EvictsTheOldestBeyondItsBudget) {
  gpl::TileVoxels ten;
  ten.voxels.resize(10);
  const std::size_t b = gpl::TileCache::bytesOf("a", ten);
  gpl::TileCache cache(2 * b);
  cache.put("a", ten);
  cache.put("b", ten);
  cache.put("c", ten);
  EXPECT_FALSE(cache.contains("a"));
  EXPECT_TRUE(cache.contains("b") && cache.contains("c"));
  EXPECT_EQ(cache.bytes(), 2 * b);
  gpl::TileVoxels big;
  big.voxels.resize(100);
  cache.put("big", big);
  EXPECT_FALSE(cache.contains("big"));
  ASSERT_TRUE(cache.take("b"));
  EXPECT_EQ(cache.bytes(), b);
  EXPECT_FALSE(cache.take("b"));
}

TEST(TileFiles, TheWorkersCpuTimeCoversItsReadsAndFolds) {
  TiledWorld w(2.0);
  gpl::MapUpdateWorker worker{gpl::VoxelMapParams()};
  EXPECT_EQ(worker.stats().worker_cpu_ms, 0.0);
  worker.submit(change(w.dir.path, true, w.ids, {}, w.s));
  worker.waitIdle();
  const gpl::MapUpdateStats stats = worker.stats();
  EXPECT_GT(stats.tile_read_cpu_ms, 0.0);
  // The thread's whole CPU time: its reads and folds, and the snapshot and bookkeeping around them.
  EXPECT_GE(stats.worker_cpu_ms, stats.tile_read_cpu_ms + stats.tile_fold_cpu_ms);
}
