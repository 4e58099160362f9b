"""What every planner shares: the ``plan`` interface and path helpers."""

from __future__ import annotations

from typing import Protocol, Sequence

import numpy as np

from common.occupancy import OccupancyGrid

Point = Sequence[float]


class Planner(Protocol):
    """A planner is built with its parameters, then asked for paths on any grid."""

    name: str

    def plan(self, grid: OccupancyGrid, start: Point, goal: Point) -> np.ndarray | None:
        """World points (N, 2) from ``start`` to ``goal`` (both included exactly), or None if there is no path."""


def path_length(points: np.ndarray | Sequence[Point]) -> float:
    """Total length of a polyline of world points (0 for fewer than two)."""
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    return float(np.hypot(*np.diff(points, axis=0).T).sum()) if len(points) > 1 else 0.0


def grid_arrays(grid: OccupancyGrid) -> tuple[np.ndarray, float, float, float]:
    """The grid as the (occupied, x0, y0, resolution) the numba kernels take (C-contiguous bools)."""
    occupied = np.ascontiguousarray(grid.occupied, dtype=np.bool_)
    return occupied, float(grid.origin[0]), float(grid.origin[1]), float(grid.resolution)
