"""ORCA among agents: every agent's new velocity, bit for bit as RVO2's ``RVOSimulator::doStep``.

Optimal reciprocal collision avoidance (van den Berg, Guy, Lin and Manocha 2011, "Reciprocal
n-body collision avoidance"): each neighbour within ``neighbor_dist`` (the ``max_neighbors``
nearest) adds a half-plane of velocities, the agent takes the velocity within ``max_speed`` closest
to its preferred one that satisfies them all (a 2D linear program), and when none does, the one
that violates the half-planes least (a 3D linear program).

This reproduces the agent part of RVO2 as pyrvo 0.4.3 ships it (IR-SIM's ``orca`` behaviour calls
it through pyrvo, and IR-SIM's groups add agents only, no obstacles). RVO2 computes in single precision, so every
operation here is float32, in RVO2's order, with its constants (``RVO_EPSILON = 1e-5f``, a
division by a vector's length a multiplication by its inverse): the velocities are then pyrvo's
bits, not just close to them. ``tests/test_orca.py`` checks that against pyrvo step by step.

One difference: RVO2 finds neighbours with a k-d tree, this with a loop over all agents in index
order. Both keep the same ``max_neighbors`` nearest (strictly nearer than ``neighbor_dist``),
sorted by squared distance, except when two candidates are at exactly the same float32 squared
distance: then which one is kept at the limit, and their order (the order of the half-planes, on
which the rounding of the linear programs depends), follows the traversal. RVO2's traversal
depends on how its tree permuted the agents in earlier steps, state a function of one snapshot
does not have, so symmetric layouts (a perfect ring, a grid) can differ in the last bits and then
drift apart; positions from a simulation rarely tie.
"""

from __future__ import annotations

import numpy as np
from numba.extending import register_jitable

from common.kernel_cache import kernel

f32 = np.float32
# float32 constants: a float32 combined with a Python float literal would be computed in float64.
EPSILON = f32(1e-5)  # RVO2's RVO_EPSILON
ZERO, HALF, ONE = f32(0.0), f32(0.5), f32(1.0)


@register_jitable
def _det(ax: np.float32, ay: np.float32, bx: np.float32, by: np.float32) -> np.float32:
    return ax * by - ay * bx


@register_jitable
def _linear_program1(directions, points, line: int, radius: np.float32, opt_x: np.float32, opt_y: np.float32,
                     direction_opt: bool):
    """The optimum on line ``line`` within the speed circle and lines ``0..line-1``: (found, x, y)."""
    dx, dy, px, py = directions[line, 0], directions[line, 1], points[line, 0], points[line, 1]
    dot = px * dx + py * dy
    discriminant = dot * dot + radius * radius - (px * px + py * py)
    if discriminant < ZERO:  # the speed circle misses the line
        return False, ZERO, ZERO
    root = np.sqrt(discriminant)
    t_left, t_right = -dot - root, -dot + root
    for i in range(line):
        denominator = _det(dx, dy, directions[i, 0], directions[i, 1])
        numerator = _det(directions[i, 0], directions[i, 1], px - points[i, 0], py - points[i, 1])
        if abs(denominator) <= EPSILON:  # (nearly) parallel: line i keeps all of this line or none
            if numerator < ZERO:
                return False, ZERO, ZERO
            continue
        t = numerator / denominator
        # Written as std::min / std::max evaluate, so that ties of signed zeros resolve alike.
        if denominator >= ZERO:
            if t < t_right:
                t_right = t
        elif t_left < t:
            t_left = t
        if t_left > t_right:
            return False, ZERO, ZERO
    if direction_opt:
        t = t_right if opt_x * dx + opt_y * dy > ZERO else t_left
    else:
        t = dx * (opt_x - px) + dy * (opt_y - py)
        if t < t_left:
            t = t_left
        elif t > t_right:
            t = t_right
    return True, px + t * dx, py + t * dy


@register_jitable
def _linear_program2(directions, points, count: int, radius: np.float32, opt_x: np.float32, opt_y: np.float32,
                     direction_opt: bool):
    """The optimum within the speed circle and the first ``count`` lines: (first failed line or count, x, y).

    ``direction_opt``: the optimum furthest along the unit vector ``opt``; otherwise the point
    closest to ``opt``. On failure (x, y) is the optimum before the failed line.
    """
    if direction_opt:
        x, y = opt_x * radius, opt_y * radius
    elif opt_x * opt_x + opt_y * opt_y > radius * radius:
        inverse = ONE / np.sqrt(opt_x * opt_x + opt_y * opt_y)
        x, y = opt_x * inverse * radius, opt_y * inverse * radius
    else:
        x, y = opt_x, opt_y
    for i in range(count):
        if _det(directions[i, 0], directions[i, 1], points[i, 0] - x, points[i, 1] - y) > ZERO:
            found, new_x, new_y = _linear_program1(directions, points, i, radius, opt_x, opt_y, direction_opt)
            if not found:
                return i, x, y
            x, y = new_x, new_y
    return count, x, y


@register_jitable
def _linear_program3(directions, points, count: int, begin: int, radius: np.float32, x: np.float32,
                     y: np.float32, projected_directions, projected_points):
    """From line ``begin`` on (where the 2D program failed), the velocity that least violates any line."""
    distance = ZERO
    for i in range(begin, count):
        dix, diy, pix, piy = directions[i, 0], directions[i, 1], points[i, 0], points[i, 1]
        if _det(dix, diy, pix - x, piy - y) > distance:
            # Lines 0..i-1 projected on line i: where each violates no more than line i does.
            projected = 0
            for j in range(i):
                djx, djy, pjx, pjy = directions[j, 0], directions[j, 1], points[j, 0], points[j, 1]
                determinant = _det(dix, diy, djx, djy)
                if abs(determinant) <= EPSILON:
                    if dix * djx + diy * djy > ZERO:  # parallel, same way: line j adds nothing
                        continue
                    qx, qy = HALF * (pix + pjx), HALF * (piy + pjy)
                else:
                    s = _det(djx, djy, pix - pjx, piy - pjy) / determinant
                    qx, qy = pix + s * dix, piy + s * diy
                ex, ey = djx - dix, djy - diy
                inverse = ONE / np.sqrt(ex * ex + ey * ey)
                projected_directions[projected, 0], projected_directions[projected, 1] = ex * inverse, ey * inverse
                projected_points[projected, 0], projected_points[projected, 1] = qx, qy
                projected += 1
            failed, new_x, new_y = _linear_program2(projected_directions, projected_points, projected, radius,
                                                    -diy, dix, True)
            # A failure here is floating-point error only (the current velocity is feasible): keep it.
            if failed >= projected:
                x, y = new_x, new_y
            distance = _det(dix, diy, pix - x, piy - y)
    return x, y


@kernel(error_model="numpy")
def orca_velocities_counted(positions, velocities, preferred, radii, max_speeds, neighbor_dists, max_neighbors,
                            time_horizons, time_step, out) -> int:
    """:func:`orca_velocities`, returning how many agents needed the 3D linear program (for tests).

    ``error_model="numpy"``: a division by zero gives inf/nan as in C++ instead of raising.
    """
    n = positions.shape[0]
    inv_step = ONE / f32(time_step)
    capacity = max(n, 1)  # at most n - 1 neighbours, one line each
    neighbors = np.empty(capacity, np.int64)
    neighbor_dist_sq = np.empty(capacity, np.float32)
    directions = np.empty((capacity, 2), np.float32)
    points = np.empty((capacity, 2), np.float32)
    projected_directions = np.empty((capacity, 2), np.float32)
    projected_points = np.empty((capacity, 2), np.float32)
    fallbacks = 0
    for a in range(n):
        x, y = f32(positions[a, 0]), f32(positions[a, 1])
        vx, vy = f32(velocities[a, 0]), f32(velocities[a, 1])
        radius, max_speed = f32(radii[a]), f32(max_speeds[a])
        limit = max_neighbors[a]

        # The `limit` nearest, sorted by squared distance; the range shrinks once `limit` are held.
        held = 0
        range_sq = f32(neighbor_dists[a]) * f32(neighbor_dists[a])
        for b in range(n if limit > 0 else 0):
            if b == a:
                continue
            ox, oy = x - f32(positions[b, 0]), y - f32(positions[b, 1])
            dist_sq = ox * ox + oy * oy
            if not dist_sq < range_sq:
                continue
            if held < limit:
                held += 1
            k = held - 1  # when full, the farthest held one is dropped
            while k > 0 and dist_sq < neighbor_dist_sq[k - 1]:
                neighbors[k], neighbor_dist_sq[k] = neighbors[k - 1], neighbor_dist_sq[k - 1]
                k -= 1
            neighbors[k], neighbor_dist_sq[k] = b, dist_sq
            if held == limit:
                range_sq = neighbor_dist_sq[held - 1]

        inv_horizon = ONE / f32(time_horizons[a])
        for k in range(held):
            b = neighbors[k]
            rx, ry = f32(positions[b, 0]) - x, f32(positions[b, 1]) - y
            rvx, rvy = vx - f32(velocities[b, 0]), vy - f32(velocities[b, 1])
            dist_sq = rx * rx + ry * ry
            combined = radius + f32(radii[b])
            combined_sq = combined * combined
            if dist_sq > combined_sq:
                # Apart: the velocity obstacle is a cone cut off by a circle of radius combined / horizon.
                # w: from the cut-off circle's centre to the relative velocity.
                wx, wy = rvx - inv_horizon * rx, rvy - inv_horizon * ry
                w_length_sq = wx * wx + wy * wy
                dot = wx * rx + wy * ry
                if dot < ZERO and dot * dot > combined_sq * w_length_sq:  # nearest the cut-off circle
                    w_length = np.sqrt(w_length_sq)
                    inverse = ONE / w_length
                    unit_x, unit_y = wx * inverse, wy * inverse
                    dx, dy = unit_y, -unit_x
                    scale = combined * inv_horizon - w_length
                    ux, uy = scale * unit_x, scale * unit_y
                else:  # nearest a leg of the cone
                    leg = np.sqrt(dist_sq - combined_sq)
                    inverse = ONE / dist_sq
                    if _det(rx, ry, wx, wy) > ZERO:
                        dx, dy = (rx * leg - ry * combined) * inverse, (rx * combined + ry * leg) * inverse
                    else:
                        dx, dy = -((rx * leg + ry * combined) * inverse), -((-rx * combined + ry * leg) * inverse)
                    along = rvx * dx + rvy * dy
                    ux, uy = along * dx - rvx, along * dy - rvy
            else:
                # Overlapping: get apart within one time step (cut-off circle of the time step).
                wx, wy = rvx - inv_step * rx, rvy - inv_step * ry
                w_length = np.sqrt(wx * wx + wy * wy)
                inverse = ONE / w_length
                unit_x, unit_y = wx * inverse, wy * inverse
                dx, dy = unit_y, -unit_x
                scale = combined * inv_step - w_length
                ux, uy = scale * unit_x, scale * unit_y
            # Reciprocal: each of the two takes half of the change u.
            directions[k, 0], directions[k, 1] = dx, dy
            points[k, 0], points[k, 1] = vx + HALF * ux, vy + HALF * uy

        failed, new_x, new_y = _linear_program2(directions, points, held, max_speed, f32(preferred[a, 0]),
                                                f32(preferred[a, 1]), False)
        if failed < held:
            fallbacks += 1
            new_x, new_y = _linear_program3(directions, points, held, failed, max_speed, new_x, new_y,
                                            projected_directions, projected_points)
        out[a, 0], out[a, 1] = new_x, new_y
    return fallbacks


@kernel
def orca_velocities(positions, velocities, preferred, radii, max_speeds, neighbor_dists, max_neighbors,
                    time_horizons, time_step, out) -> None:
    """Every agent's new ORCA velocity into ``out`` (N, 2), as one RVO2 ``doStep`` computes them.

    ``positions``, ``velocities`` (the current ones: the previous step's new velocities),
    ``preferred``: float32 (N, 2); ``radii``, ``max_speeds``, ``neighbor_dists``, ``time_horizons``:
    float32 (N,); ``max_neighbors``: int64 (N,), 0 for none; ``time_step``: a float32 scalar (it
    bounds how fast overlapping agents separate). All agents are computed from the same inputs,
    which are not modified.
    """
    orca_velocities_counted(positions, velocities, preferred, radii, max_speeds, neighbor_dists, max_neighbors,
                            time_horizons, time_step, out)
