"""`gpm experiment`: runs the localizer on a bag in each map mode (experiment.modes), monitors
CPU and memory, records the trajectories, and writes the evaluation report. ROS tools (roscore,
roslaunch, rosbag) are driven as child processes; no rospy in this process."""
