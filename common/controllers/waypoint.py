"""The path a local controller follows: straight to the goal, or round the static returns in the way.

Steering straight for a goal behind an obstacle is a local controller's local minimum: it stops
in front of the obstacle, or creeps into a gap too narrow for it (dwa and orca did, in 30–70%
of ``cluttered`` episodes). So, as ROS's local planners follow a global plan, a :class:`Guide`
keeps a grid of the static returns (those the tracker does not take for movers), lowering the
cells each beam passes through on its way to its return (a person's trail goes once beams see
through it), and each step plans an A* path to the goal on it, inflated by the robot's radius
and a clearance (unseen space is free), shortcut by line of sight; it keeps its previous path
while that stays free and not much longer. With nothing in the way the path is the straight
line. A :class:`Path` tells the controllers how far along it a point is (their progress) and
where to aim (a point ahead on it, short of any corner beyond the next).
"""

from __future__ import annotations

import math

import numpy as np

from common.controllers.base import LidarGeometry
from common.occupancy import OccupancyGrid, bounded_resolution, inflate
from common.planners import AStar, shortcut
from common.planners.base import grid_arrays
from common.planners.collision import line_of_sight

HIT = 2  # a return counts for this many passes of a beam through its cell


class Guide:
    """A grid of static returns, lowered along the beams, and a path on it (see the module).

    Args:
        lidar: the beams' geometry.
        radius: the robot's, m: the grid is inflated by it and ``clearance``.
        clearance: how far beyond touching the path keeps from returns where it can, m.
        resolution: cell side, m (0.1: finer than the narrowest gaps worth taking).
        hysteresis: how much longer the previous path may be and still be kept, m (1.0).
    """

    def __init__(self, lidar: LidarGeometry, radius: float, clearance: float, resolution: float = 0.1,
                 hysteresis: float = 1.0) -> None:
        self.lidar, self.radius, self.clearance = lidar, radius, clearance
        self.resolution, self.hysteresis = resolution, hysteresis
        self.planner = AStar()
        self.reset()

    def reset(self) -> None:
        """Forget the map (its extent is set by the next episode's start and goal) and the path."""
        self.evidence: np.ndarray | None = None  # per cell: 0 free, more the surer it is occupied
        self.previous: Path | None = None

    def path(self, ranges: np.ndarray, pose: tuple[float, float, float], static: np.ndarray,
             goal: np.ndarray) -> "Path":
        """Mark this scan (``static``: its returns that stand still) and plan; the straight line to
        the goal when no path is found."""
        position = np.asarray(pose[:2], float)
        if self.evidence is None:  # the box round start and goal, widened by the lidar's range
            margin = self.lidar.spec.range_max
            self.origin = np.minimum(position, goal) - margin
            size = np.abs(goal - position) + 2.0 * margin
            self.cell = bounded_resolution(size[0], size[1], self.resolution)
            self.evidence = np.zeros((int(math.ceil(size[1] / self.cell)), int(math.ceil(size[0] / self.cell))), np.int8)
        self._mark(ranges, pose, static)
        occupied, origin = self.evidence > 0, (float(self.origin[0]), float(self.origin[1]))
        # With the clearance, or where that closes every way (a goal beside an obstacle), without.
        for inflation in (self.radius + self.clearance, self.radius):
            grid = OccupancyGrid(inflate(occupied, inflation, self.cell), origin, self.cell)
            start, end = self._free(grid, position), self._free(grid, goal)
            path = self.planner.plan(grid, start, end) if start is not None and end is not None else None
            if path is not None:
                break
        else:
            self.previous = None
            return Path(np.vstack([position, goal]))
        # The robot passing close by, or the goal beside an obstacle, stand in inflated cells.
        points = [position] * (start is not position) + [shortcut(grid, path)] + [goal] * (end is not goal)
        new = Path(np.vstack(points))
        kept = self._kept(grid, position, new)
        self.previous = new if kept is None else kept
        return new if kept is None else Path(np.vstack([position, kept.points]))

    def _kept(self, grid: OccupancyGrid, position: np.ndarray, new: "Path") -> "Path | None":
        """What is left of the previous path beyond the robot, if it is still free and at most
        ``hysteresis`` longer than ``new``: as the robot turns, the cells at the edge of what it
        sees change, and two routes round an obstacle can take turns as the shorter one."""
        old = self.previous
        if old is None:
            return None
        along, off = old.locate(position[None])
        if off[0] + old.length - along[0] > new.length + self.hysteresis:
            return None
        rest = np.vstack([old.ahead(along, 0.0, 0.0), old.points[old.along > along[0]]])
        # Its ends may lie in inflated cells (the robot or the goal close to a return): check it where it is free.
        free = np.flatnonzero([grid.is_free(*point) for point in rest])
        occupied, x0, y0, resolution = grid_arrays(grid)
        checked = rest[free[0]:free[-1] + 1] if free.size else rest[:0]
        if free.size and all(line_of_sight(occupied, x0, y0, resolution, *a, *b) for a, b in zip(checked[:-1], checked[1:])):
            return Path(rest)
        return None

    def _cells(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of the points that fall on the grid."""
        cells = np.floor((points - self.origin) / self.cell).astype(int)
        rows, cols = self.evidence.shape
        on = (cells[:, 0] >= 0) & (cells[:, 0] < cols) & (cells[:, 1] >= 0) & (cells[:, 1] < rows)
        return cells[on, 1], cells[on, 0]

    def _mark(self, ranges: np.ndarray, pose: tuple[float, float, float], static: np.ndarray) -> None:
        """Lower the cells the beams passed through (short of their returns' cells), then raise the
        returns'. A return counts for ``HIT`` passes: a beam grazing an obstacle's edge does not
        clear it at once, so a thin obstacle's cells do not flicker and the plan with them."""
        x, y, yaw = pose
        mx, my, _ = self.lidar.spec.offset
        c, s = math.cos(yaw), math.sin(yaw)
        origin = np.array([x + c * mx - s * my, y + s * mx + c * my])
        angles = yaw + self.lidar.relative_angles
        steps = np.arange(0.0, self.lidar.spec.range_max, 0.5 * self.cell)
        along = steps[None] < (ranges - self.cell)[:, None]
        points = origin + steps[None, :, None] * np.stack([np.cos(angles), np.sin(angles)], axis=-1)[:, None]
        passed = self._cells(points[along])
        self.evidence[passed] = np.maximum(self.evidence[passed] - 1, 0)
        hit = self._cells(static)
        self.evidence[hit] = np.minimum(self.evidence[hit] + HIT, 2 * HIT)

    @staticmethod
    def _free(grid: OccupancyGrid, point: np.ndarray) -> np.ndarray | None:
        """``point`` if its cell is free, else the centre of the free cell nearest it (None if none is)."""
        if grid.is_free(*point):
            return point
        rows, cols = np.nonzero(~grid.occupied)
        if rows.size == 0:
            return None
        centres = np.asarray(grid.origin) + (np.column_stack([cols, rows]) + 0.5) * grid.resolution
        return centres[int(np.argmin(np.hypot(*(centres - point).T)))]


class Path:
    """A polyline to the goal, and where points stand along it."""

    def __init__(self, points: np.ndarray) -> None:
        self.points = points = np.vstack([points, points[-1:]]) if len(points) == 1 else points  # a point: no length
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
