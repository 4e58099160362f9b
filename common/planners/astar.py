"""A* on an occupancy grid: 8-connected (or 4-), Euclidean heuristic, no corner cutting; or, on a
:class:`~common.planners.footprint.FootprintGrid`, over position and heading.

The search runs in a numba kernel with an array binary heap and lazy deletion (a cell may sit in
the heap several times; stale entries are skipped when popped), so a plan on a 50 × 50 grid takes
tens of microseconds rather than the milliseconds of a ``heapq`` loop in Python.

With a footprint, a state is a cell and one of eight headings 45° apart: the robot steps one cell
ahead along its heading (where its footprint keeps the grid's margin there) or turns 45° on the
spot (where the turn sweeps nothing). A step costs its length, more where the footprint passes
closer than ``band`` to an obstacle (up to ``1 + weight`` times: so the path keeps to the middle
of a gap and takes the wider of two), and a turn costs ``turn_cost`` metres' worth.
"""

from __future__ import annotations

import math

import numpy as np

from common.kernel_cache import kernel
from common.occupancy import OccupancyGrid
from common.planners.base import Point, grid_arrays, path_length
from common.planners.footprint import FootprintGrid, pose_clearance, pose_free, turn_free

__all__ = ["AStar", "path_length"]

# Neighbour offsets: the four orthogonal moves first, so a 4-connected search uses the first four.
_DR = np.array([0, 1, 0, -1, 1, 1, -1, -1], dtype=np.int64)
_DC = np.array([1, 0, -1, 0, 1, -1, 1, -1], dtype=np.int64)
_COST = np.array([1.0, 1.0, 1.0, 1.0, math.sqrt(2.0), math.sqrt(2.0), math.sqrt(2.0), math.sqrt(2.0)])
# The lattice's headings, counter-clockwise from +x, 45° apart: the cell a step along each reaches.
_HEADING_DR = np.array([0, 1, 1, 1, 0, -1, -1, -1], dtype=np.int64)
_HEADING_DC = np.array([1, 1, 0, -1, -1, -1, 0, 1], dtype=np.int64)
_EIGHTH = math.pi / 4.0


@kernel
def heap_push(keys: np.ndarray, items: np.ndarray, size: int, key: float, item: int) -> None:
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
def heap_pop(keys: np.ndarray, items: np.ndarray, size: int) -> int:
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
def _relax(keys: np.ndarray, items: np.ndarray, size: int, g: np.ndarray, parent: np.ndarray, state: int,
           cost: float, came_from: int, h: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Lower ``state``'s cost to ``cost`` if that is lower, pushing it (the heap grown if full)."""
    if cost >= g[state]:
        return keys, items, size
    g[state] = cost
    parent[state] = came_from
    if size == keys.size:  # lazy deletion can hold one entry per relaxation
        keys = np.concatenate((keys, np.empty(keys.size, dtype=np.float64)))
        items = np.concatenate((items, np.empty(items.size, dtype=np.int64)))
    heap_push(keys, items, size, cost + h, state)
    return keys, items, size + 1


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
    keys, items, size = _relax(keys, items, 0, g, parent, start, 0.0, -1, 0.0)
    found = False
    while size > 0:
        current = heap_pop(keys, items, size)
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
            h = math.sqrt((nr - goal_r) ** 2 + (nc - goal_c) ** 2)
            keys, items, size = _relax(keys, items, size, g, parent, nxt, g[current] + _COST[k], current, h)
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


@kernel
def _astar_lattice(field: np.ndarray, occupied: np.ndarray, x0: float, y0: float, resolution: float,
                   centres: np.ndarray, radii: np.ndarray, exact: int, boxes: np.ndarray, margin: float, sx: float,
                   sy: float, syaw: float, goal: int, turn_cost: float, weight: float, band: float) -> np.ndarray:
    """Flat cell indices (heading dropped, turns merged) of a cheapest path over (cell, heading)
    states from the pose (sx, sy, syaw) to the cell ``goal``, or an empty array."""
    rows, cols = field.shape
    n = rows * cols * 8
    g = np.full(n, np.inf)
    parent = np.full(n, -1, dtype=np.int64)
    closed = np.zeros(n, dtype=np.bool_)
    free = np.zeros(n, dtype=np.int8)  # each state's pose: 0 not yet checked, 1 free, 2 blocked
    goal_r, goal_c = goal // cols, goal % cols
    keys = np.empty(max(64, n // 16), dtype=np.float64)
    items = np.empty(keys.size, dtype=np.int64)
    size = 0
    start = (min(max(int((sy - y0) / resolution), 0), rows - 1) * cols
             + min(max(int((sx - x0) / resolution), 0), cols - 1))
    h0 = math.hypot(start // cols - goal_r, start % cols - goal_c) * resolution
    for k in range(8):  # the robot turns on the spot to each heading it can (NaN: it may start facing any)
        if math.isnan(syaw):
            if pose_free(field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin, sx, sy, k * _EIGHTH):
                keys, items, size = _relax(keys, items, size, g, parent, start * 8 + k, 0.0, -1, h0)
            continue
        turn = abs((k * _EIGHTH - syaw + math.pi) % (2.0 * math.pi) - math.pi)
        if turn_free(field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin, sx, sy, syaw,
                     k * _EIGHTH):
            keys, items, size = _relax(keys, items, size, g, parent, start * 8 + k, turn_cost * turn / _EIGHTH, -1, h0)
    if size == 0 and not math.isnan(syaw):  # boxed in where it stands: it may drive out along the heading nearest its own
        k = int(round((syaw % (2.0 * math.pi)) / _EIGHTH)) % 8
        keys, items, size = _relax(keys, items, size, g, parent, start * 8 + k, 0.0, -1, h0)
    found = -1
    while size > 0:
        current = heap_pop(keys, items, size)
        size -= 1
        if closed[current]:
            continue
        cell, heading = current // 8, current % 8
        if cell == goal:
            found = current
            break
        closed[current] = True
        r, c = cell // cols, cell % cols
        cx, cy = x0 + (c + 0.5) * resolution, y0 + (r + 0.5) * resolution
        nr, nc = r + _HEADING_DR[heading], c + _HEADING_DC[heading]
        if 0 <= nr < rows and 0 <= nc < cols:
            ahead = (nr * cols + nc) * 8 + heading
            ax, ay, yaw = cx + _HEADING_DC[heading] * resolution, cy + _HEADING_DR[heading] * resolution, heading * _EIGHTH
            if not closed[ahead] and free[ahead] == 0:
                free[ahead] = 1 if pose_free(field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin,
                                             ax, ay, yaw) else 2
            if not closed[ahead] and free[ahead] == 1:
                # The discs' clearance (at most the footprint's) prices passing close.
                near = 1.0 - (pose_clearance(field, x0, y0, resolution, centres, radii, ax, ay, yaw) - margin) / band
                step = resolution * (math.sqrt(2.0) if heading % 2 else 1.0)
                cost = g[current] + step * (1.0 + weight * min(max(near, 0.0), 1.0))
                h = math.hypot(nr - goal_r, nc - goal_c) * resolution
                keys, items, size = _relax(keys, items, size, g, parent, ahead, cost, current, h)
        for turn in (-1, 1):
            other = cell * 8 + (heading + turn) % 8
            if not closed[other] and turn_free(field, occupied, x0, y0, resolution, centres, radii, exact, boxes,
                                               margin, cx, cy, heading * _EIGHTH, (heading + turn) * _EIGHTH):
                h = math.hypot(r - goal_r, c - goal_c) * resolution
                keys, items, size = _relax(keys, items, size, g, parent, other, g[current] + turn_cost, current, h)
    if found < 0:
        return np.empty(0, dtype=np.int64)
    count = 1
    state = found
    while parent[state] >= 0:
        if parent[state] // 8 != state // 8:
            count += 1
        state = parent[state]
    path = np.empty(count, dtype=np.int64)
    state = found
    i = count - 1
    path[i] = found // 8
    while parent[state] >= 0:
        state = parent[state]
        if state // 8 != path[i]:
            i -= 1
            path[i] = state // 8
    return path


class AStar:
    """A* between the cells of start and goal; the path runs through cell centres, with the exact
    start and goal points in place of their own cells' centres (on a footprint grid, the goal's
    cell centre stays where the footprint cannot drive on to the goal itself).

    On a :class:`~common.planners.footprint.FootprintGrid` it searches positions and headings
    (see the module): ``turn_cost`` (m per 45° turn), ``weight`` and ``band`` (m) shape the cost
    of passing close to obstacles.
    """

    name = "astar"

    def __init__(self, allow_diagonal: bool = True, turn_cost: float = 0.1, weight: float = 2.0,
                 band: float = 0.3) -> None:
        if turn_cost < 0.0 or weight < 0.0 or band <= 0.0:
            raise ValueError("need turn_cost >= 0, weight >= 0 and band > 0")
        self.allow_diagonal = allow_diagonal
        self.turn_cost, self.weight, self.band = turn_cost, weight, band

    def plan(self, grid: OccupancyGrid | FootprintGrid, start: Point, goal: Point) -> np.ndarray | None:
        """World points (N, 2) from start to goal, or None if either is occupied, off the grid or
        unreachable. On a footprint grid ``start`` may carry the robot's heading (x, y, yaw)."""
        (sx, sy), (gx, gy) = (float(v) for v in start[:2]), (float(v) for v in goal[:2])
        if not (grid.is_free(sx, sy) and grid.is_free(gx, gy)):
            return None
        cols = grid.occupied.shape[1]
        s_r, s_c = grid.cell_of(sx, sy)
        g_r, g_c = grid.cell_of(gx, gy)
        if isinstance(grid, FootprintGrid):
            yaw = float(start[2]) if len(start) > 2 else math.nan
            cells = _astar_lattice(*grid.arrays, sx, sy, yaw, g_r * cols + g_c, self.turn_cost, self.weight, self.band)
        else:
            cells = _astar(grid_arrays(grid)[0], s_r * cols + s_c, g_r * cols + g_c, 8 if self.allow_diagonal else 4)
        if cells.size == 0:
            return None
        if cells.size == 1:  # start and goal share a cell
            return np.array([[sx, sy], [gx, gy]])
        x0, y0 = grid.origin
        centres = np.column_stack([x0 + (cells % cols + 0.5) * grid.resolution, y0 + (cells // cols + 0.5) * grid.resolution])
        points = centres.copy()
        points[0] = sx, sy
        points[-1] = gx, gy
        # The lattice checked the footprint into the goal cell's centre, not along a last step bent
        # towards the exact goal: where that step, or the turn onto it from the heading the robot
        # arrives with (the lattice's step between cell centres; at the start, its own), clips,
        # the path ends at the centre.
        if isinstance(grid, FootprintGrid):
            arriving = yaw
            if len(cells) > 2:
                dx, dy = centres[-2] - centres[-3]
                arriving = math.atan2(dy, dx)
            if not grid.path_free(points[-2:], arriving):
                points[-1] = centres[-1]
        return points
