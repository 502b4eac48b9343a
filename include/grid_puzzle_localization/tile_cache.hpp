// Tiles read ahead of the window (prefetch), bounded by a byte budget. No ROS.
#pragma once

#include <cstddef>
#include <list>
#include <optional>
#include <string>
#include <unordered_map>
#include <utility>

#include "grid_puzzle_localization/voxel_map.hpp"

namespace grid_puzzle_localization {

/// Tiles read ahead, reduced to their voxels' statistics (TileVoxels), keyed by path; the least recently stored is
/// evicted first once their bytes exceed the budget. A tile leaves the cache when it is taken (it enters the window and
/// is folded into the NDT target), so the cache never holds a second copy of what the target holds. Not thread-safe
/// (one owner).
class TileCache {
 public:
  explicit TileCache(std::size_t budget_bytes = 0) : budget_(budget_bytes) {}

  /// Stores `tile` under `path` unless it alone exceeds the budget; evicts the oldest entries to fit.
  void put(const std::string& path, TileVoxels tile);
  /// Removes and returns the tile of `path`, if cached.
  std::optional<TileVoxels> take(const std::string& path);
  bool contains(const std::string& path) const { return index_.count(path) != 0; }
  void clear();
  void setBudget(std::size_t budget_bytes);

  std::size_t bytes() const { return bytes_; }
  /// What an entry counts against the budget: the tile's statistics plus the entry's key and list and index nodes.
  static std::size_t bytesOf(const std::string& path, const TileVoxels& tile) {
    return tile.bytes() + 2 * (sizeof(std::string) + path.size()) + 8 * sizeof(void*);
  }
  std::size_t budget() const { return budget_; }
  std::size_t size() const { return index_.size(); }

 private:
  void evictToFit();

  using Entry = std::pair<std::string, TileVoxels>;
  std::size_t budget_;
  std::size_t bytes_ = 0;
  std::list<Entry> entries_;  // oldest first
  std::unordered_map<std::string, std::list<Entry>::iterator> index_;
};

}  // namespace grid_puzzle_localization
