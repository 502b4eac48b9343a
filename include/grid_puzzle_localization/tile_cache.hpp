// Tiles read ahead of the window (prefetch), bounded by a byte budget. No ROS.
#pragma once

#include <cstddef>
#include <list>
#include <optional>
#include <string>
#include <unordered_map>
#include <utility>

#include "grid_puzzle_localization/point_cloud.hpp"

namespace grid_puzzle_localization {

/// Point clouds of tile files keyed by path, least recently stored evicted first once their bytes exceed
/// the budget. A tile leaves the cache when it is taken (it enters the window and is folded into the NDT
/// target), so the cache never holds a second copy of what the target holds. Not thread-safe (one owner).
class TileCache {
 public:
  explicit TileCache(std::size_t budget_bytes = 0) : budget_(budget_bytes) {}

  /// Stores `points` under `path` unless they alone exceed the budget; evicts the oldest entries to fit.
  void put(const std::string& path, PointCloud points);
  /// Removes and returns the cloud of `path`, if cached.
  std::optional<PointCloud> take(const std::string& path);
  bool contains(const std::string& path) const { return index_.count(path) != 0; }
  void clear();
  void setBudget(std::size_t budget_bytes);

  std::size_t bytes() const { return bytes_; }
  std::size_t budget() const { return budget_; }
  std::size_t size() const { return index_.size(); }
  static std::size_t bytesOf(const PointCloud& points) { return points.capacity() * sizeof(Point); }

 private:
  void evictToFit();

  using Entry = std::pair<std::string, PointCloud>;
  std::size_t budget_;
  std::size_t bytes_ = 0;
  std::list<Entry> entries_;  // oldest first
  std::unordered_map<std::string, std::list<Entry>::iterator> index_;
};

}  // namespace grid_puzzle_localization
