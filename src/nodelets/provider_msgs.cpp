#include "provider_msgs.hpp"

#include <boost/make_shared.hpp>
#include <cmath>

#include "grid_puzzle_localization/provider/tile_directory.hpp"

namespace grid_puzzle_localization {
namespace {

std::vector<std::string> stems(const std::vector<TileKey>& keys, double s) {
  std::vector<std::string> out;
  out.reserve(keys.size());
  for (const TileKey& k : keys) out.push_back(tileStem(k.i, k.j, s));
  return out;
}

}  // namespace

PoseSample poseSampleOf(const geometry_msgs::Pose& pose, const ros::Time& stamp, const geometry_msgs::Twist* twist) {
  PoseSample p;
  p.x = pose.position.x;
  p.y = pose.position.y;
  p.t = stamp.toSec();
  const geometry_msgs::Quaternion& q = pose.orientation;
  if (q.x == 0.0 && q.y == 0.0 && q.z == 0.0 && q.w == 0.0) return p;
  const double yaw = std::atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z));
  p.yaw = yaw;
  if (twist != nullptr) {
    const double c = std::cos(yaw), s = std::sin(yaw), vx = twist->linear.x, vy = twist->linear.y;
    p.velocity = std::array<double, 2>{c * vx - s * vy, s * vx + c * vy};
  }
  return p;
}

TileDelta::Ptr makeTileDelta(const ros::Time& stamp, const std::string& frame, std::uint32_t revision, bool reset,
                             double s, const Window& window, const std::string& tile_dir,
                             const std::string& index_revision, const std::vector<TileKey>& added,
                             const std::vector<TileKey>& removed, const std::vector<TileKey>& prefetch) {
  TileDelta::Ptr msg = boost::make_shared<TileDelta>();
  msg->header.stamp = stamp;
  msg->header.frame_id = frame;
  msg->revision = revision;
  msg->reset = reset;
  msg->grid_size = s;
  msg->tile_dir = tile_dir;
  msg->index_revision = index_revision;
  msg->added_ids = stems(added, s);
  msg->removed_ids = stems(removed, s);
  msg->prefetch_ids = stems(prefetch, s);
  const TileBox b = window.bounds();
  msg->i_min = b.i_min;
  msg->i_max = b.i_max;
  msg->j_min = b.j_min;
  msg->j_max = b.j_max;
  return msg;
}

ProviderStatus providerStatusMsg(const TileDelta& delta, const Window& window, std::size_t tiles_loaded,
                                 double update_ms) {
  ProviderStatus msg;
  msg.header = delta.header;
  msg.i_min = delta.i_min;
  msg.i_max = delta.i_max;
  msg.j_min = delta.j_min;
  msg.j_max = delta.j_max;
  msg.theta = window.theta;
  msg.sector = window.sector;
  msg.tile_dir = delta.tile_dir;
  msg.index_revision = delta.index_revision;
  msg.tiles_loaded = static_cast<std::uint32_t>(tiles_loaded);
  msg.tiles_added = static_cast<std::uint32_t>(delta.added_ids.size());
  msg.tiles_removed = static_cast<std::uint32_t>(delta.removed_ids.size());
  msg.tiles_prefetch = static_cast<std::uint32_t>(delta.prefetch_ids.size());
  msg.update_ms = update_ms;
  msg.store_reachable = true;  // a directory; a map store's provider sets its own state
  return msg;
}

}  // namespace grid_puzzle_localization
