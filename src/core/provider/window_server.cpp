#include "grid_puzzle_localization/provider/window_server.hpp"

#include <algorithm>
#include <tuple>

#include "grid_puzzle_localization/tile_geometry.hpp"

namespace grid_puzzle_localization {

void sortNearestFirst(std::vector<TileKey>& keys, double x, double y, double s) {
  const auto distance2 = [&](const TileKey& k) {
    const Eigen::Vector2d centre = tileCentre(k, s);
    const double dx = centre.x() - x;
    const double dy = centre.y() - y;
    return dx * dx + dy * dy;
  };
  std::sort(keys.begin(), keys.end(), [&](const TileKey& a, const TileKey& b) {
    return std::make_tuple(distance2(a), a.i, a.j) < std::make_tuple(distance2(b), b.i, b.j);
  });
}

WindowServer::WindowServer(const WindowConfig& window, double max_half_side, TileDirectory directory)
    : tracker_(window, directory.grid_size),
      tiles_(std::move(directory)),
      lost_(max_half_side, tracker_.config().n * tiles_.directory().grid_size, tiles_.directory().grid_size) {}

std::optional<Served> WindowServer::onSearch(const LostSearchRegion& region) {
  const std::optional<TileBox> served = window_ ? std::optional<TileBox>(window_->bounds()) : std::nullopt;
  const std::optional<Window> window = lost_.cover(region, tracker_.window(), served);
  if (!window) return std::nullopt;
  PoseSample centre;
  centre.x = region.x;
  centre.y = region.y;
  centre.t = region.t;
  return serve(centre, *window);
}

std::optional<Served> WindowServer::onWholeMap() {
  const TileBox b = tiles_.directory().bounds;
  if (b.empty()) return std::nullopt;
  const double s = tracker_.s();
  PoseSample centre;
  centre.x = static_cast<double>(b.i_min + b.i_max + 1) * s / 2;
  centre.y = static_cast<double>(b.j_min + b.j_max + 1) * s / 2;
  const double half_side = static_cast<double>(std::max(b.i_max - b.i_min + 1, b.j_max - b.j_min + 1)) * s / 2;
  const Window window = windowCovering(std::nullopt, centre.x, centre.y, half_side, s);
  if (window_ && window.bounds() == window_->bounds()) return std::nullopt;
  lost_.hold();
  return serve(centre, window);
}

MapExtent WindowServer::mapExtent() const {
  const TileBox b = tiles_.directory().bounds;
  const double s = tracker_.s();
  return {cellLow(b.i_min, s), cellLow(b.i_max + 1, s), cellLow(b.j_min, s), cellLow(b.j_max + 1, s)};
}

bool WindowServer::touchesMap(const LostSearchRegion& region) const {
  const MapExtent m = mapExtent();
  const double r = region.radius;
  return m.x_min <= region.x + r && region.x - r <= m.x_max && m.y_min <= region.y + r && region.y - r <= m.y_max;
}

double WindowServer::mapArea() const {
  const TileBox b = tiles_.directory().bounds;
  if (b.empty()) return 0.0;
  const double s = tracker_.s();
  return static_cast<double>(b.i_max - b.i_min + 1) * static_cast<double>(b.j_max - b.j_min + 1) * s * s;
}

std::optional<Served> WindowServer::onPose(const PoseSample& pose) {
  if (lost_.active()) return std::nullopt;  // while the localizer is lost its pose is a prediction
  const std::optional<Window> window = tracker_.update(pose);
  if (!window) return std::nullopt;
  return serve(pose, *window);
}

std::optional<std::pair<Window, ReferenceDelta>> WindowServer::whole() {
  if (!window_) return std::nullopt;
  // Changes nothing, except after a refresh, which emptied the set: then it loads the new directory's.
  ReferenceDelta delta;
  delta.prefetch = tiles_.update(window_->bounds(), tracker_.predictedWindows()).prefetch;
  delta.added = tiles_.loaded();
  sortNearestFirst(delta.added, focus_.x, focus_.y, tracker_.s());
  return std::make_pair(*window_, std::move(delta));
}

Served WindowServer::serve(const PoseSample& pose, const Window& window) {
  Served s;
  s.delta = tiles_.update(window.bounds(), tracker_.predictedWindows());
  sortNearestFirst(s.delta.added, pose.x, pose.y, tracker_.s());
  s.first = !window_;
  s.changed = s.first || !s.delta.added.empty() || !s.delta.removed.empty() || window.bounds() != window_->bounds();
  s.window = window;
  s.pose = pose;
  window_ = window;
  focus_ = pose;
  return s;
}

}  // namespace grid_puzzle_localization
