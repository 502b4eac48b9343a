#include "saved_pose.hpp"

#include <ros/console.h>

#include <cmath>
#include <sstream>
#include <vector>

namespace grid_puzzle_localization {

std::optional<XyzRpy> readSavedPose(const ros::NodeHandle& pnh, const std::string& log_name) {
  std::vector<double> saved;
  if (!pnh.getParam("last_pose/pose", saved)) return std::nullopt;
  bool finite = saved.size() == 6;
  for (const double v : saved) finite = finite && std::isfinite(v);
  if (finite) return XyzRpy(saved.data());
  std::ostringstream text;
  for (std::size_t i = 0; i < saved.size(); ++i) text << (i ? ", " : "") << saved[i];
  ROS_WARN("%s: parameter ~last_pose/pose = [%s] is not 6 finite numbers [x y z roll pitch yaw] (m, rad); ignored",
           log_name.c_str(), text.str().c_str());
  return std::nullopt;
}

SavedPoseWriter::SavedPoseWriter(ros::NodeHandle& timer_nh, const ros::NodeHandle& pnh, double rate) : pnh_(pnh) {
  if (rate > 0.0) timer_ = timer_nh.createWallTimer(ros::WallDuration(1.0 / rate), &SavedPoseWriter::write, this);
}

void SavedPoseWriter::set(const XyzRpy& pose, double stamp) {
  std::lock_guard<std::mutex> lock(mutex_);
  pose_ = pose;
  stamp_ = stamp;
  ++seq_;
}

void SavedPoseWriter::write(const ros::WallTimerEvent&) {
  XmlRpc::XmlRpcValue value, xyz_rpy;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (seq_ == written_seq_) return;
    written_seq_ = seq_;
    xyz_rpy.setSize(6);
    for (int i = 0; i < 6; ++i) xyz_rpy[i] = pose_(i);
    value["stamp"] = stamp_;
  }
  value["pose"] = xyz_rpy;
  pnh_.setParam("last_pose", value);
}

}  // namespace grid_puzzle_localization
