"""RRT in continuous space, collision-checked against an occupancy grid, or on a
:class:`~common.planners.footprint.FootprintGrid` for the robot's footprint: each edge driven
straight, heading along it, after a turn on the spot at the node it leaves from.

All randomness is drawn up front with the planner's ``numpy.random.Generator`` and handed to a
numba kernel, so a seed fixes the result exactly and the kernel itself stays deterministic.
"""

from __future__ import annotations

import math

import numpy as np

from common.kernel_cache import kernel
from common.occupancy import OccupancyGrid
from common.planners.base import Point
from common.planners.collision import segment_free_sampled
from common.planners.footprint import FootprintGrid, kernel_arrays, segment_free, turn_free


@kernel
def _edge_free(field: np.ndarray, occupied: np.ndarray, x0: float, y0: float, resolution: float, centres: np.ndarray,
               radii: np.ndarray, exact: int, boxes: np.ndarray, margin: float, heading: float, ax: float, ay: float,
               bx: float, by: float) -> bool:
    """Whether a tree edge a -> b is free: sampled on the grid, or (a ``field`` given) for the
    footprint turning at a from ``heading`` (NaN: no turn to check) and driving straight on."""
    if field.size == 0:
        return segment_free_sampled(occupied, x0, y0, resolution, ax, ay, bx, by)
    if not math.isnan(heading) and not turn_free(field, occupied, x0, y0, resolution, centres, radii, exact, boxes,
                                                 margin, ax, ay, heading, math.atan2(by - ay, bx - ax)):
        return False
    return segment_free(field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin, ax, ay, bx, by)


@kernel
def _rrt(field: np.ndarray, occupied: np.ndarray, x0: float, y0: float, resolution: float, centres: np.ndarray,
         radii: np.ndarray, exact: int, boxes: np.ndarray, margin: float, start: np.ndarray, heading: float,
         goal: np.ndarray, draws: np.ndarray, goal_bias: float, step: float) -> np.ndarray:
    """The tree's path start → goal as world points (N, 2), or an empty (0, 2) array. Edges are
    checked by :func:`_edge_free` (an empty ``field``: on ``occupied`` alone; the root's
    ``heading`` NaN: any).

    ``draws`` holds one row per iteration: a uniform sample in [0, 1)² scaled to the grid, and a
    uniform number deciding whether this iteration steers towards the goal instead.
    """
    width, height = occupied.shape[1] * resolution, occupied.shape[0] * resolution
    iterations = draws.shape[0]
    nodes = np.empty((iterations + 1, 2))
    headings = np.empty(iterations + 1)  # the heading each node is reached with
    parent = np.empty(iterations + 1, dtype=np.int64)
    nodes[0] = start
    headings[0] = heading
    parent[0] = -1
    count = 1
    last = -1
    if math.hypot(goal[0] - start[0], goal[1] - start[1]) <= step and _edge_free(
            field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin, heading, start[0], start[1],
            goal[0], goal[1]):
        last = 0
    for i in range(iterations):
        if last >= 0:
            break
        if draws[i, 2] < goal_bias:
            qx, qy = goal[0], goal[1]
        else:
            qx, qy = x0 + draws[i, 0] * width, y0 + draws[i, 1] * height
        # Nearest node by linear scan: trees stay in the low thousands, where a k-d tree does not pay.
        best, best_d2 = 0, math.inf
        for j in range(count):
            d2 = (nodes[j, 0] - qx) ** 2 + (nodes[j, 1] - qy) ** 2
            if d2 < best_d2:
                best, best_d2 = j, d2
        d = math.sqrt(best_d2)
        if d == 0.0:
            continue
        f = min(1.0, step / d)
        nx, ny = nodes[best, 0] + f * (qx - nodes[best, 0]), nodes[best, 1] + f * (qy - nodes[best, 1])
        if not _edge_free(field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin, headings[best],
                          nodes[best, 0], nodes[best, 1], nx, ny):
            continue
        nodes[count, 0] = nx
        nodes[count, 1] = ny
        headings[count] = math.atan2(ny - nodes[best, 1], nx - nodes[best, 0])
        parent[count] = best
        count += 1
        if math.hypot(goal[0] - nx, goal[1] - ny) <= step and _edge_free(
                field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin, headings[count - 1], nx, ny,
                goal[0], goal[1]):
            last = count - 1
    if last < 0:
        return np.empty((0, 2))
    length = 2  # the goal, then the chain of nodes back to the root
    j = last
    while parent[j] >= 0:
        j = parent[j]
        length += 1
    path = np.empty((length, 2))
    path[length - 1] = goal
    j = last
    for k in range(length - 2, -1, -1):
        path[k] = nodes[j]
        j = parent[j]
    return path


class RRT:
    """Rapidly-exploring random tree with goal bias; each ``plan`` draws fresh samples from the planner's
    generator, so two planners with the same seed return the same paths call by call."""

    name = "rrt"

    def __init__(self, step_size: float = 0.3, goal_bias: float = 0.1, max_iterations: int = 5000,
                 seed: int | None = None, rng: np.random.Generator | None = None) -> None:
        if step_size <= 0.0 or not 0.0 <= goal_bias <= 1.0 or max_iterations < 1:
            raise ValueError("need step_size > 0, goal_bias in [0, 1] and max_iterations >= 1")
        self.step_size = step_size
        self.goal_bias = goal_bias
        self.max_iterations = max_iterations
        self.rng = rng if rng is not None else np.random.default_rng(seed)

    def plan(self, grid: OccupancyGrid | FootprintGrid, start: Point, goal: Point) -> np.ndarray | None:
        """World points (N, 2) from start to goal, or None if either is blocked or no path is found
        in time. On a footprint grid ``start`` may carry the robot's heading (x, y, yaw)."""
        s = np.array([float(start[0]), float(start[1])])
        g = np.array([float(goal[0]), float(goal[1])])
        if not (grid.is_free(*s) and grid.is_free(*g)):
            return None
        draws = self.rng.random((self.max_iterations, 3))
        heading = float(start[2]) if isinstance(grid, FootprintGrid) and len(start) > 2 else math.nan
        path = _rrt(*kernel_arrays(grid), s, heading, g, draws, self.goal_bias, self.step_size)
        return path if len(path) else None
