"""A* on an occupancy grid: 8-connected (or 4-), Euclidean heuristic, no corner cutting.

The search runs in a numba kernel with an array binary heap and lazy deletion (a cell may sit in
the heap several times; stale entries are skipped when popped), so a plan on a 50 × 50 grid takes
tens of microseconds rather than the milliseconds of a ``heapq`` loop in Python.
"""

from __future__ import annotations

import math

import numpy as np

from common.kernel_cache import kernel
from common.occupancy import OccupancyGrid
from common.planners.base import Point, grid_arrays, path_length

__all__ = ["AStar", "path_length"]

# Neighbour offsets: the four orthogonal moves first, so a 4-connected search uses the first four.
_DR = np.array([0, 1, 0, -1, 1, 1, -1, -1], dtype=np.int64)
_DC = np.array([1, 0, -1, 0, 1, -1, 1, -1], dtype=np.int64)
_COST = np.array([1.0, 1.0, 1.0, 1.0, math.sqrt(2.0), math.sqrt(2.0), math.sqrt(2.0), math.sqrt(2.0)])


@kernel
def _heap_push(keys: np.ndarray, items: np.ndarray, size: int, key: float, item: int) -> None:
    """Insert at position ``size`` and sift up (the caller has made room)."""
    i = size
    while i > 0:
        up = (i - 1) >> 1
        if keys[up] <= key:
            break
        keys[i] = keys[up]
        items[i] = items[up]
        i = up
    keys[i] = key
    items[i] = item


@kernel
def _heap_pop(keys: np.ndarray, items: np.ndarray, size: int) -> int:
    """Remove and return the item with the smallest key from a heap of ``size`` entries."""
    top = items[0]
    size -= 1
    key, item = keys[size], items[size]
    i = 0
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        if child + 1 < size and keys[child + 1] < keys[child]:
            child += 1
        if keys[child] >= key:
            break
        keys[i] = keys[child]
        items[i] = items[child]
        i = child
    if size > 0:
        keys[i] = key
        items[i] = item
    return top


@kernel
def _astar(occupied: np.ndarray, start: int, goal: int, neighbours: int) -> np.ndarray:
    """Flat cell indices of a shortest path start → goal, or an empty array if there is none."""
    rows, cols = occupied.shape
    n = rows * cols
    g = np.full(n, np.inf)
    parent = np.full(n, -1, dtype=np.int64)
    closed = np.zeros(n, dtype=np.bool_)
    goal_r, goal_c = goal // cols, goal % cols
    keys = np.empty(max(64, n // 4), dtype=np.float64)
    items = np.empty(keys.size, dtype=np.int64)
    g[start] = 0.0
    _heap_push(keys, items, 0, 0.0, start)
    size = 1
    found = False
    while size > 0:
        current = _heap_pop(keys, items, size)
        size -= 1
        if closed[current]:
            continue  # a stale entry: this cell was already expanded with a smaller g
        if current == goal:
            found = True
            break
        closed[current] = True
        r, c = current // cols, current % cols
        for k in range(neighbours):
            nr, nc = r + _DR[k], c + _DC[k]
            if nr < 0 or nc < 0 or nr >= rows or nc >= cols or occupied[nr, nc]:
                continue
            if k >= 4 and (occupied[r + _DR[k], c] or occupied[r, c + _DC[k]]):
                continue  # a diagonal move must not cut the corner of an occupied cell
            nxt = nr * cols + nc
            if closed[nxt]:
                continue
            cost = g[current] + _COST[k]
            if cost < g[nxt]:
                g[nxt] = cost
                parent[nxt] = current
                if size == keys.size:  # grow the heap: lazy deletion can hold one entry per relaxation
                    keys = np.concatenate((keys, np.empty(keys.size, dtype=np.float64)))
                    items = np.concatenate((items, np.empty(items.size, dtype=np.int64)))
                h = math.sqrt((nr - goal_r) ** 2 + (nc - goal_c) ** 2)
                _heap_push(keys, items, size, cost + h, nxt)
                size += 1
    if not found:
        return np.empty(0, dtype=np.int64)
    count = 1
    cell = goal
    while cell != start:
        cell = parent[cell]
        count += 1
    path = np.empty(count, dtype=np.int64)
    cell = goal
    for i in range(count - 1, -1, -1):
        path[i] = cell
        cell = parent[cell]
    return path


class AStar:
    """A* between the cells of start and goal; the path runs through cell centres, with the exact
    start and goal points in place of their own cells' centres."""

    name = "astar"

    def __init__(self, allow_diagonal: bool = True) -> None:
        self.allow_diagonal = allow_diagonal

    def plan(self, grid: OccupancyGrid, start: Point, goal: Point) -> np.ndarray | None:
        """World points (N, 2) from start to goal, or None if either is occupied, off the grid or unreachable."""
        (sx, sy), (gx, gy) = (float(v) for v in start[:2]), (float(v) for v in goal[:2])
        if not (grid.is_free(sx, sy) and grid.is_free(gx, gy)):
            return None
        occupied, x0, y0, resolution = grid_arrays(grid)
        cols = occupied.shape[1]
        s_r, s_c = grid.cell_of(sx, sy)
        g_r, g_c = grid.cell_of(gx, gy)
        cells = _astar(occupied, s_r * cols + s_c, g_r * cols + g_c, 8 if self.allow_diagonal else 4)
        if cells.size == 0:
            return None
        if cells.size == 1:  # start and goal share a cell
            return np.array([[sx, sy], [gx, gy]])
        points = np.column_stack([x0 + (cells % cols + 0.5) * resolution, y0 + (cells // cols + 0.5) * resolution])
        points[0] = sx, sy
        points[-1] = gx, gy
        return points
