#include "grid_puzzle_localization/global_localization.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <sstream>
#include <stdexcept>
#include <unordered_map>
#include <unordered_set>

#include "grid_puzzle_localization/bbs_search.hpp"
#include "grid_puzzle_localization/preprocess.hpp"

namespace grid_puzzle_localization {

namespace {

constexpr double kTwoPi = 2.0 * 3.14159265358979323846;
/// [m] radius around a position whose ground cells give its ground height.
constexpr double kGroundRadius = 8.0;

std::int64_t cellKey(std::int64_t x, std::int64_t y) { return (x << 32) ^ (y & 0xffffffffLL); }

/// Lowest z per ground cell (x-y cells of edge `cell`).
using GroundCells = std::unordered_map<std::int64_t, double>;

GroundCells groundCells(const std::vector<Eigen::Vector3d>& points, double cell) {
  GroundCells ground;
  for (const Eigen::Vector3d& p : points) {
    const std::int64_t key = cellKey(static_cast<std::int64_t>(std::floor(p.x() / cell)),
                                     static_cast<std::int64_t>(std::floor(p.y() / cell)));
    auto it = ground.emplace(key, p.z()).first;
    it->second = std::min(it->second, p.z());
  }
  return ground;
}

double groundOf(const GroundCells& ground, const Eigen::Vector3d& p, double cell) {
  return ground.at(cellKey(static_cast<std::int64_t>(std::floor(p.x() / cell)),
                           static_cast<std::int64_t>(std::floor(p.y() / cell))));
}

/// The points standing min_height..max_height above the ground of their cell (walls, poles, trunks).
std::vector<Eigen::Vector3d> structurePoints(const std::vector<Eigen::Vector3d>& points, const GroundCells& ground,
                                             const GlobalLocalizationConfig& cfg) {
  std::vector<Eigen::Vector3d> out;
  for (const Eigen::Vector3d& p : points) {
    const double h = p.z() - groundOf(ground, p, cfg.ground_cell);
    if (h >= cfg.min_height && h <= cfg.max_height) out.push_back(p);
  }
  return out;
}

/// Median of the ground cells whose centre lies within kGroundRadius of (x, y); false when there is none.
bool groundHeight(const GroundCells& ground, double cell, double x, double y, double* height) {
  std::vector<double> near;
  const int r = static_cast<int>(std::ceil(kGroundRadius / cell));
  const std::int64_t cx = static_cast<std::int64_t>(std::floor(x / cell));
  const std::int64_t cy = static_cast<std::int64_t>(std::floor(y / cell));
  for (int dy = -r; dy <= r; ++dy)
    for (int dx = -r; dx <= r; ++dx) {
      const double ex = (static_cast<double>(cx + dx) + 0.5) * cell - x;
      const double ey = (static_cast<double>(cy + dy) + 0.5) * cell - y;
      if (ex * ex + ey * ey > kGroundRadius * kGroundRadius) continue;
      const auto it = ground.find(cellKey(cx + dx, cy + dy));
      if (it != ground.end()) near.push_back(it->second);
    }
  if (near.empty()) return false;
  std::nth_element(near.begin(), near.begin() + near.size() / 2, near.end());
  *height = near[near.size() / 2];
  return true;
}

double wrapAngle(double a) { return std::remainder(a, kTwoPi); }

GlobalLocalizationResult refused(GlobalLocalizationResult result, const std::string& reason,
                                 std::chrono::steady_clock::time_point start) {
  result.found = false;
  result.reason = reason;
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace

std::string GlobalLocalizationConfig::validate() const {
  std::ostringstream err;
  auto positive = [&](const char* name, double v) {
    if (!(v > 0.0) || !std::isfinite(v)) err << name << " must be > 0 (got " << v << "); ";
  };
  auto fraction = [&](const char* name, double v, bool zero_ok) {
    if (!(zero_ok ? v >= 0.0 : v > 0.0) || !(v <= 1.0))
      err << name << " must be in " << (zero_ok ? "[0, 1]" : "(0, 1]") << " (got " << v << "); ";
  };
  positive("resolution", resolution);
  positive("ground_cell", ground_cell);
  positive("max_range", max_range);
  positive("runner_up_distance", runner_up_distance);
  positive("runner_up_yaw", runner_up_yaw);
  positive("max_refinement_shift", max_refinement_shift);
  if (!std::isfinite(min_height) || !std::isfinite(max_height) || !(min_height < max_height))
    err << "min_height must be < max_height, both finite (got " << min_height << ", " << max_height << "); ";
  if (max_scan_points < 10) err << "max_scan_points must be >= 10 (got " << max_scan_points << "); ";
  if (min_scan_points < 3) err << "min_scan_points must be >= 3 (got " << min_scan_points << "); ";
  if (!(blur_sigma >= 0.0) || !std::isfinite(blur_sigma)) err << "blur_sigma must be >= 0 (got " << blur_sigma << "); ";
  if (!(yaw_step >= 0.0) || !(yaw_step < kTwoPi)) err << "yaw_step must be in [0, 2 pi) (got " << yaw_step << "); ";
  if (levels < 1 || levels > 12) err << "levels must be in 1..12 (got " << levels << "); ";
  if (initial_descents < 1) err << "initial_descents must be >= 1 (got " << initial_descents << "); ";
  fraction("min_score", min_score, true);
  fraction("max_runner_up_ratio", max_runner_up_ratio, false);
  fraction("min_inlier_fraction", min_inlier_fraction, true);
  if (threads < 0) err << "threads must be >= 0 (got " << threads << "); ";
  const std::string ndt_error = ndt.validate();
  if (!ndt_error.empty()) err << "ndt: " << ndt_error;
  return err.str();
}

struct GlobalLocalizer::Map {
  std::vector<Eigen::Vector2d> structure;  ///< [m] x-y of the map's structure points
  GroundCells ground;
  Eigen::AlignedBox2d bounds;
  std::shared_ptr<const VoxelMap> ndt_target;
};

GlobalLocalizer::GlobalLocalizer(const GlobalLocalizationConfig& config) : config_(config) {
  const std::string error = config.validate();
  if (!error.empty()) throw std::invalid_argument("GlobalLocalizationConfig: " + error);
}
GlobalLocalizer::~GlobalLocalizer() = default;
GlobalLocalizer::GlobalLocalizer(GlobalLocalizer&&) noexcept = default;
GlobalLocalizer& GlobalLocalizer::operator=(GlobalLocalizer&&) noexcept = default;

void GlobalLocalizer::setMap(const PointCloud& map_points, std::shared_ptr<const VoxelMap> ndt_target) {
  auto map = std::make_unique<Map>();
  std::vector<Eigen::Vector3d> points;
  points.reserve(map_points.size());
  for (const Point& p : map_points)
    if (p.allFinite()) points.push_back(p.cast<double>());
  map->ground = groundCells(points, config_.ground_cell);
  for (const Eigen::Vector3d& p : structurePoints(points, map->ground, config_)) {
    map->structure.push_back(p.head<2>());
    map->bounds.extend(p.head<2>());
  }
  if (ndt_target) {
    if (std::abs(ndt_target->resolution() - config_.ndt.resolution) > 1e-9)
      throw std::invalid_argument("GlobalLocalizer::setMap: the NDT target's resolution differs from ndt.resolution");
    map->ndt_target = std::move(ndt_target);
  } else {
    NdtTarget target(config_.ndt);
    target.setTarget(map_points);
    map->ndt_target = target.snapshot();
  }
  map_ = std::move(map);
}

bool GlobalLocalizer::hasMap() const { return map_ && !map_->structure.empty(); }

Eigen::AlignedBox2d GlobalLocalizer::mapBounds() const {
  if (!hasMap()) return Eigen::AlignedBox2d(Eigen::Vector2d::Zero(), Eigen::Vector2d::Zero());
  return map_->bounds;
}

GlobalLocalizationResult GlobalLocalizer::localize(const PointCloud& scan, const GlobalSearchRequest& request,
                                                   const std::optional<Eigen::Vector3d>& up_in_base) const {
  const auto start = std::chrono::steady_clock::now();
  const GlobalLocalizationConfig& cfg = config_;
  GlobalLocalizationResult result;
  if (!hasMap()) return refused(result, "no map (or a map without structure above the ground): call setMap", start);
  if (!std::isfinite(request.center_x) || !std::isfinite(request.center_y) || !(request.size > 0.0) ||
      !std::isfinite(request.size) || !std::isfinite(request.yaw_center) || !(request.yaw_range > 0.0) ||
      !std::isfinite(request.yaw_range))
    return refused(result, "invalid search request: the centre and yaw centre must be finite, size and yaw range > 0",
                   start);
  if (up_in_base && (!up_in_base->allFinite() || up_in_base->norm() < 1e-6))
    return refused(result, "invalid gravity direction: up_in_base must be finite and non-zero", start);

  // Level the scan with gravity: the search runs over x, y and yaw only.
  const Eigen::Matrix3d level =
      up_in_base
          ? Eigen::Quaterniond::FromTwoVectors(up_in_base->normalized(), Eigen::Vector3d::UnitZ()).toRotationMatrix()
          : Eigen::Matrix3d::Identity();
  std::vector<Eigen::Vector3d> leveled;
  PointCloud finite;
  for (const Point& p : scan) {
    if (!p.allFinite() || p.isZero()) continue;
    finite.push_back(p);
    const Eigen::Vector3d q = level * p.cast<double>();
    if (q.head<2>().norm() <= cfg.max_range) leveled.push_back(q);
  }
  if (finite.empty()) return refused(result, "the scan has no finite points: check the scan topic or file", start);
  const GroundCells scan_ground = groundCells(leveled, cfg.ground_cell);
  // Thin the scan's structure to one point per search cell (first seen), then to max_scan_points evenly.
  std::vector<Eigen::Vector2d> points;
  {
    std::unordered_set<std::int64_t> seen;
    for (const Eigen::Vector3d& q : structurePoints(leveled, scan_ground, cfg))
      if (seen.insert(cellKey(static_cast<std::int64_t>(std::floor(q.x() / cfg.resolution)),
                              static_cast<std::int64_t>(std::floor(q.y() / cfg.resolution))))
              .second)
        points.push_back(q.head<2>());
  }
  if (points.size() > static_cast<std::size_t>(cfg.max_scan_points)) {
    std::vector<Eigen::Vector2d> kept;
    for (int i = 0; i < cfg.max_scan_points; ++i)
      kept.push_back(points[static_cast<std::size_t>(i) * points.size() / cfg.max_scan_points]);
    points.swap(kept);
  }
  result.scan_points_used = points.size();
  if (points.size() < static_cast<std::size_t>(cfg.min_scan_points)) {
    std::ostringstream msg;
    msg << "too few points: the scan has " << points.size() << " structure points (min_height..max_height above "
        << "the ground, within max_range), the search needs min_scan_points = " << cfg.min_scan_points;
    return refused(result, msg.str(), start);
  }
  double scan_ground_z = 0.0;
  if (!groundHeight(scan_ground, cfg.ground_cell, 0.0, 0.0, &scan_ground_z))
    return refused(result, "the scan shows no ground within 8 m of the sensor, so z cannot be set", start);

  // Yaws: the step moves the farthest point by at most one cell.
  double reach = cfg.resolution;
  for (const Eigen::Vector2d& p : points) reach = std::max(reach, p.norm());
  const double step = cfg.yaw_step > 0.0 ? cfg.yaw_step : cfg.resolution / reach;
  std::vector<double> yaws;
  if (request.yaw_range >= kTwoPi - 1e-9) {
    const int n = static_cast<int>(std::ceil(kTwoPi / step));
    for (int i = 0; i < n; ++i) yaws.push_back(wrapAngle(request.yaw_center + kTwoPi * i / n));
  } else {
    const int n = static_cast<int>(std::ceil(request.yaw_range / step)) + 1;
    for (int i = 0; i < n; ++i)
      yaws.push_back(wrapAngle(request.yaw_center - request.yaw_range / 2 + request.yaw_range * i / (n - 1)));
  }

  // The grid: the search square plus the scan's reach on each side, in whole cells so poses sit on cell corners.
  const double r = cfg.resolution;
  const int window = static_cast<int>(std::floor(request.size / r)) + 1;
  const int margin = static_cast<int>(std::ceil(reach / r)) + 1;
  const double x_lo = request.center_x - request.size / 2, y_lo = request.center_y - request.size / 2;
  const double gx0 = x_lo - margin * r, gy0 = y_lo - margin * r;
  const int side = window + 2 * margin + 1;
  std::vector<std::uint8_t> fine(static_cast<std::size_t>(side) * side, 0);
  const int k = static_cast<int>(std::ceil(2.0 * cfg.blur_sigma / r));
  std::vector<std::uint8_t> kernel(static_cast<std::size_t>(2 * k + 1) * (2 * k + 1), 255);
  if (cfg.blur_sigma > 0.0)
    for (int dy = -k; dy <= k; ++dy)
      for (int dx = -k; dx <= k; ++dx)
        kernel[static_cast<std::size_t>(dy + k) * (2 * k + 1) + dx + k] = static_cast<std::uint8_t>(
            std::lround(255.0 * std::exp(-(dx * dx + dy * dy) * r * r / (2 * cfg.blur_sigma * cfg.blur_sigma))));
  std::size_t map_cells_in_square = 0;
  for (const Eigen::Vector2d& m : map_->structure) {
    const int cx = static_cast<int>(std::floor((m.x() - gx0) / r)),
              cy = static_cast<int>(std::floor((m.y() - gy0) / r));
    if (cx < -k || cy < -k || cx >= side + k || cy >= side + k) continue;
    if (cx >= margin && cy >= margin && cx <= margin + window && cy <= margin + window) ++map_cells_in_square;
    for (int dy = -k; dy <= k; ++dy)
      for (int dx = -k; dx <= k; ++dx) {
        const int x = cx + dx, y = cy + dy;
        if (x < 0 || y < 0 || x >= side || y >= side) continue;
        std::uint8_t& v = fine[static_cast<std::size_t>(y) * side + x];
        v = std::max(v, kernel[static_cast<std::size_t>(dy + k) * (2 * k + 1) + dx + k]);
      }
  }
  if (map_cells_in_square == 0) {
    std::ostringstream msg;
    const Eigen::AlignedBox2d& b = map_->bounds;
    msg << "no map structure in the search square (centre " << request.center_x << ", " << request.center_y << ", size "
        << request.size << " m); the map's structure spans x " << b.min().x() << ".." << b.max().x() << ", y "
        << b.min().y() << ".." << b.max().y() << ": move the centre onto the map";
    return refused(result, msg.str(), start);
  }

  const LikelihoodPyramid pyramid(std::move(fine), side, side, cfg.levels);
  BbsProblem problem;
  problem.pyramid = &pyramid;
  problem.width = problem.height = window;
  for (const double yaw : yaws) {
    const Eigen::Rotation2Dd rot(yaw);
    std::vector<Eigen::Vector2i> cells;
    cells.reserve(points.size());
    for (const Eigen::Vector2d& p : points) {
      const Eigen::Vector2d q = rot * p / r + Eigen::Vector2d::Constant(margin);
      cells.emplace_back(static_cast<int>(std::floor(q.x())), static_cast<int>(std::floor(q.y())));
    }
    problem.cells.push_back(std::move(cells));
  }
  const double full = 255.0 * static_cast<double>(points.size());
  const auto min_score = static_cast<std::int64_t>(std::ceil(cfg.min_score * full));
  const BbsOutcome outcome = branchAndBound(problem, min_score, cfg.max_runner_up_ratio,
                                            cfg.adapted_initial_score ? cfg.initial_descents : 0, cfg.threads);
  result.candidates_evaluated = outcome.evaluated;
  if (outcome.leaves.empty()) {
    std::ostringstream msg;
    msg << "no pose in the search area scores min_score = " << cfg.min_score
        << ": the robot is elsewhere, or the map or the scan shows too little of the same structure";
    return refused(result, msg.str(), start);
  }

  const BbsNode& winner = outcome.leaves.front();
  const double wx = x_lo + winner.x * r, wy = y_lo + winner.y * r, wyaw = yaws[static_cast<std::size_t>(winner.yaw)];
  result.score = static_cast<double>(winner.score) / full;
  // Every leaf scores >= max_runner_up_ratio * best, so a far one makes the answer ambiguous; without one, that
  // product bounds the runner-up from above.
  result.runner_up_score = cfg.max_runner_up_ratio * result.score;
  bool ambiguous = false;
  for (const BbsNode& leaf : outcome.leaves) {
    const double distance = r * std::hypot(leaf.x - winner.x, leaf.y - winner.y);
    const double turn = std::abs(wrapAngle(yaws[static_cast<std::size_t>(leaf.yaw)] - wyaw));
    if (distance >= cfg.runner_up_distance || turn >= cfg.runner_up_yaw) {
      result.runner_up_score = static_cast<double>(leaf.score) / full;
      ambiguous = true;
      break;
    }
  }
  result.confidence = std::clamp(1.0 - result.runner_up_score / result.score, 0.0, 1.0);

  // z from the map's ground under the winner and the scan's ground under the sensor; roll and pitch from gravity.
  double map_ground_z = 0.0;
  if (!groundHeight(map_->ground, cfg.ground_cell, wx, wy, &map_ground_z))
    return refused(result, "the map has no ground within 8 m of the best pose, so z cannot be set", start);
  Eigen::Isometry3d guess = Eigen::Isometry3d::Identity();
  guess.translation() = Eigen::Vector3d(wx, wy, map_ground_z - scan_ground_z);
  guess.linear() = Eigen::AngleAxisd(wyaw, Eigen::Vector3d::UnitZ()).toRotationMatrix() * level;
  result.map_T_base = guess;

  // NDT refinement of the winner.
  const NdtAligner aligner(cfg.ndt);
  result.refinement =
      aligner.align(*map_->ndt_target, voxelDownsample(finite, cfg.resolution), guess.cast<float>().matrix());
  const NdtResult& ndt = result.refinement;
  const bool usable = ndt.status == NdtResultStatus::OK || ndt.status == NdtResultStatus::MAX_ITERATIONS;
  if (usable) result.map_T_base.matrix() = ndt.transform.cast<double>();
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  std::ostringstream why;
  const double shift = (result.map_T_base.translation() - guess.translation()).norm();
  if (ambiguous)
    why << "ambiguous: a pose " << cfg.runner_up_distance << " m or " << cfg.runner_up_yaw << " rad away scores "
        << result.runner_up_score << " against the best " << result.score << " (max_runner_up_ratio "
        << cfg.max_runner_up_ratio << "): search a smaller area or give a better centre";
  else if (!usable)
    why << "the NDT refinement failed (" << toString(ndt.status) << ": " << ndt.message << ")";
  else if (ndt.inlier_fraction < cfg.min_inlier_fraction)
    why << "the refined pose explains only " << ndt.inlier_fraction << " of the scan (min_inlier_fraction "
        << cfg.min_inlier_fraction << ")";
  else if (shift > cfg.max_refinement_shift)
    why << "the NDT refinement moved the search's answer by " << shift << " m (max_refinement_shift "
        << cfg.max_refinement_shift << ")";
  result.reason = why.str();
  result.found = result.reason.empty();
  return result;
}

}  // namespace grid_puzzle_localization
