"""Plan for the robot's own footprint on a map built from its lidar scans, then follow the plan
with pure pursuit.

The map starts empty (unknown space counts as free), so the first plan is optimistic; each scan
adds returns, and the follower replans when a new return blocks the rest of its path (the
footprint no longer fits along it), every ``replan_every`` steps, or when it has no plan. The
map covers the box around the start and the goal widened by the lidar's range: a robot knows
where it starts and where it must go, not the world's size.

The planners check the footprint itself, heading included (:mod:`common.planners.footprint`): a
rectangle passes a gap its bounding circle would not. A* searches positions and headings and
prefers the middle of gaps; RRT is informed RRT*, whose routes approach the shortest: the first
route a plain RRT's tree happens on changes from replan to replan, and the robot drives back and
forth between them. The plan is then shortcut where a straight line keeps a wider
``open_clearance`` (in the open) and kept as planned where it does not (in the gaps). Pure
pursuit follows it, its lookahead and speed shrinking with the footprint's clearance, so the
robot threads a gap slowly along its middle and drives fast in the open.
"""

from __future__ import annotations

import math

import numpy as np

from common.controllers.base import Controller
from common.controllers.waypoint import Path
from common.kinematics import wrap_angle
from common.occupancy import ScanMapper
from common.planners import PLANNERS, keep_clear, path_length, shortcut
from common.planners.footprint import Footprint, FootprintGrid
from common.readings import Readings
from common.scenario import LidarSpec, RobotProfile


def _nearest(grid: FootprintGrid, x: float, y: float) -> tuple[float, float] | None:
    """The centre of the cell nearest (x, y) where the robot can stand (None if there is none)."""
    rows, cols = np.nonzero(grid.standable)
    if rows.size == 0:
        return None
    cx = grid.origin[0] + (cols + 0.5) * grid.resolution
    cy = grid.origin[1] + (rows + 0.5) * grid.resolution
    best = int(np.argmin(np.hypot(cx - x, cy - y)))
    return float(cx[best]), float(cy[best])


def _merge_straight(path: np.ndarray) -> np.ndarray:
    """The path without the vertices where it runs straight on (a lattice path's cell centres)."""
    if len(path) < 3:
        return path
    edges = np.diff(path, axis=0)
    turns = np.abs(edges[:-1, 0] * edges[1:, 1] - edges[:-1, 1] * edges[1:, 0]) > 1e-9
    return np.vstack([path[:1], path[1:-1][turns], path[-1:]])


class PathFollower(Controller):
    """A planner (``astar`` or ``rrt``) for the robot's footprint on a scan-built grid, smoothed,
    driven by pure pursuit (see the module).

    The planner is the class's ``default_planner`` (``astar`` or ``rrt``); the registry holds one
    subclass per planner.

    Args:
        lookahead: pure-pursuit lookahead distance in the open, m (0.5).
        k_angular: turn gain when the lookahead point is far off the heading (2.0).
        resolution: map resolution, m (0.05: fine enough to find the middle of a gap 1.2 robot widths across).
        clearance: how far every planned pose keeps the footprint from the returns, m (0.02).
        open_clearance: the clearance a shortcut must keep, and within which the robot slows, m (0.3).
        replan_every: steps between routine replans (20).
        smooth: shortcut the planned path (True).
        turn_in_place: heading error beyond which the robot turns on the spot, rad (pi/4).
        stop_distance: within this many metres of the goal (by odometry), stand still; None (default):
            half the scenario's goal threshold, so the robot drives into any goal radius.
        seed: RRT's sampling seed (0).
    """

    default_planner = "astar"
    keeps_clear = False  # move the smoothed path up the clearance (a sampled path hugs what it passed)
    # The slowest it threads a gap (m/s; 3 cm a step at 10 Hz), and how fast it may close on the
    # goal (1/s: at 0.1 m from it the robot drives 0.2 m/s).
    SLOWEST = 0.3
    GOAL_GAIN = 2.0
    HYSTERESIS = 0.5  # m: how much shorter a routine replan's path must be to replace the current one

    def __init__(self, lookahead: float = 0.5, k_angular: float = 2.0, resolution: float = 0.05,
                 clearance: float = 0.02, open_clearance: float = 0.3, replan_every: int = 20, smooth: bool = True,
                 turn_in_place: float = math.pi / 4, stop_distance: float | None = None, seed: int = 0) -> None:
        self.name = f"{self.default_planner}_pursuit"
        self.seed = seed
        self.lookahead, self.k_angular = lookahead, k_angular
        self.resolution, self.clearance, self.open_clearance = resolution, clearance, open_clearance
        self.replan_every, self.smooth, self.turn_in_place = replan_every, smooth, turn_in_place
        self.stop_distance = stop_distance

    def bind(self, robot: RobotProfile, lidar: LidarSpec, goal_threshold: float = 0.3) -> None:
        super().bind(robot, lidar, goal_threshold)
        self.range_max = lidar.range_max
        self.footprint = Footprint.of(robot)

    def reset(self) -> None:
        planner = PLANNERS[self.default_planner]
        self.planner = planner(seed=self.seed, optimise=True) if self.default_planner == "rrt" else planner()
        self.mapper: ScanMapper | None = None
        self._grid: FootprintGrid | None = None
        self._stale = False
        self._turning = 0.0  # the way it turns on the spot: +1 left, -1 right, 0 not turning
        self.path: np.ndarray | None = None
        self.target = 0
        self.since_plan = 0
        self.plans = 0

    @property
    def grid(self) -> FootprintGrid:
        """The footprint's view of the map, rebuilt if returns came since (a distance transform of
        the whole map: the planner and the check of a threatened path need it, the speed does not)."""
        if self._grid is None or self._stale:
            self._grid, self._stale = FootprintGrid(self.mapper.grid, self.footprint, self.clearance), False
        return self._grid

    def _make_mapper(self, x: float, y: float, goal: tuple[float, float]) -> ScanMapper:
        margin = self.range_max
        x0, y0 = min(x, goal[0]) - margin, min(y, goal[1]) - margin
        width, height = abs(goal[0] - x) + 2 * margin, abs(goal[1] - y) + 2 * margin
        return ScanMapper((x0, y0, width, height), self.resolution)

    def _add_scan(self, ranges: np.ndarray, pose: tuple[float, float, float]) -> np.ndarray:
        """Mark the scan's returns; the world points of those that fell in cells no return had marked."""
        points = self.lidar.returns_world_frame(np.asarray(ranges, dtype=float), pose)
        rows, cols, keep = self.mapper.cells_of(points)
        new = points[keep & ~self.mapper.observed[rows, cols]]
        if len(new):
            self.mapper.add_points(new)
            self._stale = True
        return new

    def _blocked(self, new: np.ndarray, x: float, y: float) -> bool:
        """Whether new returns leave no room for the footprint along the rest of the path."""
        ahead = np.vstack([(x, y), self.path[self.target + 1:]])
        reach = self.robot.bounding_radius + self.clearance + self.resolution
        if Path(ahead).locate(new)[1].min() > reach:
            return False  # every new return lies beyond the footprint's reach of the path
        return not self.grid.path_free(ahead[1:], None) or not self.grid.segment_free(ahead[0], ahead[1])

    def _plan(self, x: float, y: float, yaw: float, goal: tuple[float, float], keep: bool = False) -> None:
        """Plan afresh; with ``keep`` (a routine replan, the path still free) the rest of the
        current path stays unless the new one is shorter by ``HYSTERESIS``: an RRT draws another
        route every time, and the robot would turn from one to the next."""
        grid = self.grid
        start = (x, y, yaw) if grid.is_free(x, y) else _nearest(grid, x, y)
        end = goal if grid.is_free(*goal) else _nearest(grid, *goal)
        path = self.planner.plan(grid, start, end) if start and end else None
        if path is not None and self.smooth:
            path = shortcut(grid.with_margin(self.open_clearance), _merge_straight(path),
                            start[2] if len(start) > 2 else None)
            if self.keeps_clear:
                path = keep_clear(grid, path, self.open_clearance)
        self.since_plan = 0
        self.plans += 1
        if keep and self.path is not None:
            rest = path_length(np.vstack([(x, y), self.path[self.target + 1:]]))
            if path is None or path_length(path) > rest - self.HYSTERESIS:
                return
        self.path, self.target = path, 0

    def act(self, readings: Readings, goal: tuple[float, float]) -> tuple[float, float]:
        x, y, yaw = readings.odometry.pose
        distance = math.hypot(goal[0] - x, goal[1] - y)
        if self.arrived(distance, self.stop_distance):
            return 0.0, 0.0
        if self.mapper is None:
            self.mapper = self._make_mapper(x, y, goal)
        new = self._add_scan(readings.lidar, (x, y, yaw))
        self.since_plan += 1
        if self.path is None or (len(new) and self._blocked(new, x, y)):
            self._plan(x, y, yaw, goal)
        elif self.since_plan >= self.replan_every:
            self._plan(x, y, yaw, goal, keep=True)
        if self.path is None:
            return self.clip(0.0, self.k_angular * wrap_angle(math.atan2(goal[1] - y, goal[0] - x) - yaw))
        # Tight: a short lookahead keeps the robot on the path's middle, and it slows to thread the gap
        # (measured on the map as last planned or checked: a return seen since is at least a step away).
        room = min(max(self._grid.clearance(x, y, yaw) - self.clearance, 0.0) / self.open_clearance, 1.0)
        tx, ty = self._lookahead_point(x, y, max(0.3 * self.lookahead, room * self.lookahead))
        alpha = wrap_angle(math.atan2(ty - y, tx - x) - yaw)
        if abs(alpha) > self.turn_in_place:
            # Forward-only: face the path before driving, and keep turning the way the turn began
            # while the path lies behind: a point behind flips from one side to the other as the
            # lookahead shortens and lengthens, and the robot would rock on the spot.
            if self._turning and abs(alpha) > 0.5 * math.pi:
                alpha = math.copysign(abs(alpha), self._turning)
            self._turning = math.copysign(1.0, alpha)
            return self.clip(0.0, self.k_angular * alpha)
        self._turning = 0.0
        # Pure pursuit: the arc through the lookahead point has curvature 2 sin(alpha) / L. Slow down
        # until w_max can hold that arc, or the robot swings wide of the path at full speed.
        curvature = 2.0 * math.sin(alpha) / max(math.hypot(tx - x, ty - y), 1e-6)
        v = min(self.robot.v_max * math.cos(alpha), self.robot.w_max / max(abs(curvature), 1e-6),
                max(self.SLOWEST, room * self.robot.v_max), self.GOAL_GAIN * distance)
        return self.clip(v, v * curvature)

    def _lookahead_point(self, x: float, y: float, lookahead: float) -> tuple[float, float]:
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
        remaining, point = lookahead, best_point
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
    """A* over positions and headings for the footprint on the scan-built grid, followed by pure pursuit."""

    default_planner = "astar"


class RrtPursuit(PathFollower):
    """Informed RRT* for the footprint on the scan-built grid, its path kept clear of what it passes, followed by
    pure pursuit."""

    default_planner = "rrt"
    keeps_clear = True  # A*'s costs already keep its path to the middle of gaps
