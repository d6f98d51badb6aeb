"""What the planners know of the static world: the voxel map (voxel_map), distance transforms on its
column grid (distance), and where the camera has seen the floor free (visibility)."""
