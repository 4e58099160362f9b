"""RRT in continuous space, collision-checked against an occupancy grid, or on a
:class:`~common.planners.footprint.FootprintGrid` for the robot's footprint: each edge driven
straight, heading along it, after a turn on the spot at the node it leaves from.

Plain RRT returns the first path its tree reaches the goal by: a route through whichever gap the
samples happened to find first, a different one every plan. With ``optimise`` the planner is
informed RRT* (Karaman & Frazzoli 2011, Gammell et al. 2014): it spends its whole budget, each
new node taking the cheapest parent among its k nearest and offering itself as a cheaper parent
to them (rewiring), and once a path exists it samples only the ellipse of points that could lie
on a shorter one. Its paths approach the shortest, so replans on a growing map agree on the route.

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
    chain = _chain(nodes, parent, last)
    path = np.empty((chain.shape[0] + 1, 2))
    path[:-1] = chain
    path[-1] = goal
    return path


@kernel
def _chain(nodes: np.ndarray, parent: np.ndarray, last: int) -> np.ndarray:
    """The tree's nodes from the root to ``last`` (N, 2)."""
    length = 1
    j = last
    while parent[j] >= 0:
        j = parent[j]
        length += 1
    path = np.empty((length, 2))
    j = last
    for k in range(length - 1, -1, -1):
        path[k] = nodes[j]
        j = parent[j]
    return path


@kernel
def _turns_free(field: np.ndarray, occupied: np.ndarray, x0: float, y0: float, resolution: float,
                centres: np.ndarray, radii: np.ndarray, exact: int, boxes: np.ndarray, margin: float,
                nodes: np.ndarray, headings: np.ndarray, first_child: np.ndarray, next_sibling: np.ndarray, q: int,
                heading: float) -> bool:
    """Whether the footprint, arriving at node ``q`` heading ``heading``, can turn there onto the
    edge to each of its children (rewiring changes the heading a node is reached with)."""
    c = first_child[q]
    while c >= 0:
        if not turn_free(field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin, nodes[q, 0],
                         nodes[q, 1], heading, headings[c]):
            return False
        c = next_sibling[c]
    return True


@kernel
def _reparent(parent: np.ndarray, first_child: np.ndarray, next_sibling: np.ndarray, q: int, p: int) -> None:
    """Move node ``q`` (with its subtree) from its parent's children, if any, to ``p``'s."""
    old = parent[q]
    if old >= 0:
        if first_child[old] == q:
            first_child[old] = next_sibling[q]
        else:
            c = first_child[old]
            while next_sibling[c] != q:
                c = next_sibling[c]
            next_sibling[c] = next_sibling[q]
    parent[q] = p
    next_sibling[q] = first_child[p]
    first_child[p] = q


@kernel
def _lower_costs(cost: np.ndarray, first_child: np.ndarray, next_sibling: np.ndarray, q: int, by: float,
                 stack: np.ndarray) -> None:
    """Lower the cost of ``q``'s descendants by ``by`` (``q`` itself already lowered)."""
    top = 0
    c = first_child[q]
    while c >= 0:
        stack[top] = c
        top += 1
        c = next_sibling[c]
    while top > 0:
        top -= 1
        j = stack[top]
        cost[j] -= by
        c = first_child[j]
        while c >= 0:
            stack[top] = c
            top += 1
            c = next_sibling[c]


@kernel
def _scan_bin(nodes: np.ndarray, head: np.ndarray, next_in_bin: np.ndarray, r: int, c: int, qx: float, qy: float,
              k: int, skip: int, out: np.ndarray, out_d: np.ndarray, found: int) -> int:
    """Merge the nodes of bin (r, c), but ``skip``, into the ``found`` nearest so far (at most ``k``)."""
    j = head[r, c]
    while j >= 0:
        if j != skip:
            d = math.hypot(nodes[j, 0] - qx, nodes[j, 1] - qy)
            if found < k or d < out_d[found - 1]:
                m = found if found < k else k - 1
                while m > 0 and out_d[m - 1] > d:
                    out[m], out_d[m] = out[m - 1], out_d[m - 1]
                    m -= 1
                out[m], out_d[m] = j, d
                found = min(found + 1, k)
        j = next_in_bin[j]
    return found


@kernel
def _nearest_k(nodes: np.ndarray, head: np.ndarray, next_in_bin: np.ndarray, x0: float, y0: float, side: float,
               qx: float, qy: float, k: int, skip: int, out: np.ndarray, out_d: np.ndarray) -> int:
    """The (up to) ``k`` nodes nearest (qx, qy), but ``skip``, into ``out`` by distance (``out_d``);
    how many. Nodes sit in square bins ``side`` wide (``head`` per bin, chained by ``next_in_bin``),
    searched in rings outward until the next ring lies beyond the k-th nearest found."""
    rows, cols = head.shape
    # Rings are counted from the bin of the query's nearest point on the binned area: no point of
    # a bin R rings out lies nearer to it (or, by projection onto a rectangle, to the query) than (R - 1) bins.
    bc = min(max(int((qx - x0) / side), 0), cols - 1)
    br = min(max(int((qy - y0) / side), 0), rows - 1)
    found = 0
    for ring in range(max(rows, cols)):
        if found == k and (ring - 1) * side >= out_d[k - 1]:
            break
        for r in range(max(br - ring, 0), min(br + ring + 1, rows)):
            if abs(r - br) == ring:  # the ring's top or bottom row
                for c in range(max(bc - ring, 0), min(bc + ring + 1, cols)):
                    found = _scan_bin(nodes, head, next_in_bin, r, c, qx, qy, k, skip, out, out_d, found)
                continue
            if bc - ring >= 0:
                found = _scan_bin(nodes, head, next_in_bin, r, bc - ring, qx, qy, k, skip, out, out_d, found)
            if bc + ring < cols:
                found = _scan_bin(nodes, head, next_in_bin, r, bc + ring, qx, qy, k, skip, out, out_d, found)
    return found


@kernel
def _bin(head: np.ndarray, next_in_bin: np.ndarray, x0: float, y0: float, side: float, node: int, x: float,
         y: float) -> None:
    """File ``node`` at (x, y) in its bin."""
    c = min(max(int((x - x0) / side), 0), head.shape[1] - 1)
    r = min(max(int((y - y0) / side), 0), head.shape[0] - 1)
    next_in_bin[node] = head[r, c]
    head[r, c] = node


@kernel
def _rrt_star(field: np.ndarray, occupied: np.ndarray, x0: float, y0: float, resolution: float, centres: np.ndarray,
              radii: np.ndarray, exact: int, boxes: np.ndarray, margin: float, start: np.ndarray, heading: float,
              goal: np.ndarray, draws: np.ndarray, goal_bias: float, step: float, turns: bool) -> np.ndarray:
    """Informed RRT* over all of ``draws``: the cheapest path start → goal its tree holds at the
    end, as world points (N, 2), or an empty (0, 2) array. Edges are checked by :func:`_edge_free`
    (an empty ``field``: on ``occupied`` alone); ``turns``: whether a turn on the spot needs checking
    (a footprint that does not turn freely), from the root's ``heading`` too unless it is NaN.

    ``draws`` holds one row per iteration: two uniform numbers placing the sample (on the grid, or
    once a path exists in the ellipse of shorter paths) and one deciding, while there is no path
    yet, whether this iteration steers towards the goal instead.
    """
    width, height = occupied.shape[1] * resolution, occupied.shape[0] * resolution
    iterations = draws.shape[0]
    size = iterations + 2  # the root, a node per iteration, the goal
    nodes = np.empty((size, 2))
    headings = np.empty(size)  # the heading each node is reached with
    cost = np.empty(size)  # path length from the root
    parent = np.full(size, -1, dtype=np.int64)
    first_child = np.full(size, -1, dtype=np.int64)
    next_sibling = np.full(size, -1, dtype=np.int64)
    stack = np.empty(size, dtype=np.int64)
    # Nearest-neighbour queries through bins: a linear scan of every node per query would make the
    # whole budget's cost quadratic in it. A fifth of a step wide, as the informed samples crowd
    # the ellipse: bins a step wide held dozens of nodes each there, and rrt_pursuit's episodes
    # took twice as long (the neighbours found, and so the paths, are the same whatever the width).
    # On a large map, wider: at most 16 bins a node, so the bins never outgrow the tree.
    side = max(step / 5.0, math.sqrt(width * height / (16.0 * size)))
    head = np.full((int(math.ceil(height / side)), int(math.ceil(width / side))), -1, dtype=np.int64)
    next_in_bin = np.empty(size, dtype=np.int64)
    near = np.empty(size, dtype=np.int64)
    near_d = np.empty(size)
    keys = np.empty(size)
    nodes[0] = start
    _bin(head, next_in_bin, x0, y0, side, 0, start[0], start[1])
    headings[0] = heading if turns else math.nan
    cost[0] = 0.0
    count = 1
    target = -1  # the goal's node, once the tree reaches it
    c_min = math.hypot(goal[0] - start[0], goal[1] - start[1])
    cx, cy = 0.5 * (start[0] + goal[0]), 0.5 * (start[1] + goal[1])
    axis = math.atan2(goal[1] - start[1], goal[0] - start[0])
    # k nearest for choosing a parent and rewiring: k(n) = e (1 + 1/d) log n keeps RRT* asymptotically
    # optimal in d = 2 dimensions (Karaman & Frazzoli 2011, the k-nearest form).
    k_rrt = math.e * 1.5
    for i in range(-1, iterations):
        if i < 0:  # first try the goal itself, as plain RRT does
            if c_min > step:
                continue
            qx, qy = goal[0], goal[1]
        elif target >= 0:
            # Informed: uniform in the ellipse with the start and goal as foci, major axis the best cost.
            c_best = cost[target]
            a = 0.5 * c_best
            b = 0.5 * math.sqrt(max(c_best * c_best - c_min * c_min, 0.0))
            r, phi = math.sqrt(draws[i, 0]), 2.0 * math.pi * draws[i, 1]
            ex, ey = a * r * math.cos(phi), b * r * math.sin(phi)
            qx = cx + ex * math.cos(axis) - ey * math.sin(axis)
            qy = cy + ex * math.sin(axis) + ey * math.cos(axis)
        elif draws[i, 2] < goal_bias:
            qx, qy = goal[0], goal[1]
        else:
            qx, qy = x0 + draws[i, 0] * width, y0 + draws[i, 1] * height
        # The goal's node is a leaf: nothing grows from it.
        _nearest_k(nodes, head, next_in_bin, x0, y0, side, qx, qy, 1, target, near, near_d)
        best, d = near[0], near_d[0]
        if d == 0.0:
            continue
        f = min(1.0, step / d)
        nx, ny = nodes[best, 0] + f * (qx - nodes[best, 0]), nodes[best, 1] + f * (qy - nodes[best, 1])
        reaches_goal = target < 0 and math.hypot(goal[0] - nx, goal[1] - ny) <= 1e-12
        if not _edge_free(field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin, headings[best],
                          nodes[best, 0], nodes[best, 1], nx, ny):
            continue
        # The k nearest nodes to the new one (the goal's node among them, to be rewired, never a parent).
        k = min(count, int(math.ceil(k_rrt * math.log(count + 1.0))))
        found = _nearest_k(nodes, head, next_in_bin, x0, y0, side, nx, ny, k, -1, near, near_d)
        # Parent: the cheapest of them with a free edge to the new node; the nearest, checked above, if none.
        for m in range(found):
            keys[m] = math.inf if near[m] == target else cost[near[m]] + near_d[m]
        chosen, chosen_cost = best, cost[best] + math.hypot(nx - nodes[best, 0], ny - nodes[best, 1])
        while True:
            m_min, key = -1, chosen_cost
            for m in range(found):
                if keys[m] < key - 1e-12:
                    m_min, key = m, keys[m]
            if m_min < 0:
                break
            keys[m_min] = math.inf
            q = near[m_min]
            if _edge_free(field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin, headings[q],
                          nodes[q, 0], nodes[q, 1], nx, ny):
                chosen, chosen_cost = q, key
                break
        new = count
        count += 1
        nodes[new, 0], nodes[new, 1] = nx, ny
        headings[new] = math.atan2(ny - nodes[chosen, 1], nx - nodes[chosen, 0]) if turns else math.nan
        cost[new] = chosen_cost
        _reparent(parent, first_child, next_sibling, new, chosen)
        _bin(head, next_in_bin, x0, y0, side, new, nx, ny)
        if reaches_goal:
            target = new
            continue
        # Rewire: the new node becomes the parent of those it offers a shorter way to.
        for m in range(found):
            q = near[m]
            through = chosen_cost + near_d[m]
            if q == 0 or q == chosen or through >= cost[q] - 1e-9:
                continue
            arrive = math.atan2(nodes[q, 1] - ny, nodes[q, 0] - nx) if turns else math.nan
            if not _edge_free(field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin,
                              headings[new], nx, ny, nodes[q, 0], nodes[q, 1]):
                continue
            if turns and not _turns_free(field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin,
                                         nodes, headings, first_child, next_sibling, q, arrive):
                continue
            _reparent(parent, first_child, next_sibling, q, new)
            headings[q] = arrive
            _lower_costs(cost, first_child, next_sibling, q, cost[q] - through, stack)
            cost[q] = through
        # The first node within a step of the goal with a free edge to it takes the goal as a leaf;
        # later nodes offer it cheaper parents by rewiring.
        if target < 0 and math.hypot(goal[0] - nx, goal[1] - ny) <= step and _edge_free(
                field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin, headings[new], nx, ny,
                goal[0], goal[1]):
            target = count
            count += 1
            nodes[target, 0], nodes[target, 1] = goal[0], goal[1]
            headings[target] = math.atan2(goal[1] - ny, goal[0] - nx) if turns else math.nan
            cost[target] = chosen_cost + math.hypot(goal[0] - nx, goal[1] - ny)
            _reparent(parent, first_child, next_sibling, target, new)
            _bin(head, next_in_bin, x0, y0, side, target, goal[0], goal[1])
    if target < 0:
        return np.empty((0, 2))
    return _chain(nodes, parent, target)


class RRT:
    """Rapidly-exploring random tree with goal bias; each ``plan`` draws fresh samples from the planner's
    generator, so two planners with the same seed return the same paths call by call. With
    ``optimise``, informed RRT* over all ``max_iterations`` (see the module)."""

    name = "rrt"

    def __init__(self, step_size: float = 0.3, goal_bias: float = 0.1, max_iterations: int = 5000,
                 seed: int | None = None, rng: np.random.Generator | None = None, optimise: bool = False) -> None:
        if step_size <= 0.0 or not 0.0 <= goal_bias <= 1.0 or max_iterations < 1:
            raise ValueError("need step_size > 0, goal_bias in [0, 1] and max_iterations >= 1")
        self.step_size = step_size
        self.goal_bias = goal_bias
        self.max_iterations = max_iterations
        self.optimise = optimise
        self.rng = rng if rng is not None else np.random.default_rng(seed)

    def plan(self, grid: OccupancyGrid | FootprintGrid, start: Point, goal: Point) -> np.ndarray | None:
        """World points (N, 2) from start to goal, or None if either is blocked or no path is found
        in time. On a footprint grid ``start`` may carry the robot's heading (x, y, yaw), ignored
        where the footprint facing it does not keep the grid's margin."""
        s = np.array([float(start[0]), float(start[1])])
        g = np.array([float(goal[0]), float(goal[1])])
        if not (grid.is_free(*s) and grid.is_free(*g)):
            return None
        draws = self.rng.random((self.max_iterations, 3))
        footprint = isinstance(grid, FootprintGrid)
        heading = float(start[2]) if footprint and len(start) > 2 else math.nan
        if not (math.isnan(heading) or grid.pose_free(*s, heading)):
            # Already closer than the margin facing that way (it stands where it may face another):
            # every turn from there would be refused, and the robot would never move again.
            heading = math.nan
        if self.optimise:
            turns = footprint and not grid.footprint.turns_freely
            path = _rrt_star(*kernel_arrays(grid), s, heading, g, draws, self.goal_bias, self.step_size, turns)
        else:
            path = _rrt(*kernel_arrays(grid), s, heading, g, draws, self.goal_bias, self.step_size)
        return path if len(path) else None
