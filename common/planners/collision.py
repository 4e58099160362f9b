"""Compiled collision checks of points and segments against a boolean occupancy grid.

Everything outside the grid counts as occupied, so no planner ever leaves the mapped area. The
grid is passed as (occupied, x0, y0, resolution) rather than as an :class:`OccupancyGrid`, since
numba kernels take arrays and scalars.
"""

from __future__ import annotations

import math

import numpy as np

from common.kernel_cache import kernel


@kernel
def point_free(occupied: np.ndarray, x0: float, y0: float, resolution: float, x: float, y: float) -> bool:
    """Whether (x, y) lies on the grid in a free cell."""
    u = (x - x0) / resolution
    v = (y - y0) / resolution
    if u < 0.0 or v < 0.0 or u >= occupied.shape[1] or v >= occupied.shape[0]:
        return False
    return not occupied[int(v), int(u)]


@kernel
def segment_free_sampled(occupied: np.ndarray, x0: float, y0: float, resolution: float,
                         ax: float, ay: float, bx: float, by: float) -> bool:
    """Whether points sampled along a→b at most half a cell apart (ends included) are all free.

    Cheap, and at half a cell no cell can be jumped; a segment may still clip the corner of an
    occupied cell, which the inflation margin absorbs. :func:`line_of_sight` is the exact check.
    """
    length = math.hypot(bx - ax, by - ay)
    n = max(1, int(math.ceil(length / (0.5 * resolution))))
    for i in range(n + 1):
        t = i / n
        if not point_free(occupied, x0, y0, resolution, ax + t * (bx - ax), ay + t * (by - ay)):
            return False
    return True


@kernel
def _cell_free(occupied: np.ndarray, row: int, col: int) -> bool:
    if row < 0 or col < 0 or row >= occupied.shape[0] or col >= occupied.shape[1]:
        return False
    return not occupied[row, col]


@kernel
def line_of_sight(occupied: np.ndarray, x0: float, y0: float, resolution: float,
                  ax: float, ay: float, bx: float, by: float) -> bool:
    """Whether every cell the segment a→b passes through is free (Amanatides–Woo traversal).

    Where the segment passes exactly through a cell corner both side cells must be free, the
    same no-corner-cutting rule as A*'s diagonal moves.
    """
    fx, fy = (ax - x0) / resolution, (ay - y0) / resolution
    dx, dy = (bx - x0) / resolution - fx, (by - y0) / resolution - fy
    col, row = int(math.floor(fx)), int(math.floor(fy))
    if not _cell_free(occupied, row, col):
        return False
    step_c = 1 if dx > 0.0 else -1
    step_r = 1 if dy > 0.0 else -1
    # Parameter t in [0, 1] along a→b at which the next vertical / horizontal cell boundary is crossed.
    delta_c = abs(1.0 / dx) if dx != 0.0 else math.inf
    delta_r = abs(1.0 / dy) if dy != 0.0 else math.inf
    next_c = ((col + 1.0 - fx) if dx > 0.0 else (fx - col)) * delta_c if dx != 0.0 else math.inf
    next_r = ((row + 1.0 - fy) if dy > 0.0 else (fy - row)) * delta_r if dy != 0.0 else math.inf
    # Each crossing moves one cell; the bound only guards against float drift looping forever.
    for _ in range(int(abs(dx)) + int(abs(dy)) + 4):
        t = min(next_c, next_r)
        if t > 1.0:
            return True
        if abs(next_c - next_r) < 1e-12:
            if not (_cell_free(occupied, row, col + step_c) and _cell_free(occupied, row + step_r, col)):
                return False
            col += step_c
            row += step_r
            next_c += delta_c
            next_r += delta_r
        elif next_c < next_r:
            col += step_c
            next_c += delta_c
        else:
            row += step_r
            next_r += delta_r
        if not _cell_free(occupied, row, col):
            return False
    return True
