"""The generators' gap check, compiled: does a proposed obstacle crowd a wall, the start, the goal
or an obstacle already placed?

A warehouse layout rejects a few hundred proposals before its 31 obstacles fit; as Python and
small numpy calls each check cost about 0.2 ms, which made generation most of an episode reset.
Shapes travel as a kind code and five parameters, so nothing is validated until a proposal fits.
"""

from __future__ import annotations

import math

import numpy as np

from common.geometry import box_distance, circle_distance
from common.kernel_cache import kernel

CIRCLE, BOX = 0, 1


@kernel
def any_within(kind: int, params: np.ndarray, points: np.ndarray, limit: float) -> bool:
    """Whether any of the points (N, 2) lies nearer than ``limit`` to the shape (a circle or a box
    as a kind and five parameters); stops at the first that does."""
    if kind == CIRCLE:
        for i in range(points.shape[0]):
            if circle_distance(points[i, 0], points[i, 1], params[0], params[1], params[2]) < limit:
                return True
        return False
    c, s = math.cos(params[4]), math.sin(params[4])
    for i in range(points.shape[0]):
        if box_distance(points[i, 0], points[i, 1], params[0], params[1], params[2], params[3], c, s) < limit:
            return True
    return False


@kernel
def bounding_radius(kind: int, params: np.ndarray) -> float:
    """The radius about the shape's centre (x, y) that holds it."""
    return params[2] if kind == CIRCLE else 0.5 * math.hypot(params[2], params[3])


@kernel
def shape_bounds(kind: int, params: np.ndarray) -> tuple[float, float, float, float]:
    """The axis-aligned box (x_min, y_min, x_max, y_max) holding the shape."""
    x, y = params[0], params[1]
    if kind == CIRCLE:
        return x - params[2], y - params[2], x + params[2], y + params[2]
    c, s = math.cos(params[4]), math.sin(params[4])
    # A centred box's corners reach |c| hl + |s| hw along x and |s| hl + |c| hw along y.
    hl, hw = 0.5 * params[2], 0.5 * params[3]
    dx, dy = abs(c) * hl + abs(s) * hw, abs(s) * hl + abs(c) * hw
    return x - dx, y - dy, x + dx, y + dy


_CIRCLE_POINTS = 32
_SIDE_POINTS = 8  # per box side: a box's outline also has 32 points
OUTLINE_POINTS = _CIRCLE_POINTS
_ANGLES = np.linspace(0.0, 2.0 * math.pi, _CIRCLE_POINTS, endpoint=False)
_UNIT_CIRCLE = np.column_stack([np.cos(_ANGLES), np.sin(_ANGLES)])  # a constant of the compiled code
_CORNER_SIGNS = ((1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0), (1.0, 1.0))  # counter-clockwise, closed


@kernel
def outline(kind: int, params: np.ndarray, out: np.ndarray) -> None:
    """Write 32 points along the shape's boundary into ``out`` (enough to measure gaps between
    convex shapes): a circle's evenly spaced, a box's eight steps along each side from its corner."""
    x, y = params[0], params[1]
    if kind == CIRCLE:
        for i in range(_CIRCLE_POINTS):
            out[i, 0] = _UNIT_CIRCLE[i, 0] * params[2] + x
            out[i, 1] = _UNIT_CIRCLE[i, 1] * params[2] + y
        return
    c, s = math.cos(params[4]), math.sin(params[4])
    hl, hw = 0.5 * params[2], 0.5 * params[3]
    for k in range(4):
        (u0, v0), (u1, v1) = _CORNER_SIGNS[k], _CORNER_SIGNS[k + 1]
        x0, y0 = u0 * hl * c - v0 * hw * s + x, u0 * hl * s + v0 * hw * c + y
        x1, y1 = u1 * hl * c - v1 * hw * s + x, u1 * hl * s + v1 * hw * c + y
        for i in range(_SIDE_POINTS):
            step = i / _SIDE_POINTS
            out[k * _SIDE_POINTS + i, 0] = x0 + step * (x1 - x0)
            out[k * _SIDE_POINTS + i, 1] = y0 + step * (y1 - y0)


@kernel
def place(kind: int, params: np.ndarray, low: np.ndarray, high: np.ndarray, ends: np.ndarray, end_clearance: float,
          clearance: float, kinds: np.ndarray, placed: np.ndarray, outlines: np.ndarray, count: int) -> bool:
    """Record the shape as the ``count``-th placed one if it fits; whether it did.

    It must keep ``clearance`` from the ``count`` shapes already placed, ``end_clearance`` from the
    start and goal (``ends``), and its outline must lie within [low, high]. The arrays hold the placed
    shapes' kinds, parameters and outlines, with room at ``count``.
    """
    points = outlines[count]
    outline(kind, params, points)
    n = points.shape[0]
    for i in range(n):
        if points[i, 0] < low[0] or points[i, 1] < low[1] or points[i, 0] > high[0] or points[i, 1] > high[1]:
            return False
    if any_within(kind, params, ends, end_clearance):
        return False
    radius = bounding_radius(kind, params)
    for j in range(count):
        # Bounding circles apart by the clearance need no closer look. Near ones are measured
        # outline to outline: the shapes are convex, so their outlines' gaps are theirs.
        gap = radius + bounding_radius(kinds[j], placed[j]) + clearance
        dx, dy = placed[j, 0] - params[0], placed[j, 1] - params[1]
        if dx * dx + dy * dy >= gap * gap:
            continue
        if any_within(kinds[j], placed[j], points, clearance) or any_within(kind, params, outlines[j], clearance):
            return False
    kinds[count] = kind
    # Element by element: a row assignment compiles numba's shape check and its error message,
    # a second of a static world's first build from an empty cache.
    for i in range(params.shape[0]):
        placed[count, i] = params[i]
    return True
