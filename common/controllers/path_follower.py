"""Plan on a map built from the robot's own lidar scans, then follow the plan with pure pursuit.

The map starts empty (unknown space counts as free), so the first plan is optimistic; each scan
adds returns, and the follower replans when a new return blocks the rest of its path, every
``replan_every`` steps, or when it has no plan. The map covers the box around the start and the
goal widened by the lidar's range: a robot knows where it starts and where it must go, not the
world's size.
"""

from __future__ import annotations

import math

import numpy as np

from common.controllers.base import Controller
from common.kinematics import wrap_angle
from common.occupancy import OccupancyGrid, ScanMapper
from common.planners import PLANNERS, shortcut
from common.planners.base import grid_arrays
from common.planners.collision import line_of_sight
from common.readings import Readings
from common.scenario import LidarSpec, RobotProfile


def _nearest_free(grid: OccupancyGrid, x: float, y: float) -> tuple[float, float] | None:
    """The centre of the free cell nearest to (x, y) (the robot's own cell may be inflated away)."""
    rows, cols = np.nonzero(~grid.occupied)
    if rows.size == 0:
        return None
    cx = grid.origin[0] + (cols + 0.5) * grid.resolution
    cy = grid.origin[1] + (rows + 0.5) * grid.resolution
    best = int(np.argmin(np.hypot(cx - x, cy - y)))
    return float(cx[best]), float(cy[best])


class PathFollower(Controller):
    """A planner (``astar`` or ``rrt``) on a scan-built grid, smoothed, driven by pure pursuit.

    The planner is the class's ``default_planner`` (``astar`` or ``rrt``); the registry holds one
    subclass per planner.

    Args:
        lookahead: pure-pursuit lookahead distance, m (0.5).
        k_angular: turn gain when the lookahead point is far off the heading (2.0).
        resolution: map resolution, m (0.2, as in the 3D tutorial).
        clearance: extra inflation beyond the robot's radius, m (0.1): map cells are coarse.
        replan_every: steps between routine replans (20).
        smooth: shortcut the planned path by line of sight (True).
        turn_in_place: heading error beyond which the robot turns on the spot, rad (pi/4).
        stop_distance: within this many metres of the goal (by odometry), stand still; None (default):
            half the scenario's goal threshold, so the robot drives into any goal radius.
        seed: RRT's sampling seed (0).
    """

    default_planner = "astar"

    def __init__(self, lookahead: float = 0.5, k_angular: float = 2.0, resolution: float = 0.2,
                 clearance: float = 0.1, replan_every: int = 20, smooth: bool = True,
                 turn_in_place: float = math.pi / 4, stop_distance: float | None = None, seed: int = 0) -> None:
        self.name = f"{self.default_planner}_pursuit"
        self.seed = seed
        self.lookahead, self.k_angular = lookahead, k_angular
        self.resolution, self.clearance = resolution, clearance
        self.replan_every, self.smooth, self.turn_in_place = replan_every, smooth, turn_in_place
        self.stop_distance = stop_distance

    def bind(self, robot: RobotProfile, lidar: LidarSpec, goal_threshold: float = 0.3) -> None:
        super().bind(robot, lidar, goal_threshold)
        self.range_max = lidar.range_max

    def reset(self) -> None:
        planner = PLANNERS[self.default_planner]
        self.planner = planner(seed=self.seed) if self.default_planner == "rrt" else planner()
        self.mapper: ScanMapper | None = None
        self.path: np.ndarray | None = None
        self.target = 0
        self.since_plan = 0
        self.plans = 0

    def _make_mapper(self, x: float, y: float, goal: tuple[float, float]) -> ScanMapper:
        margin = self.range_max
        x0, y0 = min(x, goal[0]) - margin, min(y, goal[1]) - margin
        width, height = abs(goal[0] - x) + 2 * margin, abs(goal[1] - y) + 2 * margin
        return ScanMapper((x0, y0, width, height), self.resolution, self.robot.bounding_radius + self.clearance)

    def _blocked(self, grid: OccupancyGrid, x: float, y: float) -> bool:
        """Whether the path ahead (from the robot on) crosses an occupied cell."""
        occupied, gx0, gy0, res = grid_arrays(grid)
        points = [(x, y), *map(tuple, self.path[self.target:])]
        return any(not line_of_sight(occupied, gx0, gy0, res, a[0], a[1], b[0], b[1])
                   for a, b in zip(points[1:-1], points[2:]))

    def _plan(self, grid: OccupancyGrid, x: float, y: float, goal: tuple[float, float]) -> None:
        start = (x, y) if grid.is_free(x, y) else _nearest_free(grid, x, y)
        end = goal if grid.is_free(*goal) else _nearest_free(grid, *goal)
        path = self.planner.plan(grid, start, end) if start and end else None
        if path is not None and self.smooth:
            path = shortcut(grid, path)
        self.path, self.target, self.since_plan = path, 0, 0
        self.plans += 1

    def act(self, readings: Readings, goal: tuple[float, float]) -> tuple[float, float]:
        x, y, yaw = readings.odometry.pose
        if self.arrived(math.hypot(goal[0] - x, goal[1] - y), self.stop_distance):
            return 0.0, 0.0
        if self.mapper is None:
            self.mapper = self._make_mapper(x, y, goal)
        new = self.mapper.add_scan(self.lidar, readings.lidar, (x, y, yaw))
        grid = self.mapper.grid
        self.since_plan += 1
        if self.path is None or self.since_plan >= self.replan_every or (new and self._blocked(grid, x, y)):
            self._plan(grid, x, y, goal)
        if self.path is None:
            return self.clip(0.0, self.k_angular * wrap_angle(math.atan2(goal[1] - y, goal[0] - x) - yaw))
        tx, ty = self._lookahead_point(x, y)
        alpha = wrap_angle(math.atan2(ty - y, tx - x) - yaw)
        if abs(alpha) > self.turn_in_place:
            return self.clip(0.0, self.k_angular * alpha)  # forward-only: face the path before driving
        # Pure pursuit: the arc through the lookahead point has curvature 2 sin(alpha) / L. Slow down
        # until w_max can hold that arc, or the robot swings wide of the path at full speed.
        curvature = 2.0 * math.sin(alpha) / max(math.hypot(tx - x, ty - y), 1e-6)
        v = min(self.robot.v_max * math.cos(alpha), self.robot.w_max / max(abs(curvature), 1e-6))
        return self.clip(v, v * curvature)

    def _lookahead_point(self, x: float, y: float) -> tuple[float, float]:
        """The point ``lookahead`` metres along the path beyond the robot's projection onto it."""
        path = self.path
        if len(path) == 1:
            return float(path[0, 0]), float(path[0, 1])
        # The nearest segment from the current one on (progress along the path never goes back).
        best, best_d, best_point = self.target, math.inf, path[self.target]
        for i in range(self.target, len(path) - 1):
            a, b = path[i], path[i + 1]
            ab = b - a
            t = min(max(float(np.dot((x, y) - a, ab) / max(np.dot(ab, ab), 1e-12)), 0.0), 1.0)
            point = a + t * ab
            d = math.hypot(point[0] - x, point[1] - y)
            if d < best_d:
                best, best_d, best_point = i, d, point
        self.target = best
        remaining, point = self.lookahead, best_point
        for i in range(best, len(path) - 1):
            end = path[i + 1]
            step = math.hypot(end[0] - point[0], end[1] - point[1])
            if step >= remaining:
                point = point + (end - point) * (remaining / step)
                return float(point[0]), float(point[1])
            remaining -= step
            point = end
        return float(path[-1, 0]), float(path[-1, 1])


class AStarPursuit(PathFollower):
    """A* on the scan-built grid, followed by pure pursuit."""

    default_planner = "astar"


class RrtPursuit(PathFollower):
    """RRT on the scan-built grid, followed by pure pursuit."""

    default_planner = "rrt"
