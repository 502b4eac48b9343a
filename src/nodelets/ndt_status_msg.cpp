#include "ndt_status_msg.hpp"

#include "grid_puzzle_localization/NdtStatus.h"

namespace grid_puzzle_localization {

ros::Publisher advertiseNdtStatus(ros::NodeHandle& nh, const std::string& topic) {
  return nh.advertise<NdtStatus>(topic, 10);
}

void publishNdtStatus(const ros::Publisher& pub, const std_msgs::Header& header, const MatchSummary& s,
                      const std::string& map_source) {
  NdtStatus msg;
  msg.header = header;
  msg.converged = s.converged;
  msg.match_accepted = s.match_accepted;
  msg.iterations = s.iterations;
  msg.score = s.score;
  msg.transformation_probability = s.transformation_probability;
  msg.nvtl = s.nvtl;
  msg.inlier_fraction = s.inlier_fraction;
  msg.align_time_ms = s.align_ms;
  msg.target_update_time_ms = s.target_update_ms;
  msg.target_voxels = s.target_voxels;
  msg.target_points = s.target_points;
  msg.source_points = static_cast<std::uint32_t>(s.source_points);
  msg.map_source = map_source;
  pub.publish(msg);
}

}  // namespace grid_puzzle_localization
