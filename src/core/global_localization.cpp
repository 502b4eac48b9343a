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
#include "structure_cells.hpp"

namespace grid_puzzle_localization {

namespace {

constexpr double kTwoPi = 2.0 * 3.14159265358979323846;
/// [m] radius around a position whose ground cells give its ground height.
constexpr double kGroundRadius = 8.0;

double wrapAngle(double a) { return std::remainder(a, kTwoPi); }

GlobalLocalizationResult refused(GlobalLocalizationResult result, const std::string& reason,
                                 std::chrono::steady_clock::time_point start) {
  result.found = false;
  result.reason = reason;
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

/// Index of the height band holding `height` (band b is [edges[b], edges[b + 1])), -1 when outside all.
int bandOf(double height, const std::vector<double>& edges) {
  const auto it = std::upper_bound(edges.begin(), edges.end(), height);
  if (it == edges.begin() || it == edges.end()) return -1;
  return static_cast<int>(it - edges.begin()) - 1;
}

/// The scan's structure as the search matches it: x-y in the levelled base frame and height band, one point per
/// search cell and band (the first seen), at most max_scan_points of them (evenly chosen).
struct ScanStructure {
  std::vector<Eigen::Vector2d> xy;
  std::vector<int> band;
  double reach = 0.0;  ///< [m] farthest point from the sensor
};

/// The scan's structure points, one per search cell and height band, at most max_scan_points of them. With
/// `on_map`, only those for which it holds (where the point may land on the map).
template <class OnMap>
ScanStructure scanStructure(const std::vector<StructurePoint>& points, const GlobalLocalizationConfig& cfg,
                            OnMap&& on_map) {
  ScanStructure all;
  std::unordered_set<std::int64_t> seen;
  for (const StructurePoint& p : points) {
    const int band = bandOf(p.height, cfg.height_bands);
    if (band < 0) continue;
    const auto cx = static_cast<std::int64_t>(std::floor(p.xy.x() / cfg.resolution));
    const auto cy = static_cast<std::int64_t>(std::floor(p.xy.y() / cfg.resolution));
    if (!seen.insert(cellKey(cx * 16 + band, cy)).second || !on_map(p.xy)) continue;
    all.xy.push_back(p.xy);
    all.band.push_back(band);
  }
  ScanStructure out;
  const std::size_t n = std::min(all.xy.size(), static_cast<std::size_t>(cfg.max_scan_points));
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t k = i * all.xy.size() / n;
    out.xy.push_back(all.xy[k]);
    out.band.push_back(all.band[k]);
    out.reach = std::max(out.reach, all.xy[k].norm());
  }
  return out;
}

/// The likelihood grids of the map's structure around a search square, one per height band, side by side in one
/// grid: band b occupies columns [b * stride, b * stride + side). The gap between them is wider than the coarsest
/// pyramid cell, so no coarse cell mixes two bands.
struct BandGrids {
  int side = 0;                      ///< cells per band along x and y
  int stride = 0;                    ///< columns from one band to the next
  double x0 = 0, y0 = 0;             ///< [m] map position of cell (0, 0)'s corner
  std::vector<std::uint8_t> values;  ///< row-major, width bands * stride
  std::size_t occupied = 0;          ///< occupied cells, all bands
};

BandGrids bandGrids(const std::vector<StructurePoint>& map, const GlobalLocalizationConfig& cfg, double x0, double y0,
                    int side) {
  const double r = cfg.resolution;
  const int bands = static_cast<int>(cfg.height_bands.size()) - 1;
  BandGrids g;
  g.side = side;
  g.stride = side + (1 << cfg.levels) + 1;
  g.x0 = x0;
  g.y0 = y0;
  const int width = bands * g.stride;
  g.values.assign(static_cast<std::size_t>(width) * side, 0);
  std::vector<std::uint8_t> occupied(g.values.size(), 0);
  std::vector<Eigen::Vector2i> cells;
  for (const StructurePoint& m : map) {
    const int cx = static_cast<int>(std::floor((m.xy.x() - x0) / r));
    const int cy = static_cast<int>(std::floor((m.xy.y() - y0) / r));
    if (cx < 0 || cy < 0 || cx >= side || cy >= side) continue;
    for (int b = 0; b < bands; ++b) {
      if (m.height < cfg.height_bands[b] - cfg.band_overlap || m.height >= cfg.height_bands[b + 1] + cfg.band_overlap)
        continue;
      std::uint8_t& o = occupied[static_cast<std::size_t>(cy) * width + b * g.stride + cx];
      if (!o) cells.emplace_back(b * g.stride + cx, cy);
      o = 1;
    }
  }
  g.occupied = cells.size();
  // The likelihood kernel, stamped (max) once per occupied cell and clipped to its band.
  const int k = static_cast<int>(std::ceil(2.0 * cfg.blur_sigma / r));
  std::vector<std::uint8_t> kernel(static_cast<std::size_t>(2 * k + 1) * (2 * k + 1), 255);
  if (cfg.blur_sigma > 0.0)
    for (int dy = -k; dy <= k; ++dy)
      for (int dx = -k; dx <= k; ++dx)
        kernel[static_cast<std::size_t>(dy + k) * (2 * k + 1) + dx + k] = static_cast<std::uint8_t>(
            std::lround(255.0 * std::exp(-(dx * dx + dy * dy) * r * r / (2 * cfg.blur_sigma * cfg.blur_sigma))));
  for (const Eigen::Vector2i& c : cells) {
    const int band_x0 = (c.x() / g.stride) * g.stride;
    for (int dy = -k; dy <= k; ++dy)
      for (int dx = -k; dx <= k; ++dx) {
        const int x = c.x() + dx, y = c.y() + dy;
        if (x < band_x0 || y < 0 || x >= band_x0 + side || y >= side) continue;
        std::uint8_t& v = g.values[static_cast<std::size_t>(y) * width + x];
        v = std::max(v, kernel[static_cast<std::size_t>(dy + k) * (2 * k + 1) + dx + k]);
      }
  }
  return g;
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
  bool increasing = height_bands.size() >= 2;
  for (std::size_t i = 0; i < height_bands.size(); ++i)
    increasing = increasing && std::isfinite(height_bands[i]) && (i == 0 || height_bands[i] > height_bands[i - 1]);
  if (!increasing) err << "height_bands must hold >= 2 finite, strictly increasing heights [m]; ";
  if (height_bands.size() > 16) err << "height_bands must hold at most 16 edges; ";
  if (!(band_overlap >= 0.0) || !std::isfinite(band_overlap))
    err << "band_overlap must be >= 0 (got " << band_overlap << "); ";
  if (refine_candidates < 1) err << "refine_candidates must be >= 1 (got " << refine_candidates << "); ";
  positive("same_pose_distance", same_pose_distance);
  positive("same_pose_yaw", same_pose_yaw);
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
  Map(const std::vector<Eigen::Vector3d>& points, double ground_cell) : ground(points, ground_cell) {}
  GroundCells ground;
  std::vector<StructurePoint> structure;  ///< within band_overlap of the height bands
  Eigen::AlignedBox2d bounds;             ///< [m] x-y of the structure
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
  if (ndt_target && std::abs(ndt_target->resolution() - config_.ndt.resolution) > 1e-9)
    throw std::invalid_argument("GlobalLocalizer::setMap: the NDT target's resolution differs from ndt.resolution");
  std::vector<Eigen::Vector3d> points;
  points.reserve(map_points.size());
  for (const Point& p : map_points)
    if (p.allFinite()) points.push_back(p.cast<double>());
  auto map = std::make_unique<Map>(points, config_.ground_cell);
  map->structure = structurePoints(points, map->ground, config_.height_bands.front() - config_.band_overlap,
                                   config_.height_bands.back() + config_.band_overlap);
  for (const StructurePoint& p : map->structure) map->bounds.extend(p.xy);
  if (ndt_target) {
    map->ndt_target = std::move(ndt_target);
  } else {
    NdtTarget target(config_.ndt);
    target.setTarget(map_points);
    map->ndt_target = target.snapshot();
  }
  map_ = std::move(map);
}

bool GlobalLocalizer::hasMap() const { return map_ && !map_->structure.empty(); }

void GlobalLocalizer::clearMap() { map_.reset(); }

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
  const GroundCells scan_ground(leveled, cfg.ground_cell);
  // With a known heading, scan points that cannot land on the map from anywhere in the search square are left out:
  // a window of tiles may end short of the sensor's range, or still be loading, and the score is the fraction of
  // what the map can explain there. Over every yaw all are kept (the heading says nothing of where they land).
  const bool heading_known = request.yaw_range < kTwoPi / 2;
  const Eigen::Rotation2Dd heading(request.yaw_center);
  const Eigen::Vector2d centre(request.center_x, request.center_y);
  const double reach_on_map = request.size / 2 + cfg.ground_cell;
  std::unordered_map<std::int64_t, bool> on_map_cache;
  auto may_land_on_map = [&](const Eigen::Vector2d& xy) {
    if (!heading_known) return true;
    const Eigen::Vector2d q = centre + heading * xy;
    const std::int64_t key = cellKey(static_cast<std::int64_t>(std::floor(q.x() / cfg.ground_cell)),
                                     static_cast<std::int64_t>(std::floor(q.y() / cfg.ground_cell)));
    const auto it = on_map_cache.find(key);
    if (it != on_map_cache.end()) return it->second;
    return on_map_cache[key] = map_->ground.holdsNear(q.x(), q.y(), reach_on_map);
  };
  const ScanStructure points = scanStructure(
      structurePoints(leveled, scan_ground, cfg.height_bands.front(), cfg.height_bands.back()), cfg, may_land_on_map);
  result.scan_points_used = points.xy.size();
  if (points.xy.size() < static_cast<std::size_t>(cfg.min_scan_points)) {
    std::ostringstream msg;
    msg << "too few points: the scan has " << points.xy.size() << " structure points (in the height bands above "
        << "the ground, within max_range), the search needs min_scan_points = " << cfg.min_scan_points;
    return refused(result, msg.str(), start);
  }
  double scan_ground_z = 0.0;
  if (!scan_ground.heightNear(0.0, 0.0, kGroundRadius, &scan_ground_z))
    return refused(result, "the scan shows no ground near the sensor, so z cannot be set", start);

  // Yaws: the step moves the farthest point by at most one cell.
  const double r = cfg.resolution;
  const double reach = std::max(r, points.reach);
  const double step = cfg.yaw_step > 0.0 ? cfg.yaw_step : r / reach;
  std::vector<double> yaws;
  if (request.yaw_range >= kTwoPi - 1e-9) {
    const int n = static_cast<int>(std::ceil(kTwoPi / step));
    for (int i = 0; i < n; ++i) yaws.push_back(wrapAngle(request.yaw_center + kTwoPi * i / n));
  } else {
    const int n = static_cast<int>(std::ceil(request.yaw_range / step)) + 1;
    for (int i = 0; i < n; ++i)
      yaws.push_back(wrapAngle(request.yaw_center - request.yaw_range / 2 + request.yaw_range * i / (n - 1)));
  }

  // The grids: the search square plus the scan's reach on each side, in whole cells so poses sit on cell corners.
  const int window = static_cast<int>(std::floor(request.size / r)) + 1;
  const int margin = static_cast<int>(std::ceil(reach / r)) + 1;
  const double x_lo = request.center_x - request.size / 2, y_lo = request.center_y - request.size / 2;
  // Where the time goes (the result's grid, search and refine seconds).
  auto stage = std::chrono::steady_clock::now();
  auto lap = [&stage](double* seconds) {
    const auto now = std::chrono::steady_clock::now();
    *seconds = std::chrono::duration<double>(now - stage).count();
    stage = now;
  };
  BandGrids grids = bandGrids(map_->structure, cfg, x_lo - margin * r, y_lo - margin * r, window + 2 * margin + 1);
  if (grids.occupied == 0) {
    std::ostringstream msg;
    const Eigen::AlignedBox2d& b = map_->bounds;
    msg << "no map structure within the scan's reach of the search square (centre " << request.center_x << ", "
        << request.center_y << ", size " << request.size << " m); the map's structure spans x " << b.min().x() << ".."
        << b.max().x() << ", y " << b.min().y() << ".." << b.max().y() << ": move the centre onto the map";
    return refused(result, msg.str(), start);
  }
  const int width = static_cast<int>(grids.values.size()) / grids.side;
  const LikelihoodPyramid pyramid(std::move(grids.values), width, grids.side, cfg.levels);
  lap(&result.grid_seconds);
  BbsProblem problem;
  problem.pyramid = &pyramid;
  problem.width = problem.height = window;
  for (const double yaw : yaws) {
    const Eigen::Rotation2Dd rot(yaw);
    std::vector<Eigen::Vector2i> cells;
    cells.reserve(points.xy.size());
    for (std::size_t i = 0; i < points.xy.size(); ++i) {
      const Eigen::Vector2d q = rot * points.xy[i] / r + Eigen::Vector2d::Constant(margin);
      cells.emplace_back(static_cast<int>(std::floor(q.x())) + points.band[i] * grids.stride,
                         static_cast<int>(std::floor(q.y())));
    }
    problem.cells.push_back(std::move(cells));
  }
  const double full = 255.0 * static_cast<double>(points.xy.size());
  const auto min_score = static_cast<std::int64_t>(std::ceil(cfg.min_score * full));
  const BbsOutcome outcome = branchAndBound(problem, min_score, cfg.max_runner_up_ratio,
                                            cfg.adapted_initial_score ? cfg.initial_descents : 0, cfg.threads);
  result.candidates_evaluated = outcome.evaluated;
  lap(&result.search_seconds);
  if (outcome.leaves.empty()) {
    std::ostringstream msg;
    msg << "no pose in the search area scores min_score = " << cfg.min_score
        << ": the robot is elsewhere, or the map or the scan shows too little of the same structure";
    return refused(result, msg.str(), start);
  }
  result.score = static_cast<double>(outcome.leaves.front().score) / full;
  result.runner_up_score = cfg.max_runner_up_ratio * result.score;  // an upper bound until a runner-up is refined

  // Distinct candidates: the best leaf, then each next leaf far (in position or yaw) from all kept ones.
  auto x_of = [&](const BbsNode& n) { return x_lo + n.x * r; };
  auto y_of = [&](const BbsNode& n) { return y_lo + n.y * r; };
  auto yaw_of = [&](const BbsNode& n) { return yaws[static_cast<std::size_t>(n.yaw)]; };
  std::vector<BbsNode> distinct;
  for (const BbsNode& leaf : outcome.leaves) {
    bool far = true;
    for (const BbsNode& d : distinct)
      far = far && (r * std::hypot(leaf.x - d.x, leaf.y - d.y) >= cfg.runner_up_distance ||
                    std::abs(wrapAngle(yaw_of(leaf) - yaw_of(d))) >= cfg.runner_up_yaw);
    if (!far) continue;
    distinct.push_back(leaf);
    if (distinct.size() > static_cast<std::size_t>(cfg.refine_candidates)) break;
  }

  // Refine each distinct candidate with NDT: z from the map's ground under it and the scan's under the sensor, roll
  // and pitch from gravity. Candidates that refine to one pose are one answer (the slope of one peak); answers compete
  // by their NDT fit, the scan's 3D agreement with the map, which the 2D search score only approximates.
  const NdtAligner aligner(cfg.ndt);
  const PointCloud source = voxelDownsample(finite, r);
  struct Answer {
    std::size_t candidate;
    Eigen::Isometry3d guess, pose;
    NdtResult ndt;
  };
  std::vector<Answer> answers;
  const std::size_t refined = std::min(distinct.size(), static_cast<std::size_t>(cfg.refine_candidates));
  for (std::size_t i = 0; i < refined; ++i) {
    const BbsNode& n = distinct[i];
    double ground_z = 0.0;
    if (!map_->ground.heightNear(x_of(n), y_of(n), kGroundRadius, &ground_z)) continue;
    Answer a{i, Eigen::Isometry3d::Identity(), Eigen::Isometry3d::Identity(), NdtResult()};
    a.guess.translation() = Eigen::Vector3d(x_of(n), y_of(n), ground_z - scan_ground_z);
    a.guess.linear() = Eigen::AngleAxisd(yaw_of(n), Eigen::Vector3d::UnitZ()).toRotationMatrix() * level;
    a.ndt = aligner.align(*map_->ndt_target, source, a.guess.cast<float>().matrix());
    if (a.ndt.status != NdtResultStatus::OK && a.ndt.status != NdtResultStatus::MAX_ITERATIONS) continue;
    a.pose.matrix() = a.ndt.transform.cast<double>();
    bool same = false;
    for (const Answer& b : answers) {
      const Eigen::Isometry3d delta = b.pose.inverse() * a.pose;
      same = same || (delta.translation().norm() < cfg.same_pose_distance &&
                      Eigen::AngleAxisd(delta.linear()).angle() < cfg.same_pose_yaw);
    }
    if (!same) answers.push_back(a);
  }
  lap(&result.refine_seconds);
  if (answers.empty())
    return refused(result, "the NDT refinement failed for every candidate: the map around them has too few voxels",
                   start);
  std::stable_sort(answers.begin(), answers.end(), [](const Answer& a, const Answer& b) {
    return a.ndt.transformation_probability > b.ndt.transformation_probability;
  });
  const Answer& best = answers.front();
  result.map_T_base = best.pose;
  result.refinement = best.ndt;
  result.score = static_cast<double>(distinct[best.candidate].score) / full;
  result.fit = best.ndt.transformation_probability;
  // Distinct candidates left unrefined could be other answers: count them as equal to the winner.
  const bool unrefined = distinct.size() > refined;
  if (answers.size() > 1) {
    result.runner_up_score = static_cast<double>(distinct[answers[1].candidate].score) / full;
    result.runner_up_fit = answers[1].ndt.transformation_probability;
  } else if (unrefined) {
    result.runner_up_score = static_cast<double>(distinct[refined].score) / full;
    result.runner_up_fit = result.fit;
  } else {
    result.runner_up_fit = cfg.max_runner_up_ratio * result.fit;
  }
  result.confidence = result.fit > 0.0 ? std::clamp(1.0 - result.runner_up_fit / result.fit, 0.0, 1.0) : 0.0;
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  std::size_t on_map = 0;
  for (const Point& p : source) {
    const Eigen::Vector3d q = best.pose * p.cast<double>();
    on_map += map_->ground.holds(q.x(), q.y());
  }
  const double inliers = best.ndt.inlier_fraction * static_cast<double>(source.size());
  result.explained_fraction = on_map ? std::min(1.0, inliers / static_cast<double>(on_map)) : 0.0;

  std::ostringstream why;
  const double shift = (best.pose.translation() - best.guess.translation()).head<2>().norm();
  if (unrefined)
    why << "ambiguous: more than refine_candidates = " << cfg.refine_candidates << " distinct places score within "
        << cfg.max_runner_up_ratio << " of the best: search a smaller area or give a better centre";
  else if (answers.size() > 1 && result.runner_up_fit >= cfg.max_runner_up_ratio * result.fit)
    why << "ambiguous: another place fits the scan " << result.runner_up_fit << " against the best " << result.fit
        << " (NDT fit, max_runner_up_ratio " << cfg.max_runner_up_ratio
        << "): search a smaller area or give a better centre";
  else if (result.explained_fraction < cfg.min_inlier_fraction)
    why << "the refined pose explains only " << result.explained_fraction
        << " of the scan points on the map's area (min_inlier_fraction " << cfg.min_inlier_fraction << ")";
  else if (shift > cfg.max_refinement_shift)
    why << "the NDT refinement moved the search's answer by " << shift << " m (max_refinement_shift "
        << cfg.max_refinement_shift << ")";
  result.reason = why.str();
  result.found = result.reason.empty();
  return result;
}

}  // namespace grid_puzzle_localization
