"""Where a local controller steers for: the goal, or, with static returns in the way, a path's corner.

Steering straight for a goal behind an obstacle is a local controller's local minimum: it stops
in front of the obstacle, or creeps into a gap too narrow for it. So a :class:`Guide` keeps a grid
of the static returns (those the tracker does not take for movers), clearing the cells each beam
passes through on its way to its return (a mover's trail, or a thin obstacle's return that was
misplaced, goes as soon as a beam sees through it), and each step plans an A* path to the goal on
it, inflated by the robot's radius and a clearance (unseen space is free), shortcut by line of
sight. The target is the path's first corner at least ``reach`` away: a point in sight that the
robot can drive straight at. With nothing in the way the path is the straight line and the target
the goal itself.
"""

from __future__ import annotations

import math

import numpy as np

from common.controllers.base import LidarGeometry
from common.occupancy import OccupancyGrid, bounded_resolution, inflate
from common.planners import AStar, shortcut


class Guide:
    """A grid of static returns with free space cleared along the beams, and the corner to steer for.

    Args:
        lidar: the beams' geometry.
        inflation: the grid's inflation, m: the robot's radius and a clearance.
        resolution: cell side, m (0.1: finer than the narrowest gaps worth taking).
    """

    def __init__(self, lidar: LidarGeometry, inflation: float, resolution: float = 0.1) -> None:
        self.lidar, self.inflation, self.resolution = lidar, inflation, resolution
        self.planner = AStar()
        self.reset()

    def reset(self) -> None:
        """Forget the map (its extent is set by the next episode's start and goal)."""
        self.occupied: np.ndarray | None = None

    def path(self, ranges: np.ndarray, pose: tuple[float, float, float], static: np.ndarray,
             goal: np.ndarray) -> "Path":
        """Mark this scan (``static``: its returns that stand still) and plan; the straight line to
        the goal when no path is found."""
        position = np.asarray(pose[:2], float)
        if self.occupied is None:  # the box round start and goal, widened by the lidar's range
            margin = self.lidar.spec.range_max
            self.origin = np.minimum(position, goal) - margin
            size = np.abs(goal - position) + 2.0 * margin
            self.cell = bounded_resolution(size[0], size[1], self.resolution)
            self.occupied = np.zeros((int(math.ceil(size[1] / self.cell)), int(math.ceil(size[0] / self.cell))), bool)
        self._mark(ranges, pose, static)
        grid = OccupancyGrid(inflate(self.occupied, self.inflation, self.cell), (float(self.origin[0]), float(self.origin[1])),
                             self.cell)
        start = position if grid.is_free(*position) else self._nearest_free(grid, position)
        path = self.planner.plan(grid, start, goal) if start is not None else None
        return Path(np.vstack([position, goal]) if path is None else shortcut(grid, path))

    def _cells(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of the points that fall on the grid."""
        cells = np.floor((points - self.origin) / self.cell).astype(int)
        rows, cols = self.occupied.shape
        on = (cells[:, 0] >= 0) & (cells[:, 0] < cols) & (cells[:, 1] >= 0) & (cells[:, 1] < rows)
        return cells[on, 1], cells[on, 0]

    def _mark(self, ranges: np.ndarray, pose: tuple[float, float, float], static: np.ndarray) -> None:
        """Clear the cells the beams passed through (short of their returns' cells), then mark the returns."""
        x, y, yaw = pose
        mx, my, _ = self.lidar.spec.offset
        c, s = math.cos(yaw), math.sin(yaw)
        origin = np.array([x + c * mx - s * my, y + s * mx + c * my])
        angles = yaw + self.lidar.relative_angles
        steps = np.arange(0.0, self.lidar.spec.range_max, 0.5 * self.cell)
        along = steps[None] < (ranges - self.cell)[:, None]
        points = origin + steps[None, :, None] * np.stack([np.cos(angles), np.sin(angles)], axis=-1)[:, None]
        self.occupied[self._cells(points[along])] = False
        self.occupied[self._cells(static)] = True

    @staticmethod
    def _nearest_free(grid: OccupancyGrid, position: np.ndarray) -> np.ndarray | None:
        """The centre of the free cell nearest ``position`` (the robot passing close by stands in an inflated one)."""
        rows, cols = np.nonzero(~grid.occupied)
        if rows.size == 0:
            return None
        centres = np.asarray(grid.origin) + (np.column_stack([cols, rows]) + 0.5) * grid.resolution
        return centres[int(np.argmin(np.hypot(*(centres - position).T)))]


class Path:
    """A polyline to the goal, and where points stand along it."""

    def __init__(self, points: np.ndarray) -> None:
        self.points = points
        self.starts, self.edges = points[:-1], np.diff(points, axis=0)
        self.lengths = np.hypot(*self.edges.T)
        self.along = np.r_[0.0, np.cumsum(self.lengths)]  # arc length at each vertex

    def locate(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For points (M, 2): (arc length of each one's projection onto the path, its distance from the path)."""
        offsets = points[:, None] - self.starts[None]
        t = np.clip(np.einsum("mkj,kj->mk", offsets, self.edges) / np.maximum(self.lengths**2, 1e-12), 0.0, 1.0)
        gaps = np.hypot(*(offsets - t[..., None] * self.edges[None]).transpose(2, 0, 1))
        nearest = gaps.argmin(axis=1)
        rows = np.arange(len(points))
        return self.along[nearest] + t[rows, nearest] * self.lengths[nearest], gaps[rows, nearest]

    def ahead(self, s: np.ndarray, lookahead: float, reach: float = 0.3) -> np.ndarray:
        """Points (M, 2) ``lookahead`` beyond arc lengths ``s`` (M,), but not past the first corner
        more than ``reach`` ahead: the corner is in sight, what lies beyond it may not be."""
        corner = self.along[np.minimum(np.searchsorted(self.along, s + reach, side="right"), len(self.along) - 1)]
        ahead = np.minimum(s + lookahead, corner)
        return np.column_stack([np.interp(ahead, self.along, self.points[:, 0]),
                                np.interp(ahead, self.along, self.points[:, 1])])

    @property
    def length(self) -> float:
        return float(self.along[-1])
