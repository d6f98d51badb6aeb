"""Planners and what they plan on: the messages (types), the brake-and-hold fallback every planner
shares (fallback), the map (map), the nominal planner (nominal), its MPC (mpc) and the passive-safety
shield around it (shield)."""
