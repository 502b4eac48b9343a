// Standalone NDT localizer: the same nodelet, loaded in-process through nodelet::Loader so node and
// nodelet can never differ. Remappings and private parameters apply as for any node.
#include <nodelet/loader.h>
#include <ros/ros.h>
#if defined(__GLIBC__)
#include <malloc.h>
#endif

int main(int argc, char** argv) {
#if defined(__GLIBC__)
  // One malloc arena for the whole process, before any thread starts (docs/localizer.md, "Memory").
  mallopt(M_ARENA_MAX, 1);
#endif
  ros::init(argc, argv, "ndt_localizer");
  nodelet::Loader loader;
  nodelet::M_string remappings(ros::names::getRemappings());
  nodelet::V_string my_argv(argv + 1, argv + argc);
  if (!loader.load(ros::this_node::getName(), "grid_puzzle_localization/NdtLocalizerNodelet", remappings, my_argv)) {
    ROS_FATAL(
        "%s: could not load grid_puzzle_localization/NdtLocalizerNodelet; is AMENT_PREFIX_PATH set "
        "(source devel/setup.bash)?",
        ros::this_node::getName().c_str());
    return 1;
  }
  ros::spin();
  return 0;
}
