#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "grid_puzzle_localization/map_update_worker.hpp"
#include "grid_puzzle_localization/ndt.hpp"
#include "synthetic_world.hpp"

namespace gpl = grid_puzzle_localization;

namespace {

gpl::PointCloud concat(const std::map<std::string, gpl::PointCloud>& tiles, const std::vector<std::string>& ids) {
  gpl::PointCloud out;
  for (const auto& id : ids) out.insert(out.end(), tiles.at(id).begin(), tiles.at(id).end());
  return out;
}

// Voxel-by-voxel comparison of two snapshots: same voxels, same Gaussians to float tolerance.
void expectSameMap(const gpl::VoxelMap& a, const gpl::VoxelMap& b) {
  ASSERT_EQ(a.voxelCount(), b.voxelCount());
  ASSERT_EQ(a.gaussianCount(), b.gaussianCount());
  ASSERT_EQ(a.pointCount(), b.pointCount());
  std::size_t checked = 0;
  a.forEach([&](const gpl::VoxelKey& key, const gpl::VoxelStats& stats, const gpl::VoxelGaussian& g) {
    const gpl::VoxelStats* other = b.stats(key);
    ASSERT_NE(other, nullptr);
    EXPECT_EQ(other->count, stats.count);
    if (!g.valid) return;
    const gpl::VoxelGaussian* h = b.find(key);
    ASSERT_NE(h, nullptr);
    EXPECT_LT((h->mean - g.mean).norm(), 1e-4f);
    ++checked;
  });
  EXPECT_GT(checked, 100u);
}

void writeAsciiPcd(std::ostream& os, const gpl::PointCloud& cloud) {
  os << "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH " << cloud.size()
     << "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " << cloud.size() << "\nDATA ascii\n";
  for (const auto& p : cloud) os << p.x() << ' ' << p.y() << ' ' << p.z() << '\n';
}

}  // namespace

TEST(MapUpdateWorker, TakeReadyHandsOutEachSnapshotOnce) {
  gpl::MapUpdateWorker worker{gpl::VoxelMapParams()};
  EXPECT_EQ(worker.takeReady(), nullptr);
  worker.submit(gpl::MapChange::fullCloud(gpl::test::makeWorld()));
  worker.waitIdle();
  EXPECT_FALSE(worker.busy());
  const auto snap = worker.takeReady();
  ASSERT_NE(snap, nullptr);
  EXPECT_GT(snap->gaussianCount(), 1000u);
  EXPECT_EQ(worker.takeReady(), nullptr);
  EXPECT_EQ(worker.stats().generation, 1u);
}

TEST(MapUpdateWorker, RetiredSnapshotIsFreedOnTheWorkerThread) {
  gpl::MapUpdateWorker worker{gpl::VoxelMapParams()};
  std::thread::id freed_on;
  std::shared_ptr<const gpl::VoxelMap> old(new gpl::VoxelMap(gpl::VoxelMapParams()), [&](const gpl::VoxelMap* m) {
    freed_on = std::this_thread::get_id();
    delete m;
  });
  worker.retire(std::move(old));
  worker.waitIdle();  // also waits until retired snapshots are dropped
  EXPECT_NE(freed_on, std::thread::id());
  EXPECT_NE(freed_on, std::this_thread::get_id());
  EXPECT_FALSE(worker.busy());  // releasing is not a map update
  EXPECT_EQ(worker.stats().generation, 0u);
  EXPECT_EQ(worker.takeReady(), nullptr);
}
TEST(MapUpdateWorker, TileSequenceEqualsASynchronousBuildOfTheRemainingTiles) {
  const auto tiles = gpl::test::cutTiles(gpl::test::makeWorld(), 10.0f);
  std::vector<std::string> ids;
  for (const auto& [id, cloud] : tiles) ids.push_back(id);
  ASSERT_GE(ids.size(), 20u);
  gpl::MapUpdateWorker worker{gpl::VoxelMapParams()};
  auto tileCloud = [&](const std::string& id) { return gpl::TileCloud{id, tiles.at(id)}; };
  // Window 1: first 12 tiles (reset), then slide: drop 4, add 4, replace one in place, remove an unknown id.
  std::vector<gpl::TileCloud> first;
  for (int i = 0; i < 12; ++i) first.push_back(tileCloud(ids[i]));
  worker.submit(gpl::MapChange::tiles(true, 0.0, first, {}));
  worker.submit(gpl::MapChange::tiles(false, 0.0, {tileCloud(ids[12]), tileCloud(ids[13]), tileCloud(ids[14])},
                                      {ids[0], ids[1], ids[2], "not_loaded"}));
  worker.submit(gpl::MapChange::tiles(false, 0.0, {tileCloud(ids[5]), tileCloud(ids[15])}, {ids[3]}));
  worker.waitIdle();
  const auto incremental = worker.takeReady();
  ASSERT_NE(incremental, nullptr);
  EXPECT_EQ(worker.stats().tiles, 12u);

  gpl::NdtTarget reference{gpl::VoxelMapParams()};
  std::vector<std::string> remaining;
  for (int i = 4; i <= 15; ++i) remaining.push_back(ids[i]);
  reference.setTarget(concat(tiles, remaining));
  expectSameMap(*incremental, *reference.snapshot());

  // And the same alignment result on both.
  const gpl::NdtAligner aligner;
  const Eigen::Isometry3d truth = gpl::test::poseXYYaw(-5.0, 0.0, 0.1, 1.5);
  const gpl::PointCloud scan = gpl::test::scanFrom(concat(tiles, remaining), truth, 25.0f, 0.01f, 1);
  const Eigen::Isometry3f guess = (gpl::test::poseXYYaw(0.3, -0.2, 0.05) * truth).cast<float>();
  const gpl::NdtResult a = aligner.align(*incremental, scan, guess);
  const gpl::NdtResult b = aligner.align(*reference.snapshot(), scan, guess);
  EXPECT_LT((a.transform - b.transform).norm(), 1e-4f);
  EXPECT_EQ(a.iterations, b.iterations);
  // A reset drops everything loaded before.
  worker.submit(gpl::MapChange::tiles(true, 0.0, {tileCloud(ids[0])}, {}));
  worker.waitIdle();
  EXPECT_EQ(worker.takeReady()->pointCount(), tiles.at(ids[0]).size());
}

TEST(MapUpdateWorker, AlignRunsAgainstTheOldSnapshotWhileAnUpdateIsBlocked) {
  // The worker reads a PCD from a FIFO that this test has not written yet, so the update is pending
  // for as long as the test wants, deterministically.
  const gpl::PointCloud world = gpl::test::makeWorld();
  gpl::MapUpdateWorker worker{gpl::VoxelMapParams()};
  worker.submit(gpl::MapChange::fullCloud(world));
  worker.waitIdle();
  const auto old_map = worker.takeReady();
  ASSERT_NE(old_map, nullptr);

  char dir_template[] = "/tmp/gpl_worker_XXXXXX";
  ASSERT_NE(mkdtemp(dir_template), nullptr);
  const std::string fifo = std::string(dir_template) + "/map.pcd";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  worker.submit(gpl::MapChange::pcdFile(fifo));

  const gpl::NdtAligner aligner;
  const Eigen::Isometry3d truth = gpl::test::poseXYYaw(2.0, 1.0, 0.2, 1.5);
  const gpl::PointCloud scan = gpl::test::scanFrom(world, truth, 25.0f, 0.01f, 2);
  for (int i = 0; i < 3; ++i) {
    EXPECT_TRUE(worker.busy());
    EXPECT_EQ(worker.takeReady(), nullptr);
    const gpl::NdtResult r = aligner.align(*old_map, scan, truth.cast<float>());
    EXPECT_LT((r.transform - truth.cast<float>().matrix()).norm(), 0.05f);
  }
  gpl::PointCloud shifted = world;
  for (auto& p : shifted) p.x() += 100.0f;
  {
    std::ofstream out(fifo);
    writeAsciiPcd(out, shifted);
  }
  worker.waitIdle();
  const auto new_map = worker.takeReady();
  ASSERT_NE(new_map, nullptr);
  EXPECT_EQ(new_map->pointCount(), world.size());
  EXPECT_NE(new_map->stats(new_map->keyOf(shifted.front())), nullptr);
  EXPECT_EQ(new_map->stats(new_map->keyOf(world.front())), nullptr);
  EXPECT_EQ(old_map->pointCount(), world.size());  // the old snapshot is untouched
  std::remove(fifo.c_str());
  rmdir(dir_template);
}

TEST(MapUpdateWorker, UnreadablePcdIsReportedWithItsPathAndKeepsTheTarget) {
  gpl::MapUpdateWorker worker{gpl::VoxelMapParams()};
  worker.submit(gpl::MapChange::fullCloud(gpl::test::makeWorld()));
  worker.submit(gpl::MapChange::pcdFile("/nonexistent/map.pcd"));
  worker.waitIdle();
  const auto errors = worker.takeErrors();
  ASSERT_EQ(errors.size(), 1u);
  EXPECT_NE(errors[0].find("/nonexistent/map.pcd"), std::string::npos);
  EXPECT_GT(worker.takeReady()->gaussianCount(), 1000u);
  EXPECT_TRUE(worker.takeErrors().empty());
}

TEST(MapUpdateWorker, RejectsBadParams) {
  gpl::VoxelMapParams p;
  p.resolution = -1.0;
  EXPECT_THROW(gpl::MapUpdateWorker{p}, std::invalid_argument);
}

namespace {

std::size_t residentBytes() {
  std::ifstream statm("/proc/self/statm");
  std::size_t pages = 0, resident = 0;
  statm >> pages >> resident;
  return resident * static_cast<std::size_t>(sysconf(_SC_PAGESIZE));
}

// Points on a 0.25 m lattice over a 100 m x 100 m x 3 m box: about 30,000 voxels of 1 m.
gpl::PointCloud denseBlock() {
  gpl::PointCloud cloud;
  for (float x = 0.f; x < 100.f; x += 0.25f)
    for (float y = 0.f; y < 100.f; y += 0.25f)
      for (float z = 0.f; z < 3.f; z += 1.f) cloud.emplace_back(x, y, z);
  return cloud;
}

}  // namespace

TEST(MapUpdateWorker, FreedMapMemoryGoesBackToTheSystemOnceTheWorkerIsIdle) {
  gpl::VoxelMapParams params;
  params.resolution = 1.0;
  gpl::MapUpdateWorker worker{params};
  worker.submit(gpl::MapChange::fullCloud(denseBlock()));
  worker.waitIdle();
  auto big = worker.takeReady();
  ASSERT_NE(big, nullptr);
  ASSERT_GT(big->gaussianCount(), 20000u);
  const std::size_t with_map = residentBytes();
  const std::size_t map_bytes = big->bytes();
  // A small map replaces it; the old one is retired as the scan thread does, and the worker frees it.
  worker.submit(gpl::MapChange::fullCloud(gpl::test::makeWorld(1.0f)));
  worker.waitIdle();
  auto small = worker.takeReady();
  ASSERT_NE(small, nullptr);
  worker.retire(std::move(big));
  worker.waitIdle();
  // Handed back after the worker's trim period (2 s) since its last change, without a further change. The deadline
  // leaves room for a busy machine: the worker runs niced (kWorkerNiceIncrement) and waits for a core there.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  std::size_t now = residentBytes();
  while (with_map - std::min(now, with_map) < map_bytes / 2 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    now = residentBytes();
  }
  EXPECT_GE(with_map - std::min(now, with_map), map_bytes / 2)
      << "resident " << with_map << " B with the map of " << map_bytes << " B, " << now << " B after it was freed";
}

namespace {

// The nice value (field 19 of /proc/self/task/TID/stat) of every thread of this process.
std::vector<int> threadNiceValues() {
  std::vector<int> out;
  for (const auto& task : std::filesystem::directory_iterator("/proc/self/task")) {
    std::ifstream stat(task.path() / "stat");
    std::string text((std::istreambuf_iterator<char>(stat)), std::istreambuf_iterator<char>());
    // The command name (field 2) may hold spaces: fields are counted after its closing parenthesis.
    std::istringstream rest(text.substr(text.rfind(')') + 2));
    std::string field;
    for (int i = 3; i <= 19 && rest >> field; ++i)
      if (i == 19) out.push_back(std::stoi(field));
  }
  return out;
}

}  // namespace

TEST(MapUpdateWorker, TheWorkerThreadIsNicerThanTheScanThread) {
  errno = 0;
  const int own = getpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)));
  ASSERT_EQ(errno, 0);
  if (own >= 19) GTEST_SKIP() << "the test runs at niceness 19 already: no thread can be nicer";
  const std::vector<int> before = threadNiceValues();
  gpl::MapUpdateWorker worker{gpl::VoxelMapParams()};
  worker.submit(gpl::MapChange::fullCloud(gpl::test::makeWorld()));
  worker.waitIdle();  // the thread lowered its priority before it took the change
  const std::vector<int> after = threadNiceValues();
  // The worker, and the OpenMP team it starts (whose threads inherit its niceness).
  const int expected = std::min(19, own + gpl::MapUpdateWorker::kWorkerNiceIncrement);
  EXPECT_GE(std::count(after.begin(), after.end(), expected), std::count(before.begin(), before.end(), expected) + 1);
}

namespace {

// Distances of `ids`' tile centres from `focus` along the farther axis [m]: the half side of the smallest square about
// the focus that holds the centre.
std::vector<double> squareDistances(const std::vector<std::string>& ids, const Eigen::Vector2d& focus, double s) {
  std::vector<double> out;
  for (const std::string& id : ids) {
    const gpl::TileKey k = gpl::tileKeyOfStem(id, s);
    const Eigen::Vector2d d = Eigen::Vector2d((k.i + 0.5) * s, (k.j + 0.5) * s) - focus;
    out.push_back(std::max(std::abs(d.x()), std::abs(d.y())));
  }
  return out;
}

}  // namespace

TEST(NearestFirstTiles, EachBatchHoldsTheTilesNearestTheMovingFocusInGrowingSquares) {
  // A 21 x 21 window of 2 m tiles named in (i, j) order, as a delta lists them; the focus (the predicted position)
  // drives diagonally across it while the batches are taken.
  const double s = 2.0;
  std::vector<std::string> ids;
  for (int i = -10; i <= 10; ++i)
    for (int j = -10; j <= 10; ++j) ids.push_back(gpl::tileStem(i, j, s));
  gpl::NearestFirstTiles tiles(ids, s);
  std::vector<std::string> left = ids;
  std::size_t taken = 0;
  for (int step = 0; !tiles.empty(); ++step) {
    const Eigen::Vector2d focus(-15.0 + 4.0 * step, -12.0 + 3.0 * step);
    const std::vector<std::string> batch = tiles.take(gpl::kTileFetchBatch, focus);
    // Closed form: the batch's distances are the smallest of what was left, in ascending order.
    std::vector<double> expected = squareDistances(left, focus, s);
    std::sort(expected.begin(), expected.end());
    expected.resize(std::min(gpl::kTileFetchBatch, left.size()));
    EXPECT_EQ(squareDistances(batch, focus, s), expected) << "batch " << step << " at " << focus.transpose();
    for (const std::string& id : batch) left.erase(std::find(left.begin(), left.end(), id));
    taken += batch.size();
  }
  EXPECT_EQ(taken, ids.size());
  EXPECT_TRUE(left.empty());
}

TEST(NearestFirstTiles, WithoutAFocusKeepsTheChangesOrderAndBadIdsGoLast) {
  const std::vector<std::string> ids = {"5.0_5.0", "not-a-tile", "1.0_1.0", "3.0_3.0"};
  gpl::NearestFirstTiles unfocused(ids, 2.0);
  EXPECT_EQ(unfocused.take(10, std::nullopt), ids);
  gpl::NearestFirstTiles focused(ids, 2.0);
  EXPECT_EQ(focused.take(2, Eigen::Vector2d(0.0, 0.0)), (std::vector<std::string>{"1.0_1.0", "3.0_3.0"}));
  EXPECT_EQ(focused.take(2, Eigen::Vector2d(0.0, 0.0)), (std::vector<std::string>{"5.0_5.0", "not-a-tile"}));
  EXPECT_TRUE(focused.empty());
}

TEST(TilesInFlight, CountsTheTilesThatMeetASquare) {
  // Tiles of 2 m: (0, 0) spans [0, 2] x [0, 2], (1, 0) spans [2, 4] x [0, 2], (5, 5) spans [10, 12] x [10, 12].
  const gpl::TilesInFlight in_flight{2.0, {{0, 0}, {1, 0}, {5, 5}}};
  EXPECT_EQ(in_flight.within(Eigen::Vector2d(1.0, 1.0), 0.5), 1u);
  EXPECT_EQ(in_flight.within(Eigen::Vector2d(2.0, 1.0), 0.5), 2u);
  EXPECT_EQ(in_flight.within(Eigen::Vector2d(3.0, 1.0), 1.0), 1u);  // [2, 4]: touches (0, 0) only at x = 2
  EXPECT_EQ(in_flight.within(Eigen::Vector2d(11.0, 11.0), 0.5), 1u);
  EXPECT_EQ(in_flight.within(Eigen::Vector2d(6.0, 6.0), 3.0), 0u);
  EXPECT_EQ(in_flight.within(Eigen::Vector2d(6.0, 6.0), 100.0), 3u);
  EXPECT_EQ(gpl::TilesInFlight().within(Eigen::Vector2d::Zero(), 100.0), 0u);
}
