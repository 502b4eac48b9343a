#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <random>

#include "grid_puzzle_localization/preprocess.hpp"

namespace gpl = grid_puzzle_localization;

TEST(Preprocess, DropsNonFiniteOriginAndOutOfRangeAndCountsThem) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  gpl::PointCloud in = {{nan, 1, 1}, {1, inf, 1}, {0, 0, 0}, {0.5f, 0, 0}, {3, 4, 0}, {200, 0, 0}, {0, 0, -10}};
  gpl::PreprocessConfig cfg;
  cfg.min_range = 1.0;
  cfg.max_range = 100.0;
  cfg.voxel_size = 0.0;
  gpl::PreprocessReport r;
  const gpl::PointCloud out = gpl::preprocess(in, cfg, &r);
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0], gpl::Point(3, 4, 0));
  EXPECT_EQ(out[1], gpl::Point(0, 0, -10));
  EXPECT_EQ(r.input, 7u);
  EXPECT_EQ(r.non_finite, 2u);
  EXPECT_EQ(r.at_origin, 1u);
  EXPECT_EQ(r.out_of_range, 2u);
  EXPECT_EQ(r.output, 2u);
}

TEST(Preprocess, VoxelFilterReturnsCentroidPerWorldAlignedVoxel) {
  // Voxel [0,1)^3 holds two points, voxel [-1,0) x [0,1) x [0,1) holds one: floor() must put the
  // negative coordinate in its own voxel, not share voxel 0 as truncation would.
  gpl::PointCloud in = {{0.2f, 0.2f, 0.2f}, {0.6f, 0.4f, 0.8f}, {-0.1f, 0.5f, 0.5f}};
  const gpl::PointCloud out = gpl::voxelDownsample(in, 1.0);
  ASSERT_EQ(out.size(), 2u);
  EXPECT_NEAR(out[0].x(), 0.4f, 1e-6);
  EXPECT_NEAR(out[0].y(), 0.3f, 1e-6);
  EXPECT_NEAR(out[0].z(), 0.5f, 1e-6);
  EXPECT_EQ(out[1], gpl::Point(-0.1f, 0.5f, 0.5f));
}

TEST(Preprocess, VoxelFilterKeepsOnePointPerOccupiedCell) {
  // A 10 x 10 x 10 lattice with spacing 0.25 m through 1 m voxels: (10 * 0.25 = 2.5 m) -> 3 cells a side.
  gpl::PointCloud in;
  for (int i = 0; i < 10; ++i)
    for (int j = 0; j < 10; ++j)
      for (int k = 0; k < 10; ++k) in.emplace_back(0.25f * i + 0.01f, 0.25f * j + 0.01f, 0.25f * k + 0.01f);
  EXPECT_EQ(gpl::voxelDownsample(in, 1.0).size(), 27u);
}

TEST(Preprocess, RejectsOutOfRangeParametersWithAMessage) {
  gpl::PreprocessConfig cfg;
  cfg.max_range = 0.5;
  cfg.min_range = 1.0;
  EXPECT_NE(cfg.validate().find("max_range"), std::string::npos);
  EXPECT_THROW(gpl::preprocess({{1, 1, 1}}, cfg), std::invalid_argument);
  cfg = gpl::PreprocessConfig();
  cfg.voxel_size = -1;
  EXPECT_NE(cfg.validate().find("voxel_size"), std::string::npos);
}

namespace {

// Brute force reference: centroids per voxel key in a std::map, in order of first appearance.
gpl::PointCloud centroidsByMap(const gpl::PointCloud& in, double leaf) {
  std::map<std::array<int, 3>, std::pair<Eigen::Vector3d, int>> cells;
  std::vector<std::array<int, 3>> order;
  for (const gpl::Point& p : in) {
    const std::array<int, 3> k = {static_cast<int>(std::floor(p.x() / leaf)),
                                  static_cast<int>(std::floor(p.y() / leaf)),
                                  static_cast<int>(std::floor(p.z() / leaf))};
    auto [it, fresh] = cells.try_emplace(k, Eigen::Vector3d::Zero(), 0);
    if (fresh) order.push_back(k);
    it->second.first += p.cast<double>();
    ++it->second.second;
  }
  gpl::PointCloud out;
  for (const auto& k : order) out.push_back((cells[k].first / cells[k].second).cast<float>());
  return out;
}

gpl::PointCloud randomCloud(unsigned seed, int n, float half_extent) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-half_extent, half_extent);
  gpl::PointCloud c(n);
  for (auto& p : c) p = gpl::Point(u(rng), u(rng), u(rng));
  return c;
}

}  // namespace

// One Preprocessor reused over scans of different sizes and places (its table keeps no stale voxel) gives
// what a brute-force std::map grouping gives for each scan alone.
TEST(Preprocess, ReusedPreprocessorMatchesBruteForceOnEveryScan) {
  gpl::PreprocessConfig cfg;
  cfg.min_range = 0.0;
  cfg.max_range = 1000.0;
  cfg.voxel_size = 0.5;
  gpl::Preprocessor pre(cfg);
  gpl::PointCloud out;
  const std::vector<std::pair<int, float>> scans = {{20000, 30.0f}, {500, 2.0f}, {20000, 30.0f}, {60000, 80.0f}};
  for (std::size_t i = 0; i < scans.size(); ++i) {
    const gpl::PointCloud in = randomCloud(static_cast<unsigned>(i), scans[i].first, scans[i].second);
    gpl::PreprocessReport r;
    pre.apply(in, out, &r);
    const gpl::PointCloud expected = centroidsByMap(in, cfg.voxel_size);
    ASSERT_EQ(out.size(), expected.size()) << "scan " << i;
    EXPECT_EQ(r.output, expected.size());
    for (std::size_t k = 0; k < out.size(); ++k) ASSERT_EQ(out[k], expected[k]) << "scan " << i << " point " << k;
  }
}
