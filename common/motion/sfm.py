"""The social force model (Helbing-Molnar 1995, Moussaïd-Helbing 2009) as IR-SIM 2.12 computes it.

One agent's next world-frame velocity is its current one plus a step of three weighted forces:
relaxation toward the desired velocity (``vmax`` along its desire), an anisotropic repulsion from
each neighbour within ``neighbor_threshold`` (the interaction vector t = lambda (v - v_other) + d,
its range B = gamma |t|, a decay along t and a sideways push by the angle between t and d), and an
exponential push from every line obstacle within 5 sigma of the body, clamped at its surface. The
result is capped at ``vmax``. The arithmetic follows IR-SIM's per-agent model term by term, bit
for bit, and its batched group model to the last bits (NumPy's vector arithmetic rounds a few
steps differently), so a crowd moves as IR-SIM moves it; IR-SIM's social groups (Moussaïd 2010)
are not modelled.
"""

from __future__ import annotations

import math

import numpy as np
from numba.extending import register_jitable

from common.motion.steering import c_pow

# The parameter vector :func:`social_force_velocity` reads, by index (names as IR-SIM's).
VMAX, STEP_TIME, NEIGHBOR_THRESHOLD, RELAXATION_TIME, FORCE_DESIRED, FORCE_SOCIAL, FORCE_OBSTACLE, SIGMA_OBSTACLE, \
    LAMBDA_IMPORTANCE, GAMMA, N_ANGULAR, N_VELOCITY, SAFETY_RADIUS = range(13)
PARAMETERS = ("vmax", "step_time", "neighbor_threshold", "relaxation_time", "force_factor_desired",
              "force_factor_social", "force_factor_obstacle", "sigma_obstacle", "lambda_importance", "gamma",
              "n_angular", "n_velocity", "safety_radius")


@register_jitable
def _social_force(x: float, y: float, vx: float, vy: float, neighbors: np.ndarray, count: int,
                  p: np.ndarray) -> tuple[float, float]:
    fx = fy = 0.0
    reach = p[NEIGHBOR_THRESHOLD]
    for k in range(count):
        dx, dy = neighbors[k, 0] - x, neighbors[k, 1] - y
        # IR-SIM's squares are the C library's pow, which differs from dx * dx in the last bit at times.
        if not c_pow(x - neighbors[k, 0], 2.0) + c_pow(y - neighbors[k, 1], 2.0) < c_pow(reach, 2.0):
            continue
        dist = math.sqrt(dx * dx + dy * dy)
        if dist < 1e-6 or dist > reach:
            continue
        d_hat_x, d_hat_y = dx / dist, dy / dist
        tx = p[LAMBDA_IMPORTANCE] * (vx - neighbors[k, 2]) + d_hat_x
        ty = p[LAMBDA_IMPORTANCE] * (vy - neighbors[k, 3]) + d_hat_y
        t_norm = math.sqrt(tx * tx + ty * ty)
        if t_norm < 1e-9:
            continue
        t_hat_x, t_hat_y = tx / t_norm, ty / t_norm
        b = p[GAMMA] * t_norm
        theta = math.atan2(t_hat_x * d_hat_y - t_hat_y * d_hat_x, t_hat_x * d_hat_x + t_hat_y * d_hat_y)
        gap = max(dist - 2.0 * p[SAFETY_RADIUS], 0.0)
        slow = p[N_VELOCITY] * b * theta
        side = p[N_ANGULAR] * b * theta
        f_v = -math.exp(-gap / b - c_pow(slow, 2.0))
        sign = 1.0 if theta > 0 else (-1.0 if theta < 0 else 0.0)
        f_a = -sign * math.exp(-gap / b - c_pow(side, 2.0))
        fx += f_v * t_hat_x + f_a * -t_hat_y
        fy += f_v * t_hat_y + f_a * t_hat_x
    return fx, fy


@register_jitable
def _obstacle_force(x: float, y: float, radius: float, segments: np.ndarray, p: np.ndarray) -> tuple[float, float]:
    fx = fy = 0.0
    sigma = p[SIGMA_OBSTACLE]
    cutoff = 5.0 * sigma + radius
    for k in range(segments.shape[0]):
        x1, y1 = segments[k, 0], segments[k, 1]
        ex, ey = segments[k, 2] - x1, segments[k, 3] - y1
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


@register_jitable
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


@register_jitable
def social_force_velocity(x: float, y: float, vx: float, vy: float, radius: float, desired_x: float,
                          desired_y: float, neighbors: np.ndarray, count: int, segments: np.ndarray,
                          p: np.ndarray) -> tuple[float, float]:
    """The next world-frame velocity of an agent at (x, y) moving at (vx, vy) that desires to move
    at (desired_x, desired_y) (:func:`desire`), among the first ``count`` rows of ``neighbors``
    (x, y, vx, vy, radius) and the line obstacles ``segments`` (x1, y1, x2, y2), with the
    parameters ``p`` (indexed by this module's constants)."""
    vmax = p[VMAX]
    tau = p[RELAXATION_TIME]
    social_x, social_y = _social_force(x, y, vx, vy, neighbors, count, p)
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
