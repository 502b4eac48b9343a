#include <gtest/gtest.h>

#include <cmath>

#include "grid_puzzle_localization/pose_prediction.hpp"
#include "grid_puzzle_localization/pose_search.hpp"

namespace gpl = grid_puzzle_localization;

namespace {

double yawOf(const Eigen::Isometry3d& t) { return std::atan2(t.linear()(1, 0), t.linear()(0, 0)); }

}  // namespace

// Before any motion is measured, the radius grows with max_speed; after, with margin times the fastest seen.
TEST(BoundedSearchRegion, RadiusAndYawGrowLinearlyWithElapsedTimeUpToTheCaps) {
  gpl::PredictionConfig c;
  c.max_speed = 15.0;
  c.max_yaw_rate = 1.5;
  c.margin = 1.5;
  c.min_radius = 1.0;
  c.max_radius = 30.0;
  c.min_yaw_range = 0.1;
  gpl::MotionBounds none;
  gpl::SearchRegion r = gpl::boundedSearchRegion(Eigen::Isometry3d::Identity(), 0.5, none, false, c);
  EXPECT_DOUBLE_EQ(r.radius, 1.0 + 15.0 * 0.5);
  EXPECT_DOUBLE_EQ(r.yaw_range, 0.1 + 1.5 * 0.5);
  gpl::MotionBounds seen;
  gpl::Twist a = gpl::Twist::Zero(), b = gpl::Twist::Zero();
  a << 3.0, 4.0, 0.0, 0.0, 0.0, -0.4;  // 5 m/s
  b << 2.0, 0.0, 0.0, 0.0, 0.0, 0.2;
  seen.add(a);
  seen.add(b);
  EXPECT_DOUBLE_EQ(seen.speed, 5.0);
  EXPECT_DOUBLE_EQ(seen.yaw_rate, 0.4);
  r = gpl::boundedSearchRegion(Eigen::Isometry3d::Identity(), 2.0, seen, false, c);
  EXPECT_DOUBLE_EQ(r.radius, 1.0 + 1.5 * 5.0 * 2.0);
  EXPECT_DOUBLE_EQ(r.yaw_range, 0.1 + 1.5 * 0.4 * 2.0);
  r = gpl::boundedSearchRegion(Eigen::Isometry3d::Identity(), 100.0, seen, false, c);
  EXPECT_DOUBLE_EQ(r.radius, 30.0);
  EXPECT_DOUBLE_EQ(r.yaw_range, M_PI);
  // A gyro that covers the interval: the rotation is known, no yaw is searched.
  r = gpl::boundedSearchRegion(Eigen::Isometry3d::Identity(), 2.0, seen, true, c);
  EXPECT_DOUBLE_EQ(r.yaw_range, 0.0);
}

TEST(SearchCandidates, GridInsideTheDiscNearestFirstWithSymmetricYaws) {
  gpl::SearchRegion region;
  region.centre.translation() << 10.0, -5.0, 2.0;
  region.centre.linear() = Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  region.radius = 2.0;
  region.yaw_range = 0.8;
  gpl::SearchConfig c;
  c.step = 1.0;
  c.yaw_step = 0.35;
  const auto all = gpl::searchCandidates(region, c);
  // Lattice points of spacing 1 in a disc of radius 2: 13; yaws 0, +-0.35, +-0.7: 5.
  ASSERT_EQ(all.size(), 13u * 5u);
  EXPECT_TRUE(all.front().isApprox(region.centre));
  double last_distance = 0.0;
  for (const auto& t : all) {
    const double d = (t.translation() - region.centre.translation()).norm();
    EXPECT_LE(d, 2.0 + 1e-9);
    EXPECT_GE(d, last_distance - 1e-9);
    last_distance = d;
    EXPECT_DOUBLE_EQ(t.translation().z(), 2.0);
    EXPECT_LE(std::abs(yawOf(t) - 0.5), 0.7 + 1e-9);
  }
  // A full circle of yaw: 0, +-k step up to pi once.
  region.yaw_range = M_PI;
  region.radius = 0.0;
  EXPECT_EQ(gpl::searchCandidates(region, c).size(), 18u);  // 0, +-0.35 ... +-2.8 (8 pairs), pi
  // A region too large for the budget is sampled more coarsely, nearest kept.
  region.radius = 50.0;
  c.max_candidates = 190;
  const auto coarse = gpl::searchCandidates(region, c);
  EXPECT_LE(coarse.size(), 190u);
  EXPECT_GT(coarse.size(), 100u);
}

// A candidate is covered by a start at its x y (within the tolerance) and within the yaw probe of its rotation, about
// the map's z axis or any other; z does not count (the search varies x y and yaw only).
TEST(CoveredByYawProbe, SamePositionWithinTheProbeOnly) {
  Eigen::Isometry3d start = Eigen::Isometry3d::Identity();
  start.translation() << 4.0, -2.0, 1.0;
  start.linear() = Eigen::AngleAxisd(1.2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  auto turned = [&](double yaw, const Eigen::Vector3d& shift) {
    Eigen::Isometry3d c = start;
    c.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * start.linear();
    c.translation() += shift;
    return c;
  };
  const double tolerance = 0.5, probe = 0.1;
  EXPECT_TRUE(gpl::coveredByYawProbe(start, start, tolerance, probe));
  EXPECT_TRUE(gpl::coveredByYawProbe(start, turned(0.05, Eigen::Vector3d::Zero()), tolerance, probe));
  EXPECT_TRUE(gpl::coveredByYawProbe(start, turned(-0.099, Eigen::Vector3d(0.3, -0.3, 0.0)), tolerance, probe));
  EXPECT_TRUE(gpl::coveredByYawProbe(start, turned(0.0, Eigen::Vector3d(0.0, 0.0, 5.0)), tolerance, probe));
  EXPECT_FALSE(gpl::coveredByYawProbe(start, turned(0.15, Eigen::Vector3d::Zero()), tolerance, probe));
  EXPECT_FALSE(gpl::coveredByYawProbe(start, turned(0.0, Eigen::Vector3d(0.4, 0.4, 0.0)), tolerance, probe));
  Eigen::Isometry3d tilted = start;
  tilted.linear() = start.linear() * Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitX());
  EXPECT_FALSE(gpl::coveredByYawProbe(start, tilted, tolerance, probe));
  EXPECT_FALSE(gpl::coveredByYawProbe(start, turned(0.05, Eigen::Vector3d::Zero()), tolerance, 0.0));
}
