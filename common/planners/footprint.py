"""The robot's own footprint in planning: discs that cover it, checked against a distance field.

A rectangle is not its bounding circle: a 0.51 x 0.43 m robot fits through a 0.52 m gap head-on,
where its 0.67 m bounding circle does not. So a :class:`FootprintGrid` checks the footprint itself
at each pose a planner would put the robot in, heading included. A pose is free when the footprint
keeps the grid's margin from every occupied cell (an obstacle in a cell may reach its corner, so
from its centre the margin plus half a cell's diagonal). Two tests decide it: the footprint's
covering discs (a circle robot is its own disc; a rectangle is covered by overlapping discs along
its long side, each at most :data:`SLACK` times its half-width; a polygon part by those of its
bounding rectangle) read the grid's distance field bilinearly, a few reads a pose, and where they
do not clear it (discs stick out past a rectangle's ends and corners) the rectangles themselves
are measured against the occupied cells around them. Turning on the spot swings a rectangle's
corners round, so a turn is checked at headings :data:`TURN_STEP` apart.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from common.geometry import box_distance
from common.kernel_cache import kernel
from common.occupancy import OccupancyGrid
from common.planners.base import grid_arrays
from common.scenario import RobotProfile

SLACK = 1.08  # a covering disc's radius is at most this many times the rectangle's half-width
MAX_DISCS = 16  # per rectangle: up to sixteen times longer than wide within the slack
TURN_STEP = math.radians(15.0)  # headings checked this far apart along a turn on the spot


def _cover_rectangle(x_min: float, y_min: float, x_max: float, y_max: float) -> tuple[list, list]:
    """Discs (centres, radii) along the long side of an axis-aligned rectangle, covering it."""
    long_x = x_max - x_min >= y_max - y_min
    half_long, half_short = (0.5 * (x_max - x_min), 0.5 * (y_max - y_min))[:: 1 if long_x else -1]
    # Each disc covers a stretch 2 * half_long / n of the long side: its radius reaches the corners of it.
    n = min(MAX_DISCS, max(1, math.ceil(half_long / (half_short * math.sqrt(SLACK**2 - 1.0)))))
    radius = math.hypot(half_short, half_long / n)
    cx, cy = 0.5 * (x_min + x_max), 0.5 * (y_min + y_max)
    offsets = [(-half_long + (2 * i + 1) * half_long / n) for i in range(n)]
    centres = [(cx + o, cy) if long_x else (cx, cy + o) for o in offsets]
    return centres, [radius] * n


@dataclass(frozen=True, eq=False)
class Footprint:
    """A robot's footprint in its own frame: ``centres`` (K, 2) and ``radii`` (K,) of discs that
    cover it, its circle parts first (``exact`` of them: those discs are the footprint itself), and
    its rectangles as ``boxes`` (M, 4): centre x, y, length along the heading, width across, m."""

    centres: np.ndarray
    radii: np.ndarray
    exact: int
    boxes: np.ndarray

    @classmethod
    def of(cls, robot: RobotProfile) -> "Footprint":
        """The footprint of ``robot.outline``: its circles, and each polygon by its bounding rectangle."""
        circles = [part for part in robot.outline if part.radius is not None]
        centres, radii = [part.center for part in circles], [part.radius for part in circles]
        boxes = []
        for part in robot.outline:
            if part.vertices is not None:
                (x_min, y_min), (x_max, y_max) = np.min(part.vertices, axis=0), np.max(part.vertices, axis=0)
                more_centres, more_radii = _cover_rectangle(x_min, y_min, x_max, y_max)
                centres += more_centres
                radii += more_radii
                boxes.append((0.5 * (x_min + x_max), 0.5 * (y_min + y_max), x_max - x_min, y_max - y_min))
        return cls(np.array(centres, dtype=float).reshape(-1, 2), np.array(radii, dtype=float), len(circles),
                   np.array(boxes, dtype=float).reshape(-1, 4))

    @classmethod
    def point(cls) -> "Footprint":
        """A robot of no size (a grid already inflated by the robot's)."""
        return cls(np.zeros((1, 2)), np.zeros(1), 1, np.zeros((0, 4)))

    @property
    def turns_freely(self) -> bool:
        """Whether turning on the spot sweeps nothing new (one disc about the reference point)."""
        return len(self.radii) == 1 and self.exact == 1 and not self.centres.any()


@kernel
def clearance_at(field: np.ndarray, x0: float, y0: float, resolution: float, x: float, y: float) -> float:
    """The field read bilinearly between cell centres at (x, y); minus infinity off the grid."""
    rows, cols = field.shape
    u = (x - x0) / resolution - 0.5
    v = (y - y0) / resolution - 0.5
    if u < -0.5 or v < -0.5 or u > cols - 0.5 or v > rows - 0.5:
        return -math.inf
    u = min(max(u, 0.0), cols - 1.0)
    v = min(max(v, 0.0), rows - 1.0)
    c0 = min(int(u), max(cols - 2, 0))
    r0 = min(int(v), max(rows - 2, 0))
    c1, r1 = min(c0 + 1, cols - 1), min(r0 + 1, rows - 1)
    fu, fv = u - c0, v - r0
    low = field[r0, c0] * (1.0 - fu) + field[r0, c1] * fu
    high = field[r1, c0] * (1.0 - fu) + field[r1, c1] * fu
    return low * (1.0 - fv) + high * fv


@kernel
def pose_clearance(field: np.ndarray, x0: float, y0: float, resolution: float, centres: np.ndarray,
                   radii: np.ndarray, x: float, y: float, yaw: float) -> float:
    """How far the footprint at (x, y, yaw) stands from the nearest obstacle (its closest disc), m."""
    c, s = math.cos(yaw), math.sin(yaw)
    least = math.inf
    for k in range(radii.shape[0]):
        px = x + c * centres[k, 0] - s * centres[k, 1]
        py = y + s * centres[k, 0] + c * centres[k, 1]
        least = min(least, clearance_at(field, x0, y0, resolution, px, py) - radii[k])
    return least


@kernel
def _box_clear(occupied: np.ndarray, x0: float, y0: float, resolution: float, bx: float, by: float, length: float,
               width: float, c: float, s: float, needed: float) -> bool:
    """Whether every occupied cell's centre lies at least ``needed`` outside the box (and the box,
    so widened, lies on the grid)."""
    rows, cols = occupied.shape
    reach_x = 0.5 * (abs(c) * length + abs(s) * width) + needed
    reach_y = 0.5 * (abs(s) * length + abs(c) * width) + needed
    c0, c1 = int(math.floor((bx - reach_x - x0) / resolution)), int(math.floor((bx + reach_x - x0) / resolution))
    r0, r1 = int(math.floor((by - reach_y - y0) / resolution)), int(math.floor((by + reach_y - y0) / resolution))
    if c0 < 0 or r0 < 0 or c1 >= cols or r1 >= rows:
        return False
    for r in range(r0, r1 + 1):
        cy = y0 + (r + 0.5) * resolution
        for col in range(c0, c1 + 1):
            if occupied[r, col] and box_distance(x0 + (col + 0.5) * resolution, cy, bx, by, length, width, c, s) < needed:
                return False
    return True


@kernel
def pose_free(field: np.ndarray, occupied: np.ndarray, x0: float, y0: float, resolution: float, centres: np.ndarray,
              radii: np.ndarray, exact: int, boxes: np.ndarray, margin: float, x: float, y: float, yaw: float) -> bool:
    """Whether the footprint at (x, y, yaw) keeps ``margin`` from every occupied cell: its discs
    first, then, where they do not clear it, its circles and rectangles themselves."""
    if pose_clearance(field, x0, y0, resolution, centres, radii, x, y, yaw) >= margin:
        return True
    if pose_clearance(field, x0, y0, resolution, centres[:exact], radii[:exact], x, y, yaw) < margin:
        return False
    c, s = math.cos(yaw), math.sin(yaw)
    needed = margin + resolution * math.sqrt(0.5)
    for k in range(boxes.shape[0]):
        bx = x + c * boxes[k, 0] - s * boxes[k, 1]
        by = y + s * boxes[k, 0] + c * boxes[k, 1]
        if not _box_clear(occupied, x0, y0, resolution, bx, by, boxes[k, 2], boxes[k, 3], c, s, needed):
            return False
    return True


@kernel
def turn_free(field: np.ndarray, occupied: np.ndarray, x0: float, y0: float, resolution: float, centres: np.ndarray,
              radii: np.ndarray, exact: int, boxes: np.ndarray, margin: float, x: float, y: float, yaw_from: float,
              yaw_to: float) -> bool:
    """Whether the footprint keeps ``margin`` at every heading of the shorter turn yaw_from -> yaw_to."""
    turn = (yaw_to - yaw_from + math.pi) % (2.0 * math.pi) - math.pi
    steps = max(1, int(math.ceil(abs(turn) / TURN_STEP)))
    for i in range(steps + 1):
        if not pose_free(field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin, x, y,
                         yaw_from + turn * i / steps):
            return False
    return True


@kernel
def segment_free(field: np.ndarray, occupied: np.ndarray, x0: float, y0: float, resolution: float, centres: np.ndarray,
                 radii: np.ndarray, exact: int, boxes: np.ndarray, margin: float, ax: float, ay: float, bx: float,
                 by: float) -> bool:
    """Whether the footprint, heading along a -> b, keeps ``margin`` at poses half a cell apart on the way."""
    length = math.hypot(bx - ax, by - ay)
    yaw = math.atan2(by - ay, bx - ax)
    n = max(1, int(math.ceil(length / (0.5 * resolution))))
    for i in range(n + 1):
        t = i / n
        if not pose_free(field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin,
                         ax + t * (bx - ax), ay + t * (by - ay), yaw):
            return False
    return True


@kernel
def _standable(field: np.ndarray, occupied: np.ndarray, x0: float, y0: float, resolution: float, centres: np.ndarray,
               radii: np.ndarray, exact: int, boxes: np.ndarray, margin: float, headings: int) -> np.ndarray:
    """Per cell: whether the footprint at its centre keeps the margin facing one of ``headings`` ways."""
    rows, cols = field.shape
    out = np.zeros((rows, cols), dtype=np.bool_)
    for r in range(rows):
        y = y0 + (r + 0.5) * resolution
        for c in range(cols):
            x = x0 + (c + 0.5) * resolution
            for k in range(headings):
                if pose_free(field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin, x, y,
                             2.0 * math.pi * k / headings):
                    out[r, c] = True
                    break
    return out


@kernel
def corner_free(field: np.ndarray, occupied: np.ndarray, x0: float, y0: float, resolution: float, centres: np.ndarray,
                radii: np.ndarray, exact: int, boxes: np.ndarray, margin: float, points: np.ndarray, heading: float,
                i: int, j: int) -> bool:
    """Whether the robot, arriving at ``points[i]`` heading ``heading`` (NaN: any), can turn there
    and drive straight on to ``points[j]``."""
    ax, ay, bx, by = points[i, 0], points[i, 1], points[j, 0], points[j, 1]
    if not math.isnan(heading) and not turn_free(field, occupied, x0, y0, resolution, centres, radii, exact, boxes,
                                                 margin, ax, ay, heading, math.atan2(by - ay, bx - ax)):
        return False
    return segment_free(field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin, ax, ay, bx, by)


class FootprintGrid:
    """Where a robot of ``footprint`` may stand on a grid of obstacle cells (``cells``, not inflated).

    ``margin`` is the clearance (m) every pose must keep beyond touching. Off the grid counts as
    occupied. A point counts as free (:meth:`is_free`) where the robot can stand on it facing one
    of eight headings.
    """

    def __init__(self, cells: OccupancyGrid, footprint: Footprint, margin: float = 0.0) -> None:
        self.cells, self.footprint, self.margin = cells, footprint, float(margin)
        self.occupied = np.ascontiguousarray(cells.occupied, dtype=np.bool_)
        self.origin = (float(cells.origin[0]), float(cells.origin[1]))
        self.resolution = float(cells.resolution)
        # A ring of occupied cells round the grid: what lies off it counts as occupied.
        ringed = np.pad(self.occupied, 1, constant_values=True)
        distance = ndimage.distance_transform_edt(~ringed, sampling=self.resolution)[1:-1, 1:-1]
        self.field = distance - self.resolution * math.sqrt(0.5)
        self._standable: np.ndarray | None = None

    def with_margin(self, margin: float) -> "FootprintGrid":
        """The same grid and field, keeping another margin."""
        other = copy.copy(self)
        other.margin, other._standable = float(margin), None
        return other

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        """The (row, col) of the cell containing (x, y), clamped to the grid."""
        return self.cells.cell_of(x, y)

    def is_free(self, x: float, y: float) -> bool:
        """Whether the robot can stand at (x, y) facing one of eight headings (any, for a circle)."""
        headings = 1 if self.footprint.turns_freely else 8
        return any(self.pose_free(x, y, 2.0 * math.pi * k / headings) for k in range(headings))

    @property
    def standable(self) -> np.ndarray:
        """Per cell, whether :meth:`is_free` holds at its centre (computed once)."""
        if self._standable is None:
            self._standable = _standable(*self.arrays, 1 if self.footprint.turns_freely else 8)
        return self._standable

    @property
    def arrays(self) -> tuple:
        """(field, occupied, x0, y0, resolution, centres, radii, exact, boxes, margin): what the kernels take."""
        footprint = self.footprint
        return (self.field, self.occupied, *self.origin, self.resolution, footprint.centres, footprint.radii,
                footprint.exact, footprint.boxes, self.margin)

    def clearance(self, x: float, y: float, yaw: float) -> float:
        """How far the footprint's discs at this pose stand from the nearest obstacle, m (negative:
        overlapping): at most the footprint's own clearance."""
        footprint = self.footprint
        return float(pose_clearance(self.field, *self.origin, self.resolution, footprint.centres, footprint.radii,
                                    float(x), float(y), float(yaw)))

    def pose_free(self, x: float, y: float, yaw: float) -> bool:
        """Whether the footprint at this pose keeps the margin."""
        return bool(pose_free(*self.arrays, float(x), float(y), float(yaw)))

    def turn_free(self, x: float, y: float, yaw_from: float, yaw_to: float) -> bool:
        """Whether turning on the spot from one heading to the other keeps the margin throughout."""
        return bool(turn_free(*self.arrays, float(x), float(y), float(yaw_from), float(yaw_to)))

    def segment_free(self, a, b) -> bool:
        """Whether driving straight from a to b (heading along it) keeps the margin throughout."""
        return bool(segment_free(*self.arrays, float(a[0]), float(a[1]), float(b[0]), float(b[1])))

    def path_free(self, points: np.ndarray, heading: float | None = None) -> bool:
        """Whether a polyline can be driven: straight along each segment, turning on the spot at
        each vertex, starting at ``heading`` (None: facing the first segment)."""
        points = np.ascontiguousarray(points, dtype=float).reshape(-1, 2)
        previous = math.nan if heading is None else float(heading)
        for i in range(len(points) - 1):
            if not corner_free(*self.arrays, points, previous, i, i + 1):
                return False
            previous = math.atan2(points[i + 1, 1] - points[i, 1], points[i + 1, 0] - points[i, 0])
        return True


def kernel_arrays(grid: "OccupancyGrid | FootprintGrid") -> tuple:
    """What the planners' kernels take: a footprint grid's :attr:`FootprintGrid.arrays`, or for an
    inflated grid (a point robot) its cells with an empty field, no discs and no boxes."""
    if isinstance(grid, FootprintGrid):
        return grid.arrays
    return (np.empty((0, 0)), *grid_arrays(grid), np.empty((0, 2)), np.empty(0), 0, np.empty((0, 4)), 0.0)
