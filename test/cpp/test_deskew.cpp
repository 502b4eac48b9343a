#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <memory>
#include <random>

#include "grid_puzzle_localization/deskew.hpp"
#include "grid_puzzle_localization/localizer.hpp"
#include "grid_puzzle_localization/preprocess.hpp"
#include "synthetic_world.hpp"

namespace gpl = grid_puzzle_localization;
namespace t = grid_puzzle_localization::test;

namespace {

constexpr double kSweep = 0.1;  // [s] one revolution at 10 Hz

// Closed form of a car on a climbing circular arc: body-frame speed v forward and w up, yaw rate r.
struct Arc {
  double v = 6.0, w = 0.3, r = 0.8;
  gpl::Twist twist() const { return (gpl::Twist() << v, 0.0, w, 0.0, 0.0, r).finished(); }
  Eigen::Isometry3d poseAt(double time) const {  // map_T_base with base at the origin, heading +x, at time 0
    Eigen::Isometry3d p = Eigen::Isometry3d::Identity();
    p.translation() << v / r * std::sin(r * time), v / r * (1.0 - std::cos(r * time)), w * time;
    p.linear() = Eigen::AngleAxisd(r * time, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    return p;
  }
};

Eigen::Isometry3d mount() {
  Eigen::Isometry3d m = t::poseXYYaw(0.4, -0.1, 0.3, 1.9);
  m.linear() = m.linear() * Eigen::AngleAxisd(0.05, Eigen::Vector3d::UnitX()).toRotationMatrix();
  return m;
}

struct Sweep {
  gpl::PointCloud measured;  // each point in the sensor frame at its own time
  gpl::PointCloud truth;     // the same points in the sensor frame at the stamp
  gpl::PointTimes times;
};

// Static world points 3-60 m away, each seen at a random time of the sweep from the moving sensor.
Sweep sweepOnArc(const Arc& arc, int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> coord(-60.0, 60.0), when(0.0, kSweep);
  const Eigen::Isometry3d sensor0 = arc.poseAt(0.0) * mount();
  Sweep s;
  while (static_cast<int>(s.truth.size()) < n) {
    const Eigen::Vector3d world(coord(rng), coord(rng), 0.1 * coord(rng));
    const Eigen::Vector3d at_stamp = sensor0.inverse() * world;
    if (at_stamp.norm() < 3.0 || at_stamp.norm() > 60.0) continue;
    const double time = when(rng);
    s.measured.push_back(((arc.poseAt(time) * mount()).inverse() * world).cast<float>());
    s.truth.push_back(at_stamp.cast<float>());
    s.times.push_back(static_cast<float>(time));
  }
  return s;
}

}  // namespace

TEST(Deskew, ConstantTwistSweepMatchesTheStaticPointsToFloatPrecision) {
  const Arc arc;
  Sweep s = sweepOnArc(arc, 5000, 1);
  const auto [t0, t1] = gpl::timeSpan(s.times);
  const gpl::SweepMotion motion = gpl::SweepMotion::fromTwist(arc.twist(), mount(), t0, t1);
  double smear = 0.0;
  for (std::size_t i = 0; i < s.truth.size(); ++i) smear = std::max(smear, double((s.measured[i] - s.truth[i]).norm()));
  EXPECT_GT(smear, 0.5);  // the skew is real: up to v * sweep plus the rotation at 60 m
  motion.apply(s.measured, s.times);
  for (std::size_t i = 0; i < s.truth.size(); ++i) {
    // float carries ~7 digits: a few ulp of a 60 m coordinate is ~1e-5 m
    const double tolerance = 4.0 * std::numeric_limits<float>::epsilon() * std::max(1.0f, s.truth[i].norm());
    ASSERT_LT((s.measured[i] - s.truth[i]).norm(), tolerance) << "point " << i << " time " << s.times[i];
  }
}

TEST(Deskew, ZeroTwistLeavesPointsUnchanged) {
  Sweep s = sweepOnArc(Arc{}, 1000, 2);
  const gpl::PointCloud before = s.measured;
  gpl::SweepMotion::fromTwist(gpl::Twist::Zero(), mount(), 0.0, kSweep).apply(s.measured, s.times);
  for (std::size_t i = 0; i < before.size(); ++i) ASSERT_EQ(s.measured[i], before[i]) << "point " << i;
}

TEST(Deskew, PointsWithoutATimeAreLeftAsMeasured) {
  Sweep s = sweepOnArc(Arc{}, 100, 3);
  s.times[7] = std::numeric_limits<float>::quiet_NaN();
  const gpl::Point seven = s.measured[7];
  gpl::SweepMotion::fromTwist(Arc{}.twist(), mount(), 0.0, kSweep).apply(s.measured, s.times);
  EXPECT_EQ(s.measured[7], seven);
  EXPECT_GT((s.measured[8] - s.truth[8]).norm(), 0.0f);
  EXPECT_LT((s.measured[8] - s.truth[8]).norm(), 1e-4f);
  s.times.pop_back();
  EXPECT_THROW(gpl::SweepMotion::fromTwist(Arc{}.twist(), mount(), 0.0, kSweep).apply(s.measured, s.times),
               std::invalid_argument);
}

TEST(Deskew, TimeSpanSkipsNonFiniteTimes) {
  const auto [lo, hi] = gpl::timeSpan({0.05f, std::numeric_limits<float>::quiet_NaN(), -0.01f, 0.09f});
  EXPECT_FLOAT_EQ(lo, -0.01f);
  EXPECT_FLOAT_EQ(hi, 0.09f);
  EXPECT_EQ(gpl::timeSpan({}), std::make_pair(0.0, 0.0));
}

TEST(Deskew, PreprocessorDeskewsAfterTheRangeCropAndOnlyWhenEnabled) {
  const Arc arc;
  const Sweep s = sweepOnArc(arc, 2000, 4);
  const gpl::SweepMotion motion = gpl::SweepMotion::fromTwist(arc.twist(), mount(), 0.0, kSweep);
  gpl::PreprocessConfig c;
  c.voxel_size = 0.0;
  c.min_range = 10.0;
  c.max_range = 50.0;
  gpl::PointCloud out;
  gpl::PreprocessReport report;
  gpl::Preprocessor(c).apply(s.measured, out, &report, &s.times, &motion);
  EXPECT_TRUE(report.deskewed);
  // The crop is on the measured ranges; every kept point is then moved to the stamp.
  std::size_t j = 0;
  for (std::size_t i = 0; i < s.measured.size(); ++i) {
    const float range = s.measured[i].norm();
    if (range < 10.0f || range > 50.0f) continue;
    ASSERT_LT(j, out.size());
    EXPECT_LT((out[j] - s.truth[i]).norm(), 1e-4f) << "point " << i;
    ++j;
  }
  EXPECT_EQ(j, out.size());
  c.deskew = false;
  gpl::Preprocessor(c).apply(s.measured, out, &report, &s.times, &motion);
  EXPECT_FALSE(report.deskewed);
  EXPECT_EQ(out, gpl::preprocess(s.measured, c));
}

namespace {

// The yard drive of test_localizer at 6 m/s, scanned by a spinning sensor: a point's time in the sweep is
// its azimuth, and it is measured from where the sensor is at that time.
Eigen::Isometry3d yardTruth(double time) {
  return t::poseXYYaw(-20.0 + 6.0 * time, 2.0 * std::sin(0.4 * time), std::atan2(0.8 * std::cos(0.4 * time), 6.0));
}

template <class Truth>
void spinningScan(const gpl::PointCloud& world, Truth&& truth, double stamp, unsigned seed, gpl::PointCloud& scan,
                  gpl::PointTimes& times) {
  const gpl::PointCloud at_stamp = t::scanFrom(world, truth(stamp) * mount(), 30.0f, 0.01f, seed);
  const Eigen::Isometry3d map_T_sensor0 = truth(stamp) * mount();
  scan.clear();
  times.clear();
  for (const gpl::Point& p : at_stamp) {
    const double time = kSweep * (std::atan2(p.y(), p.x()) + M_PI) / (2.0 * M_PI);
    const Eigen::Vector3d world_p = map_T_sensor0 * p.cast<double>();
    scan.push_back(((truth(stamp + time) * mount()).inverse() * world_p).template cast<float>());
    times.push_back(static_cast<float>(time));
  }
}

// The localizer of these drives: 0.4 m voxels, 30 m range, `world` as its map.
std::unique_ptr<gpl::Localizer> yardLocalizer(const gpl::PointCloud& world, bool deskew) {
  gpl::LocalizerConfig c;
  c.preprocess.voxel_size = 0.4;
  c.preprocess.max_range = 30.0;
  c.preprocess.deskew = deskew;
  auto loc = std::make_unique<gpl::Localizer>(c);
  loc->map().submit(gpl::MapChange::fullCloud(world));
  loc->map().waitIdle();
  return loc;
}

double worstError(bool deskew) {
  const gpl::PointCloud world = t::makeWorld();
  const std::unique_ptr<gpl::Localizer> localizer = yardLocalizer(world, deskew);
  gpl::Localizer& loc = *localizer;
  loc.setInitialPose(yardTruth(0.0));
  gpl::PointCloud scan;
  gpl::PointTimes times;
  double worst = 0.0;
  for (int i = 0; i <= 40; ++i) {
    const double stamp = 0.1 * i;
    spinningScan(world, yardTruth, stamp, 100 + i, scan, times);
    const gpl::LocalizerOutput out = loc.processScan(stamp, scan, mount(), &times);
    EXPECT_EQ(out.preprocess.deskewed, deskew);
    // Scans 0 and 1 are matched without a measured motion (not deskewed, 0.5 m behind along the smear); scan 2,
    // the first deskewed one, corrects that offset, and the twists measured across the correction deskew scans 3
    // and 4: the twist is free of it from scan 5 on.
    if (i >= 5) worst = std::max(worst, t::translationError(out.pose, yardTruth(stamp)));
  }
  return worst;
}

}  // namespace

TEST(Deskew, LocalizerPoseIsThePoseAtTheStampWhenScansAreDeskewed) {
  const double skewed = worstError(false);
  const double deskewed = worstError(true);
  RecordProperty("worst_error_skewed_m", std::to_string(skewed));
  RecordProperty("worst_error_deskewed_m", std::to_string(deskewed));
  EXPECT_LT(deskewed, 0.05);
  EXPECT_LT(deskewed, 0.5 * skewed);
}

namespace {

// A sensor turning on the spot at 3 rad/s (a hand-held swing): 17 deg within one sweep.
Eigen::Isometry3d turningTruth(double time) { return t::poseXYYaw(-5.0, 1.0, 0.3 + 3.0 * time); }

// The worst rotation error [rad] over the first scans after an exact initial pose, which have no measured
// velocity; with a gyro its rotation deskews them (the body-frame rate is the truth's, 3 rad/s about z).
double worstTurningRotationError(bool gyro) {
  const gpl::PointCloud world = t::makeWorld();
  const std::unique_ptr<gpl::Localizer> localizer = yardLocalizer(world, true);
  gpl::Localizer& loc = *localizer;
  loc.setInitialPose(turningTruth(0.0));
  if (gyro)
    for (double t = -0.1; t < 0.5; t += 0.005) loc.addGyro(t, Eigen::Vector3d(0.0, 0.0, 3.0));
  gpl::PointCloud scan;
  gpl::PointTimes times;
  double worst = 0.0;
  for (int i = 0; i < 3; ++i) {
    const double stamp = 0.1 * i;
    spinningScan(world, turningTruth, stamp, 200 + i, scan, times);
    const gpl::LocalizerOutput out = loc.processScan(stamp, scan, mount(), &times);
    worst = std::max(worst, out.match_accepted ? t::rotationError(out.pose, turningTruth(stamp)) : M_PI);
  }
  return worst;
}

}  // namespace

TEST(Deskew, AGyroDeskewsTheScansRightAfterAnInitialPose) {
  const double with_gyro = worstTurningRotationError(true);
  const double without = worstTurningRotationError(false);
  RecordProperty("worst_rotation_error_with_gyro_deg", std::to_string(with_gyro * 180.0 / M_PI));
  RecordProperty("worst_rotation_error_without_deg", std::to_string(without * 180.0 / M_PI));
  EXPECT_LT(with_gyro, 0.5 * M_PI / 180.0);
  EXPECT_LT(with_gyro, 0.5 * without);
}
