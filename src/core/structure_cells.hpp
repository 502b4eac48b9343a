// Private helper of GlobalLocalizer: the ground height of x-y cells and the structure (walls, poles, trunks) standing
// above it, the same way for the map and for a scan so that their heights compare.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <unordered_map>
#include <vector>

namespace grid_puzzle_localization {

/// Key of the x-y cell (x, y) (cell indices, not metres). Shifted as unsigned: shifting a negative value left is
/// undefined before C++20 (UBSan reports it).
inline std::int64_t cellKey(std::int64_t x, std::int64_t y) {
  return static_cast<std::int64_t>((static_cast<std::uint64_t>(x) << 32) ^
                                   (static_cast<std::uint64_t>(y) & 0xffffffffULL));
}

/// The lowest z of the points in each x-y cell of edge `cell` [m].
class GroundCells {
 public:
  GroundCells(const std::vector<Eigen::Vector3d>& points, double cell);
  /// Lowest z of the cell holding (x, y) (which must hold a point given to the constructor).
  double lowest(double x, double y) const;
  /// Median of the lowest z of the cells whose centre lies within `radius` of (x, y); false when there is none.
  bool heightNear(double x, double y, double radius, double* height) const;
  /// Whether the cell holding (x, y) holds a point given to the constructor.
  bool holds(double x, double y) const { return lowest_.count(keyOf(x, y)) > 0; }
  /// Whether a cell whose centre lies within `radius` of (x, y) holds a point given to the constructor.
  bool holdsNear(double x, double y, double radius) const;

 private:
  std::int64_t keyOf(double x, double y) const;
  /// Calls `visit` with the lowest z of each cell near (x, y) holding points until it returns true; true if it did.
  bool visitNear(double x, double y, double radius, const std::function<bool(double)>& visit) const;
  double cell_;
  std::unordered_map<std::int64_t, double> lowest_;
};

/// A point of the structure: x-y [m] and height above the ground of its cell [m].
struct StructurePoint {
  Eigen::Vector2d xy;
  double height;
};

/// The points standing between `min_height` and `max_height` above the lowest point of their cell.
std::vector<StructurePoint> structurePoints(const std::vector<Eigen::Vector3d>& points, const GroundCells& ground,
                                            double min_height, double max_height);

}  // namespace grid_puzzle_localization
