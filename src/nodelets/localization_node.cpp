// The localization stack as one process: a nodelet manager that loads the NDT localizer nodelet and, with
// --provider, the grid puzzle tile provider nodelet itself, in-process through nodelet::Loader, so no
// `nodelet load` process waits beside it. launch/localization.launch starts it as `localizer_manager`:
//   localization_node [--localizer NAME] [--provider NAME]
// NAME is a nodelet's node name, relative to the process's namespace (defaults: ndt_localizer, no provider). Each
// nodelet keeps its own private namespace (/ns/NAME/..., parameters and ~status as with `nodelet load`); the
// process's remappings apply to both. The process keeps the nodelet manager's services (~load_nodelet,
// ~unload_nodelet, ~list), so more nodelets can still be loaded into it.
#include <nodelet/loader.h>
#include <ros/ros.h>
#include <rosgraph_msgs/Log.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>
#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace {

constexpr const char* kLocalizerType = "grid_puzzle_localization/NdtLocalizerNodelet";
constexpr const char* kProviderType = "grid_puzzle_localization/GridPuzzleProviderNodelet";

struct Options {
  std::string localizer = "ndt_localizer";
  std::string provider;  // empty: no provider nodelet
  bool ok = true;
};

Options parseOptions(const std::vector<std::string>& args) {
  Options opts;
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& arg = args[i];
    if ((arg == "--localizer" || arg == "--provider") && i + 1 < args.size()) {
      (arg == "--localizer" ? opts.localizer : opts.provider) = args[++i];
    } else {
      ROS_FATAL("localization_node: unknown argument '%s' (use [--localizer NAME] [--provider NAME])", arg.c_str());
      opts.ok = false;
    }
  }
  return opts;
}

// Subscribers the master lists for /rosout, other than this process.
int rosoutSubscribers() {
  XmlRpc::XmlRpcValue args, result, payload;
  args[0] = ros::this_node::getName();
  if (!ros::master::execute("getSystemState", args, result, payload, false)) return 0;
  XmlRpc::XmlRpcValue& subscribed = payload[1];
  for (int i = 0; i < subscribed.size(); ++i) {
    if (static_cast<std::string>(subscribed[i][0]) != "/rosout") continue;
    int n = 0;
    for (int k = 0; k < subscribed[i][1].size(); ++k)
      if (static_cast<std::string>(subscribed[i][1][k]) != ros::this_node::getName()) ++n;
    return n;
  }
  return 0;
}

// What the nodelets log as they start (where a respawned localizer resumes its search, say) goes out on /rosout, and
// roscpp drops what it publishes there before a subscriber has connected. `nodelet manager` gets its nodelets seconds
// after it starts (from the `nodelet load` processes); this process loads them at once, so it first waits, at most
// kRosoutWait, until every subscriber the master lists for /rosout (rosout itself, rqt_console, a test) is connected.
constexpr double kRosoutWait = 3.0;  // [s] wall clock

void waitForRosoutSubscribers(ros::NodeHandle& nh) {
  // The same publication as roscpp's own /rosout appender: its subscriber count is theirs.
  const ros::Publisher rosout = nh.advertise<rosgraph_msgs::Log>("/rosout", 0);
  const ros::WallTime until = ros::WallTime::now() + ros::WallDuration(kRosoutWait);
  while (ros::ok() && ros::WallTime::now() < until) {
    if (static_cast<int>(rosout.getNumSubscribers()) >= std::max(1, rosoutSubscribers())) return;
    ros::WallDuration(0.02).sleep();
  }
}

bool loadNodelet(nodelet::Loader& loader, const std::string& name, const std::string& type) {
  const std::string resolved = ros::names::resolve(name, false);  // in the process's namespace, not remapped
  const nodelet::M_string remappings(ros::names::getRemappings());
  if (loader.load(resolved, type, remappings, nodelet::V_string())) {
    ROS_INFO("%s: loaded %s as %s", ros::this_node::getName().c_str(), type.c_str(), resolved.c_str());
    return true;
  }
  ROS_FATAL("%s: could not load %s as %s; is AMENT_PREFIX_PATH set (source devel/setup.bash)?",
            ros::this_node::getName().c_str(), type.c_str(), resolved.c_str());
  return false;
}

}  // namespace

int main(int argc, char** argv) {
#if defined(__GLIBC__)
  // One malloc arena for the whole process, before any thread starts (docs/localizer.md, "Memory"), unless the
  // environment chose (the launch files' malloc_arenas sets glibc.malloc.arena_max through GLIBC_TUNABLES).
  const char* tunables = std::getenv("GLIBC_TUNABLES");
  if (tunables == nullptr || std::strstr(tunables, "arena_max") == nullptr) {
    mallopt(M_ARENA_MAX, 1);
  }
#endif
  ros::init(argc, argv, "localizer_manager");
  std::vector<std::string> args;
  ros::removeROSArgs(argc, argv, args);
  const Options opts = parseOptions(std::vector<std::string>(args.begin() + 1, args.end()));
  if (!opts.ok) {
    return 2;
  }
  ros::NodeHandle nh;
  waitForRosoutSubscribers(nh);
  nodelet::Loader loader;  // with the manager's services, as `nodelet manager`
  // The provider first: once the localizer subscribes to points, both are up.
  if (!opts.provider.empty() && !loadNodelet(loader, opts.provider, kProviderType)) {
    return 1;
  }
  if (!loadNodelet(loader, opts.localizer, kLocalizerType)) {
    return 1;
  }
  ros::spin();
  return 0;
}
