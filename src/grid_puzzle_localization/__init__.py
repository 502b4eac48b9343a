"""Grid puzzle map localization: ROS-free Python core (PCD I/O, tiling, window maths, tile store,
simulation, monitoring, evaluation). rospy is imported only in the ``ros`` subpackage."""
