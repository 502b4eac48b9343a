#include "grid_puzzle_localization/global_localization.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <sstream>
#include <stdexcept>
#include <tuple>
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
/// A coarse search keeps this many distinct places per one refined by NDT, to be chosen among at full resolution.
constexpr std::size_t kCoarseCandidatesPerRefined = 4;

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

/// `r` [m] is the cell and `blur_sigma` [m] the likelihood spread (the search's, which may be coarser than cfg's).
BandGrids bandGrids(const std::vector<StructurePoint>& map, const GlobalLocalizationConfig& cfg, double r,
                    double blur_sigma, int levels, double x0, double y0, int side) {
  const int bands = static_cast<int>(cfg.height_bands.size()) - 1;
  BandGrids g;
  g.side = side;
  g.stride = side + (1 << levels) + 1;
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
  const int k = static_cast<int>(std::ceil(2.0 * blur_sigma / r));
  std::vector<std::uint8_t> kernel(static_cast<std::size_t>(2 * k + 1) * (2 * k + 1), 255);
  if (blur_sigma > 0.0)
    for (int dy = -k; dy <= k; ++dy)
      for (int dx = -k; dx <= k; ++dx)
        kernel[static_cast<std::size_t>(dy + k) * (2 * k + 1) + dx + k] = static_cast<std::uint8_t>(
            std::lround(255.0 * std::exp(-(dx * dx + dy * dy) * r * r / (2 * blur_sigma * blur_sigma))));
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

/// Yaws [rad] every `step` or less: over the full circle when `range` >= 2 pi, else over [centre - range / 2,
/// centre + range / 2] ends included.
std::vector<double> yawList(double centre, double range, double step) {
  std::vector<double> yaws;
  if (range >= kTwoPi - 1e-9) {
    const int n = static_cast<int>(std::ceil(kTwoPi / step));
    for (int i = 0; i < n; ++i) yaws.push_back(wrapAngle(centre + kTwoPi * i / n));
  } else {
    const int n = static_cast<int>(std::ceil(range / step)) + 1;
    for (int i = 0; i < n; ++i) yaws.push_back(wrapAngle(centre - range / 2 + range * i / (n - 1)));
  }
  return yaws;
}

/// A pose of the search in the map frame.
struct Candidate {
  double x = 0, y = 0, yaw = 0;  ///< [m], [m], [rad]
  std::int64_t score = 0;        ///< sum of likelihoods (255 per point on structure)
};

/// One branch-and-bound search over a square of base positions (corner x_lo, y_lo; `side` positions per side every
/// `r` metres) and a list of yaws, on likelihood grids of cell `r` and spread `blur_sigma`.
struct SquareSearch {
  double x_lo = 0, y_lo = 0, r = 0, blur_sigma = 0;
  int side = 0;
  int levels = 1;  ///< pyramid levels above the finest
  std::vector<double> yaws;
  std::size_t poses() const { return static_cast<std::size_t>(side) * side * yaws.size(); }
};

/// Runs `s`; the leaves of `BbsOutcome` as candidates in the map frame, best first. False when no map structure lies
/// within the scan's reach of the square (nothing searched). Adds the time of the grids and of the search.
bool runSearch(const std::vector<StructurePoint>& map, const ScanStructure& points, const GlobalLocalizationConfig& cfg,
               const SquareSearch& s, std::int64_t min_score, double ratio, std::vector<Candidate>* leaves,
               std::size_t* evaluated, double* grid_seconds, double* search_seconds) {
  auto stage = std::chrono::steady_clock::now();
  auto lap = [&stage](double* seconds) {
    const auto now = std::chrono::steady_clock::now();
    *seconds += std::chrono::duration<double>(now - stage).count();
    stage = now;
  };
  // The grids: the square plus the scan's reach on each side, in whole cells so poses sit on cell corners.
  const double r = s.r;
  const int margin = static_cast<int>(std::ceil(std::max(r, points.reach) / r)) + 1;
  BandGrids grids =
      bandGrids(map, cfg, r, s.blur_sigma, s.levels, s.x_lo - margin * r, s.y_lo - margin * r, s.side + 2 * margin + 1);
  if (grids.occupied == 0) return false;
  const int width = static_cast<int>(grids.values.size()) / grids.side;
  const LikelihoodPyramid pyramid(std::move(grids.values), width, grids.side, s.levels);
  lap(grid_seconds);
  BbsProblem problem;
  problem.pyramid = &pyramid;
  problem.width = problem.height = s.side;
  for (const double yaw : s.yaws) {
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
  const BbsOutcome outcome =
      branchAndBound(problem, min_score, ratio, cfg.adapted_initial_score ? cfg.initial_descents : 0, cfg.threads);
  *evaluated += outcome.evaluated;
  leaves->clear();
  for (const BbsNode& n : outcome.leaves)
    leaves->push_back(Candidate{s.x_lo + n.x * r, s.y_lo + n.y * r, s.yaws[static_cast<std::size_t>(n.yaw)], n.score});
  lap(search_seconds);
  return true;
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
  if (max_poses < 1000) err << "max_poses must be in [1000, 2^31 - 1] (got " << max_poses << "); ";
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
  GlobalLocalizationConfig cfg = config_;
  if (request.threads >= 0) cfg.threads = request.threads;
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

  // The search over the whole square at resolution * 2^k, the smallest k whose poses fit max_poses; the yaw step
  // (which moves the farthest point by at most one cell) and the likelihood spread scale with it, so it is the same
  // search in cells.
  const double r = cfg.resolution;
  const double reach = std::max(r, points.reach);
  const double step = cfg.yaw_step > 0.0 ? cfg.yaw_step : r / reach;
  const double x_lo = request.center_x - request.size / 2, y_lo = request.center_y - request.size / 2;
  auto squareAt = [&](int k) {
    SquareSearch s;
    s.r = std::ldexp(r, k);
    s.blur_sigma = std::ldexp(cfg.blur_sigma, k);
    s.levels = cfg.levels;
    s.x_lo = x_lo;
    s.y_lo = y_lo;
    s.side = static_cast<int>(std::floor(request.size / s.r)) + 1;
    s.yaws = yawList(request.yaw_center, request.yaw_range, std::ldexp(step, k));
    return s;
  };
  int k = 0;
  SquareSearch square = squareAt(0);
  // Terminates: the poses shrink to 1 position x 1 or 2 yaws, and max_poses >= 1000.
  while (square.poses() > static_cast<std::size_t>(cfg.max_poses)) square = squareAt(++k);
  result.search_resolution = square.r;
  result.search_poses = square.poses();

  const double full = 255.0 * static_cast<double>(points.xy.size());
  const auto min_score = static_cast<std::int64_t>(std::ceil(cfg.min_score * full));
  std::vector<Candidate> leaves;
  if (!runSearch(map_->structure, points, cfg, square, min_score, cfg.max_runner_up_ratio, &leaves,
                 &result.candidates_evaluated, &result.grid_seconds, &result.search_seconds)) {
    std::ostringstream msg;
    const Eigen::AlignedBox2d& b = map_->bounds;
    msg << "no map structure within the scan's reach of the search square (centre " << request.center_x << ", "
        << request.center_y << ", size " << request.size << " m); the map's structure spans x " << b.min().x() << ".."
        << b.max().x() << ", y " << b.min().y() << ".." << b.max().y() << ": move the centre onto the map";
    return refused(result, msg.str(), start);
  }
  auto noPose = [&]() {
    std::ostringstream msg;
    msg << "no pose in the search area scores min_score = " << cfg.min_score
        << ": the robot is elsewhere, or the map or the scan shows too little of the same structure";
    return refused(result, msg.str(), start);
  };
  if (leaves.empty()) return noPose();
  result.score = static_cast<double>(leaves.front().score) / full;
  result.runner_up_score = cfg.max_runner_up_ratio * result.score;  // an upper bound until a runner-up is refined

  // Distinct candidates: the best one, then each next one far (in position or yaw) from all kept ones, at most `keep`.
  auto selectDistinct = [&](const std::vector<Candidate>& sorted, double apart, double apart_yaw, std::size_t keep) {
    std::vector<Candidate> out;
    for (const Candidate& c : sorted) {
      bool far = true;
      for (const Candidate& d : out)
        far = far && (std::hypot(c.x - d.x, c.y - d.y) >= apart || std::abs(wrapAngle(c.yaw - d.yaw)) >= apart_yaw);
      if (!far) continue;
      out.push_back(c);
      if (out.size() >= keep) break;
    }
    return out;
  };
  const auto refinable = static_cast<std::size_t>(cfg.refine_candidates) + 1;  // one more tells an ambiguous scene
  std::vector<Candidate> distinct;
  if (k == 0) {
    distinct = selectDistinct(leaves, cfg.runner_up_distance, cfg.runner_up_yaw, refinable);
  } else {
    // A coarse search is a filter: its broad peaks put many places within max_runner_up_ratio, and a coarse score
    // only approximates the fine one. So more places (those 2 cells or 2 yaw steps apart) are kept, and each is brought
    // down to full resolution one level at a time: the best pose within 2 cells and 2 yaw steps of the level above
    // (9 x 9 positions x 9 yaws), on the map structure near it only. The places are then chosen at full resolution.
    const std::vector<Candidate> coarse =
        selectDistinct(leaves, std::max(cfg.runner_up_distance, 2.0 * square.r),
                       std::max(cfg.runner_up_yaw, 2.0 * std::ldexp(step, k)), kCoarseCandidatesPerRefined * refinable);
    // [m] what the grids of the levels can hold: the squares drift by < 4 coarse cells, plus the reach.
    const double halo = 10.0 * square.r + reach;
    std::vector<Candidate> fine, best;
    std::vector<StructurePoint> near;
    for (Candidate c : coarse) {
      near.clear();
      for (const StructurePoint& p : map_->structure)
        if (std::abs(p.xy.x() - c.x) <= halo && std::abs(p.xy.y() - c.y) <= halo) near.push_back(p);
      bool kept = true;
      for (int level = k - 1; level >= 0 && kept; --level) {
        SquareSearch local;
        local.r = std::ldexp(r, level);
        local.blur_sigma = std::ldexp(cfg.blur_sigma, level);
        local.x_lo = c.x - 4.0 * local.r;
        local.y_lo = c.y - 4.0 * local.r;
        local.side = 9;
        local.levels = std::min(cfg.levels, 4);  // 2^4 >= 9: one root per yaw
        const double local_step = std::ldexp(step, level);
        local.yaws = yawList(c.yaw, 8.0 * local_step, local_step);
        result.local_poses += local.poses();
        kept = runSearch(near, points, cfg, local, 0, 1.0, &best, &result.candidates_evaluated, &result.grid_seconds,
                         &result.search_seconds) &&
               !best.empty();
        if (kept) c = best.front();
      }
      if (kept && c.score >= min_score) fine.push_back(c);
    }
    std::sort(fine.begin(), fine.end(), [](const Candidate& a, const Candidate& b) {
      return std::make_tuple(-a.score, a.x, a.y, a.yaw) < std::make_tuple(-b.score, b.x, b.y, b.yaw);
    });
    if (fine.empty()) return noPose();
    const double bound = cfg.max_runner_up_ratio * static_cast<double>(fine.front().score);
    fine.erase(std::remove_if(fine.begin(), fine.end(),
                              [bound](const Candidate& c) { return static_cast<double>(c.score) < bound; }),
               fine.end());
    distinct = selectDistinct(fine, cfg.runner_up_distance, cfg.runner_up_yaw, refinable);
    result.score = static_cast<double>(distinct.front().score) / full;
    result.runner_up_score = cfg.max_runner_up_ratio * result.score;
  }

  // Refine each distinct candidate with NDT: z from the map's ground under it and the scan's under the sensor, roll
  // and pitch from gravity. Candidates that refine to one pose are one answer (the slope of one peak); answers compete
  // by their NDT fit, the scan's 3D agreement with the map, which the 2D search score only approximates.
  const NdtAligner aligner(cfg.ndt);
  const PointCloud source = voxelDownsample(finite, r);
  auto stage = std::chrono::steady_clock::now();
  struct Answer {
    std::size_t candidate;
    Eigen::Isometry3d guess, pose;
    NdtResult ndt;
  };
  std::vector<Answer> answers;
  const std::size_t refined = std::min(distinct.size(), static_cast<std::size_t>(cfg.refine_candidates));
  for (std::size_t i = 0; i < refined; ++i) {
    const Candidate& n = distinct[i];
    double ground_z = 0.0;
    if (!map_->ground.heightNear(n.x, n.y, kGroundRadius, &ground_z)) continue;
    Answer a{i, Eigen::Isometry3d::Identity(), Eigen::Isometry3d::Identity(), NdtResult()};
    a.guess.translation() = Eigen::Vector3d(n.x, n.y, ground_z - scan_ground_z);
    a.guess.linear() = Eigen::AngleAxisd(n.yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix() * level;
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
  result.refine_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - stage).count();
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
