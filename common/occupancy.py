"""Occupancy grids: obstacles rasterised at a resolution and inflated by the robot's footprint.

The ground-truth grid of a scenario decides reachability (the generators' guarantee) and, later,
the planners' shortest paths for SPL.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from common.scenario import Scenario


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
    gx, gy = np.meshgrid(xs, ys)
    points = np.column_stack([gx.ravel(), gy.ravel()])
    occupied = (scenario.signed_distance(points) < inflation).reshape(rows, cols)
    if world.walls:
        x0, y0 = world.offset
        occupied |= (gx - x0 < inflation) | (x0 + world.width - gx < inflation)
        occupied |= (gy - y0 < inflation) | (y0 + world.height - gy < inflation)
    return OccupancyGrid(occupied=occupied, origin=tuple(world.offset), resolution=resolution)


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
