// A rectangle of the map frame: the box of a directory's tiles, or of the provider's window.
#pragma once

namespace grid_puzzle_localization {

/// [m] map frame.
struct MapExtent {
  double x_min = 0.0, x_max = 0.0, y_min = 0.0, y_max = 0.0;
};

}  // namespace grid_puzzle_localization
