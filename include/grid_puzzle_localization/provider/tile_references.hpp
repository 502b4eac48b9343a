// The window's tiles by reference: which tile files enter and leave the window and which are likely to enter next,
// without reading a point (the localizer reads the files). The C++ twin of provider/tile_references.py. No ROS; not
// thread-safe (the provider serialises its updates).
#pragma once

#include <cstdint>
#include <string>
#include <unordered_set>
#include <vector>

#include "grid_puzzle_localization/provider/tile_directory.hpp"
#include "grid_puzzle_localization/provider/window.hpp"

namespace grid_puzzle_localization {

/// Bound of one prefetch list: the localizer's byte budget bounds what it reads.
constexpr std::size_t kPrefetchMaxTiles = 256;

struct ReferenceDelta {
  std::vector<TileKey> added, removed;
  std::vector<TileKey> prefetch;  ///< most likely first
};

/// `a` without `b`, as at most four disjoint boxes (the strips of `a` around `b`).
std::vector<TileBox> boxMinus(const TileBox& a, const TileBox& b);

class TileReferences {
 public:
  explicit TileReferences(TileDirectory directory);

  /// The tiles that entered and left since the last update, and the prefetch list of the `ahead` windows (most
  /// likely first) that are not in `box`.
  ReferenceDelta update(const TileBox& box, const std::vector<Window>& ahead);
  /// The window's tiles, sorted.
  std::vector<TileKey> loaded() const;
  std::size_t loadedCount() const { return loaded_.size(); }
  /// Reopens the directory when its index revision changed: true then (the window must be sent again as a reset).
  /// Throws std::invalid_argument when the directory became unusable (the old one is kept).
  bool refresh();

  const TileDirectory& directory() const { return directory_; }
  const std::string& revision() const { return revision_; }

 private:
  std::vector<std::uint64_t> codesIn(const std::vector<TileBox>& boxes) const;

  TileDirectory directory_;
  std::string revision_;
  std::unordered_set<std::uint64_t> loaded_;
  bool has_box_ = false;
  TileBox box_;
};

}  // namespace grid_puzzle_localization
