"""Occupancy grids: obstacles rasterised at a resolution and inflated by the robot's footprint.

The ground-truth grid of a scenario decides reachability (the generators' guarantee) and, later,
the planners' shortest paths for SPL.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

import numpy as np
from scipy import ndimage

from common.geometry import box_distance, circle_distance, segment_distance
from common.grid_maps import occupied_boxes
from common.kernel_cache import kernel, uncounted
from common.placement import BOX, CIRCLE, shape_bounds
from common.scenario import BoxObstacle, CircleObstacle, PolygonObstacle, Scenario, WorldSpec

if TYPE_CHECKING:  # a runtime import would tie the grid module to the controllers package
    from common.controllers.base import LidarGeometry


@uncounted
def clamped_cell(x: float, y: float, x0: float, y0: float, resolution: float, rows: int,
                 cols: int) -> tuple[int, int]:
    """The (row, col) of the cell containing (x, y) in a grid of ``rows`` x ``cols`` cells of
    ``resolution`` whose corner is (x0, y0), clamped to the grid (compiled code calls it too)."""
    return int(min(max((y - y0) / resolution, 0), rows - 1)), int(min(max((x - x0) / resolution, 0), cols - 1))


@dataclass(frozen=True)
class OccupancyGrid:
    """Boolean grid ``occupied[row, col]``; cell (r, c) has centre ``origin + (c + 0.5, r + 0.5) * resolution``."""

    occupied: np.ndarray
    origin: tuple[float, float]
    resolution: float

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        """The (row, col) of the cell containing world point (x, y), clamped to the grid."""
        rows, cols = self.occupied.shape
        return clamped_cell(x, y, self.origin[0], self.origin[1], self.resolution, rows, cols)

    def centre_of(self, row: int, col: int) -> tuple[float, float]:
        """World coordinates of a cell's centre."""
        return (
            self.origin[0] + (col + 0.5) * self.resolution,
            self.origin[1] + (row + 0.5) * self.resolution,
        )

    def inside(self, x: float, y: float) -> bool:
        """Whether world point (x, y) lies on the grid (``cell_of`` clamps, so check this first)."""
        rows, cols = self.occupied.shape
        u = (x - self.origin[0]) / self.resolution
        v = (y - self.origin[1]) / self.resolution
        return 0.0 <= u < cols and 0.0 <= v < rows

    def is_free(self, x: float, y: float) -> bool:
        """Whether (x, y) lies on the grid in a free cell."""
        return self.inside(x, y) and not self.occupied[self.cell_of(x, y)]

    def free_component(self, x: float, y: float) -> np.ndarray:
        """Mask of the free cells 8-connected to the cell of (x, y); all False if that cell is occupied."""
        labels, _ = ndimage.label(~self.occupied, structure=np.ones((3, 3), dtype=bool))
        label = labels[self.cell_of(x, y)]
        return labels == label if label else np.zeros_like(self.occupied)


MAX_CELLS = 4_000_000  # a grid's cells at most: 2,000 x 2,000, about 40 MB for an A* search's arrays


def bounded_resolution(width: float, height: float, resolution: float) -> float:
    """``resolution``, coarsened where a world is so large that its grid would pass :data:`MAX_CELLS`
    (a 1 km world is planned at 0.5 m): what a grid costs is bounded by the world's meaning."""
    return max(resolution, math.sqrt(width * height / MAX_CELLS))


def scenario_grid(scenario: Scenario, resolution: float = 0.2, inflation: float | None = None) -> OccupancyGrid:
    """The ground-truth grid of a scenario: a cell is occupied when its centre lies within
    ``inflation`` (default: the robot's bounding radius) of a static obstacle or of a boundary wall."""
    inflation = scenario.robot.bounding_radius if inflation is None else inflation
    # Circles and boxes, nearly every obstacle there is, are rasterised compiled; the rest here.
    kinds, params, others = [], [], []
    for obstacle in scenario.static_obstacles:  # movers are where they start only at the start
        if obstacle.unobstructed:
            continue
        if isinstance(obstacle, CircleObstacle):
            kinds.append(CIRCLE)
            params.append((obstacle.x, obstacle.y, obstacle.radius, 0.0, 0.0))
        elif isinstance(obstacle, BoxObstacle):
            kinds.append(BOX)
            params.append((obstacle.x, obstacle.y, obstacle.length, obstacle.width, obstacle.yaw))
        else:
            others.append(obstacle)
    if scenario.grid_map is not None:
        world = scenario.world
        for x, y, width, height in occupied_boxes(scenario.grid_map, world.width, world.height, world.offset):
            kinds.append(BOX)
            params.append((x, y, width, height, 0.0))
    grid = shapes_grid(scenario.world, np.array(kinds, dtype=np.int64), np.array(params, dtype=float).reshape(-1, 5),
                       resolution, inflation)
    for obstacle in others:
        closed = isinstance(obstacle, PolygonObstacle)
        ring = np.asarray(obstacle.vertices if closed else obstacle.points, dtype=float)
        _rasterise_line(grid.occupied, ring, closed, *grid.origin, grid.resolution, inflation)
    return grid


def shapes_grid(world: WorldSpec, kinds: np.ndarray, params: np.ndarray, resolution: float,
                inflation: float) -> OccupancyGrid:
    """The grid of circles and boxes given as kinds and parameters (see :mod:`common.placement`)
    in ``world``, with its boundary walls if it has them, inflated as :func:`scenario_grid` does
    (at :func:`bounded_resolution`)."""
    resolution = bounded_resolution(world.width, world.height, resolution)
    cols = max(1, int(round(world.width / resolution)))
    rows = max(1, int(round(world.height / resolution)))
    occupied = np.zeros((rows, cols), dtype=bool)
    x0, y0 = world.offset
    _rasterise(occupied, kinds, params, x0, y0, resolution, inflation)
    if world.walls:
        _mark_walls(occupied, x0, y0, world.width, world.height, resolution, inflation)
    return OccupancyGrid(occupied=occupied, origin=(x0, y0), resolution=resolution)


@kernel
def _rasterise_line(occupied: np.ndarray, points: np.ndarray, closed: bool, x0: float, y0: float, resolution: float,
                    inflation: float) -> None:
    """Mark the cells whose centres lie inside a closed ring (even-odd, a scanline per row) or within
    ``inflation`` of one of its edges (each edge's own neighbourhood): the cells where the ring's
    signed distance is below ``inflation``, in time linear in the cells and edges, not their product."""
    rows, cols = occupied.shape
    n = len(points)
    if closed:
        crossings = np.empty(n)
        low = max(0, math.floor((points[:, 1].min() - y0) / resolution))
        high = min(rows, math.ceil((points[:, 1].max() - y0) / resolution) + 1)
        for row in range(low, high):
            y = y0 + (row + 0.5) * resolution
            count = 0
            for j in range(n):
                ax, ay, bx, by = points[j - 1, 0], points[j - 1, 1], points[j, 0], points[j, 1]
                if (ay > y) != (by > y):
                    crossings[count] = ax + (y - ay) * (bx - ax) / (by - ay)
                    count += 1
            inside = np.sort(crossings[:count])
            for k in range(0, count - 1, 2):
                first = max(0, math.floor((inside[k] - x0) / resolution - 0.5))
                last = min(cols - 1, math.floor((inside[k + 1] - x0) / resolution - 0.5))
                for col in range(first, last + 1):
                    cx = x0 + (col + 0.5) * resolution
                    if inside[k] <= cx < inside[k + 1]:
                        occupied[row, col] = True
    for j in range(0 if closed else 1, n):
        ax, ay, bx, by = points[j - 1, 0], points[j - 1, 1], points[j, 0], points[j, 1]
        c0, c1 = _cell_span(min(ax, bx) - inflation, max(ax, bx) + inflation, x0, resolution, cols)
        r0, r1 = _cell_span(min(ay, by) - inflation, max(ay, by) + inflation, y0, resolution, rows)
        for row in range(r0, r1):
            for col in range(c0, c1):
                if not occupied[row, col] and segment_distance(x0 + (col + 0.5) * resolution,
                                                               y0 + (row + 0.5) * resolution, ax, ay, bx, by) < inflation:
                    occupied[row, col] = True


@kernel
def _cell_span(low: float, high: float, origin: float, resolution: float, cells: int) -> tuple[int, int]:
    """The cells [first, last) whose centres may lie within [low, high], one spare cell each side."""
    first = math.floor((low - origin) / resolution - 0.5) - 1
    last = math.ceil((high - origin) / resolution - 0.5) + 2
    return max(0, min(cells, first)), max(0, min(cells, last))


@kernel
def _rasterise(occupied: np.ndarray, kinds: np.ndarray, params: np.ndarray, x0: float, y0: float,
               resolution: float, inflation: float) -> None:
    """Mark the cells within ``inflation`` of each circle or box (a kind and five parameters).

    Only cells within ``inflation`` of a shape's bounding box can be occupied by it: measuring
    just those makes a grid cost its obstacles' area, not the world's.
    """
    rows, cols = occupied.shape
    for k in range(kinds.shape[0]):
        x_min, y_min, x_max, y_max = shape_bounds(kinds[k], params[k])
        c0, c1 = _cell_span(x_min - inflation, x_max + inflation, x0, resolution, cols)
        r0, r1 = _cell_span(y_min - inflation, y_max + inflation, y0, resolution, rows)
        x, y, a, b, yaw = params[k, 0], params[k, 1], params[k, 2], params[k, 3], params[k, 4]
        c, s = math.cos(yaw), math.sin(yaw)
        for row in range(r0, r1):
            cy = y0 + (row + 0.5) * resolution
            for col in range(c0, c1):
                cx = x0 + (col + 0.5) * resolution
                if kinds[k] == CIRCLE:
                    distance = circle_distance(cx, cy, x, y, a)
                else:
                    distance = box_distance(cx, cy, x, y, a, b, c, s)
                if distance < inflation:
                    occupied[row, col] = True


@kernel
def _mark_walls(occupied: np.ndarray, x0: float, y0: float, width: float, height: float, resolution: float,
                inflation: float) -> None:
    """Mark the cells whose centres lie within ``inflation`` of the world's boundary."""
    rows, cols = occupied.shape
    for row in range(rows):
        y = y0 + (row + 0.5) * resolution
        near_y = y - y0 < inflation or y0 + height - y < inflation
        for col in range(cols):
            x = x0 + (col + 0.5) * resolution
            if near_y or x - x0 < inflation or x0 + width - x < inflation:
                occupied[row, col] = True


def goal_reachable(scenario: Scenario, resolution: float = 0.1) -> bool:
    """Whether the robot's footprint can travel from start to goal without touching anything, on
    the scenario's grid at ``resolution`` (see :func:`path_exists`)."""
    return path_exists(scenario_grid(scenario, resolution), scenario.start[:2], scenario.goal, scenario.goal_threshold)


def path_exists(grid: OccupancyGrid, start: Sequence[float], goal: Sequence[float], threshold: float) -> bool:
    """Whether free cells connect the start's cell to a cell within ``threshold`` of the goal.

    The goal counts as reached within the threshold, so the goal cell may sit in a narrow pocket:
    any free cell inside that radius will do.
    """
    return _reaches(grid.occupied, grid.cell_of(start[0], start[1]), grid.origin[0], grid.origin[1], grid.resolution,
                    goal[0], goal[1], threshold)


@kernel
def _reaches(occupied: np.ndarray, start: tuple[int, int], x0: float, y0: float, resolution: float,
             gx: float, gy: float, threshold: float) -> bool:
    """Whether a free cell 8-connected to the start cell has its centre within ``threshold`` of the goal.

    A depth-first fill that tries the goal-ward neighbour first and stops at the first such cell:
    the generators ask this of every layout, and most reach the goal in a few dozen cells where a
    full labelling visits thousands.
    """
    rows, cols = occupied.shape
    if occupied[start[0], start[1]]:
        return False
    seen = np.zeros((rows, cols), dtype=np.bool_)
    stack = np.empty((rows * cols, 2), dtype=np.int64)
    stack[0, 0], stack[0, 1] = start[0], start[1]
    seen[start[0], start[1]] = True
    top = 1
    order = np.empty(8)
    steps = np.array([(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)])
    while top:
        top -= 1
        row, col = stack[top, 0], stack[top, 1]
        cx, cy = x0 + (col + 0.5) * resolution, y0 + (row + 0.5) * resolution
        if math.hypot(cx - gx, cy - gy) <= threshold:
            return True
        for k in range(8):
            order[k] = steps[k, 1] * (gx - cx) + steps[k, 0] * (gy - cy)
        for k in np.argsort(order):  # the most goal-ward pushed last, so explored next
            r, c = row + steps[k, 0], col + steps[k, 1]
            if 0 <= r < rows and 0 <= c < cols and not occupied[r, c] and not seen[r, c]:
                seen[r, c] = True
                stack[top, 0], stack[top, 1] = r, c
                top += 1
    return False


def inflate(occupied: np.ndarray, radius: float, resolution: float) -> np.ndarray:
    """Cells whose centre lies within ``radius`` of an occupied cell's centre (``radius`` 0: a copy).

    Each occupied cell marks the rows of its disk as runs, summed along each row. The local
    planners inflate a scan's grid every step, and a Euclidean distance transform of the whole
    grid took 1.5 ms for 300 returns on 200 x 200 cells, this 0.12 ms. Distances are reckoned as
    that transform reckons them, so the two mark the same cells (tests/test_planners.py)."""
    if radius <= 0.0 or not occupied.any():
        return occupied.copy()
    return _inflated(occupied, _disk_half_widths(radius, resolution))


def _disk_half_widths(radius: float, resolution: float) -> np.ndarray:
    """For each row offset -R..R (R the disk's reach in cells), the furthest column offset whose
    cell centre lies within ``radius`` (``scipy.ndimage.distance_transform_edt``'s arithmetic)."""
    reach = int(radius / resolution) + 1
    offsets = np.arange(-reach, reach + 1)
    rows, cols = np.meshgrid(offsets, np.arange(reach + 1), indexing="ij")
    inside = np.sqrt((rows * resolution) ** 2 + (cols * resolution) ** 2) <= radius + 1e-9
    return (inside.sum(axis=1) - 1).astype(np.int64)  # the cells inside run from column 0: -1 for none


@kernel
def _inflated(occupied: np.ndarray, half_widths: np.ndarray) -> np.ndarray:
    """``occupied`` dilated by the disk whose row ``k`` spans columns -half_widths[k]..half_widths[k]
    (-1: none) at row offset ``k - len(half_widths) // 2``."""
    rows, cols = occupied.shape
    reach = half_widths.shape[0] // 2
    starts = np.zeros((rows, cols + 1), np.int32)  # +1 where a run starts, -1 past where it ends
    for r in range(rows):
        for c in range(cols):
            if not occupied[r, c]:
                continue
            for k in range(half_widths.shape[0]):
                row, width = r + k - reach, half_widths[k]
                if width < 0 or row < 0 or row >= rows:
                    continue
                starts[row, max(c - width, 0)] += 1
                starts[row, min(c + width, cols - 1) + 1] -= 1
    out = np.empty((rows, cols), np.bool_)
    for r in range(rows):
        runs = 0
        for c in range(cols):
            runs += starts[r, c]
            out[r, c] = runs > 0
    return out


class ScanMapper:
    """An occupancy grid built from lidar returns over time.

    A cell holding a return is occupied from then on (static worlds; no free-space clearing), and
    unseen space counts as free, so a planner on :attr:`grid` is optimistic about what it has not
    scanned and replans as returns arrive. ``world_bounds`` is (x0, y0, width, height).
    """

    def __init__(self, world_bounds: tuple[float, float, float, float], resolution: float = 0.2,
                 inflation: float = 0.0) -> None:
        x0, y0, width, height = world_bounds
        self.origin = (float(x0), float(y0))
        self.resolution = resolution = bounded_resolution(width, height, float(resolution))
        self.inflation = float(inflation)
        self.shape = (max(1, int(round(height / resolution))), max(1, int(round(width / resolution))))
        self.hits = np.zeros(self.shape, dtype=np.int32)
        self._grid: OccupancyGrid | None = None

    @classmethod
    def for_scenario(cls, scenario: Scenario, resolution: float = 0.2) -> "ScanMapper":
        """A mapper over the scenario's world, inflated by the robot's bounding radius."""
        world = scenario.world
        bounds = (world.offset[0], world.offset[1], world.width, world.height)
        return cls(bounds, resolution, scenario.robot.bounding_radius)

    def reset(self) -> None:
        """Forget every return."""
        self.hits[:] = 0
        self._grid = None

    def add_points(self, points: np.ndarray) -> int:
        """Mark the cells of world points (N, 2); return how many fell on the grid.

        Points up to one cell outside the grid are clamped onto its edge (returns from boundary
        walls lie exactly on it, and lidar noise pushes some just beyond); farther ones are dropped.
        """
        rows, cols, keep = self.cells_of(points)
        flat = rows[keep] * self.shape[1] + cols[keep]
        if flat.size:
            self.hits += np.bincount(flat, minlength=self.hits.size).reshape(self.shape).astype(np.int32)
            self._grid = None
        return int(flat.size)

    def cells_of(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rows, cols) of world points (N, 2), clamped onto the grid, and which of them
        :meth:`add_points` keeps (those at most one cell off the grid)."""
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        rows, cols = self.shape
        c = np.floor((points[:, 0] - self.origin[0]) / self.resolution).astype(np.int64)
        r = np.floor((points[:, 1] - self.origin[1]) / self.resolution).astype(np.int64)
        keep = (c >= -1) & (c <= cols) & (r >= -1) & (r <= rows)
        return np.clip(r, 0, rows - 1), np.clip(c, 0, cols - 1), keep

    def add_scan(self, geometry: "LidarGeometry", ranges: np.ndarray, pose: tuple[float, float, float]) -> int:
        """Mark the returns of one scan taken at ``pose`` (beams that hit nothing are ignored)."""
        return self.add_points(geometry.returns_world_frame(np.asarray(ranges, dtype=float), pose))

    @property
    def observed(self) -> np.ndarray:
        """Cells that hold at least one return (not inflated)."""
        return self.hits > 0

    @property
    def grid(self) -> OccupancyGrid:
        """The inflated grid for planning (cached until the next scan)."""
        if self._grid is None:
            occupied = inflate(self.observed, self.inflation, self.resolution)
            self._grid = OccupancyGrid(occupied=occupied, origin=self.origin, resolution=self.resolution)
        return self._grid
