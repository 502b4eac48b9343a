// Tiles mode: the localizer asks the provider for its whole window until the first one arrives. The provider sends a
// new subscriber the window when it connects, but a window computed before the connection (a provider that started
// first, a respawned manager that loaded the provider first) and a connection made before the first window can miss
// each other; the request settles it either way. No process of its own.
#pragma once

#include <ros/node_handle.h>
#include <ros/service_client.h>
#include <ros/wall_timer.h>

#include <atomic>
#include <string>

namespace grid_puzzle_localization {

class WindowRequest {
 public:
  /// Calls `resend_service` (std_srvs/Trigger) every kPeriod [s, wall clock] from a timer on `timer_nh`'s queue until
  /// received() is called; `log_name` names the logger.
  WindowRequest(ros::NodeHandle& timer_nh, const std::string& resend_service, std::string log_name);
  static constexpr double kPeriod = 2.0;
  /// A whole window (a reset delta) was taken: no more requests. Thread-safe.
  void received() { received_ = true; }

 private:
  void ask(const ros::WallTimerEvent&);

  ros::ServiceClient resend_;  // its own client: the tile_delta callback uses another, concurrently
  ros::WallTimer timer_;
  std::string log_name_;
  std::atomic<bool> received_{false};
  bool announced_ = false;  // timer callback only
};

}  // namespace grid_puzzle_localization
