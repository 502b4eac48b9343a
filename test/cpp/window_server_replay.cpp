// Replays a window server session given as JSON lines on stdin and prints one JSON line per command, so that
// test_window_server_equality.py can hold the C++ WindowServer (the provider nodelet's) equal to the Python one
// (the rospy provider's). First line: {"dir": DIR, "grid_size": S, "max_half_side": M, "window": {n, k,
// update_distance, heading_source, lookahead_time, preset}}; then one command a line: {"pose": {x, y, t, yaw,
// velocity}}, {"search": {x, y, radius, t}}, {"end_search": true}, {"whole": true} or {"whole_map": true}. With
// --defaults it prints the provider nodelet's parameter defaults as {"group/name": value} (test_provider_config holds
// them equal to Python's).
#include <cmath>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>

#include "grid_puzzle_localization/provider/provider_config.hpp"
#include "grid_puzzle_localization/provider/window_server.hpp"

using grid_puzzle_localization::Served;
using grid_puzzle_localization::TileKey;
using grid_puzzle_localization::Window;
using grid_puzzle_localization::WindowServer;
using json = nlohmann::json;

namespace {

json stems(const std::vector<TileKey>& keys, double s) {
  json out = json::array();
  for (const TileKey& k : keys) out.push_back(grid_puzzle_localization::tileStem(k.i, k.j, s));
  return out;
}

json windowJson(const Window& w) {
  const auto b = w.bounds();
  return {{"bounds", {b.i_min, b.i_max, b.j_min, b.j_max}},
          {"sector", w.sector},
          {"theta", std::isfinite(w.theta) ? json(w.theta) : json(nullptr)}};
}

json servedJson(const std::optional<Served>& served, double s) {
  if (!served) return nullptr;
  json out = windowJson(served->window);
  out["first"] = served->first;
  out["changed"] = served->changed;
  out["added"] = stems(served->delta.added, s);
  out["removed"] = stems(served->delta.removed, s);
  out["prefetch"] = stems(served->delta.prefetch, s);
  return out;
}

}  // namespace

json providerDefaults() {
  const grid_puzzle_localization::ProviderConfig c;
  return {{"tiles/dir", c.tiles_dir},
          {"tiles/grid_size", c.tiles_grid_size},
          {"window/n", c.window.n},
          {"window/k", c.window.k},
          {"window/update_distance", c.window.update_distance},
          {"window/heading_source", c.window.heading_source},
          {"window/lookahead_time", c.window.lookahead_time},
          {"window/preset", c.window.preset},
          {"lost/max_half_side", c.lost_max_half_side},
          {"start/search_timeout", c.start_search_timeout},
          {"start/max_area", c.start_max_area},
          {"pose_source", c.pose_source},
          {"publish_map_cloud", c.publish_map_cloud},
          {"map_cloud_period", c.map_cloud_period},
          {"map_frame", c.map_frame},
          {"save_pose_rate", c.save_pose_rate}};
}

int main(int argc, char** argv) {
  if (argc > 1 && std::string(argv[1]) == "--defaults") {
    std::cout << providerDefaults().dump() << '\n';
    return 0;
  }
  std::string line;
  if (!std::getline(std::cin, line)) return 2;
  const json setup = json::parse(line);
  grid_puzzle_localization::WindowConfig config;
  const json& w = setup.at("window");
  config.n = w.at("n");
  config.k = w.at("k");
  config.update_distance = w.at("update_distance");
  config.heading_source = w.at("heading_source");
  config.lookahead_time = w.at("lookahead_time");
  config.preset = w.at("preset");
  WindowServer server(config, setup.at("max_half_side"),
                      grid_puzzle_localization::openTileDirectory(setup.at("dir"), setup.at("grid_size")));
  const double s = server.tiles().directory().grid_size;
  while (std::getline(std::cin, line)) {
    const json cmd = json::parse(line);
    json out;
    if (cmd.contains("pose")) {
      const json& p = cmd["pose"];
      grid_puzzle_localization::PoseSample pose;
      pose.x = p.at("x");
      pose.y = p.at("y");
      pose.t = p.at("t");
      if (!p.at("yaw").is_null()) pose.yaw = p["yaw"].get<double>();
      if (!p.at("velocity").is_null()) pose.velocity = std::array<double, 2>{p["velocity"][0], p["velocity"][1]};
      out = servedJson(server.onPose(pose), s);
    } else if (cmd.contains("search")) {
      const json& r = cmd["search"];
      out = servedJson(server.onSearch({r.at("x"), r.at("y"), r.at("radius"), r.at("t")}), s);
    } else if (cmd.contains("end_search")) {
      server.endSearch();
    } else if (cmd.contains("whole_map")) {
      out = servedJson(server.onWholeMap(), s);
    } else if (cmd.contains("whole")) {
      const auto whole = server.whole();
      if (whole) {
        out = windowJson(whole->first);
        out["added"] = stems(whole->second.added, s);
        out["prefetch"] = stems(whole->second.prefetch, s);
      }
    }
    std::cout << out.dump() << '\n';
  }
  return 0;
}
