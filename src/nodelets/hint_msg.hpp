// initialpose_hint (geometry_msgs/PoseWithCovarianceStamped): a coarse position, as the search region it asks for.
// Shared by the localizer and the provider nodelets, which both take hints.
#pragma once

#include <geometry_msgs/PoseWithCovarianceStamped.h>

#include <optional>
#include <string>

#include "grid_puzzle_localization/provider/window.hpp"

namespace grid_puzzle_localization {

struct HintRegion {
  std::optional<LostSearchRegion> region;  ///< hintRegion() of the message, when it is usable
  std::string error;                       ///< else why not (names initialpose_hint and what to do)
};

/// The search region of a hint in `map_frame` (an empty frame id is taken as it), or the error that refuses it: another
/// frame, or a position that is not finite.
HintRegion hintRegionOf(const geometry_msgs::PoseWithCovarianceStamped& msg, const std::string& map_frame);

}  // namespace grid_puzzle_localization
