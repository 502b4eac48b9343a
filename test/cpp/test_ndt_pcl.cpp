// RADIUS search against PCL 1.13's pcl::NormalDistributionsTransform on the same input, with settings under which
// PCL converges: the two final poses must agree within 1 mm and 0.01 deg.
#include <gtest/gtest.h>
#include <pcl/pcl_config.h>
#include <pcl/point_types.h>
#include <pcl/registration/ndt.h>

#include <iostream>

#include "grid_puzzle_localization/ndt.hpp"
#include "ndt_synthetic.hpp"

namespace gpl = grid_puzzle_localization;

namespace {

pcl::PointCloud<pcl::PointXYZ>::Ptr toPcl(const gpl::PointCloud& c) {
  pcl::PointCloud<pcl::PointXYZ>::Ptr out(new pcl::PointCloud<pcl::PointXYZ>);
  for (const auto& p : c) out->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
  return out;
}

TEST(NdtVersusPcl, RadiusSearchLandsOnPclsPose) {
  const Eigen::Matrix4d truth = gpl::poseToMatrix((gpl::Vector6d() << 0.3, -0.2, 0.05, 0.01, -0.02, 0.05).finished());
  // Dense scans (many points per voxel) so that PCL's biased covariance scaling, ((n-1)/n)^2 smaller than the
  // unbiased one used here, moves the optimum by far less than the tolerance.
  const gpl::PointCloud target = gpl::synthetic::scene(1, 0.02, 60000);
  const gpl::PointCloud source = gpl::synthetic::transformed(gpl::synthetic::scene(2, 0.02, 15000), truth.inverse());
  const Eigen::Matrix4f guess =
      gpl::poseToMatrix((gpl::Vector6d() << 0.2, -0.1, 0.0, 0.0, 0.0, 0.02).finished()).cast<float>();

  gpl::NdtConfig cfg;
  cfg.search = gpl::NdtSearchMethod::RADIUS;
  cfg.transformation_epsilon = 1e-6;
  cfg.max_iterations = 100;
  gpl::NdtTarget ours_target(cfg);
  ours_target.setTarget(target);
  const gpl::NdtResult ours = gpl::NdtAligner(cfg).align(*ours_target.snapshot(), source, guess);
  ASSERT_EQ(ours.status, gpl::NdtResultStatus::OK) << ours.message;

  pcl::NormalDistributionsTransform<pcl::PointXYZ, pcl::PointXYZ> ndt;
  ndt.setResolution(static_cast<float>(cfg.resolution));
  ndt.setStepSize(cfg.step_size);
  ndt.setTransformationEpsilon(cfg.transformation_epsilon);
  ndt.setMaximumIterations(cfg.max_iterations);
  ndt.setOulierRatio(cfg.outlier_ratio);  // sic: PCL 1.13's spelling
  ndt.setInputTarget(toPcl(target));
  ndt.setInputSource(toPcl(source));
  pcl::PointCloud<pcl::PointXYZ> aligned;
  ndt.align(aligned, guess);
  ASSERT_TRUE(ndt.hasConverged());
  ASSERT_LT(ndt.getFinalNumIteration(), cfg.max_iterations) << "PCL must converge on this case";

  const Eigen::Matrix4d pcl_pose = ndt.getFinalTransformation().cast<double>();
  const auto [te, re] = gpl::synthetic::poseError(pcl_pose, ours.transform.cast<double>());
  const auto [te_truth, re_truth] = gpl::synthetic::poseError(truth, pcl_pose);
  std::cout << "ours vs truth " << gpl::synthetic::poseError(truth, ours.transform.cast<double>()).first * 1000
            << " mm " << gpl::synthetic::poseError(truth, ours.transform.cast<double>()).second << " deg; ";
  std::cout << "ours vs PCL: " << te * 1000 << " mm, " << re << " deg (PCL " << ndt.getFinalNumIteration()
            << " iterations, ours " << ours.iterations << "); PCL vs truth " << te_truth * 1000 << " mm" << std::endl;
#if PCL_VERSION_COMPARE(<, 1, 12, 1)
  // Before 1.12.1 PCL's NDT Hessian has a sign error (PCL issue 4888: the pitch-squared term), so its Newton steps stop
  // short of the optimum (PCL 1.11: 7.8 mm from the truth here) and it is no sub-millimetre reference. Ours must still
  // land at least as near the truth as PCL does.
  const auto [te_ours, re_ours] = gpl::synthetic::poseError(truth, ours.transform.cast<double>());
  EXPECT_LE(te_ours, te_truth + 0.001);
  EXPECT_LE(re_ours, re_truth + 0.01);
#else
  EXPECT_LT(te, 0.001);
  EXPECT_LT(re, 0.01);
#endif
}

}  // namespace
