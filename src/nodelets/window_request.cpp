#include "window_request.hpp"

#include <ros/console.h>
#include <std_srvs/Trigger.h>

#include <utility>

namespace grid_puzzle_localization {

WindowRequest::WindowRequest(ros::NodeHandle& timer_nh, const std::string& resend_service, std::string log_name)
    : resend_(timer_nh.serviceClient<std_srvs::Trigger>(resend_service)), log_name_(std::move(log_name)) {
  timer_ = timer_nh.createWallTimer(ros::WallDuration(kPeriod), &WindowRequest::ask, this);
}

void WindowRequest::ask(const ros::WallTimerEvent&) {
  if (received_) {
    timer_.stop();
    return;
  }
  if (!announced_) {
    ROS_INFO_NAMED(log_name_, "no tile window from the provider yet: asking %s for it every %.0f s until one comes",
                   resend_.getService().c_str(), kPeriod);
    announced_ = true;
  }
  std_srvs::Trigger srv;
  // The provider may not be up yet, or have no window before its first pose: asked again at the next period.
  if (!resend_.call(srv) || !srv.response.success)
    ROS_DEBUG_NAMED(log_name_, "%s: no window yet (%s)", resend_.getService().c_str(), srv.response.message.c_str());
}

}  // namespace grid_puzzle_localization
