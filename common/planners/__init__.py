"""Grid planners (A*, RRT) on occupancy grids from lidar scans or from a scenario."""
