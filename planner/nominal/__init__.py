"""The nominal planner: a global path and cost-to-go on the map, a maneuver chosen among sampled motions,
the MPC refining it, and the camera heading (navigator.MPCPlanner)."""
