#include "hint_msg.hpp"

#include <sstream>

namespace grid_puzzle_localization {

HintRegion hintRegionOf(const geometry_msgs::PoseWithCovarianceStamped& msg, const std::string& map_frame) {
  HintRegion out;
  if (!msg.header.frame_id.empty() && msg.header.frame_id != map_frame) {
    out.error = "initialpose_hint is in frame '" + msg.header.frame_id + "' but map_frame is '" + map_frame +
                "'; ignored: send the hint in the map frame";
    return out;
  }
  const geometry_msgs::Point& p = msg.pose.pose.position;
  out.region = hintRegion(p.x, p.y, msg.pose.covariance[0], msg.pose.covariance[7], msg.header.stamp.toSec());
  if (!out.region) {
    std::ostringstream e;
    e << "initialpose_hint ignored: its position (" << p.x << ", " << p.y
      << ") is not finite; send x and y in metres in the map frame";
    out.error = e.str();
  }
  return out;
}

}  // namespace grid_puzzle_localization
