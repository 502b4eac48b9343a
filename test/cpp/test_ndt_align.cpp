// Alignment on synthetic scenes with a known transform, thread-count invariance, degenerate inputs, line search.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <cmath>
#include <limits>
#include <random>

#include "grid_puzzle_localization/more_thuente.hpp"
#include "grid_puzzle_localization/ndt.hpp"
#include "ndt_synthetic.hpp"

namespace gpl = grid_puzzle_localization;

namespace {

struct Scene {
  gpl::PointCloud target, source;
  Eigen::Matrix4d truth;  // T_target_source
};

// Two independent noisy scans of one world; the source is expressed in a frame moved by `truth`.
Scene makeScene(const gpl::Vector6d& truth_pose, double noise = 0.02) {
  Scene s;
  s.truth = gpl::poseToMatrix(truth_pose);
  s.target = gpl::synthetic::scene(1, noise, 30000);
  s.source = gpl::synthetic::transformed(gpl::synthetic::scene(2, noise, 12000), s.truth.inverse());
  return s;
}

gpl::NdtResult alignScene(const Scene& s, const gpl::NdtConfig& cfg) {
  gpl::NdtTarget target(cfg);
  target.setTarget(s.target);
  return gpl::NdtAligner(cfg).align(*target.snapshot(), s.source, Eigen::Matrix4f::Identity());
}

class NdtRecoversTransform : public ::testing::TestWithParam<gpl::NdtSearchMethod> {};

TEST_P(NdtRecoversTransform, SixDofOnPlanesBoxesAndPoles) {
  const std::vector<gpl::Vector6d> truths = {
      (gpl::Vector6d() << 0.5, -0.3, 0.1, 0.02, -0.03, 0.08).finished(),
      (gpl::Vector6d() << -0.4, 0.6, -0.15, -0.03, 0.02, -0.12).finished(),
  };
  for (const auto& truth : truths) {
    const Scene s = makeScene(truth);
    gpl::NdtConfig cfg;
    cfg.search = GetParam();
    cfg.resolution = 1.0;
    cfg.transformation_epsilon = 1e-4;
    cfg.max_iterations = 60;
    const gpl::NdtResult r = alignScene(s, cfg);
    ASSERT_EQ(r.status, gpl::NdtResultStatus::OK) << r.message;
    EXPECT_TRUE(r.converged);
    const auto [te, re] = gpl::synthetic::poseError(s.truth, r.transform.cast<double>());
    EXPECT_LT(te, 0.02) << "translation error [m]";
    EXPECT_LT(re, 0.1) << "rotation error [deg]";
    EXPECT_GT(r.inlier_fraction, 0.8);
    EXPECT_GT(r.nvtl, 0.0);
    EXPECT_NEAR(r.transformation_probability, -r.score / r.source_points, 1e-9);
    // At the optimum the cost Hessian is positive definite: its inverse is a usable covariance.
    Eigen::SelfAdjointEigenSolver<gpl::Matrix6d> eig(r.hessian);
    EXPECT_GT(eig.eigenvalues()(0), 0.0);
  }
}

INSTANTIATE_TEST_SUITE_P(Methods, NdtRecoversTransform,
                         ::testing::Values(gpl::NdtSearchMethod::DIRECT1, gpl::NdtSearchMethod::DIRECT7,
                                           gpl::NdtSearchMethod::DIRECT27, gpl::NdtSearchMethod::RADIUS),
                         [](const auto& info) { return std::string(gpl::toString(info.param)); });

TEST(NdtAlign, FixedStepWithoutLineSearchAlsoConverges) {
  const Scene s = makeScene((gpl::Vector6d() << 0.3, 0.2, -0.05, 0.01, 0.02, -0.05).finished());
  gpl::NdtConfig cfg;
  cfg.line_search = false;
  cfg.step_size = 0.02;  // without a line search a 0.1 step (rad for the angles) overshoots a 15 m scene
  cfg.transformation_epsilon = 1e-4;
  cfg.max_iterations = 100;
  const gpl::NdtResult r = alignScene(s, cfg);
  const auto [te, re] = gpl::synthetic::poseError(s.truth, r.transform.cast<double>());
  ASSERT_EQ(r.status, gpl::NdtResultStatus::OK) << r.message;
  EXPECT_LT(te, 0.02);
  EXPECT_LT(re, 0.1);
}

// Tracking case: the guess is already within transformation_epsilon of the optimum, where the Newton step is exact
// to second order and is taken whole (no line search): one iteration, two passes over the scan, landing on the
// optimum found by a long run with a tiny epsilon (the reference). test_localizer checks the same on scans where a
// line search used to spend up to 11 passes.
TEST(NdtAlign, GuessWithinEpsilonTakesTheNewtonStepInTwoPasses) {
  const Scene s = makeScene((gpl::Vector6d() << 0.2, -0.1, 0.03, 0.01, -0.02, 0.04).finished());
  gpl::NdtConfig cfg;  // defaults: line search on, transformation_epsilon 0.01
  gpl::NdtTarget target(cfg);
  target.setTarget(s.target);
  const gpl::NdtAligner aligner(cfg);
  gpl::NdtConfig fine = cfg;
  fine.transformation_epsilon = 1e-7;
  fine.max_iterations = 100;
  const gpl::NdtResult reference =
      gpl::NdtAligner(fine).align(*target.snapshot(), s.source, Eigen::Matrix4f::Identity());
  ASSERT_EQ(reference.status, gpl::NdtResultStatus::OK) << reference.message;
  const gpl::Vector6d optimum = gpl::matrixToPose(reference.transform.cast<double>());
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  for (int trial = 0; trial < 10; ++trial) {
    gpl::Vector6d offset;
    for (int i = 0; i < 3; ++i) offset(i) = 0.003 * unit(rng);   // up to 3 mm per axis
    for (int i = 3; i < 6; ++i) offset(i) = 0.0005 * unit(rng);  // up to 0.5 mrad per axis
    const Eigen::Matrix4f guess = gpl::poseToMatrix(optimum + offset).cast<float>();
    const gpl::NdtResult r = aligner.align(*target.snapshot(), s.source, guess);
    ASSERT_EQ(r.status, gpl::NdtResultStatus::OK) << r.message;
    EXPECT_EQ(r.iterations, 1);
    EXPECT_EQ(r.evaluations, 2);  // at the guess and at the result
    const auto [te, re] = gpl::synthetic::poseError(reference.transform.cast<double>(), r.transform.cast<double>());
    EXPECT_LT(te, 0.5e-3) << "translation from the reference optimum [m]";
    EXPECT_LT(re, 0.01) << "rotation from the reference optimum [deg]";
  }
}

TEST(NdtAlign, ResultDoesNotDependOnThreadCount) {
  const Scene s = makeScene((gpl::Vector6d() << 0.4, -0.2, 0.05, 0.02, -0.01, 0.06).finished());
  for (const auto method : {gpl::NdtSearchMethod::DIRECT7, gpl::NdtSearchMethod::RADIUS}) {
    gpl::NdtConfig cfg;
    cfg.search = method;
    cfg.threads = 1;
    const gpl::NdtResult one = alignScene(s, cfg);
    for (const int threads : {2, 3, 8}) {
      cfg.threads = threads;
      const gpl::NdtResult r = alignScene(s, cfg);
      EXPECT_EQ(r.iterations, one.iterations);
      EXPECT_LT((r.transform - one.transform).cwiseAbs().maxCoeff(), 1e-6) << threads << " threads";
      EXPECT_NEAR(r.score, one.score, 1e-9 * std::abs(one.score));
      EXPECT_LT((r.hessian - one.hessian).norm(), 1e-9 * one.hessian.norm());
    }
  }
}

void expectFinite(const gpl::NdtResult& r) {
  EXPECT_TRUE(r.transform.allFinite());
  EXPECT_TRUE(r.hessian.allFinite());
  EXPECT_TRUE(std::isfinite(r.score) && std::isfinite(r.nvtl) && std::isfinite(r.transformation_probability));
  EXPECT_FALSE(r.converged);
  EXPECT_FALSE(r.message.empty());
}

TEST(NdtAlign, DegenerateInputsGiveAnErrorStatusNotACrash) {
  const gpl::NdtConfig cfg;
  const gpl::NdtAligner aligner(cfg);
  const gpl::PointCloud scene = gpl::synthetic::scene(1, 0.02, 5000);
  gpl::NdtTarget empty(cfg);
  gpl::NdtResult r = aligner.align(*empty.snapshot(), scene, Eigen::Matrix4f::Identity());
  EXPECT_EQ(r.status, gpl::NdtResultStatus::EMPTY_TARGET);
  expectFinite(r);

  gpl::NdtTarget target(cfg);
  target.setTarget(scene);
  r = aligner.align(*target.snapshot(), gpl::PointCloud(scene.begin(), scene.begin() + 3), Eigen::Matrix4f::Identity());
  EXPECT_EQ(r.status, gpl::NdtResultStatus::TOO_FEW_POINTS);
  expectFinite(r);

  const float nan = std::numeric_limits<float>::quiet_NaN();
  gpl::PointCloud with_nan = {{nan, 0, 0}, {0, nan, 0}};
  r = aligner.align(*target.snapshot(), with_nan, Eigen::Matrix4f::Identity());
  EXPECT_EQ(r.status, gpl::NdtResultStatus::TOO_FEW_POINTS);
  expectFinite(r);

  Eigen::Matrix4f bad_guess = Eigen::Matrix4f::Identity();
  bad_guess(0, 3) = nan;
  r = aligner.align(*target.snapshot(), scene, bad_guess);
  EXPECT_EQ(r.status, gpl::NdtResultStatus::INVALID_INPUT);
  EXPECT_TRUE(r.hessian.allFinite());

  // Far from the map: no correspondence.
  Eigen::Matrix4f far = Eigen::Matrix4f::Identity();
  far(0, 3) = 1000.0f;
  r = aligner.align(*target.snapshot(), scene, far);
  EXPECT_EQ(r.status, gpl::NdtResultStatus::NO_CORRESPONDENCE);
  expectFinite(r);

  // All target and source points in one voxel: one Gaussian cannot pin down a 6-DoF pose.
  gpl::PointCloud blob;
  std::mt19937 rng(2);
  std::uniform_real_distribution<float> u(0.05f, 0.95f);
  for (int i = 0; i < 200; ++i) blob.emplace_back(u(rng), 0.3f * u(rng), 0.1f * u(rng));
  gpl::NdtTarget one_voxel(cfg);
  one_voxel.setTarget(blob);
  ASSERT_EQ(one_voxel.snapshot()->gaussianCount(), 1u);
  r = aligner.align(*one_voxel.snapshot(), blob, Eigen::Matrix4f::Identity());
  EXPECT_EQ(r.status, gpl::NdtResultStatus::DEGENERATE);
  expectFinite(r);
  EXPECT_EQ(r.transform, Eigen::Matrix4f::Identity());

  // A target built with another resolution is refused, not silently misused.
  gpl::NdtConfig other = cfg;
  other.resolution = 2.0;
  gpl::NdtTarget coarse(other);
  coarse.setTarget(scene);
  r = aligner.align(*coarse.snapshot(), scene, Eigen::Matrix4f::Identity());
  EXPECT_EQ(r.status, gpl::NdtResultStatus::INVALID_INPUT);
  EXPECT_NE(r.message.find("resolution"), std::string::npos);
}

TEST(NdtConfig, ValidateAndParse) {
  gpl::NdtConfig cfg;
  EXPECT_EQ(cfg.validate(), "");
  cfg.outlier_ratio = 1.0;
  cfg.max_iterations = 0;
  cfg.coarse_yaw_probe = std::nan("");
  const std::string msg = cfg.validate();
  EXPECT_NE(msg.find("outlier_ratio"), std::string::npos);
  EXPECT_NE(msg.find("max_iterations"), std::string::npos);
  EXPECT_NE(msg.find("coarse_yaw_probe"), std::string::npos);
  EXPECT_THROW(gpl::NdtAligner{cfg}, std::invalid_argument);
  gpl::NdtSearchMethod m;
  ASSERT_TRUE(gpl::parseSearchMethod("radius", &m));
  EXPECT_EQ(m, gpl::NdtSearchMethod::RADIUS);
  EXPECT_FALSE(gpl::parseSearchMethod("KDTREE", &m));
}

TEST(MoreThuente, FindsAStrongWolfePointOnAQuartic) {
  // phi(a) = (a - 2)^4 - 3 a: phi'(0) = -32 - 3 < 0; the minimiser solves 4 (a - 2)^3 = 3.
  int evaluations = 0;
  const auto phi = [&](double a, double* f, double* g) {
    ++evaluations;
    *f = std::pow(a - 2, 4) - 3 * a;
    *g = 4 * std::pow(a - 2, 3) - 3;
  };
  double f0, g0;
  phi(0.0, &f0, &g0);
  const gpl::LineSearchParams params;
  const double a = gpl::moreThuente(phi, f0, g0, 0.5, 0.0, 10.0, params);
  double fa, ga;
  phi(a, &fa, &ga);
  EXPECT_LE(fa, f0 + params.mu * a * g0);             // sufficient decrease
  EXPECT_LE(std::abs(ga), params.nu * std::abs(g0));  // curvature
  EXPECT_LE(evaluations, params.max_evaluations + 2);
  // With a step cap below the minimiser, the search stops at the cap (still descending there).
  EXPECT_DOUBLE_EQ(gpl::moreThuente(phi, f0, g0, 0.5, 0.0, 0.1, params), 0.1);
}

}  // namespace
