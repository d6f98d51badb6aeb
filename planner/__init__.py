"""Static voxel map with dynamic clearing and an MPC planner (closed-loop issue)."""
