// grid_puzzle_localization/TileDelta -> core MapChange, in revision order: a gap asks the provider to resend
// the whole window, and a tile directory that is gone is noticed here, with the delta.
#pragma once

#include <ros/service_client.h>

#include <optional>
#include <string>
#include <utility>

#include "grid_puzzle_localization/TileDelta.h"
#include "grid_puzzle_localization/map_update_worker.hpp"
#include "grid_puzzle_localization/tile_delta_sequence.hpp"

namespace grid_puzzle_localization {

/// One per localizer; its calls must not overlap (one subscriber callback).
class TileDeltaInput {
 public:
  /// `resend`: std_srvs/Trigger of the provider that sends the whole window again; `ndt_resolution` [m] to warn
  /// when it does not divide the tile side; `log_name` names the logger (the nodelet's name).
  TileDeltaInput(ros::ServiceClient resend, double ndt_resolution, std::string log_name)
      : resend_(std::move(resend)), ndt_resolution_(ndt_resolution), log_name_(std::move(log_name)) {}

  /// The map change `msg` brings, or nullopt when it is not applied (a duplicate or stale revision, a gap that
  /// asks for a resend, a malformed message or a missing tile directory; each logged). The error of a missing
  /// directory quotes the tiles `map` has loaded (matching goes on with them).
  std::optional<MapChange> accept(const TileDelta& msg, const MapUpdateWorker& map);

 private:
  bool inSequence(const TileDelta& msg);

  ros::ServiceClient resend_;
  double ndt_resolution_;
  std::string log_name_;
  TileDeltaSequence sequence_;
};

}  // namespace grid_puzzle_localization
