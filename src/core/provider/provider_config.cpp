#include "grid_puzzle_localization/provider/provider_config.hpp"

#include <cmath>
#include <stdexcept>

namespace grid_puzzle_localization {

ProviderConfig ProviderConfig::checked() const {
  if (tiles_dir.empty())
    throw std::invalid_argument("parameter tiles/dir is empty; set it to a tile directory written by `gpm tile`");
  if (!(tiles_grid_size >= 0.0))
    throw std::invalid_argument("parameter tiles/grid_size must be > 0 m, or 0 to read it from the index (got " +
                                std::to_string(tiles_grid_size) + ")");
  if (!(map_cloud_period >= 0.0))
    throw std::invalid_argument("parameter map_cloud_period must be >= 0 s (got " + std::to_string(map_cloud_period) +
                                ")");
  if (!(std::isfinite(lost_max_half_side) && lost_max_half_side >= 0.0))
    throw std::invalid_argument("parameter lost/max_half_side must be >= 0 m (got " +
                                std::to_string(lost_max_half_side) + "); 0 = off");
  if (!(std::isfinite(start_search_timeout) && start_search_timeout >= 0.0))
    throw std::invalid_argument("parameter start/search_timeout must be >= 0 s (got " +
                                std::to_string(start_search_timeout) + "); 0 = off");
  if (!(std::isfinite(start_max_area) && start_max_area > 0.0))
    throw std::invalid_argument("parameter start/max_area must be > 0 m^2 (got " + std::to_string(start_max_area) +
                                ")");
  if (!(std::isfinite(save_pose_rate) && save_pose_rate >= 0.0))
    throw std::invalid_argument("parameter save_pose_rate must be >= 0 Hz (got " + std::to_string(save_pose_rate) +
                                "); 0 = off");
  if (pose_source != "odom" && pose_source != "pose")
    throw std::invalid_argument("parameter pose_source '" + pose_source + "' is unknown; use one of odom, pose");
  ProviderConfig c = *this;
  c.window = window.resolved();
  return c;
}

}  // namespace grid_puzzle_localization
