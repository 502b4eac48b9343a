// A nodelet's last pose kept on the parameter server, as amcl keeps its own (save_pose_rate): ~last_pose
// {pose: [x y z roll pitch yaw] (m, rad, fixed-axis), stamp (s)}, written in one setParam call so that a reader never
// sees a pose with another pose's stamp, and read back by a respawned process. No process of its own.
#pragma once

#include <ros/node_handle.h>
#include <ros/wall_timer.h>

#include <cstdint>
#include <mutex>
#include <optional>
#include <string>

#include "grid_puzzle_localization/rpy.hpp"

namespace grid_puzzle_localization {

/// ~last_pose/pose of `pnh` when it is 6 finite numbers; a malformed value (state, not a setting) is logged with
/// `log_name` and ignored.
std::optional<XyzRpy> readSavedPose(const ros::NodeHandle& pnh, const std::string& log_name);

/// Writes the newest pose given to set() to ~last_pose at `rate` [Hz] (wall clock), from a timer on `timer_nh`'s
/// queue (never on the caller's thread: a setParam is a call to the master); nothing new, no call. Rate 0: off.
class SavedPoseWriter {
 public:
  SavedPoseWriter(ros::NodeHandle& timer_nh, const ros::NodeHandle& pnh, double rate);
  void set(const XyzRpy& pose, double stamp);  ///< thread-safe, cheap

 private:
  void write(const ros::WallTimerEvent&);

  ros::NodeHandle pnh_;
  ros::WallTimer timer_;
  std::mutex mutex_;  // guards the fields below (set() callers, the timer)
  XyzRpy pose_ = XyzRpy::Zero();
  double stamp_ = 0.0;
  std::uint64_t seq_ = 0, written_seq_ = 0;
};

}  // namespace grid_puzzle_localization
