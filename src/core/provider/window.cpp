#include "grid_puzzle_localization/provider/window.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <stdexcept>

namespace grid_puzzle_localization {
namespace {

// Sector boundaries [deg] inside the normalised range [-20, 340); sector m is [kBounds[m], kBounds[m + 1]).
constexpr std::array<double, 9> kSectorBoundsDeg{-20.0, 20.0, 70.0, 110.0, 160.0, 200.0, 250.0, 290.0, 340.0};
// Table I: (du_min, du_max, dv_min, dv_max) in units of k, per sector.
constexpr std::array<std::array<int, 4>, 8> kSectorDeltas{{
    {0, 1, 0, 0},    // [-20, 20): +x
    {0, 1, 0, 1},    // [20, 70): +x +y
    {0, 0, 0, 1},    // [70, 110): +y
    {-1, 0, 0, 1},   // [110, 160): -x +y
    {-1, 0, 0, 0},   // [160, 200): -x
    {-1, 0, -1, 0},  // [200, 250): -x -y
    {0, 0, -1, 0},   // [250, 290): -y
    {0, 1, -1, 0},   // [290, 340): +x -y
}};
// The paper's two experiments (n, k), both with s = 2 m.
const std::map<std::string, std::array<int, 2>>& presets() {
  static const std::map<std::string, std::array<int, 2>> p{{"urban", {25, 20}}, {"courtyard", {17, 10}}};
  return p;
}
// The constants of Python's math.degrees and math.radians, so both implementations round alike.
constexpr double kRadToDeg = 180.0 / M_PI;
constexpr double kDegToRad = M_PI / 180.0;

// Python's round(x, 9): correctly rounded to 9 decimals (printf rounds the exact binary value, as Python does).
double roundTo9Decimals(double x) {
  const int size = std::snprintf(nullptr, 0, "%.9f", x);
  std::string text(static_cast<std::size_t>(size) + 1, '\0');
  std::snprintf(&text[0], text.size(), "%.9f", x);
  return std::strtod(text.c_str(), nullptr);
}

// Python's float % float: the result takes the divisor's sign.
double floorMod(double x, double m) {
  double r = std::fmod(x, m);
  if (r != 0.0) {
    if ((m < 0.0) != (r < 0.0)) r += m;
  } else {
    r = std::copysign(0.0, m);
  }
  return r;
}

}  // namespace

std::int64_t tileIndex(double coord, double s) { return static_cast<std::int64_t>(std::floor(coord / s)); }

int sectorOfDegrees(double deg) {
  const double d = floorMod(roundTo9Decimals(deg) + 20.0, 360.0) - 20.0;
  return static_cast<int>(std::upper_bound(kSectorBoundsDeg.begin(), kSectorBoundsDeg.end(), d) -
                          kSectorBoundsDeg.begin()) -
         1;
}

int sectorOf(double theta) { return sectorOfDegrees(theta * kRadToDeg); }

double sectorMidDegrees(int sector) { return (kSectorBoundsDeg[sector] + kSectorBoundsDeg[sector + 1]) / 2.0; }

Window computeWindow(double x, double y, std::optional<double> theta, double s, int n, int k) {
  Window w;
  w.centre = {tileIndex(x, s), tileIndex(y, s)};
  if (!theta || !std::isfinite(*theta)) {
    w.theta = std::nan("");
    w.u_range = {-n, n};
    w.v_range = {-n, n};
    return w;
  }
  w.theta = *theta;
  w.sector = sectorOf(*theta);
  const std::array<int, 4>& d = kSectorDeltas[w.sector];
  w.u_range = {-n + d[0] * k, n + d[1] * k};
  w.v_range = {-n + d[2] * k, n + d[3] * k};
  return w;
}

Window windowCovering(const std::optional<Window>& window, double x, double y, double half_side, double s) {
  std::int64_t i0 = tileIndex(x - half_side, s), i1 = tileIndex(x + half_side, s);
  std::int64_t j0 = tileIndex(y - half_side, s), j1 = tileIndex(y + half_side, s);
  if (window) {
    const TileBox b = window->bounds();
    i0 = std::min(i0, b.i_min);
    i1 = std::max(i1, b.i_max);
    j0 = std::min(j0, b.j_min);
    j1 = std::max(j1, b.j_max);
  }
  Window w;
  w.centre = {tileIndex(x, s), tileIndex(y, s)};
  w.theta = std::nan("");
  w.u_range = {i0 - w.centre[0], i1 - w.centre[0]};
  w.v_range = {j0 - w.centre[1], j1 - w.centre[1]};
  return w;
}

WindowConfig WindowConfig::resolved() const {
  WindowConfig r = *this;
  if (!preset.empty()) {
    const auto it = presets().find(preset);
    if (it == presets().end())
      throw std::invalid_argument("window preset '" + preset + "' is unknown; use one of courtyard, urban or ''");
    r.n = it->second[0];
    r.k = it->second[1];
    r.preset.clear();
  }
  if (r.n < 0 || r.k < 0)
    throw std::invalid_argument("window n and k must be integers >= 0 (got n=" + std::to_string(r.n) +
                                ", k=" + std::to_string(r.k) + ")");
  if (heading_source != "motion" && heading_source != "yaw")
    throw std::invalid_argument("window heading_source '" + heading_source + "' is unknown; use one of motion, yaw");
  if (!(std::isfinite(update_distance) && update_distance >= 0.0))
    throw std::invalid_argument("window update_distance must be >= 0 m (got " + std::to_string(update_distance) +
                                "); 0 means s / 2");
  if (!(std::isfinite(lookahead_time) && lookahead_time >= 0.0))
    throw std::invalid_argument("window lookahead_time must be >= 0 s (got " + std::to_string(lookahead_time) + ")");
  return r;
}

WindowTracker::WindowTracker(const WindowConfig& config, double s)
    : config_(config.resolved()), s_(s), update_distance_(config_.updateDistanceFor(s)) {}

std::optional<Window> WindowTracker::update(const PoseSample& pose) {
  if (anchor_) {
    const double step = std::hypot(pose.x - anchor_->x, pose.y - anchor_->y);
    if (!(step > update_distance_)) return std::nullopt;
    last_step_ = step;
    theta_ = std::atan2(pose.y - anchor_->y, pose.x - anchor_->x);
  }
  if (config_.heading_source == "yaw" && pose.yaw) theta_ = *pose.yaw;
  centre_point_ = lookaheadPoint(pose);
  anchor_ = pose;
  window_ = computeWindow(centre_point_[0], centre_point_[1], theta_, s_, config_.n, config_.k);
  return window_;
}

std::array<double, 2> WindowTracker::lookaheadPoint(const PoseSample& pose) const {
  const double t = config_.lookahead_time;
  if (t <= 0.0) return {pose.x, pose.y};
  std::optional<std::array<double, 2>> velocity = pose.velocity;
  if (!velocity && anchor_ && pose.t > anchor_->t) {
    const double dt = pose.t - anchor_->t;
    velocity = std::array<double, 2>{(pose.x - anchor_->x) / dt, (pose.y - anchor_->y) / dt};
  }
  if (!velocity) return {pose.x, pose.y};
  return {pose.x + (*velocity)[0] * t, pose.y + (*velocity)[1] * t};
}

std::vector<Window> WindowTracker::predictedWindows() const {
  if (!theta_ || !window_) return {};
  const double step = std::max(last_step_, update_distance_) * 1.01;
  const double x = centre_point_[0] + step * std::cos(*theta_);
  const double y = centre_point_[1] + step * std::sin(*theta_);
  const int sector = sectorOf(*theta_);
  std::vector<Window> out;
  out.push_back(computeWindow(x, y, theta_, s_, config_.n, config_.k));
  for (const int d : {1, 7}) {  // the next sector, then the previous one
    const double heading = sectorMidDegrees((sector + d) % 8) * kDegToRad;
    out.push_back(computeWindow(x, y, heading, s_, config_.n, config_.k));
  }
  return out;
}

std::optional<LostSearchRegion> hintRegion(double x, double y, double variance_x, double variance_y, double t) {
  if (!std::isfinite(x) || !std::isfinite(y)) return std::nullopt;
  const double variance = std::max(variance_x, variance_y);
  const double radius = std::isfinite(variance) && variance > 0.0 ? kHintSigmas * std::sqrt(variance) : 0.0;
  return LostSearchRegion{x, y, radius, t};
}

std::optional<Window> LostSearchWindow::cover(const LostSearchRegion& region, const std::optional<Window>& pose_window,
                                              const std::optional<TileBox>& served) {
  const double half_side = std::min(std::ceil((region.radius + reach_) / kSearchStep) * kSearchStep, max_half_side_);
  const Window window = windowCovering(pose_window, region.x, region.y, half_side, s_);
  if (served && window.bounds() == *served) return std::nullopt;
  active_ = true;
  return window;
}

}  // namespace grid_puzzle_localization
