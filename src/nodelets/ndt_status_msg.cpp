#include "ndt_status_msg.hpp"

#include <cmath>

namespace grid_puzzle_localization {

NdtStatus toStatusMsg(const LocalizerOutput& out, const std_msgs::Header& header, const MapUpdateStats& map,
                      const std::string& map_source) {
  NdtStatus msg;
  msg.header = header;
  msg.state = toString(out.state);
  msg.tiles_in_flight = static_cast<std::uint32_t>(out.tiles_in_flight);
  msg.tiles_awaited = static_cast<std::uint32_t>(out.tiles_awaited);
  msg.start_pending = out.start_pending;
  if (out.start_pending) {
    msg.start_x = out.prediction.translation().x();
    msg.start_y = out.prediction.translation().y();
    msg.start_yaw = std::atan2(out.prediction.linear()(1, 0), out.prediction.linear()(0, 0));
  }
  msg.start_motion_guessed = out.start_motion_guessed;
  msg.converged = out.ndt.converged;
  msg.match_accepted = out.match_accepted;
  msg.iterations = out.ndt.iterations;
  msg.score = out.ndt.score;
  msg.transformation_probability = out.ndt.transformation_probability;
  msg.nvtl = out.ndt.nvtl;
  msg.inlier_fraction = out.ndt.inlier_fraction;
  msg.align_time_ms = out.align_ms;
  msg.scan_time_ms = out.scan_ms;
  msg.target_update_time_ms = map.update_ms;
  msg.map_worker_cpu_s = 1e-3 * map.worker_cpu_ms;
  msg.target_voxels = out.target_voxels;
  msg.target_points = out.target_points;
  msg.source_points = static_cast<std::uint32_t>(out.ndt.source_points);
  msg.map_source = map_source;
  msg.lost = out.lost;
  msg.published = out.publish;
  msg.since_last_match = out.since_last_match;
  msg.global_search = out.global_search;
  msg.global_search_reason = out.global_search_reason;
  msg.search_started = out.search_started;
  msg.search_x = out.search_region.centre.translation().x();
  msg.search_y = out.search_region.centre.translation().y();
  msg.search_radius = out.search_region.radius;
  msg.hypotheses = static_cast<std::uint32_t>(out.hypotheses);
  return msg;
}

}  // namespace grid_puzzle_localization
