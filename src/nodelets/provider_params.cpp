#include "provider_params.hpp"

#include <stdexcept>
#include <string>

namespace grid_puzzle_localization {
namespace {

const char* typeName(const double*) { return "float"; }
const char* typeName(const int*) { return "int"; }
const char* typeName(const bool*) { return "bool"; }
const char* typeName(const std::string*) { return "str"; }

// Reads `name` into `field` when it is set; a value of another type stops the start-up naming the parameter.
template <class T>
void load(const ros::NodeHandle& pnh, const std::string& name, T& field) {
  if (!pnh.hasParam(name)) return;
  T value;
  if (!pnh.getParam(name, value))
    throw std::invalid_argument("parameter " + name + " must be a " + typeName(&field) +
                                "; fix it in the launch file or YAML of the provider");
  field = value;
}

}  // namespace

ProviderConfig loadProviderConfig(const ros::NodeHandle& pnh) {
  ProviderConfig c;
  load(pnh, "tiles/dir", c.tiles_dir);
  load(pnh, "tiles/grid_size", c.tiles_grid_size);
  load(pnh, "window/n", c.window.n);
  load(pnh, "window/k", c.window.k);
  load(pnh, "window/update_distance", c.window.update_distance);
  load(pnh, "window/heading_source", c.window.heading_source);
  load(pnh, "window/lookahead_time", c.window.lookahead_time);
  load(pnh, "window/preset", c.window.preset);
  load(pnh, "lost/max_half_side", c.lost_max_half_side);
  load(pnh, "start/search_timeout", c.start_search_timeout);
  load(pnh, "start/max_area", c.start_max_area);
  load(pnh, "pose_source", c.pose_source);
  load(pnh, "publish_map_cloud", c.publish_map_cloud);
  load(pnh, "map_cloud_period", c.map_cloud_period);
  load(pnh, "map_frame", c.map_frame);
  load(pnh, "save_pose_rate", c.save_pose_rate);
  return c.checked();
}

}  // namespace grid_puzzle_localization
