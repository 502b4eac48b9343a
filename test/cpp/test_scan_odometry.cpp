// Scan-to-scan odometry on the real HDL-32E pair (test/data/hdl32_pair), against the independent fast_gicp
// reference, at the settings the localizer carries a start with (0.5 m leaves, 2 m voxels).
#include <gtest/gtest.h>

#include "grid_puzzle_localization/preprocess.hpp"
#include "grid_puzzle_localization/scan_odometry.hpp"
#include "ndt_real_pair.hpp"
#include "ndt_synthetic.hpp"

namespace gpl = grid_puzzle_localization;

namespace {

gpl::PointCloud localizerLeaves(const gpl::PointCloud& scan) {
  gpl::PreprocessConfig c;  // the localizer's defaults: 1-100 m, 0.5 m leaves
  return gpl::preprocess(scan, c);
}

gpl::ScanOdometry odometry() {
  gpl::NdtConfig ndt;
  ndt.resolution = 2.0;  // 4 leaves a side, as the localizer derives it from its 1 m voxels and 0.5 m leaves
  ndt.threads = 1;
  return gpl::ScanOdometry(ndt, 0.5, 15.0);
}

}  // namespace

TEST(ScanOdometry, TheStepBetweenTheRealPairMatchesTheReference) {
  gpl::ScanOdometry odo = odometry();
  gpl::OdometryStep step;
  const Eigen::Isometry3d first = odo.add(0.0, localizerLeaves(gpl::real_pair::target()), &step);
  EXPECT_EQ(step, gpl::OdometryStep::kFirst);
  EXPECT_TRUE(first.isApprox(Eigen::Isometry3d::Identity()));
  const Eigen::Isometry3d motion = odo.add(0.1, localizerLeaves(gpl::real_pair::source()), &step);
  ASSERT_EQ(step, gpl::OdometryStep::kMeasured);
  const auto [te, re] = gpl::synthetic::poseError(gpl::real_pair::reference(), motion.matrix());
  EXPECT_LT(te, 0.05) << "m";
  EXPECT_LT(re, 0.5) << "deg";
}

TEST(ScanOdometry, AScanThatMatchesNothingIsCarriedByTheLastVelocity) {
  gpl::ScanOdometry odo = odometry();
  gpl::OdometryStep step;
  odo.add(0.0, localizerLeaves(gpl::real_pair::target()), &step);
  const gpl::PointCloud second = localizerLeaves(gpl::real_pair::source());
  const Eigen::Isometry3d measured = odo.add(0.1, second, &step);
  ASSERT_EQ(step, gpl::OdometryStep::kMeasured);
  // The same scan 40 m away: no match within the NDT's reach of the guess, nor within 15 m/s.
  gpl::PointCloud elsewhere = second;
  for (gpl::Point& p : elsewhere) p.x() += 40.0f;
  const Eigen::Isometry3d guessed = odo.add(0.2, elsewhere, &step);
  EXPECT_EQ(step, gpl::OdometryStep::kGuessed);
  // Constant velocity over an equal interval repeats the measured step.
  EXPECT_TRUE(guessed.isApprox(measured, 1e-6));
}

TEST(ScanOdometry, AScanNotNewerThanTheLastStartsOver) {
  gpl::ScanOdometry odo = odometry();
  gpl::OdometryStep step;
  odo.add(1.0, localizerLeaves(gpl::real_pair::target()), &step);
  const Eigen::Isometry3d motion = odo.add(0.5, localizerLeaves(gpl::real_pair::source()), &step);
  EXPECT_EQ(step, gpl::OdometryStep::kFirst);
  EXPECT_TRUE(motion.isApprox(Eigen::Isometry3d::Identity()));
}
