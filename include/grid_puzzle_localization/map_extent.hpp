// A rectangle of the map frame: the box of a directory's tiles, or of the provider's window.
#pragma once

namespace grid_puzzle_localization {

/// [m] map frame.
struct MapExtent {
  double x_min = 0.0, x_max = 0.0, y_min = 0.0, y_max = 0.0;

  /// Whether the square of half-side `half` [m] around (x, y) lies inside.
  bool holdsSquare(double x, double y, double half) const {
    return x_min <= x - half && x_max >= x + half && y_min <= y - half && y_max >= y + half;
  }
};

}  // namespace grid_puzzle_localization
