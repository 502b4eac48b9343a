// Sliding-window fusion against a closed-form trajectory: IMU samples are its exact derivatives (plus seeded
// noise and bias where a test says so), NDT measurements are the true pose plus seeded noise.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "grid_puzzle_localization/fusion/fusion_tracker.hpp"
#include "grid_puzzle_localization/fusion/sliding_window.hpp"
#include "imu_drive.hpp"

namespace gpl = grid_puzzle_localization;
using namespace grid_puzzle_localization::imu_drive;  // NOLINT: test-local shorthand

namespace {

bool finite(const gpl::FusedState& s) {
  return s.pose.matrix().allFinite() && s.velocity.allFinite() && s.bias.gyro.allFinite() && s.bias.accel.allFinite();
}

bool anyWarningContains(const std::vector<std::string>& warnings, const std::string& text) {
  for (const auto& w : warnings)
    if (w.find(text) != std::string::npos) return true;
  return false;
}

// Runs `scans` scans of `motion`: IMU samples up to each scan stamp, then the scan with a noisy NDT pose
// (none when `measured(k)` is false). Returns the newest estimate after each scan.
struct Replay {
  std::vector<gpl::FusedState> estimates;
  std::vector<Eigen::Isometry3d> measurements;
  std::vector<std::string> warnings;
};

template <class Measured, class ImuFilter>
Replay run(gpl::SlidingWindow& w, Truth (*motion)(double), int scans, const ImuErrors& errors, Measured measured,
           ImuFilter keep_imu, double sp = 0.05, double sr = 0.005) {
  std::mt19937 imu_rng(7), ndt_rng(11);
  Replay out;
  int next_imu = 0;
  for (int k = 0; k < scans; ++k) {
    const double stamp = k / kScanRate;
    for (; next_imu / kImuRate <= stamp + 1e-9; ++next_imu) {
      const gpl::ImuSample s = imuSample(motion, next_imu / kImuRate, errors, imu_rng);
      if (keep_imu(s.stamp)) w.addImu(s);
    }
    const Eigen::Isometry3d m = noisyPose(motion(stamp).pose, sp, sr, ndt_rng);
    out.measurements.push_back(m);
    const auto est = w.addScan(stamp, measured(k) ? &m : nullptr, information(sp, sr));
    if (est) out.estimates.push_back(*est);
    for (auto& s : w.takeWarnings()) out.warnings.push_back(s);
  }
  return out;
}

auto always = [](auto) { return true; };

double positionError(const gpl::FusedState& s, Truth (*motion)(double)) {
  return (s.pose.translation() - motion(s.stamp).pose.translation()).norm();
}

}  // namespace

TEST(SlidingWindow, FusedTrackIsCloserToTruthThanTheNdtMeasurements) {
  gpl::SlidingWindow w{gpl::SlidingWindowConfig()};
  const Replay r = run(w, drive, 150, mems(), always, always);
  ASSERT_EQ(r.estimates.size(), 150u);
  double fused = 0.0, raw = 0.0;
  int n = 0;
  for (std::size_t k = 20; k < r.estimates.size(); ++k, ++n) {  // after the biases settled
    ASSERT_TRUE(finite(r.estimates[k]));
    fused += std::pow(positionError(r.estimates[k], drive), 2);
    raw += (r.measurements[k].translation() - drive(r.estimates[k].stamp).pose.translation()).squaredNorm();
  }
  fused = std::sqrt(fused / n), raw = std::sqrt(raw / n);
  EXPECT_LT(fused, 0.6 * raw) << "fused RMSE " << fused << " m, NDT RMSE " << raw << " m";
  EXPECT_EQ(w.size(), 20u);  // N_a
}

TEST(SlidingWindow, MarginalizationPriorReproducesTheFullBatchSolution) {
  gpl::SlidingWindowConfig batch_config;
  batch_config.max_states = 1000;
  batch_config.max_iterations = 50;
  gpl::SlidingWindowConfig window_config = batch_config;
  window_config.max_states = 4;
  window_config.reset_states = 2;
  gpl::SlidingWindow batch(batch_config), window(window_config);
  const int scans = 30;
  const Replay b = run(batch, drive, scans, mems(), always, always);
  const Replay s = run(window, drive, scans, mems(), always, always);
  ASSERT_EQ(batch.size(), static_cast<std::size_t>(scans));
  ASSERT_EQ(window.size(), 4u);
  // The newest state of a fixed-lag smoother is the batch's newest state: exactly for a linear-Gaussian
  // problem, to linearization error here (the measurement noise is 5 cm, 0.005 rad).
  const gpl::FusedState& fb = b.estimates.back();
  const gpl::FusedState& fs = s.estimates.back();
  EXPECT_LT((fb.pose.translation() - fs.pose.translation()).norm(), 1e-3);
  EXPECT_LT(Eigen::AngleAxisd(fb.pose.rotation().transpose() * fs.pose.rotation()).angle(), 1e-4);
  EXPECT_LT((fb.velocity - fs.velocity).norm(), 1e-3);
  EXPECT_LT((fb.bias.accel - fs.bias.accel).norm(), 1e-3);
}

TEST(SlidingWindow, ShrinkingOnABlockSwitchKeepsTrackingWithTheSummarizedPast) {
  gpl::SlidingWindow w{gpl::SlidingWindowConfig()};
  run(w, drive, 25, mems(), always, always);
  ASSERT_EQ(w.size(), 20u);
  w.shrink();
  EXPECT_EQ(w.size(), 5u);  // N_r
  ASSERT_TRUE(w.latest());
  EXPECT_LT(positionError(*w.latest(), drive), 0.05);
  // Predicting ahead from the shrunk window still follows the motion.
  const auto ahead = w.predict(w.latest()->stamp + 0.1);
  ASSERT_TRUE(ahead);
}

TEST(SlidingWindow, ImuDropoutIsBridgedWithAWarningAndNoNaN) {
  gpl::SlidingWindow w{gpl::SlidingWindowConfig()};
  // No IMU samples in [5.0, 5.6) s, and the NDT match rejected for two of those scans.
  const Replay r = run(
      w, drive, 100, mems(), [](int k) { return k != 52 && k != 53; }, [](double t) { return t < 5.0 || t >= 5.6; });
  ASSERT_EQ(r.estimates.size(), 100u);
  for (const auto& e : r.estimates) {
    ASSERT_TRUE(finite(e));
    EXPECT_LT(positionError(e, drive), 0.3) << "at " << e.stamp << " s";
  }
  EXPECT_TRUE(anyWarningContains(r.warnings, "IMU dropout"));
}

TEST(SlidingWindow, OutOfOrderAndDuplicatedImuStampsAreDroppedWithAWarning) {
  gpl::SlidingWindow clean{gpl::SlidingWindowConfig()}, messy{gpl::SlidingWindowConfig()};
  const Replay a = run(clean, drive, 40, mems(), always, always);
  // The same samples, each fed again (duplicate), and a stale one replayed every 20.
  std::mt19937 imu_rng(7), ndt_rng(11);
  std::vector<std::string> warnings;
  std::vector<gpl::FusedState> est;
  int next_imu = 0;
  for (int k = 0; k < 40; ++k) {
    const double stamp = k / kScanRate;
    for (; next_imu / kImuRate <= stamp + 1e-9; ++next_imu) {
      const gpl::ImuSample s = imuSample(drive, next_imu / kImuRate, mems(), imu_rng);
      EXPECT_TRUE(messy.addImu(s));
      EXPECT_FALSE(messy.addImu(s));
      if (next_imu % 20 == 19) {
        gpl::ImuSample stale = s;
        stale.stamp -= 0.5 / kImuRate;
        EXPECT_FALSE(messy.addImu(stale));
      }
    }
    const Eigen::Isometry3d m = noisyPose(drive(stamp).pose, 0.05, 0.005, ndt_rng);
    est.push_back(*messy.addScan(stamp, &m, information(0.05, 0.005)));
    for (auto& s : messy.takeWarnings()) warnings.push_back(s);
  }
  EXPECT_TRUE(anyWarningContains(warnings, "out of order or duplicated"));
  EXPECT_LT((est.back().pose.translation() - a.estimates.back().pose.translation()).norm(), 1e-9);
  // A scan older than the window's newest state is refused, not inserted.
  const Eigen::Isometry3d m = drive(1.0).pose;
  EXPECT_EQ(messy.addScan(1.0, &m, information(0.05, 0.005))->stamp, est.back().stamp);
  EXPECT_TRUE(anyWarningContains(messy.takeWarnings(), "not after the window's newest state"));
}

TEST(SlidingWindow, ZeroVelocityUpdatesHoldAStandingRobotWithoutNdt) {
  gpl::SlidingWindowConfig with_zupt;
  gpl::SlidingWindowConfig without_zupt;
  without_zupt.zupt_max_speed = 0.0;
  gpl::SlidingWindow a(with_zupt), b(without_zupt);
  ImuErrors errors = mems();
  errors.accel_bias << 0.05, -0.04, 0.03;
  // NDT for the first second, then 5 s of rejected matches: only the IMU (and the standstill) remain.
  auto first_second = [](int k) { return k < 10; };
  const Replay ra = run(a, standStill, 60, errors, first_second, always);
  const Replay rb = run(b, standStill, 60, errors, first_second, always);
  for (const auto& e : ra.estimates) ASSERT_TRUE(finite(e));
  EXPECT_TRUE(a.lastReport().stationary);
  // How far the estimate moved after the last NDT match (its offset from the truth is the mean NDT noise).
  auto moved = [](const Replay& r) {
    double worst = 0.0;
    for (std::size_t k = 10; k < r.estimates.size(); ++k)
      worst = std::max(worst, (r.estimates[k].pose.translation() - r.estimates[9].pose.translation()).norm());
    return worst;
  };
  EXPECT_LT(moved(ra), 0.02);  // over 5 s; without the updates it is tens of centimetres (below)
  EXPECT_LT(ra.estimates.back().velocity.norm(), 0.01);
  // Without the zero-velocity updates the unestimated part of the bias integrates into drift.
  EXPECT_GT(moved(rb), 5.0 * moved(ra)) << "moved " << moved(rb) << " m without, " << moved(ra) << " m with";
}

TEST(SlidingWindow, ARobotSettingOffSmoothlyIsNotHeldStill) {
  // A smooth start barely changes the specific force's spread, so standing still is told from setting off by its
  // mean: gravity alone at rest, gravity plus the acceleration once moving. Held still, the estimate fell metres
  // behind.
  gpl::SlidingWindow w{gpl::SlidingWindowConfig()};
  const Replay r = run(w, startFromRest, 30, mems(), always, always);
  ASSERT_EQ(r.estimates.size(), 30u);
  double worst = 0.0, worst_ndt = 0.0;
  for (std::size_t k = 10; k < r.estimates.size(); ++k) {  // from setting off (1 s) on
    ASSERT_TRUE(finite(r.estimates[k]));
    worst = std::max(worst, positionError(r.estimates[k], startFromRest));
    worst_ndt = std::max(
        worst_ndt, (r.measurements[k].translation() - startFromRest(r.estimates[k].stamp).pose.translation()).norm());
  }
  EXPECT_LT(worst, 0.5 * worst_ndt) << "fused worst " << worst << " m, NDT worst " << worst_ndt << " m";
  EXPECT_FALSE(w.lastReport().stationary);
}

TEST(SlidingWindow, ImuWithoutCovarianceUsesTheConfiguredDensitiesAndSaysSo) {
  gpl::SlidingWindow w{gpl::SlidingWindowConfig()};
  const Replay r = run(w, drive, 30, mems(), always, always);
  EXPECT_TRUE(anyWarningContains(r.warnings, "no covariance"));
  int count = 0;
  for (const auto& s : r.warnings) count += s.find("no covariance") != std::string::npos;
  EXPECT_EQ(count, 1);  // said once, not per sample
  for (const auto& e : r.estimates) ASSERT_TRUE(finite(e));
  EXPECT_LT(positionError(r.estimates.back(), drive), 0.05);

  // With a covariance in each sample there is no such warning.
  gpl::SlidingWindow v{gpl::SlidingWindowConfig()};
  gpl::ImuSample s;
  s.stamp = 0.0;
  s.accel.z() = kG;
  s.gyro_variance = 1e-6;
  s.accel_variance = 1e-4;
  v.addImu(s);
  EXPECT_FALSE(anyWarningContains(v.takeWarnings(), "no covariance"));
}

TEST(SlidingWindow, NonFiniteInputIsRefusedAndNeverReachesTheEstimate) {
  gpl::SlidingWindow w{gpl::SlidingWindowConfig()};
  run(w, drive, 10, mems(), always, always);
  gpl::ImuSample bad;
  bad.stamp = 10.0;
  bad.accel.x() = std::nan("");
  EXPECT_FALSE(w.addImu(bad));
  Eigen::Isometry3d nan_pose = Eigen::Isometry3d::Identity();
  nan_pose(0, 3) = std::nan("");
  const auto est = w.addScan(1.0, &nan_pose, information(0.05, 0.005));
  ASSERT_TRUE(est);
  EXPECT_TRUE(finite(*est));
  EXPECT_TRUE(anyWarningContains(w.takeWarnings(), "not finite"));
}

TEST(SlidingWindow, InvalidConfigIsRefusedWithTheFieldName) {
  gpl::SlidingWindowConfig c;
  c.reset_states = 50;
  c.gyro_noise_density = -1.0;
  try {
    gpl::SlidingWindow w(c);
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("reset_states"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("gyro_noise_density"), std::string::npos);
  }
}

TEST(NdtInformation, AtIdentityTheEulerParametersAreTheTangent) {
  gpl::Matrix6d cov = gpl::Matrix6d::Zero();
  cov.diagonal() << 0.01, 0.04, 0.09, 1e-4, 4e-4, 9e-4;
  const gpl::Matrix6d info = gpl::ndtInformation(Eigen::Isometry3d::Identity(), cov);
  EXPECT_LT((info - gpl::Matrix6d(cov.inverse())).norm(), 1e-4 * cov.inverse().norm());
}

TEST(NdtInformation, YawOnlyUncertaintyStaysAboutTheVerticalAtAnyHeading) {
  // Uncertain yaw only (x y z roll pitch tight): about the map's vertical, which for a level pose is the body's z.
  gpl::Matrix6d cov = gpl::Matrix6d::Identity() * 1e-6;
  cov(5, 5) = 0.01;
  const Eigen::Isometry3d pose(Eigen::AngleAxisd(2.0, Eigen::Vector3d::UnitZ()));
  const gpl::Matrix6d info = gpl::ndtInformation(pose, cov);
  EXPECT_NEAR(info(5, 5), 100.0, 1e-3);
  EXPECT_NEAR(info(3, 3), 1e6, 1.0);
  EXPECT_NEAR(info(4, 4), 1e6, 1.0);
}

// fusion/mode auto (the default): the window starts with the first IMU sample that carries a specific force and
// rates. A gyro-only or accelerometer-only IMU (sensor_msgs/Imu marks the missing part with covariance element 0 at
// -1) leaves NDT alone; once the window runs, such samples are skipped with a warning instead of being integrated as
// zeros.
TEST(FusionTracker, AutoStartsTheWindowWithTheFirstSampleThatHasASpecificForceAndRates) {
  EXPECT_EQ(gpl::FusionConfig().mode, gpl::FusionMode::kAuto);
  EXPECT_EQ(gpl::parseFusionMode("auto"), gpl::FusionMode::kAuto);
  gpl::FusionConfig c;
  c.mode = gpl::FusionMode::kAuto;
  gpl::FusionTracker tracker(c);
  EXPECT_FALSE(tracker.enabled());
  EXPECT_TRUE(tracker.mayRun());
  std::mt19937 rng(3);
  const ImuErrors exact;
  const Eigen::Isometry3d pose = drive(0.0).pose;
  const gpl::Matrix6d ndt_covariance = information(0.05, 0.005).inverse();
  int next_imu = 0;
  auto feed = [&](double until, bool has_accel, bool has_gyro) {
    for (; next_imu / kImuRate <= until + 1e-9; ++next_imu) {
      gpl::ImuSample s = imuSample(drive, next_imu / kImuRate, exact, rng);
      s.has_accel = has_accel;
      s.has_gyro = has_gyro;
      tracker.addImu(s);
    }
  };
  feed(0.1, false, true);
  EXPECT_FALSE(tracker.enabled());
  feed(0.2, true, false);
  EXPECT_FALSE(tracker.enabled());
  EXPECT_FALSE(tracker.update(0.2, false, &pose, ndt_covariance).has_value());
  EXPECT_TRUE(tracker.takeWarnings().empty());
  feed(0.3, true, true);
  ASSERT_TRUE(tracker.enabled());
  const Eigen::Isometry3d at_03 = drive(0.3).pose;
  ASSERT_TRUE(tracker.update(0.3, false, &at_03, ndt_covariance).has_value());
  EXPECT_EQ(tracker.states(), 1u);
  feed(0.4, false, true);
  EXPECT_TRUE(anyWarningContains(tracker.takeWarnings(), "no specific force"));
  feed(0.5, true, false);
  EXPECT_TRUE(anyWarningContains(tracker.takeWarnings(), "no angular velocity"));

  c.mode = gpl::FusionMode::kNone;
  gpl::FusionTracker none(c);
  EXPECT_FALSE(none.mayRun());
  none.addImu(imuSample(drive, 0.0, exact, rng));
  EXPECT_FALSE(none.enabled());
}
