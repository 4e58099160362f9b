"""Vectorised signed distances from points to obstacle shapes (negative inside).

Used for scenario validation, non-overlap in the generators and ground-truth occupancy grids,
so every consumer agrees on what "inside an obstacle" means.
"""

from __future__ import annotations

import numpy as np
from matplotlib.path import Path as _MplPath


def circle_sdf(points: np.ndarray, cx: float, cy: float, radius: float) -> np.ndarray:
    """Signed distance from ``points`` (N, 2) to a circle."""
    return np.hypot(points[:, 0] - cx, points[:, 1] - cy) - radius


def box_sdf(
    points: np.ndarray, cx: float, cy: float, length: float, width: float, yaw: float
) -> np.ndarray:
    """Signed distance to a box of ``length`` along its local x and ``width`` along local y."""
    c, s = np.cos(yaw), np.sin(yaw)
    dx, dy = points[:, 0] - cx, points[:, 1] - cy
    local = np.stack([c * dx + s * dy, -s * dx + c * dy], axis=1)
    q = np.abs(local) - np.array([0.5 * length, 0.5 * width])
    outside = np.hypot(np.maximum(q[:, 0], 0.0), np.maximum(q[:, 1], 0.0))
    inside = np.minimum(np.maximum(q[:, 0], q[:, 1]), 0.0)
    return outside + inside


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
    inside = _MplPath(vertices).contains_points(points)
    return np.where(inside, -dist, dist)
