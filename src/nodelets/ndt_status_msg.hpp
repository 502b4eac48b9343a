// Core LocalizerOutput -> grid_puzzle_localization/NdtStatus (the ~status message).
#pragma once

#include <string>

#include "grid_puzzle_localization/NdtStatus.h"
#include "grid_puzzle_localization/localizer.hpp"

namespace grid_puzzle_localization {

/// The diagnostics of one tracked scan; `target_update_ms` is the last background target update [ms] and
/// `map_source` the ~map_source parameter (cloud | tiles | pcd).
NdtStatus toStatusMsg(const LocalizerOutput& out, const std_msgs::Header& header, double target_update_ms,
                      const std::string& map_source);

}  // namespace grid_puzzle_localization
