"""Whether a move is clear: the compiled test that spares most moves a pymunk query.

A footprint of bounding radius R whose centre moves from A to B stays, at every pose on the way,
inside the capsule of radius R around the segment AB (plus the sagitta of an arc, for the exact
integrator), so with no obstacle within that capsule the move cannot touch anything. Most moves
are such moves (all but 663 of 20,000 random steps in generated warehouses), and pymunk's Python
layer, which the full sweep goes through, costs more than the rest of a step.
"""

from __future__ import annotations


import numpy as np
from numba.extending import register_jitable

from common.geometry import segment_box_gap, segment_distance, segments_gap
from common.kernel_cache import kernel

_MARGIN = 1e-9  # m: a distance this close to the radius counts as within it (rounding)


@register_jitable
def swept_capsule(bounding_radius: float, v: float, w: float, dt: float) -> float:
    """The radius around the chord of a step of (v, w) that holds the footprint all along it: the
    bounding radius plus the sagitta of the arc, R (1 - cos(θ/2)) <= |v| |w| dt² / 8."""
    return bounding_radius + 0.125 * abs(v * w) * dt * dt


@kernel
def path_clear(ax: float, ay: float, bx: float, by: float, radius: float, circles: np.ndarray, boxes: np.ndarray,
               segments: np.ndarray, solids: np.ndarray) -> bool:
    """Whether no obstacle comes within ``radius`` of the segment from (ax, ay) to (bx, by).

    ``circles``, ``boxes`` and ``segments`` are rows as :class:`flatland.lidar.Lidar` takes them;
    ``solids`` (rows x_min, y_min, x_max, y_max) bound what segments outline but do not fill (a
    polygon's inside), so a path inside one is not taken for clear.
    """
    limit = radius + _MARGIN
    # The path's box grown by the limit: a shape whose own box misses it is skipped unmeasured.
    x0, x1, y0, y1 = min(ax, bx) - limit, max(ax, bx) + limit, min(ay, by) - limit, max(ay, by) + limit
    for i in range(circles.shape[0]):
        cx, cy, r = circles[i, 0], circles[i, 1], circles[i, 2]
        if (cx + r > x0 and cx - r < x1 and cy + r > y0 and cy - r < y1
                and segment_distance(cx, cy, ax, ay, bx, by) - r < limit):
            return False
    for i in range(boxes.shape[0]):
        reach = boxes[i, 4] + boxes[i, 5]  # at least the half diagonal
        if (boxes[i, 0] + reach > x0 and boxes[i, 0] - reach < x1 and boxes[i, 1] + reach > y0
                and boxes[i, 1] - reach < y1
                and segment_box_gap(ax, ay, bx, by, boxes[i, 0], boxes[i, 1], boxes[i, 2], boxes[i, 3], boxes[i, 4],
                                    boxes[i, 5]) < limit):
            return False
    for i in range(segments.shape[0]):
        sx0, sy0, sx1, sy1 = segments[i, 0], segments[i, 1], segments[i, 2], segments[i, 3]
        if (max(sx0, sx1) > x0 and min(sx0, sx1) < x1 and max(sy0, sy1) > y0 and min(sy0, sy1) < y1
                and segments_gap(ax, ay, bx, by, sx0, sy0, sx1, sy1) < limit):
            return False
    for i in range(solids.shape[0]):
        if solids[i, 2] > x0 and solids[i, 0] < x1 and solids[i, 3] > y0 and solids[i, 1] < y1:
            return False
    return True
