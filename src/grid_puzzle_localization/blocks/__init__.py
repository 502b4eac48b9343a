"""Block maps: the overlapping map partitions the grid puzzle map is compared against.

- keyframe-stitched block maps (Feng et al., ICRA 2024, Algorithm 1): :mod:`.builder`, :mod:`.rules`;
- fixed-size overlapping submaps cut from a global map (the grid puzzle paper's Fig. 1): :mod:`.fixed_cut`;
- the on-disk block directory both share (numbered PCDs, centroids, index): :mod:`.store`;
- nearest-block selection for the block map server: :mod:`.select`.

No rospy here; the bag reader and the server node live in ``grid_puzzle_localization.ros``.
"""
