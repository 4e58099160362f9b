"""Path shortcutting: drop the waypoints a straight, collision-free line can skip."""

from __future__ import annotations

import numpy as np

from common.kernel_cache import kernel
from common.occupancy import OccupancyGrid
from common.planners.base import grid_arrays
from common.planners.collision import line_of_sight


@kernel
def _shortcut(occupied: np.ndarray, x0: float, y0: float, resolution: float, points: np.ndarray) -> np.ndarray:
    """Indices of the kept waypoints: from each kept point, the farthest one in line of sight."""
    n = points.shape[0]
    keep = np.empty(n, dtype=np.int64)
    keep[0] = 0
    kept = 1
    i = 0
    while i < n - 1:
        j = n - 1
        # The next waypoint is always kept as a fallback, so an input segment that fails the
        # exact check (e.g. a sampled RRT edge clipping a corner) is never made worse.
        while j > i + 1 and not line_of_sight(occupied, x0, y0, resolution,
                                              points[i, 0], points[i, 1], points[j, 0], points[j, 1]):
            j -= 1
        keep[kept] = j
        kept += 1
        i = j
    return keep[:kept]


def shortcut(grid: OccupancyGrid, path: np.ndarray) -> np.ndarray:
    """A path through a subset of ``path``'s waypoints (same ends), each new segment checked
    cell by cell on the grid; by the triangle inequality it is never longer."""
    points = np.ascontiguousarray(path, dtype=float).reshape(-1, 2)
    if len(points) < 3:
        return points.copy()
    return points[_shortcut(*grid_arrays(grid), points)]
