"""A 2D lidar: beams against circles, oriented boxes and segments in one compiled loop.

Each primitive is tested only against the beams inside the angular window its bounding circle
subtends, so a 36-beam scan of a 31-obstacle warehouse costs a few hundred ray tests instead of
over a thousand, and a 720-beam scan is not 20 times slower. One Python call per beam (e.g.
pymunk segment queries) would cost more than the rest of an env step.
"""

from __future__ import annotations

import functools
import math
from typing import Callable

import numpy as np

from common.geometry import sensor_origin, slab
from common.kernel_cache import compiled_for, kernel
from common.readings import sensed_ranges
from common.scenario import LidarSpec

_EPS = 1e-9  # a hit nearer than this is the sensor's own surface, not an obstacle
_TWO_PI = 2.0 * math.pi


@kernel(inline="always")
def _hit_circle(ox, oy, dx, dy, cx, cy, r):
    fx, fy = ox - cx, oy - cy
    c = fx * fx + fy * fy - r * r
    b = fx * dx + fy * dy
    disc = b * b - c
    if disc < 0.0:
        return math.inf
    # From inside, the beam reads where it leaves the obstacle, as in IR-SIM.
    return -b - math.sqrt(disc) if c > 0.0 else -b + math.sqrt(disc)


@kernel(inline="always")
def _hit_box(ox, oy, dx, dy, cx, cy, cos_yaw, sin_yaw, half_length, half_width):
    # Slab test in the box's frame: one test per box instead of four edge tests.
    rx, ry = ox - cx, oy - cy
    t_near, t_far = slab(cos_yaw * rx + sin_yaw * ry, cos_yaw * dx + sin_yaw * dy, half_length, -math.inf, math.inf)
    t_near, t_far = slab(-sin_yaw * rx + cos_yaw * ry, -sin_yaw * dx + cos_yaw * dy, half_width, t_near, t_far)
    if t_far < t_near:
        return math.inf
    return t_near if t_near > _EPS else t_far


@kernel(inline="always")
def _hit_segment(ox, oy, dx, dy, x1, y1, x2, y2):
    ex, ey = x2 - x1, y2 - y1
    denom = dx * ey - dy * ex
    if denom == 0.0:
        return math.inf
    wx, wy = x1 - ox, y1 - oy
    u = (wx * dy - wy * dx) / denom
    if u < 0.0 or u > 1.0:
        return math.inf
    return (wx * ey - wy * ex) / denom


@kernel
def _window(ox, oy, cx, cy, radius, a0, delta, n, range_max, bounds):
    """Beam index ranges [lo, hi] (up to three, for wrap-around) that may hit a bounding circle.
    Returns how many ranges were written into ``bounds``; 0 when the circle is out of range."""
    d = math.hypot(cx - ox, cy - oy)
    if d - radius >= range_max:
        return 0
    if d <= radius or delta == 0.0:
        bounds[0, 0], bounds[0, 1] = 0, n - 1
        return 1
    half = math.asin(radius / d)
    centre = (math.atan2(cy - oy, cx - ox) - a0) % _TWO_PI
    count = 0
    for shift in (-_TWO_PI, 0.0, _TWO_PI):
        lo = max(0, int(math.floor((centre + shift - half) / delta)))
        hi = min(n - 1, int(math.ceil((centre + shift + half) / delta)))
        if lo <= hi:
            bounds[count, 0], bounds[count, 1] = lo, hi
            count += 1
    return count


@kernel
def cast_scan(ox, oy, a0, delta, circles, boxes, segments, range_max, out):
    """Fill ``out`` (n beams at world angles a0 + k * delta) with the distance from (ox, oy) to the
    first circle (rows x, y, r), box (rows x, y, cos yaw, sin yaw, half length, half width) or
    segment (rows x1, y1, x2, y2), or ``range_max`` where nothing is nearer."""
    dirs = _start_scan(a0, delta, range_max, out)
    _cast(ox, oy, a0, delta, circles, boxes, segments, range_max, dirs, out)


@kernel
def cast_scan_among(ox, oy, a0, delta, circles, boxes, segments, more_circles, more_boxes, range_max, out):
    """:func:`cast_scan` among two sets of circles and boxes (the static ones and the movers, without
    joining their tables every step)."""
    dirs = _start_scan(a0, delta, range_max, out)
    _cast(ox, oy, a0, delta, circles, boxes, segments, range_max, dirs, out)
    _cast(ox, oy, a0, delta, more_circles, more_boxes, segments[:0], range_max, dirs, out)


@kernel(inline="always")
def _start_scan(a0, delta, range_max, out):
    n = out.shape[0]
    dirs = np.empty((n, 2))
    for k in range(n):
        dirs[k, 0] = math.cos(a0 + k * delta)
        dirs[k, 1] = math.sin(a0 + k * delta)
        out[k] = range_max
    return dirs


@kernel(inline="always")
def _cast(ox, oy, a0, delta, circles, boxes, segments, range_max, dirs, out):
    """Shorten ``out``'s ranges to the circles, boxes and segments the beams ``dirs`` hit first."""
    n = out.shape[0]
    bounds = np.empty((3, 2), dtype=np.int64)
    for i in range(circles.shape[0]):
        cx, cy, r = circles[i, 0], circles[i, 1], circles[i, 2]
        for w in range(_window(ox, oy, cx, cy, r, a0, delta, n, range_max, bounds)):
            for k in range(bounds[w, 0], bounds[w, 1] + 1):
                t = _hit_circle(ox, oy, dirs[k, 0], dirs[k, 1], cx, cy, r)
                if _EPS < t < out[k]:
                    out[k] = t
    for i in range(boxes.shape[0]):
        radius = math.hypot(boxes[i, 4], boxes[i, 5])
        for w in range(_window(ox, oy, boxes[i, 0], boxes[i, 1], radius, a0, delta, n, range_max, bounds)):
            for k in range(bounds[w, 0], bounds[w, 1] + 1):
                t = _hit_box(ox, oy, dirs[k, 0], dirs[k, 1], boxes[i, 0], boxes[i, 1], boxes[i, 2], boxes[i, 3],
                             boxes[i, 4], boxes[i, 5])
                if _EPS < t < out[k]:
                    out[k] = t
    for i in range(segments.shape[0]):
        x1, y1, x2, y2 = segments[i, 0], segments[i, 1], segments[i, 2], segments[i, 3]
        radius = 0.5 * math.hypot(x2 - x1, y2 - y1)
        for w in range(_window(ox, oy, 0.5 * (x1 + x2), 0.5 * (y1 + y2), radius, a0, delta, n, range_max, bounds)):
            for k in range(bounds[w, 0], bounds[w, 1] + 1):
                t = _hit_segment(ox, oy, dirs[k, 0], dirs[k, 1], x1, y1, x2, y2)
                if _EPS < t < out[k]:
                    out[k] = t


@kernel
def cast_grid(ox, oy, a0, delta, occupied, x0, y0, cell_x, cell_y, out):
    """Shorten ``out`` (beams at world angles a0 + k * delta from (ox, oy)) to where each beam first
    enters an occupied cell of ``occupied`` (indexed [i, j]: the cell from x0 + i cell_x, y0 + j
    cell_y), walking only the cells it crosses (Amanatides and Woo); from inside an occupied cell
    a beam reads where it leaves that cell, as from inside a box."""
    nx, ny = occupied.shape
    for k in range(out.shape[0]):
        dx, dy = math.cos(a0 + k * delta), math.sin(a0 + k * delta)
        i, j = int(math.floor((ox - x0) / cell_x)), int(math.floor((oy - y0) / cell_y))
        step_i, step_j = (1 if dx > 0.0 else -1), (1 if dy > 0.0 else -1)
        next_x = x0 + (i + (1 if dx > 0.0 else 0)) * cell_x  # the cell's edge the beam leaves by in x
        next_y = y0 + (j + (1 if dy > 0.0 else 0)) * cell_y
        t_x = (next_x - ox) / dx if dx != 0.0 else math.inf
        t_y = (next_y - oy) / dy if dy != 0.0 else math.inf
        delta_x = cell_x / abs(dx) if dx != 0.0 else math.inf
        delta_y = cell_y / abs(dy) if dy != 0.0 else math.inf
        if 0 <= i < nx and 0 <= j < ny and occupied[i, j]:
            leave = min(t_x, t_y)
            if _EPS < leave < out[k]:
                out[k] = leave
            continue
        while True:
            if t_x < t_y:
                i, t, t_x = i + step_i, t_x, t_x + delta_x
            else:
                j, t, t_y = j + step_j, t_y, t_y + delta_y
            if t >= out[k] or (i < 0 and step_i < 0) or (i >= nx and step_i > 0) or (j < 0 and step_j < 0) \
                    or (j >= ny and step_j > 0):
                break
            if 0 <= i < nx and 0 <= j < ny and occupied[i, j]:
                if t > _EPS:
                    out[k] = t
                break


_TABLES = np.empty((0, 3)), np.empty((0, 6)), np.empty((0, 4)), np.empty(1)  # circles, boxes, segments, ranges


@functools.cache
def _scan_code() -> Callable:
    """:func:`cast_scan`'s machine code for a lidar's tables (float64, C-contiguous): called
    directly, a scan skips the dispatcher's matching of its arguments' types (about 1.5% of a
    crowd's env step, in turns against the old path in one process)."""
    circles, boxes, segments, ranges = _TABLES
    return compiled_for(cast_scan, *(0.0,) * 4, circles, boxes, segments, 0.0, ranges)


@functools.cache
def _scan_among_code() -> Callable:
    """:func:`cast_scan_among`'s, likewise; compiled at a world's first scan among movers, not
    before: from an empty cache it takes 6 s, a sixth of a static world's first build."""
    circles, boxes, segments, ranges = _TABLES
    return compiled_for(cast_scan_among, *(0.0,) * 4, circles, boxes, segments, circles, boxes, 0.0, ranges)


def _table(rows, width: int) -> np.ndarray:
    """``rows`` as a float64, C-contiguous (N, width) table: the array itself if it is one."""
    table = np.ascontiguousarray(rows, dtype=np.float64)
    return table if table.ndim == 2 and table.shape[1] == width else table.reshape(-1, width)


class Lidar:
    """A lidar mounted on the robot, scanning a fixed set of primitives.

    Args:
        spec: beams, ranges, angular range, mounting offset (x, y, yaw in the robot frame), noise.
        circles: (K, 3) array of x, y, radius.
        boxes: (B, 6) array of x, y, cos yaw, sin yaw, half length, half width.
        segments: (M, 4) array of x1, y1, x2, y2.
        rng: the generator the Gaussian range noise is drawn from.
    """

    def __init__(self, spec: LidarSpec, circles: np.ndarray, boxes: np.ndarray, segments: np.ndarray,
                 rng: np.random.Generator) -> None:
        self.spec = spec
        self._limited = spec.noise_std > 0.0 or spec.range_min > 0.0  # whether finish() has anything to do
        self.place(circles, boxes, segments)
        self.grid: tuple | None = None  # (occupied cells, x0, y0, cell width, cell height): cast_grid's
        self.rng = rng
        angles = spec.beam_angles()
        self.first_beam = float(angles[0]) + spec.offset[2]  # in the robot frame, mounting yaw included
        self.beam_step = float(angles[1] - angles[0]) if spec.beams > 1 else 0.0
        self._mount_x, self._mount_y = spec.offset[0], spec.offset[1]
        self._scan_code = _scan_code()
        self._conformant: tuple[np.ndarray | None, np.ndarray | None] = (None, None)  # the movers' tables last scanned

    def place(self, circles: np.ndarray, boxes: np.ndarray, segments: np.ndarray) -> None:
        """Scan these primitives from now on (arrays as the constructor takes them)."""
        self.circles, self.boxes, self.segments = _table(circles, 3), _table(boxes, 6), _table(segments, 4)

    def origin(self, x: float, y: float, yaw: float) -> tuple[float, float]:
        """The sensor's position for a robot pose."""
        return sensor_origin(x, y, yaw, self._mount_x, self._mount_y)

    def scan(self, x: float, y: float, yaw: float, circles: np.ndarray | None = None,
             boxes: np.ndarray | None = None) -> np.ndarray:
        """Ranges for a robot at (x, y, yaw), in beam order; a new array each call. ``circles`` and
        ``boxes`` (rows as the constructor's) are seen too: the movers, where they are now."""
        ox, oy = sensor_origin(x, y, yaw, self._mount_x, self._mount_y)
        a0 = yaw + self.first_beam
        ranges = np.empty(self.spec.beams)
        if circles is None:
            self._scan_code(ox, oy, a0, self.beam_step, self.circles, self.boxes, self.segments, self.spec.range_max,
                            ranges)
        else:
            circles, boxes = self._movers_tables(circles, boxes)
            _scan_among_code()(ox, oy, a0, self.beam_step, self.circles, self.boxes, self.segments, circles, boxes,
                               self.spec.range_max, ranges)
        if self.grid is not None:
            cast_grid(ox, oy, a0, self.beam_step, *self.grid, ranges)
        return self.finish(ranges)

    def _movers_tables(self, circles, boxes) -> tuple[np.ndarray, np.ndarray]:
        """``circles`` and ``boxes`` as the compiled scan takes them. The movers hand over the same
        two tables every step, rewritten in place: checked once, then passed on as they are. An
        array that needed converting is never the copy kept, so it is converted on every call."""
        if circles is not self._conformant[0] or boxes is not self._conformant[1]:
            self._conformant = _table(circles, 3), _table(boxes, 6)
        return self._conformant

    def finish(self, ranges: np.ndarray) -> np.ndarray:
        """What the sensor makes of exact ranges (``cast_scan``'s): :func:`~common.readings.sensed_ranges`."""
        return sensed_ranges(ranges, self.spec, self.rng) if self._limited else ranges
