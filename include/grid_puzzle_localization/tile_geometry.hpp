// Where a tile lies in the map frame: the map's x-y plane cut into squares of side s [m], tile (or cell) (i, j)
// covering [i s, (i + 1) s) x [j s, (j + 1) s). No ROS includes here.
#pragma once

#include <Eigen/Core>
#include <cstdint>

namespace grid_puzzle_localization {

/// Index of a square map tile of side s [m]: tile (i, j) covers [i s, (i + 1) s) x [j s, (j + 1) s).
struct TileKey {
  std::int64_t i = 0, j = 0;
  bool operator==(const TileKey& o) const { return i == o.i && j == o.j; }
};

/// Low edge i s [m] of tile (or cell) i of side `s` [m] along one axis.
inline double cellLow(std::int64_t i, double s) { return static_cast<double>(i) * s; }
/// Centre (i + 0.5) s [m] of tile (or cell) i of side `s` [m] along one axis.
inline double cellCentre(std::int64_t i, double s) { return (static_cast<double>(i) + 0.5) * s; }

/// Low corner (i s, j s) [m] of tile `key` of side `s` [m].
inline Eigen::Vector2d tileLow(const TileKey& key, double s) { return {cellLow(key.i, s), cellLow(key.j, s)}; }
/// Centre ((i + 0.5) s, (j + 0.5) s) [m] of tile `key` of side `s` [m].
inline Eigen::Vector2d tileCentre(const TileKey& key, double s) { return {cellCentre(key.i, s), cellCentre(key.j, s)}; }

}  // namespace grid_puzzle_localization
