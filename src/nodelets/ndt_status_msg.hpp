// ~status publishing, in its own translation unit: the generated NdtStatus message and the core's
// NdtStatus enum (ndt.hpp) share a namespace and cannot be included together.
#pragma once

#include <ros/node_handle.h>
#include <ros/publisher.h>
#include <std_msgs/Header.h>

#include <string>

#include "grid_puzzle_localization/match_summary.hpp"

namespace grid_puzzle_localization {

ros::Publisher advertiseNdtStatus(ros::NodeHandle& nh, const std::string& topic);
void publishNdtStatus(const ros::Publisher& pub, const std_msgs::Header& header, const MatchSummary& summary,
                      const std::string& map_source);

}  // namespace grid_puzzle_localization
