// Branch-and-bound search over 2D translations and a list of yaws on a max-pooled likelihood pyramid
// (Hess et al. 2016, with the block map paper's adapted initial score). Used by GlobalLocalizer; exposed for tests.
// No ROS includes here.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace grid_puzzle_localization {

/// A 2D grid of likelihoods (0..255) and its coarser levels: level h at cell (x, y) holds the maximum of the finest
/// level over the 2^h x 2^h cells [x, x + 2^h) x [y, y + 2^h) (cells outside the grid count as 0). Level h is stored
/// from cell -(2^h - 1) on, so a window hanging over the low edge keeps the cells it covers, and coordinates are the
/// finest level's on every level, so a node's score needs no coordinate change.
class LikelihoodPyramid {
 public:
  /// `fine` is row-major (index y * width + x). Throws std::invalid_argument when sizes do not match or levels < 0.
  LikelihoodPyramid(std::vector<std::uint8_t> fine, int width, int height, int levels);
  int width() const { return width_; }
  int height() const { return height_; }
  int levels() const { return static_cast<int>(grids_.size()) - 1; }  ///< levels above the finest
  /// Value of level `level` at (x, y); 0 where the window holds no cell of the grid.
  std::uint8_t value(int level, int x, int y) const {
    const Level& g = grids_[static_cast<std::size_t>(level)];
    x += g.offset;
    y += g.offset;
    if (x < 0 || y < 0 || x >= g.width || y >= g.height) return 0;
    return g.values[static_cast<std::size_t>(y) * g.width + x];
  }
  /// Sum over `cells` of value(level, cell + (dx, dy)).
  std::int64_t score(int level, const std::vector<Eigen::Vector2i>& cells, int dx, int dy) const;

 private:
  struct Level {
    int offset, width, height;  ///< stored cell (0, 0) is cell (-offset, -offset)
    std::vector<std::uint8_t> values;
  };
  int width_, height_;
  std::vector<Level> grids_;
};

/// A search node: translation offsets [x, x + 2^level) x [y, y + 2^level) (in finest cells) at one yaw. At level 0
/// it is one pose and `score` is exact; above, `score` bounds every pose under it from above.
struct BbsNode {
  int yaw = 0;    ///< index into BbsProblem::cells
  int x = 0;      ///< translation offset [cells]
  int y = 0;      ///< translation offset [cells]
  int level = 0;  ///< pyramid level
  std::int64_t score = 0;
};

/// Orders nodes by score (high first), ties by yaw, x, y, level so that every sort is deterministic.
bool betterNode(const BbsNode& a, const BbsNode& b);

/// What is searched: for every yaw, the pyramid cells of the scan's points at translation offset (0, 0); a pose
/// (yaw, x, y) maps point i to cell cells[yaw][i] + (x, y). Offsets range over [0, width) x [0, height).
struct BbsProblem {
  const LikelihoodPyramid* pyramid = nullptr;
  std::vector<std::vector<Eigen::Vector2i>> cells;
  int width = 0;
  int height = 0;
};

struct BbsOutcome {
  /// Every pose (level-0 node) scoring >= max(min_score, ratio * best), best first (betterNode order). Empty when
  /// none reaches min_score.
  std::vector<BbsNode> leaves;
  std::size_t evaluated = 0;       ///< nodes scored, all levels (depends on the thread schedule)
  std::int64_t initial_bound = 0;  ///< the bound the search started from (S0 or min_score)
};

/// Root nodes: every yaw at the coarsest level, scored, in betterNode order.
std::vector<BbsNode> rootNodes(const BbsProblem& problem, int threads);

/// Greedy descent from `node`: always into the best child, down to level 0. Returns that pose.
BbsNode greedyDescent(const BbsProblem& problem, BbsNode node, std::size_t* evaluated = nullptr);

/// Branch and bound. Explores every node whose bound is >= max(min_score, ratio * best leaf so far), depth first
/// with the best child first, roots in parallel (`threads`, 0 = all cores). With `initial_descents` > 0 the bound
/// starts from S0, the best leaf of greedy descents from that many best roots (the adapted initial score); with 0
/// it starts from min_score (plain BBS). The leaves returned do not depend on the thread count or the schedule.
BbsOutcome branchAndBound(const BbsProblem& problem, std::int64_t min_score, double ratio, int initial_descents,
                          int threads);

}  // namespace grid_puzzle_localization
