#include "grid_puzzle_localization/pose_search.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace grid_puzzle_localization {
namespace {

std::vector<double> yawOffsets(double yaw_range, double yaw_step) {
  std::vector<double> out{0.0};
  const bool full_circle = yaw_range >= M_PI;
  const int n = full_circle ? static_cast<int>(std::ceil(M_PI / yaw_step)) : static_cast<int>(yaw_range / yaw_step);
  for (int k = 1; k <= n; ++k) {
    const double a = k * yaw_step;
    if (full_circle && a > M_PI - 1e-9) {
      out.push_back(M_PI);  // the half-turn once, not twice
      break;
    }
    out.push_back(a);
    out.push_back(-a);
  }
  return out;
}

// Grid offsets (x y) inside the disc, nearest first.
std::vector<Eigen::Vector2d> positionOffsets(double radius, double step) {
  std::vector<Eigen::Vector2d> out;
  const int n = static_cast<int>(std::floor(radius / step + 1e-9));
  for (int i = -n; i <= n; ++i)
    for (int j = -n; j <= n; ++j) {
      const Eigen::Vector2d o(i * step, j * step);
      if (o.norm() <= radius + 1e-9) out.push_back(o);
    }
  std::stable_sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return a.norm() < b.norm(); });
  return out;
}

}  // namespace

std::vector<Eigen::Isometry3d> searchCandidates(const SearchRegion& region, const SearchConfig& config) {
  const std::vector<double> yaws = yawOffsets(std::max(0.0, region.yaw_range), config.yaw_step);
  const double radius = std::max(0.0, region.radius);
  // Positions in a disc of radius r at spacing s: about pi r^2 / s^2 (+ the centre).
  const double budget = std::max(1.0, static_cast<double>(config.max_candidates) / yaws.size());
  const double step = std::max(config.step, radius * std::sqrt(M_PI / budget));
  std::vector<Eigen::Vector2d> positions = positionOffsets(radius, step);
  const std::size_t max_positions = static_cast<std::size_t>(budget);
  if (positions.size() > max_positions) positions.resize(max_positions);  // nearest kept
  std::vector<Eigen::Isometry3d> out;
  out.reserve(positions.size() * yaws.size());
  for (const Eigen::Vector2d& p : positions)
    for (double yaw : yaws) {
      Eigen::Isometry3d c = region.centre;
      c.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * region.centre.linear();
      c.translation().head<2>() += p;
      out.push_back(c);
    }
  return out;
}

std::vector<Eigen::Isometry3d> screenCandidates(const NdtAligner& aligner, const VoxelMap& target,
                                                const PointCloud& source, const std::vector<Eigen::Isometry3d>& all,
                                                const SearchConfig& config) {
  const std::size_t want = static_cast<std::size_t>(config.refine);
  if (all.size() <= want) return all;
  PointCloud subsample;
  const std::size_t stride = std::max<std::size_t>(1, source.size() / config.screen_points);
  for (std::size_t i = 0; i < source.size(); i += stride) subsample.push_back(source[i]);
  std::vector<double> cost(all.size());
  for (std::size_t i = 0; i < all.size(); ++i)
    cost[i] = aligner.derivatives(target, subsample, matrixToPose(all[i].matrix())).cost;
  std::vector<std::size_t> order(all.size());
  std::iota(order.begin(), order.end(), 0);
  std::partial_sort(order.begin(), order.begin() + want, order.end(),
                    [&](std::size_t a, std::size_t b) { return cost[a] < cost[b]; });
  std::vector<Eigen::Isometry3d> out;
  for (std::size_t k = 0; k < want; ++k) out.push_back(all[order[k]]);
  return out;
}

bool coveredByYawProbe(const Eigen::Isometry3d& start, const Eigen::Isometry3d& candidate, double position_tolerance,
                       double yaw_probe) {
  const double apart = (candidate.translation().head<2>() - start.translation().head<2>()).norm();
  const double turned = Eigen::AngleAxisd(start.linear().transpose() * candidate.linear()).angle();
  return apart <= position_tolerance && turned <= yaw_probe;
}

}  // namespace grid_puzzle_localization
