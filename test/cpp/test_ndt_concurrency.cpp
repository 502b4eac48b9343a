// A background thread updates the target (add/remove tiles) while the foreground aligns against snapshots.
// Built and run under ThreadSanitizer by `make tsan`; here it also checks that every snapshot stays consistent.
#include <gtest/gtest.h>

#include <atomic>
#include <thread>

#include "grid_puzzle_localization/ndt.hpp"
#include "ndt_synthetic.hpp"

namespace gpl = grid_puzzle_localization;

namespace {

TEST(NdtConcurrency, BackgroundUpdatesNeverDisturbAForegroundAlign) {
  gpl::NdtConfig cfg;
  cfg.threads = 1;
  cfg.max_iterations = 5;
  const gpl::PointCloud world = gpl::synthetic::scene(1, 0.02, 8000);
  std::vector<gpl::PointCloud> tiles(6);
  for (const auto& p : world) tiles[std::min(5, static_cast<int>((p.x() + 15.0f) / 5.0f))].push_back(p);
  const gpl::PointCloud source = gpl::synthetic::scene(2, 0.02, 1000);

  gpl::NdtTarget target(cfg);
  for (std::size_t i = 0; i < 3; ++i) target.addTarget(i, tiles[i]);
  std::atomic<bool> stop{false};
  std::atomic<int> updates{0};
  std::thread writer([&] {
    // Slide a window of three tiles back and forth: every voxel of the middle tiles changes over and over.
    for (int step = 0; !stop.load() && step < 200; ++step) {
      if (step % 50 == 25) target.setTarget(tiles[step % 6]);  // a full rebuild must never publish an empty map
      const std::size_t out = step % 6, in = (step + 3) % 6;
      if (target.hasTarget(out)) target.removeTarget(out);
      if (!target.hasTarget(in)) target.addTarget(in, tiles[in]);
      ++updates;
    }
  });
  const gpl::NdtAligner aligner(cfg);
  int aligns = 0;
  while (updates.load() < 20 || aligns < 20) {
    const std::shared_ptr<const gpl::VoxelMap> snap = target.snapshot();
    const std::size_t voxels = snap->voxelCount(), points = snap->pointCount();
    EXPECT_GT(voxels, 0u);
    const gpl::NdtResult r = aligner.align(*snap, source, Eigen::Matrix4f::Identity());
    EXPECT_TRUE(r.transform.allFinite());
    // The snapshot did not change under the align, whatever the writer did meanwhile.
    std::size_t seen = 0;
    std::int64_t counted = 0;
    snap->forEach([&](const gpl::VoxelKey&, const gpl::VoxelStats& s, const gpl::VoxelGaussian&) {
      ++seen;
      counted += s.count;
    });
    EXPECT_EQ(seen, voxels);
    EXPECT_EQ(static_cast<std::size_t>(counted), points);
    ++aligns;
    if (updates.load() >= 200) break;
  }
  stop = true;
  writer.join();
  EXPECT_GE(aligns, 20);
}

}  // namespace
