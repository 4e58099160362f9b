"""Grid planners (A*, RRT) on occupancy grids from lidar scans or from a scenario.

Every planner is a class built with its parameters whose ``plan(grid, start, goal)`` returns world
points (N, 2) or None; :data:`PLANNERS` maps names to those classes.
"""

from common.planners.astar import AStar
from common.planners.base import Planner, path_length
from common.planners.rrt import RRT
from common.planners.smoothing import keep_clear, shortcut

PLANNERS: dict[str, type] = {"astar": AStar, "rrt": RRT}

__all__ = ["AStar", "PLANNERS", "Planner", "RRT", "keep_clear", "path_length", "shortcut"]
