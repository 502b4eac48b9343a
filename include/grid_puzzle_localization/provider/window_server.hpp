// What the provider serves: the window that follows the pose, or while the localizer is lost the window that holds
// its search, and that window's tiles by reference. The C++ twin of provider/window_server.py (the rospy provider's),
// held equal to it by test_window_server_equality. No ROS; not thread-safe (the nodelet serialises its calls).
#pragma once

#include <optional>
#include <utility>
#include <vector>

#include "grid_puzzle_localization/map_extent.hpp"
#include "grid_puzzle_localization/provider/tile_references.hpp"
#include "grid_puzzle_localization/provider/window.hpp"

namespace grid_puzzle_localization {

/// One window update: the window, its tile change, and where it was computed.
struct Served {
  Window window;
  ReferenceDelta delta;
  bool first = false;    ///< the first window: sent as a reset
  bool changed = false;  ///< the tile set or the bounds changed: a new delta revision is due
  PoseSample pose;       ///< the pose, or the search region's centre, the window was computed for
};

/// `keys` sorted by the distance of their tile's centre from (x, y) [m], nearest first, ties in (i, j) order: the
/// localizer loads a delta's tiles in its order, so the tiles under the scan arrive first. Tile side `s` [m]. The twin
/// of window_server.py's nearest_first.
void sortNearestFirst(std::vector<TileKey>& keys, double x, double y, double s);

class WindowServer {
 public:
  WindowServer(const WindowConfig& window, double max_half_side, TileDirectory directory);

  /// The localizer tracks again: the next pose recomputes the window wherever it is.
  void endSearch() {
    if (lost_.end()) tracker_.restart();
  }
  /// The window holding the lost localizer's search region, or nullopt when it is served already.
  std::optional<Served> onSearch(const LostSearchRegion& region);
  /// Every tile of the directory, for the global search of a start without a pose or a hint, or nullopt when it is
  /// served already (or the directory is empty). Like a search's window it stays until the localizer tracks.
  std::optional<Served> onWholeMap();
  /// The box of the directory's tiles.
  MapExtent mapExtent() const;
  /// True when the square of half side `region.radius` around its centre meets the directory's tiles' box.
  bool touchesMap(const LostSearchRegion& region) const;
  /// [m^2] of the directory's bounding box of tiles.
  double mapArea() const;
  /// The window after `pose`, or nullopt when it stays (not moved far enough, or a search's window is served).
  std::optional<Served> onPose(const PoseSample& pose);
  /// True when the tile directory was rewritten (a new index revision): the whole window is due as a reset. Throws
  /// std::invalid_argument when the directory became unusable.
  bool refresh() { return tiles_.refresh(); }
  /// The served window with all its tiles as `added` (a reset), or nullopt before the first window.
  std::optional<std::pair<Window, ReferenceDelta>> whole();

  bool searching() const { return lost_.active(); }
  const WindowTracker& tracker() const { return tracker_; }
  const TileReferences& tiles() const { return tiles_; }

 private:
  Served serve(const PoseSample& pose, const Window& window);

  WindowTracker tracker_;
  TileReferences tiles_;
  LostSearchWindow lost_;
  std::optional<Window> window_;  // the window served last
  PoseSample focus_;              // the pose or search centre it was served for: its tiles go out nearest it first
};

}  // namespace grid_puzzle_localization
