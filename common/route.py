"""A route to the goal on the scenario's static map: what a global planner gives a local policy.

A navigation stack splits the work: a global planner plans on the known map once, a local
controller (here a policy) drives the robot along the plan by its sensors. Among thin posts, a
policy that knows only the goal's bearing drives at the fence between it and the goal; one that
also knows where the route goes drives at the gap (Arena-Rosnav's DRL local planners take a global
planner's subgoal for this reason).

:class:`Route` holds the cost-to-go of every cell of the scenario's grid (Dijkstra's algorithm from
the goal over 8 neighbours). A cell costs its length, more near obstacles so the route keeps to the
middle of a gap, and is closed where the robot's width would not fit (its centre nearer an obstacle
than 0.45 of its width: a gap 1.2 widths across stays open by 0.3 widths). The route is for the
robot's footprint crossing gaps head-on, as the ``passages`` generator guarantees them.

Two readings: :meth:`Route.distance`, the cost-to-go from a point (the potential of a progress
reward that pays for driving toward the gap, not the fence), and :meth:`Route.ahead`, the point
``lookahead`` metres down the route (a pure-pursuit carrot for the observation).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from common.kernel_cache import kernel
from common.occupancy import clamped_cell, scenario_grid
from common.planners.astar import heap_pop, heap_push
from common.scenario import Scenario

CLOSED = 0.45  # of the robot's width: a cell whose centre is nearer an obstacle is closed
NEAR = 1.0  # of the robot's width: within this clearance a cell costs more, up to NEAR_COST times
NEAR_COST = 3.0
CELLS_ACROSS = 10  # grid cells across the robot's width (at most 5 cm each)
_STEPS = np.array([(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)], dtype=np.int64)


@kernel
def _cost_to_go(cost: np.ndarray, seeds: np.ndarray, seed_costs: np.ndarray, resolution: float) -> np.ndarray:
    """Dijkstra from the seed cells (each starting at its own cost) over 8 neighbours: an edge costs
    its length times the mean of its two cells' costs; infinite cells are never entered. A binary
    heap in arrays (A*'s) with stale entries skipped: each relaxation pushes at most one entry."""
    rows, cols = cost.shape
    out = np.full(rows * cols, np.inf)
    flat_cost = cost.ravel()
    keys = np.empty(8 * rows * cols + seeds.shape[0])
    items = np.empty(keys.shape[0], dtype=np.int64)
    size = 0
    for k in range(seeds.shape[0]):
        cell = seeds[k, 0] * cols + seeds[k, 1]
        if math.isfinite(flat_cost[cell]) and seed_costs[k] < out[cell]:
            out[cell] = seed_costs[k]
            heap_push(keys, items, size, seed_costs[k], cell)
            size += 1
    diagonal = math.sqrt(2.0) * resolution
    while size:
        d = keys[0]
        cell = heap_pop(keys, items, size)
        size -= 1
        if d > out[cell]:
            continue
        r, c = cell // cols, cell % cols
        for k in range(8):
            nr, nc = r + _STEPS[k, 0], c + _STEPS[k, 1]
            if nr < 0 or nr >= rows or nc < 0 or nc >= cols:
                continue
            near = nr * cols + nc
            if not math.isfinite(flat_cost[near]):
                continue
            length = diagonal if _STEPS[k, 0] != 0 and _STEPS[k, 1] != 0 else resolution
            nd = d + length * 0.5 * (flat_cost[cell] + flat_cost[near])
            if nd < out[near]:
                out[near] = nd
                heap_push(keys, items, size, nd, near)
                size += 1
    return out.reshape(rows, cols)


@kernel
def _open_near(field: np.ndarray, row: int, col: int) -> tuple[int, int, bool]:
    """(row, col) if its cost-to-go is finite, else the cell of least finite cost-to-go within two
    cells of it (the robot's centre a cell or two into a closed margin); and whether there is one."""
    if math.isfinite(field[row, col]):
        return row, col, True
    rows, cols = field.shape
    best, best_row, best_col = np.inf, row, col
    for r in range(max(0, row - 2), min(rows, row + 3)):
        for c in range(max(0, col - 2), min(cols, col + 3)):
            if field[r, c] < best:
                best, best_row, best_col = field[r, c], r, c
    return best_row, best_col, math.isfinite(best)


@kernel
def _walk(field: np.ndarray, x0: float, y0: float, resolution: float, x: float, y: float, reach: float,
          gx: float, gy: float, threshold: float) -> tuple[float, float, bool]:
    """Follow the field's steepest descent from the open cell at or beside (x, y)'s for ``reach``
    metres of cells, stopping early at a cell within ``threshold`` of the goal; the centre of the
    cell it ends on, and whether there was an open cell to start from."""
    rows, cols = field.shape
    row, col = clamped_cell(x, y, x0, y0, resolution, rows, cols)
    row, col, found = _open_near(field, row, col)
    if not found:
        return gx, gy, False
    travelled = 0.0
    while travelled < reach:
        cx, cy = x0 + (col + 0.5) * resolution, y0 + (row + 0.5) * resolution
        if math.hypot(cx - gx, cy - gy) <= threshold:
            break
        best, br, bc = field[row, col], row, col
        for k in range(8):
            r, c = row + _STEPS[k, 0], col + _STEPS[k, 1]
            if 0 <= r < rows and 0 <= c < cols and field[r, c] < best:
                best, br, bc = field[r, c], r, c
        if br == row and bc == col:
            break  # a seed cell: the route ends here
        travelled += resolution * (math.sqrt(2.0) if br != row and bc != col else 1.0)
        row, col = br, bc
    return x0 + (col + 0.5) * resolution, y0 + (row + 0.5) * resolution, True


@kernel
def _cost_at(field: np.ndarray, x0: float, y0: float, resolution: float, x: float, y: float, gx: float,
             gy: float) -> float:
    """The cost-to-go at (x, y): bilinear between the open cells around it; beside a closed cell,
    the nearest open cell's plus the way to it (:func:`_open_near`); with no open cell near, the
    straight distance to the goal. Compiled: the reward reads it every step."""
    rows, cols = field.shape
    u, v = (x - x0) / resolution - 0.5, (y - y0) / resolution - 0.5
    c0, r0 = int(math.floor(u)), int(math.floor(v))
    total = weight = 0.0
    for r in (r0, r0 + 1):
        wr = 1.0 - abs(v - r)
        for c in (c0, c0 + 1):
            if 0 <= r < rows and 0 <= c < cols and math.isfinite(field[r, c]):
                wc = 1.0 - abs(u - c)
                total += wr * wc * field[r, c]
                weight += wr * wc
    if weight > 1e-9:
        return total / weight
    row, col = clamped_cell(x, y, x0, y0, resolution, rows, cols)
    row, col, found = _open_near(field, row, col)
    if found:
        cx, cy = x0 + (col + 0.5) * resolution, y0 + (row + 0.5) * resolution
        return field[row, col] + math.hypot(cx - x, cy - y)
    return math.hypot(gx - x, gy - y)


def _clearance(occupied: np.ndarray, resolution: float, walls: bool) -> np.ndarray:
    """Each cell centre's distance to the nearest occupied cell's centre, or to the boundary
    walls (a ring of cells just outside the grid) where the world has them; inf with neither."""
    if walls:
        occupied = np.pad(occupied, 1, constant_values=True)
    elif not occupied.any():
        return np.full(occupied.shape, np.inf)
    clearance = ndimage.distance_transform_edt(~occupied, sampling=resolution)
    return clearance[1:-1, 1:-1] if walls else clearance


class Route:
    """The cost-to-go field of a scenario for its robot (see the module), and its readings."""

    def __init__(self, scenario: Scenario, goal_radius: float) -> None:
        self.scenario = scenario  # what it was planned for (an env plans a fixed world's once)
        width = scenario.robot.width_across
        resolution = min(0.05, width / CELLS_ACROSS)
        self.grid = grid = scenario_grid(scenario, resolution, inflation=0.0)  # where the field's cells lie
        self.goal = (float(scenario.goal[0]), float(scenario.goal[1]))
        self.goal_radius = float(goal_radius)
        clearance = _clearance(grid.occupied, resolution, scenario.world.walls)
        near = np.clip(1.0 - clearance / (NEAR * width), 0.0, 1.0)
        cost = 1.0 + (NEAR_COST - 1.0) * near
        cost[clearance < CLOSED * width] = np.inf
        # Seeds: every open cell within the goal radius (the goal may sit in a closed margin), at its distance.
        rows, cols = np.nonzero(np.isfinite(cost))
        cx = grid.origin[0] + (cols + 0.5) * resolution
        cy = grid.origin[1] + (rows + 0.5) * resolution
        gap = np.hypot(cx - self.goal[0], cy - self.goal[1])
        inside = gap <= max(self.goal_radius, resolution)
        if not inside.any() and gap.size:  # no open cell within reach: the nearest open one
            inside = gap == gap.min()
        self.field = _cost_to_go(cost, np.column_stack([rows[inside], cols[inside]]), gap[inside], resolution)

    def distance(self, x: float, y: float) -> float:
        """The cost-to-go from (x, y) (bilinear between the open cells around it); the straight
        distance to the goal where no open cell is near."""
        return _cost_at(self.field, *self.grid.origin, self.grid.resolution, x, y, *self.goal)

    def ahead(self, x: float, y: float, lookahead: float) -> tuple[float, float]:
        """The point ``lookahead`` metres down the route from (x, y) (the goal once nearer than that,
        and the goal where no route leaves (x, y))."""
        ax, ay, found = _walk(self.field, *self.grid.origin, self.grid.resolution, x, y, lookahead, *self.goal,
                              self.goal_radius)
        if not found or math.hypot(ax - self.goal[0], ay - self.goal[1]) <= self.goal_radius:
            return self.goal
        return ax, ay
