// The real HDL-32E pair: origin removal, 0.1 m voxel filter, resolution 1.0, identity guess, against the
// independent fast_gicp / small_gicp references (which agree with each other to about 2 cm).
#include <gtest/gtest.h>

#include <algorithm>
#include <iostream>

#include "grid_puzzle_localization/ndt.hpp"
#include "grid_puzzle_localization/pose_search.hpp"
#include "ndt_real_pair.hpp"
#include "ndt_synthetic.hpp"

namespace gpl = grid_puzzle_localization;

namespace {

// A guess off the reference by (along, across) [m] and `yaw` [rad], in the source frame.
Eigen::Matrix4d offReference(double along, double across, double yaw) {
  const Eigen::Affine3d off =
      Eigen::Translation3d(along, across, 0.0) * Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ());
  return off.matrix() * gpl::real_pair::reference();
}

gpl::NdtResult alignReal(gpl::NdtSearchMethod method) {
  gpl::NdtConfig cfg;
  cfg.search = method;
  cfg.resolution = 1.0;
  gpl::NdtTarget target(cfg);
  target.setTarget(gpl::real_pair::target());
  return gpl::NdtAligner(cfg).align(*target.snapshot(), gpl::real_pair::source(), Eigen::Matrix4f::Identity());
}

TEST(NdtRealPair, Direct7AndRadiusMatchTheReference) {
  const Eigen::Matrix4d ref = gpl::real_pair::reference();
  const Eigen::Matrix4d ref2 = gpl::real_pair::readMatrix("T_target_source_small_gicp.txt");
  for (const auto method : {gpl::NdtSearchMethod::DIRECT1, gpl::NdtSearchMethod::DIRECT7,
                            gpl::NdtSearchMethod::DIRECT27, gpl::NdtSearchMethod::RADIUS}) {
    const gpl::NdtResult r = alignReal(method);
    ASSERT_EQ(r.status, gpl::NdtResultStatus::OK) << gpl::toString(method) << ": " << r.message;
    const auto [te, re] = gpl::synthetic::poseError(ref, r.transform.cast<double>());
    const auto [te2, re2] = gpl::synthetic::poseError(ref2, r.transform.cast<double>());
    std::cout << gpl::toString(method) << ": " << r.iterations << " iterations, error vs fast_gicp " << te << " m "
              << re << " deg, vs small_gicp " << te2 << " m " << re2 << " deg" << std::endl;
    if (method == gpl::NdtSearchMethod::DIRECT1) continue;  // reported, not required
    EXPECT_LT(te, 0.03) << gpl::toString(method);
    EXPECT_LT(re, 0.3) << gpl::toString(method);
  }
}

// A guess 1.2 m and 4 deg off the reference, as a late or jittered scan between keyframes gives. The growing step
// limit and the coarse stage must reach the same minimum as PCL's fixed 0.1 step on the full scan, with fewer passes
// over the scan.
TEST(NdtRealPair, FarGuessConvergesWithFewerPassesOverTheScan) {
  const Eigen::Matrix4d ref = gpl::real_pair::reference();
  const Eigen::Matrix4f guess = offReference(0.9, -0.8, 0.07).cast<float>();
  gpl::NdtConfig fixed;
  fixed.max_step_size = fixed.step_size;
  fixed.coarse_points = 0;
  gpl::NdtConfig growing = fixed;
  growing.max_step_size = gpl::NdtConfig().max_step_size;
  const gpl::NdtConfig defaults;
  ASSERT_GT(gpl::real_pair::source().size(), 2u * static_cast<std::size_t>(defaults.coarse_points));
  gpl::NdtTarget target(defaults);
  target.setTarget(gpl::real_pair::target());
  int passes[3];
  const gpl::NdtConfig* configs[3] = {&fixed, &growing, &defaults};
  for (int i = 0; i < 3; ++i) {
    const gpl::NdtResult r = gpl::NdtAligner(*configs[i]).align(*target.snapshot(), gpl::real_pair::source(), guess);
    ASSERT_EQ(r.status, gpl::NdtResultStatus::OK) << i << ": " << r.message;
    const auto [te, re] = gpl::synthetic::poseError(ref, r.transform.cast<double>());
    std::cout << "config " << i << ": " << r.iterations << " iterations, " << r.evaluations << " passes over the scan, "
              << r.coarse_evaluations << " over the coarse subsample, error " << te << " m " << re << " deg"
              << std::endl;
    EXPECT_LT(te, 0.03) << i;
    EXPECT_LT(re, 0.3) << i;
    EXPECT_EQ(r.coarse_evaluations > 0, configs[i]->coarse_points > 0) << i;
    passes[i] = r.evaluations;
  }
  EXPECT_LT(passes[1], passes[0]) << "the growing step limit";
  EXPECT_LT(passes[2], passes[1]) << "the coarse stage";
}

// coarseAlign: the subsample alone brings the far guess of FarGuessConvergesWithFewerPassesOverTheScan to within a few
// decimetres of the reference, and there is none without a coarse stage.
TEST(NdtRealPair, CoarseAlignLandsNearTheMinimum) {
  const Eigen::Matrix4d ref = gpl::real_pair::reference();
  const Eigen::Isometry3d guess(offReference(0.9, -0.8, 0.07));
  gpl::NdtConfig cfg;
  gpl::NdtTarget target(cfg);
  target.setTarget(gpl::real_pair::target());
  const std::optional<Eigen::Isometry3d> coarse =
      gpl::NdtAligner(cfg).coarseAlign(*target.snapshot(), gpl::real_pair::source(), guess);
  ASSERT_TRUE(coarse.has_value());
  const auto [te_guess, re_guess] = gpl::synthetic::poseError(ref, guess.matrix());
  const auto [te, re] = gpl::synthetic::poseError(ref, coarse->matrix());
  std::cout << "coarse stage alone: " << te_guess << " m " << re_guess << " deg -> " << te << " m " << re << " deg"
            << std::endl;
  EXPECT_LT(te, 0.3);
  EXPECT_LT(re, 1.0);
  cfg.coarse_points = 0;
  EXPECT_FALSE(gpl::NdtAligner(cfg).coarseAlign(*target.snapshot(), gpl::real_pair::source(), guess).has_value());
}

// Guesses as a vehicle entering a turn between keyframes gets them: the prediction keeps the old heading, up to
// 0.4 rad off in yaw and a metre to the side. From some of them the coarse stage settles in a false basin near the
// guessed heading and the full scan needs 20-30 passes to climb out. With the yaw probes
// (NdtConfig::coarse_yaw_probe) every guess still reaches the reference and the worst costs less than half as much.
// Work counts passes over the scan, a pass over the coarse subsample as its share of the points.
TEST(NdtRealPair, TurnEntryGuessesCostLessWithTheYawProbes) {
  const Eigen::Matrix4d ref = gpl::real_pair::reference();
  gpl::NdtConfig with;
  ASSERT_GT(with.coarse_yaw_probe, 0.0);
  gpl::NdtConfig without = with;
  without.coarse_yaw_probe = 0.0;
  gpl::NdtTarget target(with);
  target.setTarget(gpl::real_pair::target());
  const gpl::PointCloud& source = gpl::real_pair::source();
  const double coarse_share = static_cast<double>(with.coarse_points) / static_cast<double>(source.size());
  double worst[2] = {0.0, 0.0};
  double total[2] = {0.0, 0.0};
  for (int step = -8; step <= 8; ++step) {
    for (const double lateral : {-1.0, 0.0, 1.0}) {
      const double yaw = 0.05 * step;
      const Eigen::Matrix4f guess = offReference(0.5, lateral, yaw).cast<float>();
      int k = 0;
      for (const gpl::NdtConfig* cfg : {&without, &with}) {
        const gpl::NdtResult r = gpl::NdtAligner(*cfg).align(*target.snapshot(), source, guess);
        ASSERT_EQ(r.status, gpl::NdtResultStatus::OK) << "yaw " << yaw << " lateral " << lateral << ": " << r.message;
        const auto [te, re] = gpl::synthetic::poseError(ref, r.transform.cast<double>());
        EXPECT_LT(te, 0.05) << "yaw " << yaw << " lateral " << lateral << " probe " << cfg->coarse_yaw_probe;
        // transformation_epsilon (0.01) lets the last step stop up to 0.57 deg short.
        EXPECT_LT(re, 0.6) << "yaw " << yaw << " lateral " << lateral << " probe " << cfg->coarse_yaw_probe;
        const double work = r.evaluations + coarse_share * r.coarse_evaluations;
        worst[k] = std::max(worst[k], work);
        total[k] += work;
        ++k;
      }
    }
  }
  std::cout << "work without the probes: worst " << worst[0] << ", total " << total[0] << "; with them: worst "
            << worst[1] << ", total " << total[1] << std::endl;
  EXPECT_LT(worst[1], 0.5 * worst[0]);
  EXPECT_LT(total[1], total[0]);
}

// Predictions extrapolated over dropped scans: 2-4 m off along and across the road, 0-0.1 rad in yaw. Starting on the
// coarse map (voxels coarse_map_factor times as large), every guess reaches the reference, and the worst and the
// total work are smaller than from the fine map alone, which does not reach it from every guess.
TEST(NdtRealPair, FarPredictionsReachTheReferenceFromTheCoarseMap) {
  const Eigen::Matrix4d ref = gpl::real_pair::reference();
  const gpl::NdtConfig cfg;
  ASSERT_GT(cfg.coarse_map_factor, 0);
  gpl::NdtTarget target(cfg);
  target.setTarget(gpl::real_pair::target());
  ASSERT_NE(target.snapshot()->coarse(), nullptr);
  const gpl::PointCloud& source = gpl::real_pair::source();
  const double coarse_share = static_cast<double>(cfg.coarse_points) / static_cast<double>(source.size());
  double worst[2] = {0.0, 0.0}, total[2] = {0.0, 0.0};
  int reached[2] = {0, 0}, guesses = 0;
  for (const double along : {-4.0, -3.0, -2.0, 2.0, 3.0, 4.0}) {
    for (const double across : {-1.0, 0.0, 1.0}) {
      for (const double yaw : {-0.1, 0.0, 0.1}) {
        const Eigen::Matrix4f guess = offReference(along, across, yaw).cast<float>();
        ++guesses;
        for (const bool from_coarse_map : {false, true}) {
          const gpl::NdtResult r = gpl::NdtAligner(cfg).align(*target.snapshot(), source, guess, from_coarse_map);
          const auto [te, re] = gpl::synthetic::poseError(ref, r.transform.cast<double>());
          const bool ok = r.status == gpl::NdtResultStatus::OK && te < 0.05 && re < 0.6;
          if (from_coarse_map) {
            EXPECT_TRUE(ok) << "along " << along << " across " << across << " yaw " << yaw << ": " << te << " m " << re
                            << " deg, " << r.message;
          }
          const double work = r.evaluations + coarse_share * r.coarse_evaluations;
          worst[from_coarse_map] = std::max(worst[from_coarse_map], work);
          total[from_coarse_map] += work;
          reached[from_coarse_map] += ok;
        }
      }
    }
  }
  std::cout << "fine map only: " << reached[0] << " of " << guesses << " reached, work worst " << worst[0] << " total "
            << total[0] << "; from the coarse map: " << reached[1] << " reached, worst " << worst[1] << " total "
            << total[1] << std::endl;
  EXPECT_LT(reached[0], guesses);
  EXPECT_LT(worst[1], 0.5 * worst[0]);
  EXPECT_LT(total[1], 0.5 * total[0]);
}

// The hypotheses' candidates after a turn was mispredicted: a yaw within half a hypothesis step (0.025 rad) of the
// reference's, at the prediction's position, metres off. From the coarse map the subsample's descent lands within
// 0.1 m and 0.5 deg of the reference from all of them; from the fine map alone it stops metres short from some.
TEST(NdtRealPair, CoarseAlignFromTheCoarseMapLandsNearTheMinimumFromMetresOff) {
  const Eigen::Matrix4d ref = gpl::real_pair::reference();
  const gpl::NdtConfig cfg;
  gpl::NdtTarget target(cfg);
  target.setTarget(gpl::real_pair::target());
  int landed[2] = {0, 0}, guesses = 0;
  for (const double along : {-3.0, -2.0, -1.0, 1.0, 2.0, 3.0}) {
    for (const double across : {-1.0, 0.0, 1.0}) {
      for (const double yaw : {-0.025, 0.0, 0.025}) {
        const Eigen::Isometry3d guess(offReference(along, across, yaw));
        ++guesses;
        for (const bool from_coarse_map : {false, true}) {
          const std::optional<Eigen::Isometry3d> coarse =
              gpl::NdtAligner(cfg).coarseAlign(*target.snapshot(), gpl::real_pair::source(), guess, from_coarse_map);
          ASSERT_TRUE(coarse.has_value());
          const auto [te, re] = gpl::synthetic::poseError(ref, coarse->matrix());
          if (from_coarse_map) {
            EXPECT_TRUE(te < 0.1 && re < 0.5)
                << "along " << along << " across " << across << " yaw " << yaw << ": " << te << " m " << re << " deg";
          }
          landed[from_coarse_map] += te < 0.1 && re < 0.5;
        }
      }
    }
  }
  std::cout << "landed: fine map only " << landed[0] << ", from the coarse map " << landed[1] << " of " << guesses
            << std::endl;
  EXPECT_LT(landed[0], guesses);
}

// The localizer's hypotheses skip a candidate at the position of one already descended and within the coarse stage's
// yaw probe of it (pose_search.hpp coveredByYawProbe): the probe makes the two descents one. From guesses metres and
// 0.2-0.3 rad off (a mispredicted turn), the coarse stage from the guess turned by up to the probe about the sensor
// lands within 0.1 m and 0.5 deg of where it lands from the guess.
TEST(NdtRealPair, CoarseStagesFromYawsWithinTheProbeLandTogether) {
  const gpl::NdtConfig cfg;
  gpl::NdtTarget target(cfg);
  target.setTarget(gpl::real_pair::target());
  const gpl::NdtAligner aligner(cfg);
  for (const double along : {-4.0, -2.0, 2.0, 4.0}) {
    for (const double yaw : {-0.3, -0.2, 0.2, 0.3}) {
      const Eigen::Isometry3d start(offReference(along, 0.0, yaw));
      const std::optional<Eigen::Isometry3d> from_start =
          aligner.coarseAlign(*target.snapshot(), gpl::real_pair::source(), start, true);
      ASSERT_TRUE(from_start.has_value());
      for (const double turn :
           {-cfg.coarse_yaw_probe, -0.5 * cfg.coarse_yaw_probe, 0.5 * cfg.coarse_yaw_probe, cfg.coarse_yaw_probe}) {
        const Eigen::Isometry3d neighbour = start * Eigen::AngleAxisd(turn, Eigen::Vector3d::UnitZ());
        ASSERT_TRUE(gpl::coveredByYawProbe(start, neighbour, 1e-9, cfg.coarse_yaw_probe + 1e-9));
        const std::optional<Eigen::Isometry3d> from_neighbour =
            aligner.coarseAlign(*target.snapshot(), gpl::real_pair::source(), neighbour, true);
        ASSERT_TRUE(from_neighbour.has_value());
        const auto [te, re] = gpl::synthetic::poseError(from_start->matrix(), from_neighbour->matrix());
        EXPECT_TRUE(te < 0.1 && re < 0.5)
            << "along " << along << " yaw " << yaw << " turned " << turn << ": " << te << " m " << re << " deg apart";
      }
    }
  }
}

TEST(NdtRealPair, PcdReaderAndPreprocessingGiveTheExpectedClouds) {
  // About 5k of the 69,088 target points lie at the origin (no return) and must be gone before the voxel filter.
  const gpl::PointCloud raw = gpl::readPcdXyz(gpl::real_pair::dataDir() + "/251370668.pcd");
  EXPECT_EQ(raw.size(), 69088u);
  std::size_t at_origin = 0;
  for (const auto& p : raw) at_origin += p.isZero();
  EXPECT_GT(at_origin, 1000u);
  for (const auto& p : gpl::real_pair::target()) EXPECT_FALSE(p.isZero());
}

}  // namespace
