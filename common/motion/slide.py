"""Movers that cannot walk into walls: the part of a step that would take a circle into static
geometry is cut, leaving the part along its surface (``Motion.static_contact: slide``).

IR-SIM's movers pass through static geometry in its ``unobstructed`` modes, and its social force
feels line obstacles only (not shelves or posts), so a person pushed sideways by the crowd
walks on through a corridor's wall or into a shelf. A sliding mover is moved back out the least
distance that clears every static circle, box and segment (walls, polygon edges, lines) by
:data:`CLEARANCE`: a person walking into a wall at an angle keeps walking along it. A step
moves a person a fraction of its radius, so it never crosses a wall within one step; two
surfaces pushing at once (a corner) take a second pass, and where no place near clears them all
(a wedge narrower than the body) the person stays where it was.
"""

from __future__ import annotations

import math

import numpy as np

from common.geometry import beyond_segment_bounds, box_distance, segment_distance
from common.kernel_cache import uncounted

CLEARANCE = 1e-6  # m: a slid body stops this far off the surface, so contact tests after the step read no touch
# m: how near counts as touching here. Pushed out to exactly CLEARANCE, a body measured again
# reads a rounding short of it about half the time: touching at CLEARANCE, the next pass pushed
# again, and after the last the step was thrown away (people stood frozen at walls).
TOUCH = 0.5 * CLEARANCE
PASSES = 3  # at a corner one push can lead into the other surface; the last pass checks


@uncounted
def _push(x: float, y: float, px: float, py: float, reach: float, from_x: float, from_y: float) -> tuple[float, float]:
    """(x, y) moved away from the surface point (px, py) until ``reach`` from it; a centre on the
    surface itself leaves toward where the step began."""
    dx, dy = x - px, y - py
    distance = math.sqrt(dx * dx + dy * dy)
    if distance < 1e-12:
        dx, dy = from_x - px, from_y - py
        distance = math.sqrt(dx * dx + dy * dy)
        if distance < 1e-12:
            return x, y
        return px + dx * reach / distance, py + dy * reach / distance
    return px + dx * reach / distance, py + dy * reach / distance


@uncounted
def _off_segment(x, y, x1, y1, x2, y2, r, from_x, from_y):
    """(x, y) pushed off the segment (x1, y1)-(x2, y2) to ``r`` + CLEARANCE if within ``r`` +
    TOUCH of it, and whether it moved."""
    ex, ey = x2 - x1, y2 - y1
    length2 = ex * ex + ey * ey
    t = 0.0 if length2 <= 0.0 else min(1.0, max(0.0, ((x - x1) * ex + (y - y1) * ey) / length2))
    px, py = x1 + t * ex, y1 + t * ey
    if (x - px) * (x - px) + (y - py) * (y - py) >= (r + TOUCH) * (r + TOUCH):
        return x, y, False
    x, y = _push(x, y, px, py, r + CLEARANCE, from_x, from_y)
    return x, y, True


@uncounted
def _off_box(x, y, bx, by, c, s, half_length, half_width, r, from_x, from_y):
    """(x, y) pushed off a box (centre, heading cosine and sine, half sizes) to ``r`` + CLEARANCE
    from its outline if within ``r`` + TOUCH of it, and whether it moved."""
    dx, dy = x - bx, y - by
    u, v = c * dx + s * dy, -s * dx + c * dy  # in the box's frame
    touch, reach = r + TOUCH, r + CLEARANCE
    if abs(u) >= half_length + touch or abs(v) >= half_width + touch:
        return x, y, False
    if abs(u) < half_length and abs(v) < half_width:  # the centre inside: out by the nearer side
        if half_length - abs(u) < half_width - abs(v):
            u = math.copysign(half_length + reach, u)
        else:
            v = math.copysign(half_width + reach, v)
        return bx + c * u - s * v, by + s * u + c * v, True
    qu, qv = min(half_length, max(-half_length, u)), min(half_width, max(-half_width, v))
    if (u - qu) * (u - qu) + (v - qv) * (v - qv) >= touch * touch:
        return x, y, False
    x, y = _push(x, y, bx + c * qu - s * qv, by + s * qu + c * qv, reach, from_x, from_y)
    return x, y, True


@uncounted
def _out_once(x, y, r, from_x, from_y, circles, boxes, segments):
    """One pass over every surface, each pushing (x, y) out of it in turn; whether any did."""
    moved = False
    for k in range(segments.shape[0]):
        x1, y1, x2, y2 = segments[k, 0], segments[k, 1], segments[k, 2], segments[k, 3]
        if beyond_segment_bounds(x, y, x1, y1, x2, y2, r + TOUCH):
            continue
        x, y, pushed = _off_segment(x, y, x1, y1, x2, y2, r, from_x, from_y)
        moved = moved or pushed
    for k in range(circles.shape[0]):
        cx, cy, near = circles[k, 0], circles[k, 1], circles[k, 2] + r + TOUCH
        if abs(x - cx) >= near or abs(y - cy) >= near or (x - cx) ** 2 + (y - cy) ** 2 >= near * near:
            continue
        x, y = _push(x, y, cx, cy, circles[k, 2] + r + CLEARANCE, from_x, from_y)
        moved = True
    for k in range(boxes.shape[0]):
        x, y, pushed = _off_box(x, y, boxes[k, 0], boxes[k, 1], boxes[k, 2], boxes[k, 3], boxes[k, 4], boxes[k, 5], r,
                                from_x, from_y)
        moved = moved or pushed
    return x, y, moved


@uncounted
def slide_out(x: float, y: float, r: float, from_x: float, from_y: float, circles: np.ndarray, boxes: np.ndarray,
              segments: np.ndarray) -> tuple[float, float]:
    """Where a circle of radius ``r`` that stepped from (from_x, from_y) to (x, y) ends when it may
    not enter static ``circles`` (x, y, r), ``boxes`` (x, y, cos, sin, half length, half width) or
    ``segments`` (x1, y1, x2, y2): moved out of each by the least distance, to ``CLEARANCE`` off it.
    Where a few passes find no clear place (a wedge narrower than the body) the step is not taken."""
    for _ in range(PASSES):
        x, y, moved = _out_once(x, y, r, from_x, from_y, circles, boxes, segments)
        if not moved:
            return x, y
    return from_x, from_y


@uncounted
def slack(x: float, y: float, r: float, circles: np.ndarray, boxes: np.ndarray, segments: np.ndarray) -> float:
    """How far a circle of radius ``r`` at (x, y) may move before :func:`slide_out` could push it:
    its least gap to the static geometry, less TOUCH. A person in the open moves for many steps on
    this one figure instead of testing every surface each step."""
    gap = math.inf
    for k in range(segments.shape[0]):
        gap = min(gap, segment_distance(x, y, segments[k, 0], segments[k, 1], segments[k, 2], segments[k, 3]))
    for k in range(circles.shape[0]):
        gap = min(gap, math.hypot(x - circles[k, 0], y - circles[k, 1]) - circles[k, 2])
    for k in range(boxes.shape[0]):
        length, width = 2.0 * boxes[k, 4], 2.0 * boxes[k, 5]
        gap = min(gap, box_distance(x, y, boxes[k, 0], boxes[k, 1], length, width, boxes[k, 2], boxes[k, 3]))
    return gap - r - TOUCH
