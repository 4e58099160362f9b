"""Occupancy grids: obstacles rasterised at a resolution and inflated by the robot's footprint.

The ground-truth grid of a scenario decides reachability (the generators' guarantee) and, later,
the planners' shortest paths for SPL.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy import ndimage

from common.scenario import Scenario

if TYPE_CHECKING:  # a runtime import would tie the grid module to the controllers package
    from common.controllers.base import LidarGeometry


@dataclass(frozen=True)
class OccupancyGrid:
    """Boolean grid ``occupied[row, col]``; cell (r, c) has centre ``origin + (c + 0.5, r + 0.5) * resolution``."""

    occupied: np.ndarray
    origin: tuple[float, float]
    resolution: float

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        """The (row, col) of the cell containing world point (x, y), clamped to the grid."""
        rows, cols = self.occupied.shape
        col = int(np.clip((x - self.origin[0]) / self.resolution, 0, cols - 1))
        row = int(np.clip((y - self.origin[1]) / self.resolution, 0, rows - 1))
        return row, col

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


def scenario_grid(scenario: Scenario, resolution: float = 0.2, inflation: float | None = None) -> OccupancyGrid:
    """The ground-truth grid of a scenario: a cell is occupied when its centre lies within
    ``inflation`` (default: the robot's bounding radius) of an obstacle or of a boundary wall."""
    inflation = scenario.robot.bounding_radius if inflation is None else inflation
    world = scenario.world
    cols = max(1, int(round(world.width / resolution)))
    rows = max(1, int(round(world.height / resolution)))
    xs = world.offset[0] + (np.arange(cols) + 0.5) * resolution
    ys = world.offset[1] + (np.arange(rows) + 0.5) * resolution
    centres = np.stack(np.meshgrid(xs, ys), axis=-1)  # (rows, cols, 2): each cell's centre
    occupied = np.zeros((rows, cols), dtype=bool)
    for obstacle in scenario.obstacles:
        if obstacle.unobstructed:
            continue
        # Only cells within ``inflation`` of the obstacle's bounding box can be occupied by it:
        # measuring just those makes a grid cost its obstacles' area, not the world's.
        x_min, y_min, x_max, y_max = obstacle.bounds()
        c0, c1 = _cell_span(x_min - inflation, x_max + inflation, world.offset[0], resolution, cols)
        r0, r1 = _cell_span(y_min - inflation, y_max + inflation, world.offset[1], resolution, rows)
        if c0 < c1 and r0 < r1:
            near = obstacle.sdf(np.ascontiguousarray(centres[r0:r1, c0:c1]).reshape(-1, 2)) < inflation
            occupied[r0:r1, c0:c1] |= near.reshape(r1 - r0, c1 - c0)
    gx, gy = centres[..., 0], centres[..., 1]
    if world.walls:
        x0, y0 = world.offset
        occupied |= (gx - x0 < inflation) | (x0 + world.width - gx < inflation)
        occupied |= (gy - y0 < inflation) | (y0 + world.height - gy < inflation)
    return OccupancyGrid(occupied=occupied, origin=tuple(world.offset), resolution=resolution)


def _cell_span(low: float, high: float, origin: float, resolution: float, cells: int) -> tuple[int, int]:
    """The cells [first, last) whose centres may lie within [low, high], one spare cell each side."""
    first = math.floor((low - origin) / resolution - 0.5) - 1
    last = math.ceil((high - origin) / resolution - 0.5) + 2
    return max(0, min(cells, first)), max(0, min(cells, last))


def goal_reachable(scenario: Scenario, resolution: float = 0.1) -> bool:
    """Whether the robot's footprint can travel from start to goal without touching anything.

    The goal counts as reached within ``goal_threshold``, so the goal cell may sit in a narrow
    pocket; we test connectivity to the start from the free cell nearest the goal inside that radius.
    """
    grid = scenario_grid(scenario, resolution)
    rows, cols = np.nonzero(grid.free_component(*scenario.start[:2]))
    cx = grid.origin[0] + (cols + 0.5) * resolution
    cy = grid.origin[1] + (rows + 0.5) * resolution
    gx, gy = scenario.goal
    return bool(np.any(np.hypot(cx - gx, cy - gy) <= scenario.goal_threshold))


def inflate(occupied: np.ndarray, radius: float, resolution: float) -> np.ndarray:
    """Cells whose centre lies within ``radius`` of an occupied cell's centre.

    A Euclidean distance transform gives the disk for any radius in one pass (no structuring
    element to build per radius); ``radius`` 0 returns a copy.
    """
    if radius <= 0.0 or not occupied.any():
        # edt of an array without zeros has no background to measure from: nothing to inflate.
        return occupied.copy()
    distance = ndimage.distance_transform_edt(~occupied, sampling=resolution)
    return distance <= radius + 1e-9


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
        self.resolution = float(resolution)
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
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        rows, cols = self.shape
        c = np.floor((points[:, 0] - self.origin[0]) / self.resolution).astype(np.int64)
        r = np.floor((points[:, 1] - self.origin[1]) / self.resolution).astype(np.int64)
        keep = (c >= -1) & (c <= cols) & (r >= -1) & (r <= rows)
        flat = np.clip(r[keep], 0, rows - 1) * cols + np.clip(c[keep], 0, cols - 1)
        if flat.size:
            self.hits += np.bincount(flat, minlength=rows * cols).reshape(self.shape).astype(np.int32)
            self._grid = None
        return int(flat.size)

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
