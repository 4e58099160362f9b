"""Simple polygons: area, winding, convexity and simplicity (the checks a scenario file passes)."""

from __future__ import annotations

import numpy as np

from common.kernel_cache import kernel


def signed_area(vertices: np.ndarray) -> float:
    """The shoelace area of a polygon (K, 2): positive when its vertices run counter-clockwise."""
    x, y = vertices[:, 0], vertices[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def is_convex(vertices: np.ndarray) -> bool:
    """Whether a polygon (K, 2), either winding, turns the same way at every vertex."""
    edges = np.roll(vertices, -1, axis=0) - vertices
    following = np.roll(edges, -1, axis=0)
    cross = edges[:, 0] * following[:, 1] - edges[:, 1] * following[:, 0]
    return bool(np.all(cross >= -1e-12) or np.all(cross <= 1e-12))


@kernel
def orientation(ax: float, ay: float, bx: float, by: float, cx: float, cy: float) -> float:
    """Twice the signed area of the triangle (a, b, c)."""
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


@kernel
def _on_segment(ax: float, ay: float, bx: float, by: float, px: float, py: float) -> bool:
    """Whether p, known to be collinear with segment ab, lies within it."""
    return min(ax, bx) <= px <= max(ax, bx) and min(ay, by) <= py <= max(ay, by)


@kernel
def _edges_meet(v: np.ndarray) -> bool:
    """Whether any edge of the closed ring meets a non-adjacent edge (touching counts)."""
    n = v.shape[0]
    for i in range(n):
        p1x, p1y, p2x, p2y = v[i, 0], v[i, 1], v[(i + 1) % n, 0], v[(i + 1) % n, 1]
        for j in range(i + 2, n):
            if i == 0 and j == n - 1:
                continue  # the last edge is adjacent to the first
            q1x, q1y, q2x, q2y = v[j, 0], v[j, 1], v[(j + 1) % n, 0], v[(j + 1) % n, 1]
            d1 = orientation(q1x, q1y, q2x, q2y, p1x, p1y)
            d2 = orientation(q1x, q1y, q2x, q2y, p2x, p2y)
            d3 = orientation(p1x, p1y, p2x, p2y, q1x, q1y)
            d4 = orientation(p1x, p1y, p2x, p2y, q2x, q2y)
            if (d1 > 0) != (d2 > 0) and (d3 > 0) != (d4 > 0) and d1 != 0 and d2 != 0 and d3 != 0 and d4 != 0:
                return True
            if ((d1 == 0 and _on_segment(q1x, q1y, q2x, q2y, p1x, p1y))
                    or (d2 == 0 and _on_segment(q1x, q1y, q2x, q2y, p2x, p2y))
                    or (d3 == 0 and _on_segment(p1x, p1y, p2x, p2y, q1x, q1y))
                    or (d4 == 0 and _on_segment(p1x, p1y, p2x, p2y, q2x, q2y))):
                return True
    return False


def is_simple_polygon(vertices: np.ndarray) -> bool:
    """Whether the closed ring (K, 2) has area and no edge meets a non-adjacent edge (shapely's validity)."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    if len(vertices) < 3 or abs(signed_area(vertices)) < 1e-12:
        return False
    return not _edges_meet(vertices)
