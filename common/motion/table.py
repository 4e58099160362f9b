"""A scenario's movers as arrays: what the compiled steps read and write.

Per mover, one row of floats (``F``) and one of integers (``I``), with named columns; its goal
queue (``goals``, rows ``head`` to ``tail``) and the route it starts over from (``routes``); its
behaviour's parameters (``params``). And the world as the movers' behaviours see it, IR-SIM's
way: every object as a disc of its centroid, velocity and bounding radius + 0.1 m (``objects``,
row 0 the controlled robot, then the scenario's obstacles in order), and line obstacles as
segments. IR-SIM's order of objects decides who steps first and the order of sums, so it is kept.

The static geometry a mover can touch (``contacts``) is kept apart: circles, boxes, segments and
polygon rings, as the tiers build them.

An IR-SIM world (``scenario.kind == "irsim"``) is seen as IR-SIM sees it, to the last bit: a disc
sits at the GEOS centroid of the object's polygon (a circle is a 64-gon) and measures its GEOS
bounding radius (:mod:`common.irsim_geometry`); a mover keeps its polygon (``outlines``) to find
its centroid wherever it moves. Elsewhere a disc is the exact circle, or a box's centre and half
diagonal. Contacts and the lidar use the exact shapes in both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from common.irsim_geometry import CIRCLE_VERTICES, bounding_radius, circle_disc, circle_outline, rectangle_disc, \
    rectangle_outline
from common.kernel_cache import kernel
from common.motion.sfm import PARAMETERS as SFM_PARAMETERS
from common.motion.spec import Dash, Motion, Orca, Rvo, Sfm
from common.scenario import BoxObstacle, CircleObstacle, PolygonObstacle, Scenario, SegmentObstacle

# Float columns of F.
(X, Y, THETA, V0, V1, VMIN0, VMIN1, VMAX0, VMAX1, ACC0, ACC1, RADIUS, LENGTH, WIDTH, GOAL_THRESHOLD, ANGLE_TOLERANCE,
 WANDER_X0, WANDER_Y0, WANDER_X1, WANDER_Y1, START_X, START_Y, INIT_THETA, INIT_V0, INIT_V1, PLAN0, PLAN1,
 SEEN_RADIUS, SLACK) = range(29)
FLOATS = 29
# Integer columns of I.
(KINEMATICS, BEHAVIOR, SHAPE, GROUP, ROLE, UNOBSTRUCTED, REACTS, TARGET, LOOP, WANDER, STOPPED, ARRIVED, HEAD, TAIL,
 ROUTE_LENGTH, ROW, PLANNED, DRIVEN, RVO_MODE, OUTLINE, SLIDES) = range(21)
INTS = 21
# Codes.
OMNI, DIFF = 0, 1
DASH, RVO, ORCA, SFM = 0, 1, 2, 3
CIRCLE, BOX = 0, 1
OBSTACLE, ROBOT = 0, 1
ALL, ROBOTS, OBSTACLES = 0, 1, 2
RVO_MODES = ("rvo", "hrvo", "vo")
EXTEND = 0.1  # m: IR-SIM's margin on a body's bounding radius, as others' behaviours see it
PARAMS = 13  # the widest behaviour's parameter count (the social force model's)
ORCA_PARAMETERS = ("neighbor_dist", "max_neighbors", "time_horizon", "safe_radius", "max_speed")
RVO_PARAMETERS = ("vxmax", "vymax", "acce", "factor", "neighbor_threshold")
# Columns of ``objects``.
OX, OY, OVX, OVY, OR, OROLE = range(6)


def enclosing_radius(points: np.ndarray) -> float:
    """The radius of the smallest circle around ``points`` (N, 2) (Welzl's algorithm, points in the
    given order)."""
    circle = (float(points[0, 0]), float(points[0, 1]), 0.0)
    for i in range(1, len(points)):
        if _outside(circle, points[i]):
            circle = (float(points[i, 0]), float(points[i, 1]), 0.0)
            for j in range(i):
                if _outside(circle, points[j]):
                    circle = _two(points[i], points[j])
                    for k in range(j):
                        if _outside(circle, points[k]):
                            circle = _three(points[i], points[j], points[k])
    return circle[2]


def _outside(circle: tuple[float, float, float], point: np.ndarray) -> bool:
    return math.hypot(point[0] - circle[0], point[1] - circle[1]) > circle[2] * (1 + 1e-12) + 1e-12


def _two(a: np.ndarray, b: np.ndarray) -> tuple[float, float, float]:
    x, y = 0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])
    return float(x), float(y), 0.5 * math.hypot(a[0] - b[0], a[1] - b[1])


def _three(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[float, float, float]:
    bx, by, cx, cy = b[0] - a[0], b[1] - a[1], c[0] - a[0], c[1] - a[1]
    d = 2.0 * (bx * cy - by * cx)
    if d == 0.0:  # collinear: the widest pair spans them
        pairs = (_two(a, b), _two(a, c), _two(b, c))
        return max(pairs, key=lambda circle: circle[2])
    ux = (cy * (bx * bx + by * by) - by * (cx * cx + cy * cy)) / d
    uy = (bx * (cx * cx + cy * cy) - cx * (bx * bx + by * by)) / d
    return float(a[0] + ux), float(a[1] + uy), math.hypot(ux, uy)


def polygon_centroid(ring: np.ndarray) -> tuple[float, float]:
    """The area centroid of a simple polygon (either winding)."""
    x, y = ring[:, 0], ring[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = 0.5 * cross.sum()
    return float(((x + xn) * cross).sum() / (6.0 * area)), float(((y + yn) * cross).sum() / (6.0 * area))


def as_disc(obstacle) -> tuple[float, float, float]:
    """An obstacle as IR-SIM's behaviours see it: its centroid and bounding radius."""
    if isinstance(obstacle, CircleObstacle):
        return obstacle.x, obstacle.y, obstacle.radius
    if isinstance(obstacle, BoxObstacle):
        return obstacle.x, obstacle.y, 0.5 * math.hypot(obstacle.length, obstacle.width)
    ring = np.asarray(obstacle.vertices, dtype=float)
    cx, cy = polygon_centroid(ring)
    return cx, cy, enclosing_radius(ring)


def _behavior_row(motion: Motion, step_time: float) -> list[float]:
    """The behaviour's parameters as a row of ``params``."""
    behavior = motion.behavior
    if isinstance(behavior, Sfm):
        row = [behavior.vmax, step_time, *(getattr(behavior, name) for name in SFM_PARAMETERS[2:])]
    elif isinstance(behavior, Orca):
        realizable = motion.vel_max[0] if motion.kinematics == "diff" else min(motion.vel_max)
        speed = realizable if behavior.max_speed is None else min(behavior.max_speed, realizable)
        row = [behavior.neighbor_dist, behavior.max_neighbors, behavior.time_horizon, behavior.safe_radius, speed]
    elif isinstance(behavior, Rvo):
        row = [getattr(behavior, name) for name in RVO_PARAMETERS]
    else:
        row = [behavior.yield_distance]
    return row + [0.0] * (PARAMS - len(row))


@dataclass
class MoverTable:
    """The arrays of a scenario's movers (see the module); build with :func:`mover_table`."""

    F: np.ndarray  # (N, FLOATS)
    I: np.ndarray  # noqa: E741  (N, INTS)
    params: np.ndarray  # (N, PARAMS)
    goals: np.ndarray  # (N, Q, 2): the queue, rows HEAD to TAIL
    routes: np.ndarray  # (N, Q, 2): the route a loop starts over from (ROUTE_LENGTH rows)
    orca_velocity: np.ndarray  # (N, 2) float32: each ORCA agent's own velocity, RVO2's state
    objects: np.ndarray  # (1 + obstacles, 6): x, y, vx, vy, bounding radius + 0.1, role
    segments: np.ndarray  # (S, 4): line obstacles, as behaviours see them
    labels: tuple[str, ...]
    obstacle_index: np.ndarray  # (N,): each mover's index in scenario.obstacles (-1: the controlled robot)
    irsim: bool  # whether discs are IR-SIM's polygons' (see the module)
    outlines: np.ndarray  # (N, 65, 2): each mover's polygon at the origin in IR-SIM worlds (OUTLINE rows); (N, 0, 2) else


_BEHAVIORS = {"dash": DASH, "rvo": RVO, "orca": ORCA, "sfm": SFM}
_TARGETS = {"all": ALL, "robot": ROBOTS, "obstacle": OBSTACLES}


def mover_table(scenario: Scenario) -> MoverTable:
    """The arrays of ``scenario``'s movers (the controlled robot too, if it carries a motion)."""
    entries: list[tuple[int, object, Motion]] = []
    if scenario.robot_motion is not None:
        entries.append((-1, None, scenario.robot_motion))
    entries += [(i, o, o.motion) for i, o in enumerate(scenario.obstacles)
                if type(o) in (CircleObstacle, BoxObstacle) and o.motion is not None]
    irsim = scenario.kind == "irsim"
    n = len(entries)
    routes = [motion.route_from(_position(scenario, obstacle)) for _, obstacle, motion in entries]
    capacity = max([2] + [len(r) + 1 for r in routes])
    floats, ints, params = [], [], []
    goals, route_table = np.zeros((n, capacity, 2)), np.zeros((n, capacity, 2))
    outlines = np.zeros((n, CIRCLE_VERTICES + 1 if irsim else 0, 2))  # (n, 0, 2): a row each, for move() to index
    groups: dict[str, int] = {}
    step_time = scenario.world.step_time
    for m, ((index, obstacle, motion), route) in enumerate(zip(entries, routes)):
        x, y = _position(scenario, obstacle)
        theta = scenario.start[2] if obstacle is None else obstacle.yaw
        body = scenario.robot if obstacle is None else obstacle
        box = isinstance(body, BoxObstacle) or (obstacle is None and body.shape == "box")
        radius = 0.5 * math.hypot(body.length, body.width) if box else body.radius
        size = len(_outline(outlines[m], box, body)) if irsim else 0
        seen = _irsim_radius(outlines[m, :size]) if irsim else radius
        behavior = motion.behavior
        v0, v1 = motion.velocity
        floats.append([x, y, theta, v0, v1, *motion.lower, *motion.vel_max, *motion.acce, radius,
                       *((body.length, body.width) if box else (0.0, 0.0)), motion.goal_threshold,
                       behavior.angle_tolerance if isinstance(behavior, Dash) else 0.1,
                       *(motion.wander or (0.0, 0.0, 0.0, 0.0)), x, y, theta, v0, v1, 0.0, 0.0, seen, 0.0])
        ints.append([DIFF if motion.kinematics == "diff" else OMNI, _BEHAVIORS[behavior.name], BOX if box else CIRCLE,
                     -1 if motion.group is None else groups.setdefault(motion.group, len(groups)),
                     ROBOT if motion.role == "robot" else OBSTACLE, 0 if obstacle is None else int(obstacle.unobstructed),
                     int(motion.reacts_to_robot), _TARGETS[motion.target_roles],
                     int(motion.route != "once" and motion.wander is None), int(motion.wander is not None), 0, 0, 0, 0,
                     len(route), index + 1, 0, int(obstacle is None),
                     RVO_MODES.index(behavior.mode) if isinstance(behavior, Rvo) else 0, size,
                     int(motion.static_contact == "slide")])
        if route:  # a wanderer without goals draws its first at reset (Movers.reset)
            route_table[m, :len(route)] = route
        params.append(_behavior_row(motion, step_time))
    objects, segments = _objects(scenario, irsim)
    return MoverTable(np.array(floats, dtype=float).reshape(n, FLOATS), np.array(ints, dtype=np.int64).reshape(n, INTS),
                      np.array(params, dtype=float).reshape(n, PARAMS), goals, route_table,
                      np.zeros((n, 2), dtype=np.float32), objects, segments, tuple(e[2].label for e in entries),
                      np.array([e[0] for e in entries], dtype=np.int64), irsim, outlines)


def _outline(out: np.ndarray, box: bool, body) -> np.ndarray:
    """Write IR-SIM's polygon of a body (a circle's 64-gon, a rectangle) at the origin into ``out``."""
    ring = rectangle_outline(body.length, body.width) if box else circle_outline(body.radius)
    out[:len(ring)] = ring
    return ring


def _irsim_radius(ring: np.ndarray) -> float:
    return float(_bounding_radius(np.ascontiguousarray(ring)))


@kernel
def _bounding_radius(ring: np.ndarray) -> float:
    return bounding_radius(ring)


@kernel
def _irsim_discs(shapes: np.ndarray) -> np.ndarray:
    """IR-SIM's discs (centroid x, y, bounding radius) of circles and rectangles given as rows
    (kind, x, y, yaw, radius or length, width): their polygons placed at (x, y, yaw)."""
    out = np.empty((shapes.shape[0], 3))
    for k in range(shapes.shape[0]):
        kind, x, y, yaw, a, b = shapes[k, 0], shapes[k, 1], shapes[k, 2], shapes[k, 3], shapes[k, 4], shapes[k, 5]
        if kind == CIRCLE:
            out[k, 0], out[k, 1], out[k, 2] = circle_disc(0.0, 0.0, a, x, y, yaw)
        else:
            out[k, 0], out[k, 1], out[k, 2] = rectangle_disc(a, b, x, y, yaw)
    return out


def _position(scenario: Scenario, obstacle) -> tuple[float, float]:
    if obstacle is None:
        return scenario.start[0], scenario.start[1]
    return obstacle.x, obstacle.y


def _objects(scenario: Scenario, irsim: bool) -> tuple[np.ndarray, np.ndarray]:
    """Every object as a disc (row 0 the robot; a line obstacle's row is unused, radius -1) and
    the line obstacles' segments, in IR-SIM's object order, the world's walls (if it has them) last."""
    objects = np.zeros((1 + len(scenario.obstacles), 6))
    robot = scenario.robot
    objects[0] = (*scenario.start[:2], 0.0, 0.0, robot.bounding_radius + EXTEND, ROBOT)
    shapes, rows = [], []
    if irsim:
        shapes.append((BOX if robot.shape == "box" else CIRCLE, *scenario.start,
                       *((robot.length, robot.width) if robot.shape == "box" else (robot.radius, 0.0))))
        rows.append(0)
    segments = []
    for row, obstacle in enumerate(scenario.obstacles, start=1):
        if isinstance(obstacle, SegmentObstacle):
            points = np.asarray(obstacle.points, dtype=float)
            segments.extend(np.hstack([points[:-1], points[1:]]).tolist())
            objects[row, OR] = -1.0  # not a disc
            continue
        role = ROBOT if getattr(obstacle, "motion", None) is not None and obstacle.motion.role == "robot" else OBSTACLE
        if irsim and not isinstance(obstacle, PolygonObstacle):
            box = isinstance(obstacle, BoxObstacle)
            shapes.append((BOX if box else CIRCLE, obstacle.x, obstacle.y, obstacle.yaw,
                           *((obstacle.length, obstacle.width) if box else (obstacle.radius, 0.0))))
            rows.append(row)
            objects[row, OROLE] = role
            continue
        x, y, radius = as_disc(obstacle)
        objects[row] = (x, y, 0.0, 0.0, radius + EXTEND, role)
    if shapes:
        discs = _irsim_discs(np.array(shapes, dtype=float))
        objects[rows, OX], objects[rows, OY], objects[rows, OR] = discs[:, 0], discs[:, 1], discs[:, 2] + EXTEND
    world = scenario.world
    if world.walls:  # lines movers keep off, last (where an IR-SIM export puts them: common.irsim_export)
        x0, y0 = world.offset
        x1, y1 = x0 + world.width, y0 + world.height
        segments += [[x0, y0, x1, y0], [x1, y0, x1, y1], [x1, y1, x0, y1], [x0, y1, x0, y0]]
    return objects, np.array(segments, dtype=float).reshape(-1, 4)


def static_contacts(scenario: Scenario) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The static geometry a mover may touch: circles (x, y, r), boxes (x, y, cos, sin, half length,
    half width), segments (x1, y1, x2, y2: walls, polygon edges, lines), and the polygons' rings
    (all vertices, and each ring's first row and length), unobstructed obstacles left out."""
    circles, boxes, segments, rings, starts = [], [], [], [], []
    world = scenario.world
    if world.walls:
        x0, y0 = world.offset
        x1, y1 = x0 + world.width, y0 + world.height
        corners = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
        segments += [(*corners[k], *corners[(k + 1) % 4]) for k in range(4)]
    for obstacle in scenario.obstacles:
        if obstacle.unobstructed or getattr(obstacle, "motion", None) is not None:
            continue
        if isinstance(obstacle, CircleObstacle):
            circles.append((obstacle.x, obstacle.y, obstacle.radius))
        elif isinstance(obstacle, BoxObstacle):
            boxes.append((obstacle.x, obstacle.y, math.cos(obstacle.yaw), math.sin(obstacle.yaw),
                          0.5 * obstacle.length, 0.5 * obstacle.width))
        else:
            points = np.asarray(obstacle.vertices if isinstance(obstacle, PolygonObstacle) else obstacle.points, dtype=float)
            closed = isinstance(obstacle, PolygonObstacle)
            ends = np.roll(points, -1, axis=0) if closed else points[1:]
            segments += np.hstack([points if closed else points[:-1], ends]).tolist()
            if closed:
                starts.append((sum(len(r) for r in rings), len(points)))
                rings.append(points)
    return (np.array(circles, dtype=float).reshape(-1, 3), np.array(boxes, dtype=float).reshape(-1, 6),
            np.array(segments, dtype=float).reshape(-1, 4),
            np.vstack(rings) if rings else np.zeros((0, 2)), np.array(starts, dtype=np.int64).reshape(-1, 2))
