#include "grid_puzzle_localization/pose_search.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <sstream>

namespace grid_puzzle_localization {
namespace {

Eigen::Isometry3d toIsometry(const Eigen::Matrix4f& m) {
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.translation() = m.topRightCorner<3, 1>().cast<double>();
  out.linear() = Eigen::Quaterniond(m.topLeftCorner<3, 3>().cast<double>()).normalized().toRotationMatrix();
  return out;
}

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

std::string SearchConfig::validate() const {
  std::ostringstream err;
  if (!(step > 0.0)) err << "search/step must be > 0 m (got " << step << "); ";
  if (!(yaw_step > 0.0)) err << "search/yaw_step must be > 0 rad (got " << yaw_step << "); ";
  if (!(max_candidates >= 1)) err << "search/max_candidates must be >= 1 (got " << max_candidates << "); ";
  if (!(screen_points >= 10)) err << "search/screen_points must be >= 10 (got " << screen_points << "); ";
  if (!(refine >= 1)) err << "search/refine must be >= 1 (got " << refine << "); ";
  if (!(ambiguity_ratio >= 0.0 && ambiguity_ratio <= 1.0))
    err << "search/ambiguity_ratio must be in [0, 1] (got " << ambiguity_ratio << "); ";
  return err.str();
}

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

SearchResult pickUnambiguous(std::vector<NdtResult> refined, const std::vector<bool>& acceptable,
                             const SearchConfig& config) {
  SearchResult out;
  int best = -1;
  for (std::size_t i = 0; i < refined.size(); ++i)
    if (acceptable[i] && (best < 0 || refined[i].nvtl > refined[best].nvtl)) best = static_cast<int>(i);
  if (best < 0) return out;
  const Eigen::Isometry3d winner = toIsometry(refined[best].transform);
  out.best_nvtl = refined[best].nvtl;
  for (std::size_t i = 0; i < refined.size(); ++i) {
    const Eigen::Isometry3d other = toIsometry(refined[i].transform);
    const bool distinct = (other.translation() - winner.translation()).norm() > 2.0 * config.step ||
                          Eigen::AngleAxisd(other.rotation().transpose() * winner.rotation()).angle() > config.yaw_step;
    if (distinct) out.runner_up_nvtl = std::max(out.runner_up_nvtl, refined[i].nvtl);
  }
  out.ambiguous = out.runner_up_nvtl >= config.ambiguity_ratio * out.best_nvtl;
  if (!out.ambiguous) out.best = std::move(refined[best]);
  return out;
}

}  // namespace grid_puzzle_localization
