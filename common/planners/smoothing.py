"""Path smoothing: drop the waypoints a straight, collision-free line can skip (:func:`shortcut`),
and move a path away from obstacles where it passes closer than it must (:func:`keep_clear`)."""

from __future__ import annotations

import math

import numpy as np

from common.kernel_cache import kernel
from common.occupancy import OccupancyGrid
from common.planners.collision import line_of_sight
from common.planners.footprint import FootprintGrid, corner_free, kernel_arrays, pose_clearance, segment_free


@kernel
def _shortcut(field: np.ndarray, occupied: np.ndarray, x0: float, y0: float, resolution: float, centres: np.ndarray,
              radii: np.ndarray, exact: int, boxes: np.ndarray, margin: float, points: np.ndarray,
              heading: float) -> np.ndarray:
    """Indices of the kept waypoints: from each kept point, the farthest one in line of sight on
    ``occupied`` (an empty ``field``), or the farthest one the footprint can turn to (from
    ``heading``, NaN: any) and drive straight to, arriving there heading along the segment."""
    n = points.shape[0]
    keep = np.empty(n, dtype=np.int64)
    keep[0] = 0
    kept = 1
    i = 0
    while i < n - 1:
        j = n - 1
        # The next waypoint is always kept as a fallback, so an input segment that fails the
        # exact check (e.g. a sampled RRT edge clipping a corner) is never made worse.
        while j > i + 1 and not (
                line_of_sight(occupied, x0, y0, resolution, points[i, 0], points[i, 1], points[j, 0], points[j, 1])
                if field.size == 0 else
                corner_free(field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin, points, heading,
                            i, j)):
            j -= 1
        keep[kept] = j
        kept += 1
        heading = math.atan2(points[j, 1] - points[i, 1], points[j, 0] - points[i, 0])
        i = j
    return keep[:kept]


def shortcut(grid: OccupancyGrid | FootprintGrid, path: np.ndarray, heading: float | None = None) -> np.ndarray:
    """A path through a subset of ``path``'s waypoints (same ends), each new segment checked
    cell by cell on the grid, or for the footprint along it and in the turn onto it (the robot
    starting at ``heading``; None: facing the first segment); by the triangle inequality it is
    never longer."""
    points = np.ascontiguousarray(path, dtype=float).reshape(-1, 2)
    if len(points) < 3:
        return points.copy()
    return points[_shortcut(*kernel_arrays(grid), points, math.nan if heading is None else float(heading))]


@kernel
def _keep_clear(field: np.ndarray, occupied: np.ndarray, x0: float, y0: float, resolution: float, centres: np.ndarray,
                radii: np.ndarray, exact: int, boxes: np.ndarray, margin: float, points: np.ndarray, wanted: float,
                rounds: int) -> None:
    """Move each inner point of ``points`` (in place) up the footprint's clearance, a cell at a
    time, while it stands closer than ``wanted`` and both its segments stay free."""
    n = points.shape[0]
    delta = 0.5 * resolution
    for _ in range(rounds):
        moved = False
        for k in range(1, n - 1):
            x, y = points[k, 0], points[k, 1]
            yaw = math.atan2(points[k + 1, 1] - points[k - 1, 1], points[k + 1, 0] - points[k - 1, 0])
            here = pose_clearance(field, x0, y0, resolution, centres, radii, x, y, yaw)
            if here >= wanted:
                continue
            gx = (pose_clearance(field, x0, y0, resolution, centres, radii, x + delta, y, yaw)
                  - pose_clearance(field, x0, y0, resolution, centres, radii, x - delta, y, yaw))
            gy = (pose_clearance(field, x0, y0, resolution, centres, radii, x, y + delta, yaw)
                  - pose_clearance(field, x0, y0, resolution, centres, radii, x, y - delta, yaw))
            norm = math.hypot(gx, gy)
            if norm < 1e-9:
                continue
            nx, ny = x + resolution * gx / norm, y + resolution * gy / norm
            if (pose_clearance(field, x0, y0, resolution, centres, radii, nx, ny, yaw) > here
                    and segment_free(field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin,
                                     points[k - 1, 0], points[k - 1, 1], nx, ny)
                    and segment_free(field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin,
                                     nx, ny, points[k + 1, 0], points[k + 1, 1])):
                points[k, 0], points[k, 1] = nx, ny
                moved = True
        if not moved:
            return


def keep_clear(grid: FootprintGrid, path: np.ndarray, clearance: float, spacing: float = 0.2,
               rounds: int = 20) -> np.ndarray:
    """``path`` resampled every ``spacing`` metres, its inner points moved away from obstacles
    (up the footprint's distance field, at most ``rounds`` cells each) while they pass closer
    than ``clearance`` and every segment stays free: a sampled path hugs the obstacles it found
    its way past, and a robot threads a gap best along its middle."""
    points = np.ascontiguousarray(path, dtype=float).reshape(-1, 2)
    dense = [points[:1]]
    for a, b in zip(points[:-1], points[1:]):
        pieces = max(1, int(math.ceil(math.hypot(*(b - a)) / spacing)))
        dense.append(a + (b - a) * (np.arange(1, pieces + 1) / pieces)[:, None])
    dense = np.ascontiguousarray(np.vstack(dense))
    _keep_clear(*grid.arrays, dense, float(clearance), rounds)
    return dense
