// Global localization: the pyramid bound, the branch and bound against exhaustive search, and GlobalLocalizer on
// synthetic worlds with known poses.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <string>

#include "grid_puzzle_localization/bbs_search.hpp"
#include "grid_puzzle_localization/global_localization.hpp"
#include "synthetic_world.hpp"

namespace gpl = grid_puzzle_localization;
using gpl::test::makeWorld;
using gpl::test::poseXYYaw;
using gpl::test::rotationError;
using gpl::test::scanFrom;
using gpl::test::translationError;

namespace {

constexpr double kPi = 3.14159265358979323846;

std::vector<std::uint8_t> randomGrid(int w, int h, std::mt19937& rng) {
  std::uniform_int_distribution<int> value(0, 255), coin(0, 9);
  std::vector<std::uint8_t> g(static_cast<std::size_t>(w) * h);
  for (auto& v : g) v = coin(rng) < 3 ? static_cast<std::uint8_t>(value(rng)) : 0;
  return g;
}

std::vector<Eigen::Vector2i> randomCells(int n, int lo, int hi, std::mt19937& rng) {
  std::uniform_int_distribution<int> c(lo, hi);
  std::vector<Eigen::Vector2i> cells;
  for (int i = 0; i < n; ++i) cells.emplace_back(c(rng), c(rng));
  return cells;
}

/// Exhaustive search: the best pose over every yaw and offset (ties by betterNode).
gpl::BbsNode bruteForce(const gpl::BbsProblem& p) {
  gpl::BbsNode best{0, 0, 0, 0, -1};
  for (int yaw = 0; yaw < static_cast<int>(p.cells.size()); ++yaw)
    for (int y = 0; y < p.height; ++y)
      for (int x = 0; x < p.width; ++x) {
        const gpl::BbsNode n{yaw, x, y, 0, p.pyramid->score(0, p.cells[static_cast<std::size_t>(yaw)], x, y)};
        if (best.score < 0 || gpl::betterNode(n, best)) best = n;
      }
  return best;
}

}  // namespace

TEST(LikelihoodPyramid, CoarseLevelIsTheMaxOfTheFineCellsUnderIt) {
  std::mt19937 rng(11);
  const int w = 37, h = 29;
  const std::vector<std::uint8_t> fine = randomGrid(w, h, rng);
  const gpl::LikelihoodPyramid pyramid(fine, w, h, 4);
  for (int level = 0; level <= 4; ++level)
    for (int y = 1 - (1 << level); y < h + 2; ++y)
      for (int x = 1 - (1 << level); x < w + 2; ++x) {
        int expected = 0;
        for (int j = std::max(0, y); j < std::min(h, y + (1 << level)); ++j)
          for (int i = std::max(0, x); i < std::min(w, x + (1 << level)); ++i)
            expected = std::max<int>(expected, fine[static_cast<std::size_t>(j) * w + i]);
        ASSERT_EQ(pyramid.value(level, x, y), expected) << "level " << level << " cell " << x << ", " << y;
      }
}

TEST(LikelihoodPyramid, BoundIsAdmissibleOnRandomMaps) {
  std::mt19937 rng(5);
  for (int trial = 0; trial < 20; ++trial) {
    const int w = 40, h = 40, levels = 4;
    const gpl::LikelihoodPyramid pyramid(randomGrid(w, h, rng), w, h, levels);
    const std::vector<Eigen::Vector2i> cells = randomCells(25, -5, 30, rng);
    std::uniform_int_distribution<int> offset(-4, 30);
    for (int k = 0; k < 50; ++k) {
      const int level = 1 + k % levels, x = offset(rng), y = offset(rng);
      const std::int64_t bound = pyramid.score(level, cells, x, y);
      for (int j = 0; j < (1 << level); ++j)
        for (int i = 0; i < (1 << level); ++i)
          ASSERT_GE(bound, pyramid.score(0, cells, x + i, y + j))
              << "trial " << trial << ": level " << level << " node " << x << ", " << y << " under-bounds pose +" << i
              << ", +" << j;
    }
  }
}

TEST(BranchAndBound, FindsTheExhaustiveOptimumWithAndWithoutS0OnAnyThreadCount) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 10; ++trial) {
    const gpl::LikelihoodPyramid pyramid(randomGrid(48, 48, rng), 48, 48, 3);
    gpl::BbsProblem p;
    p.pyramid = &pyramid;
    p.width = 21;
    p.height = 19;
    for (int yaw = 0; yaw < 6; ++yaw) p.cells.push_back(randomCells(30, 0, 26, rng));
    const gpl::BbsNode truth = bruteForce(p);
    for (int descents : {0, 3})
      for (int threads : {1, 2, 3}) {
        const gpl::BbsOutcome out = gpl::branchAndBound(p, 0, 0.9, descents, threads);
        ASSERT_FALSE(out.leaves.empty());
        const gpl::BbsNode& best = out.leaves.front();
        EXPECT_EQ(best.score, truth.score) << "trial " << trial;
        EXPECT_EQ(std::make_tuple(best.yaw, best.x, best.y), std::make_tuple(truth.yaw, truth.x, truth.y))
            << "trial " << trial << " descents " << descents << " threads " << threads;
        for (const gpl::BbsNode& leaf : out.leaves) EXPECT_GE(static_cast<double>(leaf.score), 0.9 * truth.score);
      }
  }
}

TEST(BranchAndBound, LeavesDoNotDependOnTheThreadCount) {
  std::mt19937 rng(17);
  const gpl::LikelihoodPyramid pyramid(randomGrid(80, 80, rng), 80, 80, 4);
  gpl::BbsProblem p;
  p.pyramid = &pyramid;
  p.width = p.height = 40;
  for (int yaw = 0; yaw < 16; ++yaw) p.cells.push_back(randomCells(40, 0, 40, rng));
  const gpl::BbsOutcome one = gpl::branchAndBound(p, 0, 0.7, 2, 1);
  for (int threads : {2, 4}) {
    const gpl::BbsOutcome many = gpl::branchAndBound(p, 0, 0.7, 2, threads);
    ASSERT_EQ(many.leaves.size(), one.leaves.size()) << threads << " threads";
    for (std::size_t i = 0; i < one.leaves.size(); ++i)
      EXPECT_EQ(std::make_tuple(many.leaves[i].yaw, many.leaves[i].x, many.leaves[i].y, many.leaves[i].score),
                std::make_tuple(one.leaves[i].yaw, one.leaves[i].x, one.leaves[i].y, one.leaves[i].score));
  }
}

// A colonnade (posts on a 3 m lattice) with one short wall: every coarse cell looks alike, so a greedy descent from
// the best coarse candidate settles on a lattice-shifted pose; the branch and bound finds the wall.
TEST(BranchAndBound, FindsTheTruePoseInRepeatedStructureWhereGreedyDescentFails) {
  const int side = 160;  // 0.25 m cells
  std::vector<std::uint8_t> fine(side * side, 0);
  auto mark = [&](int x, int y) {
    if (x >= 0 && y >= 0 && x < side && y < side) fine[static_cast<std::size_t>(y) * side + x] = 255;
  };
  for (int y = 2; y < side; y += 12)
    for (int x = 2; x < side; x += 12) mark(x, y);
  const Eigen::Vector2i wall(87, 70);
  for (int i = 0; i < 8; ++i) mark(wall.x() + i, wall.y());
  const gpl::LikelihoodPyramid pyramid(fine, side, side, 5);
  // The scan: the posts and the wall seen from offset `truth` (cells relative to offset (0, 0)), 4 yaws (the true one
  // is index 2, the others are 90 degree turns, which the lattice makes look alike).
  const Eigen::Vector2i truth(43, 37);
  std::vector<Eigen::Vector2i> seen;
  for (int y = 2; y < side; y += 12)
    for (int x = 2; x < side; x += 12)
      if ((Eigen::Vector2i(x, y) - (truth + Eigen::Vector2i(40, 40))).cast<double>().norm() < 40)
        seen.push_back(Eigen::Vector2i(x, y) - truth);
  for (int i = 0; i < 8; ++i) seen.push_back(wall + Eigen::Vector2i(i, 0) - truth);
  gpl::BbsProblem p;
  p.pyramid = &pyramid;
  p.width = p.height = 80;
  for (int turn : {1, 3, 0, 2}) {
    std::vector<Eigen::Vector2i> cells;
    const Eigen::Vector2i centre = wall - truth;
    for (const Eigen::Vector2i& c : seen) {
      Eigen::Vector2i d = c - centre;
      for (int t = 0; t < turn; ++t) d = Eigen::Vector2i(-d.y(), d.x());
      cells.push_back(centre + d);
    }
    p.cells.push_back(cells);
  }
  const gpl::BbsNode best = bruteForce(p);
  ASSERT_EQ(std::make_tuple(best.yaw, best.x, best.y), std::make_tuple(2, truth.x(), truth.y()));
  const gpl::BbsNode greedy = gpl::greedyDescent(p, gpl::rootNodes(p, 1).front());
  EXPECT_LT(greedy.score, best.score) << "the scene must defeat a greedy descent to test anything";
  const gpl::BbsOutcome out = gpl::branchAndBound(p, 0, 0.95, 1, 2);
  ASSERT_FALSE(out.leaves.empty());
  EXPECT_EQ(std::make_tuple(out.leaves[0].yaw, out.leaves[0].x, out.leaves[0].y),
            std::make_tuple(2, truth.x(), truth.y()));
}

// ---------------------------------------------------------------- GlobalLocalizer on a synthetic yard

class GlobalLocalizerTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { world_ = new gpl::PointCloud(makeWorld(0.2f, 3)); }
  static void TearDownTestSuite() { delete world_; }
  static gpl::GlobalLocalizationConfig config(int threads = 2) {
    gpl::GlobalLocalizationConfig c;
    c.threads = threads;
    c.ndt.threads = threads;
    return c;
  }
  static gpl::GlobalSearchRequest around(double x, double y, double size = 40.0) {
    gpl::GlobalSearchRequest r;
    r.center_x = x;
    r.center_y = y;
    r.size = size;
    return r;
  }
  static gpl::PointCloud* world_;
};
gpl::PointCloud* GlobalLocalizerTest::world_ = nullptr;

TEST_F(GlobalLocalizerTest, FindsAKnownPoseAnywhereInTheSearchSquareAndAnyYaw) {
  gpl::GlobalLocalizer localizer(config());
  localizer.setMap(*world_);
  const Eigen::Isometry3d truth = poseXYYaw(6.3, -4.1, 2.2, 1.8);
  const gpl::PointCloud scan = scanFrom(*world_, truth, 40.0f, 0.02f, 1);
  const gpl::GlobalLocalizationResult r = localizer.localize(scan, around(-6.0, 5.0));
  ASSERT_TRUE(r.found) << r.reason;
  EXPECT_LT(translationError(r.map_T_base, truth), 0.05);
  EXPECT_LT(rotationError(r.map_T_base, truth), 0.5 * kPi / 180);
  EXPECT_GT(r.score, r.runner_up_score);
  EXPECT_GT(r.confidence, 0.0);
  EXPECT_GT(r.candidates_evaluated, 0u);
  // The stages are parts of the whole (each ran, and they do not overlap).
  EXPECT_GT(r.grid_seconds, 0.0);
  EXPECT_GT(r.search_seconds, 0.0);
  EXPECT_GT(r.refine_seconds, 0.0);
  EXPECT_LE(r.grid_seconds + r.search_seconds + r.refine_seconds, r.seconds);
}

TEST_F(GlobalLocalizerTest, JudgesTheScanOnlyWhereTheMapReaches) {
  // A window of tiles that ends well inside the sensor's range: most of the scan lands beyond the map. The
  // answer is judged on the points that land on the map's area, so it is found, and those it explains are most.
  const Eigen::Isometry3d truth = poseXYYaw(3.0, -2.0, 0.6, 1.8);
  gpl::PointCloud window;
  for (const gpl::Point& p : *world_)
    if (std::abs(p.x() - 3.0f) < 10.0f && std::abs(p.y() + 2.0f) < 10.0f) window.push_back(p);
  gpl::GlobalLocalizer localizer(config());
  localizer.setMap(window);
  const gpl::PointCloud scan = scanFrom(*world_, truth, 40.0f, 0.02f, 4);
  gpl::GlobalSearchRequest request = around(3.0, -2.0, 4.0);
  request.yaw_center = 0.6;
  request.yaw_range = 0.5;
  const gpl::GlobalLocalizationResult r = localizer.localize(scan, request);
  ASSERT_TRUE(r.found) << r.reason;
  EXPECT_LT(translationError(r.map_T_base, truth), 0.05);
  EXPECT_LT(r.refinement.inlier_fraction, localizer.config().min_inlier_fraction);  // of the whole scan
  EXPECT_GE(r.explained_fraction, localizer.config().min_inlier_fraction);
  EXPECT_LE(r.explained_fraction, 1.0);
}

TEST_F(GlobalLocalizerTest, UsesGravityForRollAndPitch) {
  gpl::GlobalLocalizer localizer(config());
  localizer.setMap(*world_);
  Eigen::Isometry3d truth = poseXYYaw(-8.0, 3.0, -1.0, 1.5);
  const Eigen::Matrix3d tilt =
      (Eigen::AngleAxisd(0.06, Eigen::Vector3d::UnitY()) * Eigen::AngleAxisd(-0.04, Eigen::Vector3d::UnitX()))
          .toRotationMatrix();
  truth.linear() = truth.linear() * tilt;
  const gpl::PointCloud scan = scanFrom(*world_, truth, 40.0f, 0.02f, 2);
  const Eigen::Vector3d up_in_base = truth.linear().transpose() * Eigen::Vector3d::UnitZ();
  const gpl::GlobalLocalizationResult r = localizer.localize(scan, around(0.0, 0.0), up_in_base);
  ASSERT_TRUE(r.found) << r.reason;
  EXPECT_LT(translationError(r.map_T_base, truth), 0.05);
  EXPECT_LT(rotationError(r.map_T_base, truth), 0.5 * kPi / 180);
}

TEST_F(GlobalLocalizerTest, ResultDoesNotDependOnTheThreadCount) {
  const Eigen::Isometry3d truth = poseXYYaw(2.0, 7.5, 0.7, 1.8);
  const gpl::PointCloud scan = scanFrom(*world_, truth, 40.0f, 0.02f, 3);
  gpl::GlobalLocalizer one(config(1));
  one.setMap(*world_);
  const gpl::GlobalLocalizationResult a = one.localize(scan, around(0.0, 0.0));
  ASSERT_TRUE(a.found) << a.reason;
  // The config's thread count, and a request's own (GlobalSearchRequest::threads, 0 = all cores).
  std::vector<gpl::GlobalLocalizationResult> others;
  for (int threads : {2, 3}) {
    gpl::GlobalLocalizer many(config(threads));
    many.setMap(*world_);
    others.push_back(many.localize(scan, around(0.0, 0.0)));
  }
  for (int threads : {0, 2}) {
    gpl::GlobalSearchRequest request = around(0.0, 0.0);
    request.threads = threads;
    others.push_back(one.localize(scan, request));
  }
  for (const gpl::GlobalLocalizationResult& b : others) {
    ASSERT_TRUE(b.found) << b.reason;
    EXPECT_EQ(a.score, b.score);
    EXPECT_EQ(a.runner_up_score, b.runner_up_score);
    EXPECT_LT(translationError(a.map_T_base, b.map_T_base), 1e-4);
    EXPECT_LT(rotationError(a.map_T_base, b.map_T_base), 1e-5);
  }
}

TEST_F(GlobalLocalizerTest, RefusesBadInputWithAClearReason) {
  gpl::GlobalLocalizer localizer(config());
  EXPECT_NE(localizer.localize(gpl::PointCloud(), around(0, 0)).reason.find("no map"), std::string::npos);
  localizer.setMap(*world_);
  const gpl::PointCloud scan = scanFrom(*world_, poseXYYaw(0, 0, 0, 1.8), 40.0f, 0.02f, 4);

  const gpl::GlobalLocalizationResult empty = localizer.localize(gpl::PointCloud(), around(0, 0));
  EXPECT_FALSE(empty.found);
  EXPECT_NE(empty.reason.find("no finite points"), std::string::npos) << empty.reason;

  const gpl::PointCloud few(scan.begin(), scan.begin() + 20);
  const gpl::GlobalLocalizationResult sparse = localizer.localize(few, around(0, 0));
  EXPECT_FALSE(sparse.found);
  EXPECT_NE(sparse.reason.find("too few points"), std::string::npos) << sparse.reason;

  const gpl::GlobalLocalizationResult off = localizer.localize(scan, around(500.0, -300.0));
  EXPECT_FALSE(off.found);
  EXPECT_NE(off.reason.find("no map structure within the scan"), std::string::npos) << off.reason;

  gpl::GlobalSearchRequest bad = around(0, 0);
  bad.size = -1.0;
  EXPECT_NE(localizer.localize(scan, bad).reason.find("invalid search request"), std::string::npos);

  gpl::GlobalLocalizationConfig wrong = config();
  wrong.resolution = 0.0;
  wrong.max_runner_up_ratio = 1.5;
  const std::string error = wrong.validate();
  EXPECT_NE(error.find("resolution"), std::string::npos) << error;
  EXPECT_NE(error.find("max_runner_up_ratio"), std::string::npos) << error;
  EXPECT_THROW(gpl::GlobalLocalizer{wrong}, std::invalid_argument);
}

TEST_F(GlobalLocalizerTest, RefusesAnAmbiguousScene) {
  // Two identical yards side by side: the scan fits both equally well.
  gpl::PointCloud twins = *world_;
  for (const gpl::Point& p : *world_) twins.push_back(p + gpl::Point(70.0f, 0.0f, 0.0f));
  gpl::GlobalLocalizer localizer(config());
  localizer.setMap(twins);
  const gpl::PointCloud scan = scanFrom(*world_, poseXYYaw(4.0, 2.0, 0.3, 1.8), 40.0f, 0.02f, 5);
  const gpl::GlobalLocalizationResult r = localizer.localize(scan, around(35.0, 0.0, 80.0));
  EXPECT_FALSE(r.found);
  EXPECT_NE(r.reason.find("ambiguous"), std::string::npos) << r.reason;
  EXPECT_GE(r.runner_up_score, 0.9 * r.score);
  EXPECT_LT(r.confidence, 0.1);
}

// ---------------------------------------------------------------- the work budget (max_poses)

namespace {

/// Yaws of a search over the full circle at `step` [rad].
std::size_t fullCircleYaws(double step) { return static_cast<std::size_t>(std::ceil(2.0 * kPi / step)); }

/// Positions x yaws of a search over a `size` [m] square at resolution * 2^k and the full circle at step * 2^k.
std::size_t posesAt(double size, double resolution, double step, int k) {
  const auto side = static_cast<std::size_t>(std::floor(size / std::ldexp(resolution, k))) + 1;
  return side * side * fullCircleYaws(std::ldexp(step, k));
}

/// Nodes a branch and bound can score on `side` x `side` positions x `yaws` with `levels` pyramid levels: every node
/// of every level (each is scored at most once as a root or a child), plus the greedy descents' 4 children per level.
std::size_t treeNodes(std::size_t side, std::size_t yaws, int levels, int descents) {
  std::size_t nodes = 0;
  for (int h = 0; h <= levels; ++h) {
    const std::size_t cells = (side + (std::size_t{1} << h) - 1) >> h;
    nodes += yaws * cells * cells;
  }
  return nodes + static_cast<std::size_t>(4 * levels * descents);
}

}  // namespace

// The default budget holds the common search, a 40 m square with the full circle of yaw at 0.5 m, for a scan
// reaching max_range (the automatic yaw step resolution / 40 m): 81^2 x 503 poses; a wrong start's 60 m square runs
// at 1 m, and the whole of a 1 km^2 map (a square of 1.2 km around its bounding box) at 4 m, not 8 m.
TEST(GlobalLocalizationConfig, DefaultBudgetHoldsA40mSquareAtFullResolutionAndA1km2MapAt4m) {
  const gpl::GlobalLocalizationConfig c;
  const double step = c.resolution / c.max_range;
  const auto budget = static_cast<std::size_t>(c.max_poses);
  const std::size_t common = posesAt(40.0, c.resolution, step, 0);
  EXPECT_EQ(common, 81u * 81u * 503u);
  EXPECT_LE(common, budget);
  EXPECT_GT(posesAt(60.0, c.resolution, step, 0), budget);
  EXPECT_LE(posesAt(60.0, c.resolution, step, 1), budget);
  EXPECT_GT(posesAt(1200.0, c.resolution, step, 2), budget);
  EXPECT_LE(posesAt(1200.0, c.resolution, step, 3), budget);
  gpl::GlobalLocalizationConfig bad;
  bad.max_poses = 999;
  EXPECT_NE(bad.validate().find("max_poses"), std::string::npos) << bad.validate();
  bad.max_poses = 1000;
  EXPECT_EQ(bad.validate(), "");
}

TEST_F(GlobalLocalizerTest, WorkPerSearchStaysWithinTheBudgetAsTheSquareGrows) {
  // The yaw step set to what the automatic one is for a scan reaching 40 m, so that every count has a closed form.
  gpl::GlobalLocalizationConfig unbounded = config();
  unbounded.yaw_step = unbounded.resolution / 40.0;
  unbounded.max_poses = std::numeric_limits<int>::max();
  gpl::GlobalLocalizer without(unbounded);
  without.setMap(*world_);
  // The default budget, and one that takes the 200 m and 400 m squares down to 8 m cells (k = 4).
  std::vector<gpl::GlobalLocalizer> with;
  for (const int budget : {gpl::GlobalLocalizationConfig().max_poses, 100000}) {
    gpl::GlobalLocalizationConfig c = unbounded;
    c.max_poses = budget;
    with.emplace_back(c);
    with.back().setMap(*world_);
  }
  const Eigen::Isometry3d truth = poseXYYaw(4.3, -3.1, 2.2, 1.8);
  const gpl::PointCloud scan = scanFrom(*world_, truth, 40.0f, 0.02f, 6);
  const int levels = unbounded.levels, descents = unbounded.initial_descents;
  const std::size_t places = 4 * static_cast<std::size_t>(unbounded.refine_candidates + 1);
  std::size_t previous_poses = 0, previous_evaluated = 0, most_evaluated_within_budget = 0;
  for (const double size : {20.0, 50.0, 100.0, 200.0, 400.0}) {
    const gpl::GlobalSearchRequest request = around(3.0, -1.0, size);
    for (const gpl::GlobalLocalizer& localizer : with) {
      const gpl::GlobalLocalizationConfig& c = localizer.config();
      SCOPED_TRACE("square " + std::to_string(size) + " m, max_poses " + std::to_string(c.max_poses));
      const gpl::GlobalLocalizationResult r = localizer.localize(scan, request);
      // The closed form of the search's resolution: resolution * 2^k with the smallest k whose poses fit the budget.
      int k = 0;
      while (posesAt(size, c.resolution, c.yaw_step, k) > static_cast<std::size_t>(c.max_poses)) ++k;
      EXPECT_DOUBLE_EQ(r.search_resolution, std::ldexp(c.resolution, k));
      EXPECT_EQ(r.search_poses, posesAt(size, c.resolution, c.yaw_step, k));
      EXPECT_LE(r.search_poses, static_cast<std::size_t>(c.max_poses));
      // Bringing the coarse places down to full resolution: 9 x 9 positions x 9 yaws per place and level.
      EXPECT_LE(r.local_poses, places * 729 * static_cast<std::size_t>(k));
      const auto side = static_cast<std::size_t>(std::floor(size / r.search_resolution)) + 1;
      EXPECT_LE(r.candidates_evaluated, treeNodes(side, fullCircleYaws(std::ldexp(c.yaw_step, k)), levels, descents) +
                                            places * static_cast<std::size_t>(k) * treeNodes(9, 9, levels, descents));
      most_evaluated_within_budget = std::max(most_evaluated_within_budget, r.candidates_evaluated);
      // The true pose (the yard is unambiguous) at full precision, whatever the search's resolution.
      ASSERT_TRUE(r.found) << r.reason;
      EXPECT_LT(translationError(r.map_T_base, truth), 0.05);
      EXPECT_LT(rotationError(r.map_T_base, truth), 0.5 * kPi / 180);
    }
    // Without the budget the work grows with the area.
    SCOPED_TRACE("square " + std::to_string(size) + " m without a budget");
    const gpl::GlobalLocalizationResult u = without.localize(scan, request);
    ASSERT_TRUE(u.found) << u.reason;
    EXPECT_DOUBLE_EQ(u.search_resolution, unbounded.resolution);
    EXPECT_EQ(u.search_poses, posesAt(size, unbounded.resolution, unbounded.yaw_step, 0));
    EXPECT_EQ(u.local_poses, 0u);
    EXPECT_GT(u.search_poses, previous_poses);
    EXPECT_GT(u.candidates_evaluated, previous_evaluated);
    previous_poses = u.search_poses;
    previous_evaluated = u.candidates_evaluated;
  }
  EXPECT_GT(previous_poses, 50u * static_cast<std::size_t>(with.front().config().max_poses));
  EXPECT_GT(previous_evaluated, 4 * most_evaluated_within_budget);
}
