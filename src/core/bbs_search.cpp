#include "grid_puzzle_localization/bbs_search.hpp"

#include <algorithm>
#include <atomic>
#include <stdexcept>
#include <tuple>

#include "omp_threads.hpp"

namespace grid_puzzle_localization {

LikelihoodPyramid::LikelihoodPyramid(std::vector<std::uint8_t> fine, int width, int height, int levels)
    : width_(width), height_(height) {
  if (width <= 0 || height <= 0 || fine.size() != static_cast<std::size_t>(width) * height || levels < 0)
    throw std::invalid_argument("LikelihoodPyramid: the grid must hold width * height > 0 values and levels >= 0");
  grids_.reserve(static_cast<std::size_t>(levels) + 1);
  grids_.push_back(Level{0, width, height, std::move(fine)});
  // Level h from level h-1: the max of the four 2^(h-1) blocks that tile [x, x + 2^h) x [y, y + 2^h).
  for (int h = 1; h <= levels; ++h) {
    const int s = 1 << (h - 1), offset = (1 << h) - 1;
    Level next{offset, width + offset, height + offset, {}};
    next.values.resize(static_cast<std::size_t>(next.width) * next.height);
    for (int y = -offset; y < height; ++y)
      for (int x = -offset; x < width; ++x)
        next.values[static_cast<std::size_t>(y + offset) * next.width + x + offset] =
            std::max({value(h - 1, x, y), value(h - 1, x + s, y), value(h - 1, x, y + s), value(h - 1, x + s, y + s)});
    grids_.push_back(std::move(next));
  }
}

std::int64_t LikelihoodPyramid::score(int level, const std::vector<Eigen::Vector2i>& cells, int dx, int dy) const {
  const Level& g = grids_[static_cast<std::size_t>(level)];
  const std::uint8_t* values = g.values.data();
  dx += g.offset;
  dy += g.offset;
  std::int64_t sum = 0;
  for (const Eigen::Vector2i& c : cells) {
    const int x = c.x() + dx, y = c.y() + dy;
    if (x >= 0 && y >= 0 && x < g.width && y < g.height) sum += values[static_cast<std::size_t>(y) * g.width + x];
  }
  return sum;
}

bool betterNode(const BbsNode& a, const BbsNode& b) {
  return std::make_tuple(-a.score, a.yaw, a.x, a.y, a.level) < std::make_tuple(-b.score, b.yaw, b.x, b.y, b.level);
}

namespace {

BbsNode scored(const BbsProblem& p, int yaw, int x, int y, int level) {
  return BbsNode{yaw, x, y, level, p.pyramid->score(level, p.cells[static_cast<std::size_t>(yaw)], x, y)};
}

/// The (up to four) children of `node`, scored, best first.
std::vector<BbsNode> children(const BbsProblem& p, const BbsNode& node) {
  const int s = 1 << (node.level - 1);
  std::vector<BbsNode> out;
  out.reserve(4);
  for (int dy : {0, s})
    for (int dx : {0, s})
      if (node.x + dx < p.width && node.y + dy < p.height)
        out.push_back(scored(p, node.yaw, node.x + dx, node.y + dy, node.level - 1));
  std::sort(out.begin(), out.end(), betterNode);
  return out;
}

/// Depth-first branch and bound under `node`; `best` is shared by all threads and only grows.
class DepthFirst {
 public:
  DepthFirst(const BbsProblem& p, std::int64_t min_score, double ratio, std::atomic<std::int64_t>* best)
      : p_(p), min_score_(min_score), ratio_(ratio), best_(best) {}

  bool worthExploring(std::int64_t score) const {
    return score >= min_score_ && static_cast<double>(score) >= ratio_ * static_cast<double>(best_->load());
  }

  void explore(const BbsNode& node) {
    if (!worthExploring(node.score)) return;
    if (node.level == 0) {
      leaves.push_back(node);
      std::int64_t seen = best_->load();
      while (node.score > seen && !best_->compare_exchange_weak(seen, node.score)) {
      }
      return;
    }
    const std::vector<BbsNode> next = children(p_, node);
    evaluated += next.size();
    for (const BbsNode& child : next) explore(child);
  }

  std::vector<BbsNode> leaves;
  std::size_t evaluated = 0;

 private:
  const BbsProblem& p_;
  std::int64_t min_score_;
  double ratio_;
  std::atomic<std::int64_t>* best_;
};

}  // namespace

std::vector<BbsNode> rootNodes(const BbsProblem& p, int threads) {
  const int top = p.pyramid->levels();
  const int step = 1 << top;
  const int nx = (p.width + step - 1) / step, ny = (p.height + step - 1) / step;
  const int per_yaw = nx * ny;
  std::vector<BbsNode> roots(static_cast<std::size_t>(per_yaw) * p.cells.size());
#pragma omp parallel for num_threads(resolveThreads(threads)) schedule(dynamic, 4)
  for (int i = 0; i < static_cast<int>(roots.size()); ++i) {
    const int yaw = i / per_yaw, cell = i % per_yaw;
    roots[static_cast<std::size_t>(i)] = scored(p, yaw, (cell % nx) * step, (cell / nx) * step, top);
  }
  std::sort(roots.begin(), roots.end(), betterNode);
  return roots;
}

BbsNode greedyDescent(const BbsProblem& p, BbsNode node, std::size_t* evaluated) {
  while (node.level > 0) {
    const std::vector<BbsNode> next = children(p, node);
    if (evaluated) *evaluated += next.size();
    node = next.front();
  }
  return node;
}

BbsOutcome branchAndBound(const BbsProblem& p, std::int64_t min_score, double ratio, int initial_descents,
                          int threads) {
  BbsOutcome out;
  const std::vector<BbsNode> roots = rootNodes(p, threads);
  out.evaluated = roots.size();
  std::atomic<std::int64_t> best{0};
  // Adapted initial score S0: the best leaf of greedy descents from the best roots bounds the search from the start.
  const std::size_t descents = std::min(roots.size(), static_cast<std::size_t>(std::max(0, initial_descents)));
  for (std::size_t i = 0; i < descents; ++i)
    best = std::max(best.load(), greedyDescent(p, roots[i], &out.evaluated).score);
  out.initial_bound = std::max(min_score, static_cast<std::int64_t>(ratio * static_cast<double>(best.load())));

  const int team = resolveThreads(threads);
  std::vector<std::vector<BbsNode>> leaves(static_cast<std::size_t>(team));
  std::vector<std::size_t> evaluated(static_cast<std::size_t>(team), 0);
#pragma omp parallel num_threads(team)
  {
    DepthFirst search(p, min_score, ratio, &best);
#pragma omp for schedule(dynamic, 1)
    for (int i = 0; i < static_cast<int>(roots.size()); ++i) search.explore(roots[static_cast<std::size_t>(i)]);
    leaves[static_cast<std::size_t>(teamThreadNum())] = std::move(search.leaves);
    evaluated[static_cast<std::size_t>(teamThreadNum())] = search.evaluated;
  }
  // Leaves found while the bound was still low are dropped, so the answer is the same on any schedule.
  const double final_bound = std::max(static_cast<double>(min_score), ratio * static_cast<double>(best.load()));
  for (std::size_t t = 0; t < leaves.size(); ++t) {
    out.evaluated += evaluated[t];
    for (const BbsNode& leaf : leaves[t])
      if (static_cast<double>(leaf.score) >= final_bound) out.leaves.push_back(leaf);
  }
  std::sort(out.leaves.begin(), out.leaves.end(), betterNode);
  return out;
}

}  // namespace grid_puzzle_localization
