"""The social force model (Helbing-Molnar 1995, Moussaïd-Helbing 2009) as IR-SIM 2.12 computes it.

One agent's next world-frame velocity is its current one plus a step of three weighted forces:
relaxation toward the desired velocity (``vmax`` along its desire), an anisotropic repulsion from
each neighbour within ``neighbor_threshold`` (the interaction vector t = lambda (v - v_other) + d,
its range B = gamma |t|, a decay along t and a sideways push by the angle between t and d), and an
exponential push from every line obstacle within 5 sigma of the body, clamped at its surface. The
result is capped at ``vmax``. The arithmetic follows IR-SIM's per-agent model term by term, bit
for bit, and its batched group model to within rounding (its vector arithmetic and hypot round a
few steps differently from the square roots here, which cost a third less), so a crowd moves as
IR-SIM moves it; IR-SIM's social groups (Moussaïd 2010) are not modelled.
"""

from __future__ import annotations

import math

import numpy as np

from common.geometry import beyond_segment_bounds
from common.kernel_cache import uncounted
from common.motion.steering import c_pow

# The parameter vector :func:`social_force_velocity` reads, by index (names as IR-SIM's).
VMAX, STEP_TIME, NEIGHBOR_THRESHOLD, RELAXATION_TIME, FORCE_DESIRED, FORCE_SOCIAL, FORCE_OBSTACLE, SIGMA_OBSTACLE, \
    LAMBDA_IMPORTANCE, GAMMA, N_ANGULAR, N_VELOCITY, SAFETY_RADIUS = range(13)
PARAMETERS = ("vmax", "step_time", "neighbor_threshold", "relaxation_time", "force_factor_desired",
              "force_factor_social", "force_factor_obstacle", "sigma_obstacle", "lambda_importance", "gamma",
              "n_angular", "n_velocity", "safety_radius")


@uncounted
def _square(value: float, exact: bool) -> float:
    """``value ** 2`` as IR-SIM's per-agent model has it (the C library's pow, which differs from
    value * value in the last bit at times) if ``exact``, else as its batched model has it (value * value)."""
    return c_pow(value, 2.0) if exact else value * value


@uncounted
def _within(dx: float, dy: float, reach: float) -> bool:
    """Whether a neighbour (dx, dy) away is within ``reach`` by IR-SIM's per-agent test with pow
    (decided by plain products, a hundred times cheaper, unless it is within rounding of the edge)."""
    distance, limit = dx * dx + dy * dy, reach * reach
    if abs(distance - limit) > 1e-9 * limit:
        return distance < limit
    return c_pow(dx, 2.0) + c_pow(dy, 2.0) < c_pow(reach, 2.0)


@uncounted
def pair_force(x: float, y: float, vx: float, vy: float, ox: float, oy: float, ovx: float, ovy: float,
               p: np.ndarray, exact: bool) -> tuple[float, float, bool]:
    """The social force on an agent at (x, y) moving at (vx, vy) from one at (ox, oy) moving at
    (ovx, ovy), and whether the other counts (within reach, not on top of it). Swapping the two
    gives exactly the opposite force, when both have the same parameters: t = lambda dv + d turns
    round, the angle between them does not."""
    reach = p[NEIGHBOR_THRESHOLD]
    dx, dy = ox - x, oy - y
    squared = dx * dx + dy * dy
    # Most of a crowd's pairs stand well beyond reach: decided by the square, whose rounding
    # cannot carry it across the edge by a millionth, before any square root is taken.
    if squared > reach * reach * (1.0 + 1e-6):
        return 0.0, 0.0, False
    if exact and not _within(dx, dy, reach):
        return 0.0, 0.0, False
    dist = math.sqrt(squared)
    if dist < 1e-6 or dist > reach:
        return 0.0, 0.0, False
    d_hat_x, d_hat_y = dx / dist, dy / dist
    tx = p[LAMBDA_IMPORTANCE] * (vx - ovx) + d_hat_x
    ty = p[LAMBDA_IMPORTANCE] * (vy - ovy) + d_hat_y
    t_norm = math.sqrt(tx * tx + ty * ty)
    if t_norm < 1e-9:
        return 0.0, 0.0, False
    t_hat_x, t_hat_y = tx / t_norm, ty / t_norm
    b = p[GAMMA] * t_norm
    theta = math.atan2(t_hat_x * d_hat_y - t_hat_y * d_hat_x, t_hat_x * d_hat_x + t_hat_y * d_hat_y)
    gap = max(dist - 2.0 * p[SAFETY_RADIUS], 0.0)
    f_v = -math.exp(-gap / b - _square(p[N_VELOCITY] * b * theta, exact))
    sign = 1.0 if theta > 0 else (-1.0 if theta < 0 else 0.0)
    f_a = -sign * math.exp(-gap / b - _square(p[N_ANGULAR] * b * theta, exact))
    return f_v * t_hat_x + f_a * -t_hat_y, f_v * t_hat_y + f_a * t_hat_x, True


SOCIAL = np.array([NEIGHBOR_THRESHOLD, LAMBDA_IMPORTANCE, GAMMA, N_ANGULAR, N_VELOCITY, SAFETY_RADIUS])  # pair_force's


@uncounted
def _social_force(x: float, y: float, vx: float, vy: float, neighbors: np.ndarray, count: int,
                  p: np.ndarray, exact: bool) -> tuple[float, float]:
    fx = fy = 0.0
    for k in range(count):
        gx, gy, counts = pair_force(x, y, vx, vy, neighbors[k, 0], neighbors[k, 1], neighbors[k, 2], neighbors[k, 3],
                                    p, exact)
        if counts:
            fx += gx
            fy += gy
    return fx, fy


@uncounted
def _obstacle_force(x: float, y: float, radius: float, segments: np.ndarray, p: np.ndarray) -> tuple[float, float]:
    fx = fy = 0.0
    sigma = p[SIGMA_OBSTACLE]
    cutoff = 5.0 * sigma + radius
    reach = cutoff + 1e-9  # a margin for rounding
    for k in range(segments.shape[0]):
        x1, y1, x2, y2 = segments[k, 0], segments[k, 1], segments[k, 2], segments[k, 3]
        if beyond_segment_bounds(x, y, x1, y1, x2, y2, reach):
            continue
        ex, ey = x2 - x1, y2 - y1
        l2 = ex * ex + ey * ey
        if l2 < 1e-12:
            cx, cy = x1, y1
        else:
            t = min(max(((x - x1) * ex + (y - y1) * ey) / l2, 0.0), 1.0)
            cx, cy = x1 + t * ex, y1 + t * ey
        dx, dy = x - cx, y - cy
        dist = math.sqrt(dx * dx + dy * dy)
        if dist > cutoff:
            continue
        if dist < 1e-9:
            fx += 1.0  # on the line: a push along +x, as IR-SIM's
            continue
        amount = math.exp(-max(dist - radius, 0.0) / sigma)
        fx += amount * dx / dist
        fy += amount * dy / dist
    return fx, fy


@uncounted
def desire(desired_x: float, desired_y: float, vmax: float, group: bool) -> tuple[float, float]:
    """The desired velocity at ``vmax`` along the desire (IR-SIM renormalises the goal-seeking
    velocity it is given): a group's norm is NumPy's hypot, an agent's own ``(...) ** 0.5``."""
    if group:
        norm = math.hypot(desired_x, desired_y)
    else:
        norm = c_pow(desired_x * desired_x + desired_y * desired_y, 0.5)
    if norm > 1e-9:
        return vmax * desired_x / norm, vmax * desired_y / norm
    return desired_x, desired_y


@uncounted
def social_force_velocity(x: float, y: float, vx: float, vy: float, radius: float, desired_x: float,
                          desired_y: float, neighbors: np.ndarray, count: int, segments: np.ndarray,
                          p: np.ndarray, group: bool = False) -> tuple[float, float]:
    """The next world-frame velocity of an agent at (x, y) moving at (vx, vy) that desires to move
    at (desired_x, desired_y) (:func:`desire`), among the first ``count`` rows of ``neighbors``
    (x, y, vx, vy, radius) and the line obstacles ``segments`` (x1, y1, x2, y2), with the
    parameters ``p`` (indexed by this module's constants); ``group``: as IR-SIM's batched group
    model rounds it, else as its per-agent model."""
    social = _social_force(x, y, vx, vy, neighbors, count, p, not group)
    return velocity_under(x, y, vx, vy, radius, desired_x, desired_y, social, segments, p)


@uncounted
def velocity_under(x: float, y: float, vx: float, vy: float, radius: float, desired_x: float, desired_y: float,
                   social: tuple[float, float], segments: np.ndarray, p: np.ndarray) -> tuple[float, float]:
    """The next velocity under the social force ``social`` (summed from :func:`pair_force`), the
    relaxation toward the desire and the line obstacles' push, capped at ``vmax``."""
    vmax = p[VMAX]
    tau = p[RELAXATION_TIME]
    social_x, social_y = social
    obstacle_x, obstacle_y = _obstacle_force(x, y, radius, segments, p)
    ax = p[FORCE_DESIRED] * ((desired_x - vx) / tau) + p[FORCE_SOCIAL] * social_x + p[FORCE_OBSTACLE] * obstacle_x
    ay = p[FORCE_DESIRED] * ((desired_y - vy) / tau) + p[FORCE_SOCIAL] * social_y + p[FORCE_OBSTACLE] * obstacle_y
    vx = vx + p[STEP_TIME] * ax
    vy = vy + p[STEP_TIME] * ay
    speed = math.sqrt(vx * vx + vy * vy)
    if speed > vmax and speed > 1e-9:
        scale = vmax / speed
        vx, vy = vx * scale, vy * scale
    return vx, vy
