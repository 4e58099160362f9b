"""Simple polygons as convex pieces: what physics engines that collide convex shapes only need."""

from __future__ import annotations

import numpy as np
import pymunk.autogeometry


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


def convex_pieces(vertices: np.ndarray) -> list[np.ndarray]:
    """A simple polygon (K, 2), either winding, as counter-clockwise convex polygons covering it exactly."""
    vertices = np.asarray(vertices, dtype=float)
    if signed_area(vertices) < 0:
        vertices = vertices[::-1]  # pymunk decomposes counter-clockwise rings only
    if is_convex(vertices):
        return [vertices]
    ring = [tuple(v) for v in vertices] + [tuple(vertices[0])]
    # Each hull comes back closed (its first vertex repeated last).
    hulls = [np.array([tuple(v) for v in hull[:-1]]) for hull in pymunk.autogeometry.convex_decomposition(ring, 0.0)]
    return [hull if signed_area(hull) > 0 else hull[::-1] for hull in hulls]
