"""Thin rospy adapters around the pure modules of grid_puzzle_localization."""
