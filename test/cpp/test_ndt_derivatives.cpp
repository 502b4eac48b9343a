// The analytic gradient and Hessian of the NDT cost against central finite differences.
#include <gtest/gtest.h>

#include <random>

#include "grid_puzzle_localization/ndt.hpp"
#include "ndt_synthetic.hpp"

namespace gpl = grid_puzzle_localization;

namespace {

// Source points whose transforms at every probed pose stay well inside their voxel, so the neighbour sets do not
// change within the finite-difference stencil (the cost is only piecewise smooth across voxel borders).
gpl::PointCloud sourceNearCentres(const gpl::VoxelMap& map, const gpl::Vector6d& pose, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> off(-0.25, 0.25);
  const Eigen::Matrix4d inv = gpl::poseToMatrix(pose).inverse();
  gpl::PointCloud world;
  const double r = map.resolution();
  map.forEach([&](const gpl::VoxelKey& k, const gpl::VoxelStats&, const gpl::VoxelGaussian& g) {
    if (!g.valid || world.size() >= 400) return;
    const Eigen::Vector3f p((k.x + 0.5 + off(rng)) * r, (k.y + 0.5 + off(rng)) * r, (k.z + 0.5 + off(rng)) * r);
    // RADIUS also switches at |p - mean| = resolution: keep points whose neighbour means are clear of that sphere.
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const gpl::VoxelGaussian* n = map.find({k.x + dx, k.y + dy, k.z + dz});
          if (n && std::abs((p - n->mean).norm() - r) < 0.1) return;
        }
    world.push_back(p);
  });
  return gpl::synthetic::transformed(world, inv);
}

class NdtDerivativesTest : public ::testing::TestWithParam<gpl::NdtSearchMethod> {};

TEST_P(NdtDerivativesTest, MatchFiniteDifferences) {
  gpl::NdtConfig cfg;
  cfg.search = GetParam();
  cfg.threads = 2;
  gpl::NdtTarget target(cfg);
  target.setTarget(gpl::synthetic::scene(1, 0.03));
  const auto map = target.snapshot();
  const gpl::NdtAligner aligner(cfg);
  // Poses with large angles exercise every term of the Euler-angle derivatives (a pitch-sine sign error shows here).
  const std::vector<gpl::Vector6d> poses = {
      (gpl::Vector6d() << 0.3, -0.2, 0.1, 0.05, -0.04, 0.1).finished(),
      (gpl::Vector6d() << 2.0, 1.0, -0.5, 0.6, -0.5, 1.2).finished(),
      (gpl::Vector6d() << -1.0, 3.0, 0.2, -0.9, 0.8, -2.5).finished(),
  };
  unsigned seed = 0;
  for (const gpl::Vector6d& pose : poses) {
    const gpl::PointCloud src = sourceNearCentres(*map, pose, ++seed);
    // Evaluate the derivatives at a pose slightly off the one the points were built for.
    const gpl::Vector6d at = pose + (gpl::Vector6d() << 0.02, -0.03, 0.01, 0.004, -0.003, 0.005).finished();
    const gpl::NdtDerivatives d = aligner.derivatives(*map, src, at);
    ASSERT_GT(std::abs(d.cost), 1.0);
    // Five-point stencil (truncation error O(h^4)): the narrow Gaussians make the cost strongly curved.
    const double h = 2e-4;
    gpl::Vector6d g_fd;
    gpl::Matrix6d H_fd;
    for (int i = 0; i < 6; ++i) {
      gpl::Vector6d e = gpl::Vector6d::Zero();
      e(i) = h;
      const gpl::NdtDerivatives p1 = aligner.derivatives(*map, src, at + e);
      const gpl::NdtDerivatives m1 = aligner.derivatives(*map, src, at - e);
      const gpl::NdtDerivatives p2 = aligner.derivatives(*map, src, at + 2 * e);
      const gpl::NdtDerivatives m2 = aligner.derivatives(*map, src, at - 2 * e);
      g_fd(i) = (8 * (p1.cost - m1.cost) - (p2.cost - m2.cost)) / (12 * h);
      H_fd.col(i) = (8 * (p1.gradient - m1.gradient) - (p2.gradient - m2.gradient)) / (12 * h);
    }
    const double g_scale = std::max(1.0, d.gradient.norm());
    const double H_scale = std::max(1.0, d.hessian.norm());
    for (int i = 0; i < 6; ++i) {
      EXPECT_NEAR(d.gradient(i), g_fd(i), 2e-3 * g_scale) << "gradient " << i << " at pose " << at.transpose();
      for (int j = 0; j < 6; ++j)
        EXPECT_NEAR(d.hessian(i, j), H_fd(i, j), 2e-3 * H_scale)
            << "Hessian " << i << "," << j << " at pose " << at.transpose();
    }
    EXPECT_LT((d.hessian - d.hessian.transpose()).norm(), 1e-9 * H_scale);
  }
}

INSTANTIATE_TEST_SUITE_P(Methods, NdtDerivativesTest,
                         ::testing::Values(gpl::NdtSearchMethod::DIRECT1, gpl::NdtSearchMethod::DIRECT7,
                                           gpl::NdtSearchMethod::DIRECT27, gpl::NdtSearchMethod::RADIUS),
                         [](const auto& info) { return std::string(gpl::toString(info.param)); });

TEST(NdtPose, MatrixRoundTripAndEulerOrder) {
  const gpl::Vector6d p = (gpl::Vector6d() << 1, -2, 3, 0.3, -0.7, 2.9).finished();
  const Eigen::Matrix4d T = gpl::poseToMatrix(p);
  // Independent composition: R = Rx(roll) Ry(pitch) Rz(yaw).
  const Eigen::Matrix3d R =
      (Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX()) * Eigen::AngleAxisd(-0.7, Eigen::Vector3d::UnitY()) *
       Eigen::AngleAxisd(2.9, Eigen::Vector3d::UnitZ()))
          .toRotationMatrix();
  EXPECT_LT((T.topLeftCorner<3, 3>() - R).norm(), 1e-12);
  EXPECT_LT((gpl::matrixToPose(T) - p).norm(), 1e-12);
}

}  // namespace
