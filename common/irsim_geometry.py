"""IR-SIM's object discs, bit for bit: its shapely circles and rectangles, their rigid transform,
GEOS's polygon centroid and GEOS's minimum bounding radius, without shapely.

IR-SIM's behaviours (social force, RVO) see every other object as a disc at the shapely centroid of
its current geometry, of radius ``minimum_bounding_radius(original geometry) + 0.1``. A circle is
``Point(center).buffer(radius)``, a 64-gon, and its centroid misses the exact centre by a few ulps
(around 1e-17 at the origin, 1e-15 at a pose a few metres away). Those ulps are not noise: with
pedestrians in exactly head-on lanes the social force takes ``sign(angle)`` of an angle that is zero
but for them, so the side a pedestrian swerves to is decided by the last bits. A faithful
reimplementation must therefore compute the same floats as GEOS (3.14, shapely 2.x), not close ones.

What is reproduced (from the GEOS sources, checked against shapely to ``==``):

* ``OffsetSegmentGenerator::createCircle`` with shapely's default ``quad_segs=16``: the start point
  ``(cx + r, cy)``, then a clockwise fillet of 64 steps of ``2 pi / 64`` whose sines and cosines go
  through ``Angle::sinCosSnap`` (values below 5e-16 become 0, so the axis points are exact); the
  buffer's noding and polygon building keep that ring as it is.
* IR-SIM's ``geometry_transform``: ``px * cos - py * sin + x``, ``px * sin + py * cos + y``.
* ``algorithm::Centroid``: triangles fanned from the first vertex, ``cg3 += a2 * (p0 + p1 + p2)``,
  ``areasum2 += a2`` in ring order, then ``cg3 / 3 / areasum2``.
* ``MinimumBoundingCircle`` on the ``ConvexHull`` of a convex ring: the hull's vertex order (clockwise
  from the lowest, then leftmost, vertex) decides every tie, then the P-Q-R iteration, the midpoint or
  ``Triangle::circumcentre`` and ``Coordinate::distance``.

Every function is ``register_jitable``: a plain function from Python, compiled into numba kernels
(``math`` on floats, loops over small arrays, no fused multiply-add, so both paths give the same bits).
"""

from __future__ import annotations

import math
import sys

import numpy as np
from numba.extending import register_jitable

from common.kernel_cache import uncounted

QUADRANT_SEGMENTS = 16  # shapely's default buffer(quad_segs=...), not GEOS's own 8
CIRCLE_VERTICES = 4 * QUADRANT_SEGMENTS  # a circle ring has these plus its closing point
SNAP = 5e-16  # Angle::sinCosSnap's threshold
DOUBLE_MAX = sys.float_info.max  # std::numeric_limits<double>::max(), GEOS's "no minimum yet"


@register_jitable
def _sin_cos_snap(angle: float) -> tuple[float, float]:
    """GEOS ``Angle::sinCosSnap``: sin and cos with near-zero values set to exactly zero."""
    sin, cos = math.sin(angle), math.cos(angle)
    if abs(sin) < SNAP:
        sin = 0.0
    if abs(cos) < SNAP:
        cos = 0.0
    return sin, cos


@register_jitable
def circle_outline(radius: float, cx: float = 0.0, cy: float = 0.0) -> np.ndarray:
    """The exterior ring (65, 2) of shapely's ``Point(cx, cy).buffer(radius)``, closing point included.

    For ``radius > 0`` (shapely's buffer is empty otherwise) and centres small enough, say
    ``|cx|, |cy| < 1e12 * radius``, that no two vertices round within ``1e-6 * radius`` of each other
    (GEOS would drop one). A wheelbase circle is centred at ``(center[0] + wheelbase / 2, center[1])``.
    """
    # GEOS's own arithmetic, kept literal: every step is exact but the loop's (-i) * angle_inc.
    fillet_angle_quantum = math.pi / 2.0 / QUADRANT_SEGMENTS
    total_angle = abs(0.0 - 2.0 * math.pi)
    segments = int(total_angle / fillet_angle_quantum + 0.5)
    angle_inc = total_angle / segments
    ring = np.empty((segments + 1, 2))
    ring[0, 0], ring[0, 1] = cx + radius, cy
    # The fillet's i = 0 point repeats the start point (GEOS drops it as redundant); clockwise from there.
    for i in range(1, segments):
        sin, cos = _sin_cos_snap(0.0 + float(-i) * angle_inc)
        ring[i, 0], ring[i, 1] = cx + radius * cos, cy + radius * sin
    ring[segments, 0], ring[segments, 1] = ring[0, 0], ring[0, 1]
    return ring


@register_jitable
def rectangle_outline(length: float, width: float, wheelbase: float = 0.0) -> np.ndarray:
    """The exterior ring (5, 2) of IR-SIM's rectangle: counter-clockwise from the rear right corner.

    IR-SIM builds ``(-l/2, -w/2), (l/2, -w/2), (l/2, w/2), (-l/2, w/2)`` without a wheelbase and
    starts at ``-(l - wheelbase) / 2`` with one; wheelbase 0 gives the former's floats exactly
    (``-l/2 + l`` is ``l/2`` in binary), so one formula serves both.
    """
    start_x = -(length - wheelbase) / 2
    start_y = -width / 2
    ring = np.empty((5, 2))
    ring[0, 0], ring[0, 1] = start_x, start_y
    ring[1, 0], ring[1, 1] = start_x + length, start_y
    ring[2, 0], ring[2, 1] = start_x + length, start_y + width
    ring[3, 0], ring[3, 1] = start_x, start_y + width
    ring[4, 0], ring[4, 1] = start_x, start_y
    return ring


@uncounted
def placed(outline: np.ndarray, i: int, x: float, y: float, cos_t: float, sin_t: float) -> tuple[float, float]:
    """Vertex ``i`` of ``outline`` as IR-SIM's ``geometry_transform`` places it at (x, y) turned by
    the angle of cosine ``cos_t`` and sine ``sin_t``."""
    px, py = outline[i, 0], outline[i, 1]
    return px * cos_t - py * sin_t + x, px * sin_t + py * cos_t + y


@uncounted
def centroid(outline: np.ndarray, x: float = 0.0, y: float = 0.0, theta: float = 0.0) -> tuple[float, float]:
    """GEOS's centroid of the polygon whose shell is the closed ring ``outline`` (n + 1, 2), no holes,
    placed at (x, y, theta) as IR-SIM places its geometry. The vertices are placed as they are read,
    to the same bits as a placed copy of the ring, so a mover's step allocates nothing.

    ``Centroid::addShell`` multiplies each triangle by +1 or -1 after the ring's orientation; negation
    is exact and rounding symmetric, so both signs end in the same quotient and none is needed here.
    """
    c, s = math.cos(theta), math.sin(theta)  # libm's, as IR-SIM's np.cos / np.sin of a float64 scalar
    base_x, base_y = placed(outline, 0, x, y, c, s)
    cg3_x = cg3_y = area_sum2 = 0.0
    x1, y1 = base_x, base_y
    for i in range(outline.shape[0] - 1):
        x2, y2 = placed(outline, i + 1, x, y, c, s)
        area2 = (x1 - base_x) * (y2 - base_y) - (x2 - base_x) * (y1 - base_y)
        cg3_x += area2 * (base_x + x1 + x2)
        cg3_y += area2 * (base_y + y1 + y2)
        area_sum2 += area2
        x1, y1 = x2, y2
    if abs(area_sum2) > 0.0:
        return cg3_x / 3 / area_sum2, cg3_y / 3 / area_sum2
    # A ring without area: GEOS's length-weighted centroid of its segments, else its first point.
    length = sum_x = sum_y = 0.0
    x1, y1 = base_x, base_y
    for i in range(outline.shape[0] - 1):
        x2, y2 = placed(outline, i + 1, x, y, c, s)
        dx, dy = x1 - x2, y1 - y2
        segment = math.sqrt(dx * dx + dy * dy)
        if segment != 0.0:
            length += segment
            sum_x += segment * ((x1 + x2) / 2)
            sum_y += segment * ((y1 + y2) / 2)
        x1, y1 = x2, y2
    if length > 0.0:
        return sum_x / length, sum_y / length
    return base_x, base_y


@register_jitable
def _hull_order(ring: np.ndarray) -> np.ndarray:
    """The vertices (n, 2) of a convex closed ring in GEOS ``ConvexHull``'s order: clockwise from the
    lowest vertex (the leftmost of equally low ones), as the Graham scan's radial sort leaves them."""
    n = ring.shape[0] - 1
    low = 0
    for i in range(1, n):
        if ring[i, 1] < ring[low, 1] or (ring[i, 1] == ring[low, 1] and ring[i, 0] < ring[low, 0]):
            low = i
    # The turn at the lowest vertex gives the ring's orientation without any cancellation to fear.
    prev, nxt = ring[(low - 1) % n], ring[(low + 1) % n]
    turn = (ring[low, 0] - prev[0]) * (nxt[1] - ring[low, 1]) - (ring[low, 1] - prev[1]) * (nxt[0] - ring[low, 0])
    step = -1 if turn > 0.0 else 1  # a counter-clockwise ring is walked backwards
    hull = np.empty((n, 2))
    for k in range(n):
        j = (low + step * k) % n
        hull[k, 0], hull[k, 1] = ring[j, 0], ring[j, 1]
    return hull


@register_jitable
def _angle_diff(a1: float, a2: float) -> float:
    """GEOS ``Angle::diff``: the unoriented difference of two angles in [-pi, pi]."""
    delta = a2 - a1 if a1 < a2 else a1 - a2
    if delta > math.pi:
        delta = 2 * math.pi - delta
    return delta


@register_jitable
def _is_obtuse(x0: float, y0: float, x1: float, y1: float, x2: float, y2: float) -> bool:
    """GEOS ``Angle::isObtuse``: the angle at (x1, y1) exceeds a right angle."""
    return (x0 - x1) * (x2 - x1) + (y0 - y1) * (y2 - y1) < 0


@register_jitable
def bounding_radius(ring: np.ndarray) -> float:
    """GEOS's minimum bounding radius (``shapely.minimum_bounding_radius``) of a convex closed ring.

    The ring must be convex with at least three vertices, each a strict corner (IR-SIM's circles,
    rectangles and convex polygons without repeated or collinear vertices): then GEOS's hull is the
    ring itself, reordered, and none of its robust orientation tests can decide otherwise.
    """
    pts = _hull_order(ring)
    n = pts.shape[0]
    # P: the lowest point, the hull's first. Q: the smallest angle with the x axis (sin as its proxy).
    p = 0
    q = -1
    min_sin = DOUBLE_MAX
    for i in range(n):
        if i == p:
            continue
        dx = pts[i, 0] - pts[p, 0]
        dy = abs(pts[i, 1] - pts[p, 1])
        sin = dy / math.sqrt(dx * dx + dy * dy)
        if sin < min_sin:
            min_sin, q = sin, i
    extremal = 0
    r = -1
    for _ in range(n):
        # R: the point seeing P-Q under the smallest angle; the first of equal ones, as in GEOS.
        min_angle = DOUBLE_MAX
        r = -1
        for i in range(n):
            if i == p or i == q:
                continue
            angle = _angle_diff(math.atan2(pts[p, 1] - pts[i, 1], pts[p, 0] - pts[i, 0]),
                                math.atan2(pts[q, 1] - pts[i, 1], pts[q, 0] - pts[i, 0]))
            if angle < min_angle:
                min_angle, r = angle, i
        px, py, qx, qy, rx, ry = pts[p, 0], pts[p, 1], pts[q, 0], pts[q, 1], pts[r, 0], pts[r, 1]
        if _is_obtuse(px, py, rx, ry, qx, qy):
            extremal = 2
            break
        if _is_obtuse(rx, ry, px, py, qx, qy):
            p = r
            continue
        if _is_obtuse(rx, ry, qx, qy, px, py):
            q = r
            continue
        extremal = 3
        break
    px, py, qx, qy = pts[p, 0], pts[p, 1], pts[q, 0], pts[q, 1]
    if extremal == 2:
        cx, cy = (px + qx) / 2.0, (py + qy) / 2.0
    else:
        cx, cy = _circumcentre(px, py, qx, qy, pts[r, 0], pts[r, 1])
    dx, dy = cx - px, cy - py
    return math.sqrt(dx * dx + dy * dy)


@register_jitable
def _circumcentre(x0: float, y0: float, x1: float, y1: float, x2: float, y2: float) -> tuple[float, float]:
    """GEOS ``Triangle::circumcentre``, relative to the third vertex as GEOS computes it."""
    ax, ay, bx, by = x0 - x2, y0 - y2, x1 - x2, y1 - y2
    denom = 2 * (ax * by - ay * bx)
    a_sq, b_sq = ax * ax + ay * ay, bx * bx + by * by
    num_x = ay * b_sq - a_sq * by
    num_y = ax * b_sq - a_sq * bx
    return x2 - num_x / denom, y2 + num_y / denom


@register_jitable
def circle_disc(cx_offset: float, cy_offset: float, radius: float, x: float, y: float,
                theta: float) -> tuple[float, float, float]:
    """An IR-SIM circle at state (x, y, theta) as its behaviours see it: (centroid x, centroid y,
    minimum bounding radius). The radius is of the untransformed circle, as IR-SIM caches it, so a
    caller may keep it per object; it is most of this function's cost (about 6 us compiled)."""
    outline = circle_outline(radius, cx_offset, cy_offset)
    cx, cy = centroid(outline, x, y, theta)
    return cx, cy, bounding_radius(outline)


@register_jitable
def rectangle_disc(length: float, width: float, x: float, y: float, theta: float,
                   wheelbase: float = 0.0) -> tuple[float, float, float]:
    """An IR-SIM rectangle at state (x, y, theta): (centroid x, centroid y, minimum bounding radius
    of the untransformed rectangle)."""
    outline = rectangle_outline(length, width, wheelbase)
    cx, cy = centroid(outline, x, y, theta)
    return cx, cy, bounding_radius(outline)
