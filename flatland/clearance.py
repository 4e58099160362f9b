"""Whether a robot's neighbourhood is clear: the compiled test that spares most moves a pymunk query.

A move of a footprint of bounding radius R by at most d keeps every point of it within d + R of
where its centre started, so with nothing nearer than that the move cannot touch anything. Most
steps of a robot in the open are such moves.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from common.geometry import box_distance, circle_distance, segment_distance

_MARGIN = 1e-9  # m: a distance this close to the reach counts as within it (rounding)


@njit(cache=True)
def nothing_within(x: float, y: float, reach: float, circles: np.ndarray, boxes: np.ndarray,
                   segments: np.ndarray, solids: np.ndarray) -> bool:
    """Whether no obstacle comes within ``reach`` of (x, y).

    ``circles``, ``boxes`` and ``segments`` are rows as :class:`flatland.lidar.Lidar` takes them;
    ``solids`` (rows x_min, y_min, x_max, y_max) bound what segments outline but do not fill (a
    polygon's inside), so a point deep inside one is not taken for clear.
    """
    limit = reach + _MARGIN
    for i in range(circles.shape[0]):
        if circle_distance(x, y, circles[i, 0], circles[i, 1], circles[i, 2]) < limit:
            return False
    for i in range(boxes.shape[0]):
        if box_distance(x, y, boxes[i, 0], boxes[i, 1], 2.0 * boxes[i, 4], 2.0 * boxes[i, 5], boxes[i, 2],
                        boxes[i, 3]) < limit:
            return False
    for i in range(segments.shape[0]):
        if segment_distance(x, y, segments[i, 0], segments[i, 1], segments[i, 2], segments[i, 3]) < limit:
            return False
    for i in range(solids.shape[0]):
        if solids[i, 0] - limit < x < solids[i, 2] + limit and solids[i, 1] - limit < y < solids[i, 3] + limit:
            return False
    return True
