"""IR-SIM's sampled reciprocal velocity obstacles (``rvo`` behaviour), in NumPy.

Reproduces IR-SIM 2.12's ``reciprocal_vel_obs.cal_vel`` (``irsim/lib/algorithm/rvo.py``) with the
neighbour pre-filter of its ``OmniRVO``/``DiffRVO`` (``irsim/lib/behavior/behavior_methods.py``):

1. neighbours farther than ``neighbor_threshold`` are dropped;
2. each neighbour gives a cone in velocity space (``rvo``: apex halfway between the two
   velocities; ``hrvo``: the hybrid apex; ``vo``: apex at the neighbour's velocity), each line
   segment a cone with its apex at zero velocity;
3. the reachable velocities are a grid, ``np.arange(low, high, 0.05)`` per axis within ``acce``
   of the current velocity and ``vmax`` (or one clipped candidate when that window is empty);
4. the candidate nearest the desired velocity outside every cone wins; if there is none, the one
   with the least penalty (distance to the desired velocity plus ``factor`` / time to collision).

The answer is a grid point, so a last-bit difference in a cone edge or a distance can pick another
candidate and send a trajectory elsewhere. Every number is therefore computed as IR-SIM computes
it: the same formulas in the same order, scalar ``**`` (the C library's ``pow``) where IR-SIM
has it, ``math.hypot`` (CPython's algorithm) for scalar distances and ``np.hypot`` (the C
library's) for the candidates' distances, and the first minimum on ties.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

MODES = ("rvo", "hrvo", "vo")
GRID_STEP = 0.05  # m/s between candidate velocities (IR-SIM's)

Neighbour = tuple[float, float, float, float, float]  # x, y, vx, vy, radius
Cone = tuple[float, float, float, float, float, float]  # apex x, apex y, left x, left y, right x, right y


def _neighbour(row: Sequence[float]) -> Neighbour:
    """A neighbour row as (x, y, vx, vy, radius); a row of three, [x, y, radius], stands still."""
    if len(row) == 3:
        return float(row[0]), float(row[1]), 0.0, 0.0, float(row[2])
    return float(row[0]), float(row[1]), float(row[2]), float(row[3]), float(row[4])


def _cone_angles(x: float, y: float, r: float, mx: float, my: float, mr: float) -> tuple[float, float, float]:
    """The cone's left and right edge directions and its half angle, toward a disc of radius ``r + mr``."""
    distance = math.sqrt((my - y) ** 2 + (mx - x) ** 2)
    bearing = math.atan2(my - y, mx - x)
    combined = r + mr
    if distance < combined:
        distance = combined  # overlapping: a half cone of 90 degrees, as if tangent
    if distance == 0.0:
        # IR-SIM divides numpy floats here (no exception): 0/0 is NaN, a cone containing nothing.
        ratio = math.nan if combined == 0.0 else math.copysign(math.inf, combined)
    else:
        ratio = combined / distance
    half = math.asin(min(max(ratio, -1.0), 1.0))
    return bearing + half, bearing - half, half


def _edges(left: float, right: float) -> tuple[float, float, float, float]:
    """Unit vectors along a cone's left and right edges."""
    return math.cos(left), math.sin(left), math.cos(right), math.sin(right)


def _neighbour_cone(mode: str, state: Neighbour, other: Neighbour) -> Cone:
    """IR-SIM's ``config_rvo_mode``/``config_hrvo_mode``/``config_vo_mode`` for one neighbour."""
    x, y, vx, vy, r = state
    mx, my, mvx, mvy, mr = other
    left, right, half = _cone_angles(x, y, r, mx, my, mr)
    if mode == "vo":
        return (mvx, mvy, *_edges(left, right))
    rvo_x, rvo_y = (vx + mvx) / 2, (vy + mvy) / 2
    if mode == "rvo":
        return (rvo_x, rvo_y, *_edges(left, right))
    # hrvo: move the apex along the right edge, toward the VO apex on the side the robot passes.
    dis_rv = math.hypot(mvx - rvo_x, mvy - rvo_y)
    radians_rv = math.atan2(rvo_y - mvy, rvo_x - mvx)
    opening = math.pi - 2 * half
    if opening == 0:
        opening = opening + 0.01  # overlapping discs: IR-SIM's guard against dividing by sin(0)
    dis_diff = dis_rv * math.sin(left - radians_rv) / math.sin(opening)
    cl_x, cl_y = mx - x, my - y
    cur_x, cur_y = vx - rvo_x, vy - rvo_y
    if float(cl_x * cur_y - cur_x * cl_y) <= 0:
        apex_x, apex_y = rvo_x - dis_diff * math.cos(right), rvo_y - dis_diff * math.sin(right)
    else:
        apex_x, apex_y = mvx + dis_diff * math.cos(right), mvy + dis_diff * math.sin(right)
    return (apex_x, apex_y, *_edges(left, right))


def _segment_cone(x: float, y: float, r: float, segment: np.ndarray) -> Cone | None:
    """IR-SIM's ``config_vo_lines`` for one segment: the angular span it covers, widened by the
    robot's radius at each end, apex at zero velocity; None for a segment of (almost) no length."""
    x1, y1, x2, y2 = (float(value) for value in segment)
    dx, dy = x2 - x1, y2 - y1
    if dx * dx + dy * dy < 1e-12:
        return None
    # (IR-SIM also computes the closest point of the segment, which it does not use.)
    angle1 = math.atan2(y1 - y, x1 - x)
    angle2 = math.atan2(y2 - y, x2 - x)
    dist1 = math.sqrt((x1 - x) ** 2 + (y1 - y) ** 2)
    dist2 = math.sqrt((x2 - x) ** 2 + (y2 - y) ** 2)
    expand1 = math.asin(min(1.0, r / max(dist1, r))) if dist1 > 1e-6 else math.pi / 2
    expand2 = math.asin(min(1.0, r / max(dist2, r))) if dist2 > 1e-6 else math.pi / 2
    turn = math.atan2(math.sin(angle2 - angle1), math.cos(angle2 - angle1))
    if turn >= 0:  # the second end is to the left of the first
        left, right = angle2 + expand2, angle1 - expand1
    else:
        left, right = angle1 + expand1, angle2 - expand2
    return (0.0, 0.0, *_edges(left, right))


def _axis_candidates(current: float, vmax: float, acce: float) -> np.ndarray:
    """Grid velocities along one axis within ``acce`` of ``current`` and within ``[-vmax, vmax]``;
    the one nearest admissible velocity when ``current`` is more than ``acce`` outside the range."""
    low = max(current - acce, -vmax)
    high = min(current + acce, vmax)
    if high <= low:
        return np.array([float(np.clip(current, -vmax, vmax))])
    return np.arange(low, high, GRID_STEP)


def _outside(cones: list[Cone], vx: np.ndarray, vy: np.ndarray) -> np.ndarray:
    """Mask of the candidates outside every cone (on an edge counts as inside)."""
    if not cones:
        return np.ones(vx.size, dtype=bool)
    apex_x, apex_y, left_x, left_y, right_x, right_y = (column[:, None] for column in np.array(cones).T)
    rel_x, rel_y = vx - apex_x, vy - apex_y
    inside = (left_x * rel_y - rel_x * left_y <= 0) & (right_x * rel_y - rel_x * right_y >= 0)
    return ~inside.any(axis=0)


def _segment_collision_times(
    x: float, y: float, r: float, vx: np.ndarray, vy: np.ndarray, segment: np.ndarray
) -> np.ndarray:
    """IR-SIM's ``_tc_line_segment_all``: time until the robot's disc reaches the segment at each
    candidate velocity, 1e6 when it never does."""
    x1, y1, x2, y2 = (float(value) for value in segment)
    dx, dy = x2 - x1, y2 - y1
    length = math.sqrt(dx * dx + dy * dy)
    if length < 1e-12:  # not the cone's test (squared length < 1e-12): short segments still count here
        return np.full(len(vx), 1e6)
    nx, ny = -dy / length, dx / length
    if nx * (x - x1) + ny * (y - y1) < 0:  # the normal pointing toward the robot
        nx, ny = -nx, -ny
    perp = nx * (x - x1) + ny * (y - y1)
    toward = -(nx * vx + ny * vy)
    approaching = toward > 1e-7
    tc = np.maximum((perp - r) / np.where(approaching, toward, 1.0), 0)
    hit_x = x + vx * tc
    hit_y = y + vy * tc
    along = ((hit_x - x1) * dx + (hit_y - y1) * dy) / (length * length)
    margin = r / length
    hits = approaching & (along >= -margin) & (along <= 1 + margin)
    return np.where(hits, tc, 1e6)


def _penalties(
    state: Neighbour, desired: tuple[float, float], near: list[Neighbour], segments: np.ndarray, factor: float,
    vx: np.ndarray, vy: np.ndarray,
) -> np.ndarray:
    """IR-SIM's ``penalties``: distance to the desired velocity plus ``factor`` / the least time to
    collision with any neighbour or segment (the distance alone when there is nothing to hit)."""
    x, y, cvx, cvy, r = state
    times = []
    for mx, my, mvx, mvy, mr in near:
        distance = math.hypot(x - mx, y - my)
        gap = distance ** 2 - (r + mr) ** 2
        gap = 0 if 0 > gap else gap  # Python's max(gap, 0), which keeps a NaN
        trans_x = 2 * vx - cvx - mvx
        trans_y = 2 * vy - cvy - mvy
        times.append(math.sqrt(gap) / (np.sqrt(trans_x ** 2 + trans_y ** 2) + 1e-7))
    for segment in segments:
        times.append(_segment_collision_times(x, y, r, vx, vy, segment))
    to_desired = np.hypot(vx - desired[0], vy - desired[1])
    if not times:
        return to_desired
    soonest = np.min(times, axis=0)
    soonest = np.where(soonest == 0, 0.0001, soonest)
    return factor * (1 / soonest) + to_desired


def rvo_velocity(state: Sequence[float], neighbors: Sequence[Sequence[float]] | np.ndarray | None,
                 segments: Sequence[Sequence[float]] | np.ndarray | None, vxmax: float = 1.5, vymax: float = 1.5,
                 acce: float = 1.0, factor: float = 1.0, mode: str = "rvo",
                 neighbor_threshold: float = 3.0) -> tuple[float, float, bool]:
    """The world-frame velocity IR-SIM's RVO picks, and whether anything was in range.

    Args:
        state: [x, y, vx, vy, radius, vx_des, vy_des(, theta)] of the robot (IR-SIM's ``rvo_state``).
        neighbors: rows [x, y, vx, vy, radius], or [x, y, radius] for one standing still (IR-SIM's
            ``rvo_neighbor_state`` of the other objects); may be empty.
        segments: rows [x1, y1, x2, y2] of line obstacles; may be empty.
        vxmax, vymax: speed limits along the world axes.
        acce: how far from the current velocity the candidates reach, per axis (m/s).
        factor: weight of 1 / time to collision when every candidate is inside a cone.
        mode: ``rvo``, ``hrvo`` or ``vo``.
        neighbor_threshold: neighbours at this distance or farther are ignored.

    Returns:
        (vx, vy, considered): the selected velocity, and whether a neighbour within the threshold
        or any segment was considered (IR-SIM's ``DiffRVO`` turns in place when nothing was and the
        velocity converts to a standstill).
    """
    if mode not in MODES:
        raise ValueError(f"RVO mode must be one of {MODES}, not {mode!r}")
    x, y, vx, vy, r, vx_des, vy_des = (float(value) for value in list(state)[:7])
    me = (x, y, vx, vy, r)
    rows = [_neighbour(row) for row in (neighbors if neighbors is not None else [])]
    near = [n for n in rows if (x - n[0]) ** 2 + (y - n[1]) ** 2 < neighbor_threshold ** 2]
    lines = np.asarray(segments if segments is not None else [], dtype=float).reshape(-1, 4)

    cones = [_neighbour_cone(mode, me, other) for other in near]
    cones += [cone for cone in (_segment_cone(x, y, r, segment) for segment in lines) if cone is not None]

    grid_x, grid_y = np.meshgrid(_axis_candidates(vx, vxmax, acce), _axis_candidates(vy, vymax, acce), indexing="ij")
    cand_x, cand_y = grid_x.ravel(), grid_y.ravel()  # vx-major, the order IR-SIM's argmin sees
    outside = _outside(cones, cand_x, cand_y)
    if outside.any():
        free_x, free_y = cand_x[outside], cand_y[outside]
        best = int(np.argmin(np.hypot(free_x - vx_des, free_y - vy_des)))
        chosen = free_x[best], free_y[best]
    else:
        costs = _penalties(me, (vx_des, vy_des), near, lines, factor, cand_x, cand_y)
        best = int(np.argmin(costs))
        chosen = cand_x[best], cand_y[best]
    return float(chosen[0]), float(chosen[1]), bool(near) or len(lines) > 0
