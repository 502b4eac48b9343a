"""Procedural LiDAR scenario simulator (`gpm simulate`): worlds as triangle meshes, smooth trajectories,
LiDAR and IMU models with motion distortion, and a drifted prior map. ROS-free except the bag writer,
which lives in ``grid_puzzle_localization.ros.bags.writer``."""
