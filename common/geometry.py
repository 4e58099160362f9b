"""Vectorised signed distances from points to obstacle shapes (negative inside), and the gaps
between segments and boxes.

Used for scenario validation, non-overlap in the generators and ground-truth occupancy grids,
so every consumer agrees on what "inside an obstacle" means. The circle and box distances are
compiled loops: the generators call them thousands of times a scenario on a handful of points.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from numba.extending import register_jitable

from common.kernel_cache import kernel, uncounted
from common.polygons import orientation


@uncounted
def hypot_excess(dx: float, dy: float, reach: float) -> float:
    """A number with the sign of ``hypot(dx, dy) - reach`` (``reach`` ≥ 0): decided by squares,
    a few times cheaper, unless the two are within rounding of each other, where it is that
    difference itself, so a comparison with it gives hypot's answer to the last bit."""
    squared, limit = dx * dx + dy * dy, reach * reach
    if limit > 1e-290:  # squares of smaller lengths underflow, and lose the bits the margin counts on
        if squared > limit * (1.0 + 1e-9):
            return 1.0
        if squared < limit * (1.0 - 1e-9):
            return -1.0
    return math.hypot(dx, dy) - reach


@uncounted
def beyond_segment_bounds(x: float, y: float, x1: float, y1: float, x2: float, y2: float, reach: float) -> bool:
    """Whether the point (x, y) lies further than ``reach`` outside the bounding box of the segment
    (x1, y1)-(x2, y2) along an axis, so further than ``reach`` from the segment: a test of four
    comparisons that spares most distance computations where most segments are far."""
    return min(x1, x2) - x > reach or x - max(x1, x2) > reach or min(y1, y2) - y > reach or y - max(y1, y2) > reach


@kernel
def circle_distance(px: float, py: float, cx: float, cy: float, radius: float) -> float:
    """Signed distance from the point (px, py) to a circle."""
    return math.hypot(px - cx, py - cy) - radius


@kernel
def box_distance(px: float, py: float, cx: float, cy: float, length: float, width: float, c: float, s: float) -> float:
    """Signed distance from the point (px, py) to a box whose yaw has cosine ``c`` and sine ``s``."""
    dx, dy = px - cx, py - cy
    qx = abs(c * dx + s * dy) - 0.5 * length
    qy = abs(-s * dx + c * dy) - 0.5 * width
    if qx > 0.0 and qy > 0.0:
        return math.hypot(qx, qy)  # beyond a corner
    # hypot(q, 0) is |q| exactly, so inside or beside a side this is hypot(max(qx, 0), max(qy, 0))
    # + min(max(qx, qy), 0) to the last bit, without the hypot.
    return max(qx, qy)


@kernel
def circle_sdf(points: np.ndarray, cx: float, cy: float, radius: float) -> np.ndarray:
    """Signed distance from ``points`` (N, 2) to a circle."""
    out = np.empty(points.shape[0])
    for i in range(points.shape[0]):
        out[i] = circle_distance(points[i, 0], points[i, 1], cx, cy, radius)
    return out


@kernel
def box_sdf(points: np.ndarray, cx: float, cy: float, length: float, width: float, yaw: float) -> np.ndarray:
    """Signed distance to a box of ``length`` along its local x and ``width`` along local y."""
    c, s = math.cos(yaw), math.sin(yaw)
    out = np.empty(points.shape[0])
    for i in range(points.shape[0]):
        out[i] = box_distance(points[i, 0], points[i, 1], cx, cy, length, width, c, s)
    return out


@kernel
def segment_distance(px: float, py: float, x1: float, y1: float, x2: float, y2: float) -> float:
    """Distance from the point (px, py) to the segment (x1, y1)-(x2, y2)."""
    ex, ey = x2 - x1, y2 - y1
    length_sq = ex * ex + ey * ey
    t = 0.0 if length_sq == 0.0 else min(max(((px - x1) * ex + (py - y1) * ey) / length_sq, 0.0), 1.0)
    return math.hypot(px - (x1 + t * ex), py - (y1 + t * ey))


@kernel
def box_corner_table(boxes: np.ndarray) -> np.ndarray:
    """The corners (B, 4, 2), counter-clockwise, of boxes given as rows (x, y, cos yaw, sin yaw,
    half length, half width).

    Products and sums one by one, no matrix product (whose rounding depends on the BLAS
    underneath) and no fused multiply-add, so a corner is the same to the last bit on every machine.
    """
    corners = np.empty((boxes.shape[0], 4, 2))
    for k in range(boxes.shape[0]):
        x, y, c, s, half_length, half_width = boxes[k, 0], boxes[k, 1], boxes[k, 2], boxes[k, 3], boxes[k, 4], boxes[k, 5]
        for i, (u, v) in enumerate(((half_length, half_width), (-half_length, half_width),
                                    (-half_length, -half_width), (half_length, -half_width))):
            corners[k, i, 0] = x + u * c - v * s
            corners[k, i, 1] = y + u * s + v * c
    return corners


def box_corners(x: float, y: float, length: float, width: float, yaw: float) -> np.ndarray:
    """The four corners (4, 2) of a box, counter-clockwise."""
    return box_corner_table(np.array([[x, y, math.cos(yaw), math.sin(yaw), 0.5 * length, 0.5 * width]]))[0]


def segments_distance(points: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Unsigned distance from ``points`` (N, 2) to the nearest of the segments (M, 2)-(M, 2)."""
    d = ends - starts
    length_sq = np.maximum((d**2).sum(axis=1), 1e-18)
    rel = points[:, None, :] - starts[None, :, :]
    t = np.clip((rel * d[None]).sum(axis=2) / length_sq[None], 0.0, 1.0)
    nearest = starts[None] + t[..., None] * d[None]
    return np.sqrt(((points[:, None, :] - nearest) ** 2).sum(axis=2)).min(axis=1)


def polygon_edges(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The closed polygon's edges as (starts, ends)."""
    return vertices, np.roll(vertices, -1, axis=0)


def polygon_sdf(points: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Signed distance to a simple polygon given by its vertices (K, 2), either winding."""
    dist = segments_distance(points, *polygon_edges(vertices))
    inside = points_in_polygon(np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(vertices, dtype=np.float64))
    return np.where(inside, -dist, dist)


@uncounted
def point_in_polygon(px: float, py: float, vertices: np.ndarray) -> bool:
    """Whether (px, py) lies inside the closed ring (K, 2), by the even-odd crossing rule."""
    crossings = False
    for j in range(len(vertices)):
        x1, y1 = vertices[j - 1, 0], vertices[j - 1, 1]
        x2, y2 = vertices[j, 0], vertices[j, 1]
        if (y1 > py) != (y2 > py) and px < x1 + (py - y1) * (x2 - x1) / (y2 - y1):
            crossings = not crossings
    return crossings


@kernel
def points_in_polygon(points: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Whether each point (N, 2) lies inside the closed ring (K, 2) (:func:`point_in_polygon`)."""
    inside = np.zeros(len(points), dtype=np.bool_)
    for i in range(len(points)):
        inside[i] = point_in_polygon(points[i, 0], points[i, 1], vertices)
    return inside


@kernel(inline="always")
def slab(p, q, half, t_near, t_far):
    """Narrow [t_near, t_far] to where p + t q lies within [-half, half] (empty: t_near > t_far)."""
    if q == 0.0:
        return (t_near, t_far) if abs(p) <= half else (math.inf, -math.inf)
    t1, t2 = (-half - p) / q, (half - p) / q
    return max(t_near, min(t1, t2)), min(t_far, max(t1, t2))


@kernel
def segments_gap(ax: float, ay: float, bx: float, by: float, cx: float, cy: float, dx: float, dy: float) -> float:
    """Distance between the segments AB and CD (0 where they cross)."""
    if (orientation(ax, ay, bx, by, cx, cy) * orientation(ax, ay, bx, by, dx, dy) < 0.0
            and orientation(cx, cy, dx, dy, ax, ay) * orientation(cx, cy, dx, dy, bx, by) < 0.0):
        return 0.0
    # Apart (or touching, where an end lies on the other segment), the nearest pair has an end in it.
    return min(segment_distance(ax, ay, cx, cy, dx, dy), segment_distance(bx, by, cx, cy, dx, dy),
               segment_distance(cx, cy, ax, ay, bx, by), segment_distance(dx, dy, ax, ay, bx, by))


@kernel
def segment_box_gap(ax: float, ay: float, bx: float, by: float, cx: float, cy: float, c: float, s: float,
                    half_length: float, half_width: float) -> float:
    """Distance between the segment AB and a box (centre, yaw cosine and sine, half sides); 0 where
    the segment enters it."""
    ux, uy = c * (ax - cx) + s * (ay - cy), -s * (ax - cx) + c * (ay - cy)
    vx, vy = c * (bx - cx) + s * (by - cy), -s * (bx - cx) + c * (by - cy)
    # The segment's parameter range [0, 1] narrowed to the box's two slabs: anything left is inside.
    low, high = slab(ux, vx - ux, half_length, 0.0, 1.0)
    low, high = slab(uy, vy - uy, half_width, low, high)
    if low <= high:
        return 0.0
    # Outside, the nearest pair is a segment end and the box, or a box corner and the segment.
    length, width = 2.0 * half_length, 2.0 * half_width
    gap = min(box_distance(ax, ay, cx, cy, length, width, c, s), box_distance(bx, by, cx, cy, length, width, c, s))
    for kx, ky in ((half_length, half_width), (-half_length, half_width), (-half_length, -half_width),
                   (half_length, -half_width)):
        gap = min(gap, segment_distance(kx, ky, ux, uy, vx, vy))
    return gap


@register_jitable
def _axes_separation(ax: float, ay: float, ac: float, as_: float, a_half_length: float, a_half_width: float,
                     bx: float, by: float, bc: float, bs: float, b_half_length: float, b_half_width: float) -> float:
    """How far apart the boxes lie along box a's two axes: the first positive gap (they are apart),
    else the larger of the two (minus how deep they overlap along it)."""
    separation = -math.inf
    for ux, uy, half in ((ac, as_, a_half_length), (-as_, ac, a_half_width)):
        centre = (bx - ax) * ux + (by - ay) * uy
        reach = abs(b_half_length * (bc * ux + bs * uy)) + abs(b_half_width * (-bs * ux + bc * uy))
        gap = abs(centre) - (half + reach)
        if gap > 0.0:  # one separating axis settles it: contact tests run this on every step
            return gap
        separation = max(separation, gap)
    return separation


@register_jitable
def boxes_separation(ax: float, ay: float, ac: float, as_: float, a_half_length: float, a_half_width: float,
                     bx: float, by: float, bc: float, bs: float, b_half_length: float, b_half_width: float) -> float:
    """The separating-axis test of two boxes (centre, yaw cosine and sine, half sides each):
    positive where the boxes are apart (the gap along a side normal that parts them, a lower bound
    of their distance), else minus the depth of their overlap (the least shift along any of their
    four side normals that parts them)."""
    separation = _axes_separation(ax, ay, ac, as_, a_half_length, a_half_width, bx, by, bc, bs, b_half_length, b_half_width)
    if separation > 0.0:
        return separation
    return max(separation,
               _axes_separation(bx, by, bc, bs, b_half_length, b_half_width, ax, ay, ac, as_, a_half_length, a_half_width))


def box_gap(a: Sequence[float], b: Sequence[float]) -> float:
    """Signed distance between two boxes, each (x, y, yaw, length, width): the gap between them,
    or where they overlap minus its depth (the least shift along a side's normal that parts them),
    as a circle's gap is its centre distance less both radii."""
    ax, ay, a_yaw, a_length, a_width = a
    bx, by, b_yaw, b_length, b_width = b
    ac, as_, bc, bs = math.cos(a_yaw), math.sin(a_yaw), math.cos(b_yaw), math.sin(b_yaw)
    halves_a, halves_b = (0.5 * a_length, 0.5 * a_width), (0.5 * b_length, 0.5 * b_width)
    separation = boxes_separation(ax, ay, ac, as_, *halves_a, bx, by, bc, bs, *halves_b)
    if separation <= 0.0:
        return separation
    # Apart, the nearest pair of points has an edge of a in it (a corner of one, or a side against a corner).
    corners = box_corners(ax, ay, a_length, a_width, a_yaw)
    return min(segment_box_gap(*corners[k - 1], *corners[k], bx, by, bc, bs, *halves_b) for k in range(4))


@register_jitable
def sensor_origin(x: float, y: float, yaw: float, mount_x: float, mount_y: float) -> tuple[float, float]:
    """Where a sensor mounted at (mount_x, mount_y) in the robot frame is, for a robot pose."""
    if mount_x == 0.0 and mount_y == 0.0:
        return x, y  # the common mount, on the robot's centre: no trigonometry in the step
    c, s = math.cos(yaw), math.sin(yaw)
    return x + c * mount_x - s * mount_y, y + s * mount_x + c * mount_y

