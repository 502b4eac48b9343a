#include "grid_puzzle_localization/tile_cache.hpp"

namespace grid_puzzle_localization {

void TileCache::put(const std::string& path, TileVoxels tile) {
  take(path);
  const std::size_t b = bytesOf(path, tile);
  if (b > budget_) return;
  entries_.emplace_back(path, std::move(tile));
  index_[path] = std::prev(entries_.end());
  bytes_ += b;
  evictToFit();
}

std::optional<TileVoxels> TileCache::take(const std::string& path) {
  const auto it = index_.find(path);
  if (it == index_.end()) return std::nullopt;
  bytes_ -= bytesOf(path, it->second->second);
  TileVoxels tile = std::move(it->second->second);
  entries_.erase(it->second);
  index_.erase(it);
  return tile;
}

void TileCache::clear() {
  entries_.clear();
  index_.clear();
  bytes_ = 0;
}

void TileCache::setBudget(std::size_t budget_bytes) {
  budget_ = budget_bytes;
  evictToFit();
}

void TileCache::evictToFit() {
  while (bytes_ > budget_ && !entries_.empty()) {
    bytes_ -= bytesOf(entries_.front().first, entries_.front().second);
    index_.erase(entries_.front().first);
    entries_.pop_front();
  }
}

}  // namespace grid_puzzle_localization
