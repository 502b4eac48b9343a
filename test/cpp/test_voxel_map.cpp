// Voxel statistics and Gaussians against brute force, and incremental add/remove against a from-scratch build.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <map>
#include <random>

#include "grid_puzzle_localization/voxel_map.hpp"
#include "ndt_synthetic.hpp"

namespace gpl = grid_puzzle_localization;

namespace {

gpl::VoxelMapParams params(double resolution, int threads = 2) {
  gpl::VoxelMapParams p;
  p.resolution = resolution;
  p.threads = threads;
  return p;
}

// Every voxel of `a` must equal the one of `b` (same stats and Gaussian up to round-off), and vice versa.
void expectSameMaps(const gpl::VoxelMap& a, const gpl::VoxelMap& b, double tol) {
  ASSERT_EQ(a.voxelCount(), b.voxelCount());
  ASSERT_EQ(a.gaussianCount(), b.gaussianCount());
  ASSERT_EQ(a.pointCount(), b.pointCount());
  std::size_t seen = 0;
  a.forEach([&](const gpl::VoxelKey& k, const gpl::VoxelStats& sa, const gpl::VoxelGaussian& ga) {
    ++seen;
    const gpl::VoxelStats* sb = b.stats(k);
    ASSERT_NE(sb, nullptr) << "voxel " << k.x << "," << k.y << "," << k.z << " missing";
    EXPECT_EQ(sa.count, sb->count);
    EXPECT_LE((sa.sum - sb->sum).norm(), tol);
    const gpl::VoxelGaussian* gb = b.find(k);
    ASSERT_EQ(ga.valid != 0, gb != nullptr);
    if (!gb) return;
    EXPECT_LT((ga.mean - gb->mean).norm(), 1e-5);
    for (int i = 0; i < 6; ++i) EXPECT_NEAR(ga.inv_cov[i], gb->inv_cov[i], 1e-4 * (1.0 + std::abs(gb->inv_cov[i])));
  });
  EXPECT_EQ(seen, a.voxelCount());
}

gpl::PointCloud cropped(const gpl::PointCloud& c, float x0, float x1) {
  gpl::PointCloud out;
  for (const auto& p : c)
    if (p.x() >= x0 && p.x() < x1) out.push_back(p);
  return out;
}

// Adds and removes `clouds` (id = index) at random, `steps` times; returns which of them the target holds at the end.
std::vector<bool> toggleAtRandom(gpl::NdtTarget& target, const std::vector<gpl::PointCloud>& clouds, unsigned seed,
                                 int steps) {
  std::mt19937 rng(seed);
  std::vector<bool> present(clouds.size(), false);
  for (int step = 0; step < steps; ++step) {
    const std::size_t i = rng() % clouds.size();
    if (present[i]) {
      EXPECT_TRUE(target.removeTarget(i));
    } else {
      target.addTarget(i, clouds[i]);
    }
    present[i] = !present[i];
  }
  return present;
}

// The points of the clouds marked present.
gpl::PointCloud joined(const std::vector<gpl::PointCloud>& clouds, const std::vector<bool>& present) {
  gpl::PointCloud out;
  for (std::size_t i = 0; i < clouds.size(); ++i)
    if (present[i]) out.insert(out.end(), clouds[i].begin(), clouds[i].end());
  return out;
}

TEST(VoxelMap, GaussianMatchesBruteForceUnbiasedCovariance) {
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0.0, 1.0);
  // Points of one voxel [10, 12)^3 at resolution 2, an anisotropic cloud around (11, 11, 11), far from the origin.
  gpl::PointCloud pts;
  for (int i = 0; i < 50; ++i)
    pts.emplace_back(Eigen::Vector3d(11 + 0.3 * n(rng), 11 + 0.1 * n(rng), 11 + 0.2 * n(rng))
                         .cwiseMax(10.01)
                         .cwiseMin(11.99)
                         .cast<float>());
  gpl::NdtTarget t(params(2.0));
  t.setTarget(pts);
  const auto map = t.snapshot();
  ASSERT_EQ(map->voxelCount(), 1u);
  const gpl::VoxelGaussian* g = map->find({5, 5, 5});
  ASSERT_NE(g, nullptr);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : pts) mean += p.cast<double>();
  mean /= pts.size();
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& p : pts) cov += (p.cast<double>() - mean) * (p.cast<double>() - mean).transpose();
  cov /= (pts.size() - 1.0);  // unbiased
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  ASSERT_GT(eig.eigenvalues()(0), 0.01 * eig.eigenvalues()(2)) << "test cloud must not trigger the clamp";
  const Eigen::Matrix3d icov = cov.inverse();
  EXPECT_LT((g->mean.cast<double>() - mean).norm(), 1e-5);
  const double expect[6] = {icov(0, 0), icov(0, 1), icov(0, 2), icov(1, 1), icov(1, 2), icov(2, 2)};
  for (int i = 0; i < 6; ++i) EXPECT_NEAR(g->inv_cov[i], expect[i], 1e-4 * std::abs(expect[i]) + 1e-3);
}

TEST(VoxelMap, EigenvalueClampAndMinimumPointCount) {
  // A perfectly flat voxel (z constant): the covariance is singular until the clamp raises the zero eigenvalue.
  gpl::PointCloud flat;
  for (int i = 0; i < 5; ++i)
    for (int j = 0; j < 5; ++j) flat.emplace_back(0.1f + 0.2f * i, 0.1f + 0.2f * j, 0.5f);
  gpl::VoxelMapParams p = params(1.0);
  gpl::NdtTarget t(p);
  t.setTarget(flat);
  const gpl::VoxelGaussian* g = t.snapshot()->find({0, 0, 0});
  ASSERT_NE(g, nullptr);
  // In-plane variance: 5 values spaced 0.2 apart, unbiased over 25 points: sum of squares / 24.
  double var = 0.0;
  for (int i = 0; i < 5; ++i) var += 5 * std::pow(0.2 * i - 0.4, 2);
  var /= 24.0;
  EXPECT_NEAR(g->inv_cov[0], 1.0 / var, 1e-3 / var);
  EXPECT_NEAR(g->inv_cov[5], 1.0 / (0.01 * var), 1e-3 / (0.01 * var));  // clamped to ratio * largest
  // Five points are fewer than min_points_per_voxel (6): the voxel exists but has no Gaussian.
  t.setTarget(gpl::PointCloud(flat.begin(), flat.begin() + 5));
  EXPECT_EQ(t.snapshot()->voxelCount(), 1u);
  EXPECT_EQ(t.snapshot()->find({0, 0, 0}), nullptr);
}

TEST(VoxelMap, IncrementalAddRemoveEqualsFromScratch) {
  // Tiles 3 m wide at resolution 2 m: voxels straddle tile borders and hold the sum of two tiles.
  const gpl::PointCloud world = gpl::synthetic::scene(5, 0.02, 30000, 15.0);
  std::vector<gpl::PointCloud> tiles;
  for (float x0 = -15.0f; x0 < 15.0f; x0 += 3.0f) tiles.push_back(cropped(world, x0, x0 + 3.0f));
  for (const double res : {2.0, 0.7}) {
    gpl::NdtTarget inc(params(res));
    const std::vector<bool> present = toggleAtRandom(inc, tiles, 11, 40);
    gpl::NdtTarget scratch(params(res, 1));
    scratch.setTarget(joined(tiles, present));
    expectSameMaps(*inc.snapshot(), *scratch.snapshot(), 1e-9);
    expectSameMaps(*scratch.snapshot(), *inc.snapshot(), 1e-9);
    // Removing everything leaves an empty map, not round-off residue.
    for (std::size_t i = 0; i < tiles.size(); ++i)
      if (present[i]) inc.removeTarget(i);
    EXPECT_EQ(inc.snapshot()->voxelCount(), 0u);
    EXPECT_EQ(inc.snapshot()->pointCount(), 0u);
  }
}

// The coarse map summed from the fine voxels equals a build of the same points at the coarse resolution, after a
// whole-map build and after incremental changes whose coarse voxels straddle the clouds' borders.
TEST(VoxelMap, CoarseMapEqualsABuildAtTheCoarseResolution) {
  const gpl::PointCloud world = gpl::synthetic::scene(5, 0.02, 30000, 15.0);
  for (const int factor : {2, 3}) {
    gpl::VoxelMapParams fine = params(0.7);
    fine.coarse_map_factor = factor;
    gpl::VoxelMapParams coarse = params(0.7 * factor, 1);
    coarse.coarse_map_factor = 0;
    gpl::NdtTarget whole(fine), direct(coarse);
    whole.setTarget(world);
    direct.setTarget(world);
    ASSERT_NE(whole.snapshot()->coarse(), nullptr) << factor;
    EXPECT_EQ(direct.snapshot()->coarse(), nullptr);
    EXPECT_DOUBLE_EQ(whole.snapshot()->coarse()->resolution(), 0.7 * factor);
    expectSameMaps(*whole.snapshot()->coarse(), *direct.snapshot(), 1e-6);
    expectSameMaps(*direct.snapshot(), *whole.snapshot()->coarse(), 1e-6);
    EXPECT_GT(whole.snapshot()->bytes(), whole.snapshot()->coarse()->bytes() + direct.snapshot()->bytes() / 2);
  }
  // Clouds 3 m wide against coarse voxels of 2.1 m: added and removed at random.
  std::vector<gpl::PointCloud> clouds;
  for (float x0 = -15.0f; x0 < 15.0f; x0 += 3.0f) clouds.push_back(cropped(world, x0, x0 + 3.0f));
  gpl::NdtTarget inc(params(0.7));
  const std::vector<bool> present = toggleAtRandom(inc, clouds, 5, 30);
  gpl::VoxelMapParams coarse = params(0.7 * gpl::VoxelMapParams().coarse_map_factor, 1);
  coarse.coarse_map_factor = 0;
  gpl::NdtTarget direct(coarse);
  direct.setTarget(joined(clouds, present));
  ASSERT_NE(inc.snapshot()->coarse(), nullptr);
  expectSameMaps(*inc.snapshot()->coarse(), *direct.snapshot(), 1e-6);
  expectSameMaps(*direct.snapshot(), *inc.snapshot()->coarse(), 1e-6);
  // Tiles of 2.8 m (4 voxels) against coarse voxels of 2.1 m, added by addTiles and dropped by removeTiles.
  const double res = 0.7, side = 2.8;
  std::map<std::pair<int, int>, gpl::PointCloud> by_tile;  // each point in the tile of its voxel
  for (const gpl::Point& p : world)
    by_tile[{static_cast<int>(std::floor(std::floor(p.x() * (1.0 / res)) / 4.0)),
             static_cast<int>(std::floor(std::floor(p.y() * (1.0 / res)) / 4.0))}]
        .push_back(p);
  gpl::NdtTarget tiled(params(res));
  std::map<std::pair<int, int>, bool> in;
  std::mt19937 rng(5);
  for (int step = 0; step < 12; ++step) {
    std::vector<std::pair<gpl::TileKey, const gpl::PointCloud*>> add;
    std::vector<gpl::TileKey> drop;
    for (const auto& [key, points] : by_tile) {
      if (rng() % 3 != 0) continue;
      if (in[key])
        drop.push_back({key.first, key.second});
      else
        add.push_back({{key.first, key.second}, &points});
      in[key] = !in[key];
    }
    EXPECT_EQ(tiled.addTiles(add, side), 0u);
    tiled.removeTiles(drop, side);
  }
  gpl::PointCloud tiled_points;
  for (const auto& [key, points] : by_tile)
    if (in[key]) tiled_points.insert(tiled_points.end(), points.begin(), points.end());
  gpl::NdtTarget tiled_direct(coarse);
  tiled_direct.setTarget(tiled_points);
  expectSameMaps(*tiled.snapshot()->coarse(), *tiled_direct.snapshot(), 1e-6);
  expectSameMaps(*tiled_direct.snapshot(), *tiled.snapshot()->coarse(), 1e-6);
  // Without a coarse map.
  gpl::VoxelMapParams none = params(0.7);
  none.coarse_map_factor = 0;
  gpl::NdtTarget plain(none);
  plain.setTarget(world);
  EXPECT_EQ(plain.snapshot()->coarse(), nullptr);
}

TEST(VoxelMap, SnapshotsAreImmutableAndShareUntouchedShards) {
  const gpl::PointCloud world = gpl::synthetic::scene(6, 0.02, 20000, 15.0);
  gpl::NdtTarget t(params(1.0));
  t.addTarget(1, cropped(world, -15.0f, 0.0f));
  const auto before = t.snapshot();
  const std::size_t voxels = before->voxelCount();
  std::map<std::tuple<int, int, int>, std::int64_t> counts;
  before->forEach([&](const gpl::VoxelKey& k, const gpl::VoxelStats& s, const gpl::VoxelGaussian&) {
    counts[{k.x, k.y, k.z}] = s.count;
  });
  t.addTarget(2, cropped(world, 0.0f, 15.0f));
  EXPECT_FALSE(t.removeTarget(3));
  EXPECT_THROW(t.addTarget(2, world), std::invalid_argument);
  EXPECT_GT(t.snapshot()->voxelCount(), voxels);
  // The old snapshot still holds exactly what it held.
  EXPECT_EQ(before->voxelCount(), voxels);
  before->forEach([&](const gpl::VoxelKey& k, const gpl::VoxelStats& s, const gpl::VoxelGaussian&) {
    EXPECT_EQ(counts.at({k.x, k.y, k.z}), s.count);
  });
  EXPECT_EQ((std::vector<gpl::TargetId>{1, 2}), t.targetIds());
  EXPECT_GT(before->bytesPerVoxel(), 0.0);
}

TEST(VoxelMap, ThreadCountDoesNotChangeTheMap) {
  const gpl::PointCloud world = gpl::synthetic::scene(8, 0.02, 30000, 15.0);
  gpl::NdtTarget one(params(1.0, 1)), two(params(1.0, 2)), four(params(1.0, 4));
  one.setTarget(world);
  two.setTarget(world);
  four.setTarget(world);
  expectSameMaps(*one.snapshot(), *two.snapshot(), 0.0);
  expectSameMaps(*one.snapshot(), *four.snapshot(), 0.0);
}

TEST(VoxelMap, ValidateNamesTheBadValue) {
  gpl::VoxelMapParams p;
  EXPECT_EQ(p.validate(), "");
  p.resolution = 0.0;
  EXPECT_NE(p.validate().find("resolution"), std::string::npos);
  EXPECT_THROW(gpl::NdtTarget{p}, std::invalid_argument);
  p = gpl::VoxelMapParams();
  p.min_points_per_voxel = 2;
  EXPECT_NE(p.validate().find("min_points_per_voxel"), std::string::npos);
  p = gpl::VoxelMapParams();
  p.eigenvalue_ratio = 0.0;
  EXPECT_NE(p.validate().find("eigenvalue_ratio"), std::string::npos);
  for (const int factor : {-1, 1, 9}) {
    p = gpl::VoxelMapParams();
    p.coarse_map_factor = factor;
    EXPECT_NE(p.validate().find("coarse_map_factor"), std::string::npos) << factor;
  }
  p.coarse_map_factor = 0;
  EXPECT_EQ(p.validate(), "");
}

}  // namespace
