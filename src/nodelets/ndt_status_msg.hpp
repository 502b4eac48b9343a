// Core LocalizerOutput -> grid_puzzle_localization/NdtStatus (the ~status message).
#pragma once

#include <string>

#include "grid_puzzle_localization/NdtStatus.h"
#include "grid_puzzle_localization/localizer.hpp"

namespace grid_puzzle_localization {

/// The diagnostics of one scan; `map` what the map worker has done (its last update, its CPU time) and `map_source`
/// the ~map_source parameter (cloud | tiles | pcd).
NdtStatus toStatusMsg(const LocalizerOutput& out, const std_msgs::Header& header, const MapUpdateStats& map,
                      const std::string& map_source);

}  // namespace grid_puzzle_localization
