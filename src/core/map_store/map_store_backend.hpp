// What MapStore forwards to: the store's work, in the library lib<package>_map_store (libcurl, OpenSSL), which the
// core loads on the first MapStore (map_store_loader.cpp) or finds linked in. No ROS.
#pragma once

#include <string>
#include <vector>

#include "grid_puzzle_localization/map_store/map_store.hpp"

namespace grid_puzzle_localization {
namespace map_store_detail {

/// MapStore's methods, as the map store library implements them (see MapStore for what each does).
class Backend {
 public:
  virtual ~Backend() = default;
  virtual bool pollIndex() = 0;
  virtual std::vector<FetchedTile> fetch(const std::vector<std::string>& ids) = 0;
  virtual const std::string& url() const = 0;
  virtual const TileIndexListing& index() const = 0;
  virtual std::string indexPath() const = 0;
  virtual std::string cacheDirectory() const = 0;
  virtual MapStoreStatus status() const = 0;
};

}  // namespace map_store_detail
}  // namespace grid_puzzle_localization

/// The map store library's entry point, found by this name: opens the store at `url` as MapStore's constructor
/// documents (and throws as it does). The caller owns the result.
extern "C" grid_puzzle_localization::map_store_detail::Backend* gpl_open_map_store(
    const std::string& url, const grid_puzzle_localization::MapStoreConfig& config);
