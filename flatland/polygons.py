"""Convex pieces of a simple polygon, as both tiers build them into collision shapes.

pymunk and PyBullet collide convex shapes only. The decomposition is pymunk's (Chipmunk's exact
convex decomposition); physics3d builds its prisms from the same pieces, so a concave obstacle is
the same set of convex bodies in both tiers.
"""

from __future__ import annotations

import numpy as np
import pymunk.autogeometry

from common.polygons import is_convex, signed_area


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
