"""The generator kinds whose worlds move: ``crowd`` and ``warehouse_moving``.

``crowd``: people in an open hall, or in two corridors that cross (walls as line obstacles, as
IR-SIM's crossing example has them). Every person wanders: walks at its own speed to a goal drawn
in its region (the hall, or its corridor) and, on arriving, to the next one, drawn from the
episode's seed. The crowd avoids itself by ORCA or by the social force model (half the scenarios
each), and the robot too if it reacts. Difficulty sets the count (4 + 16 d: 12 at 0.5) and the
fastest walker (0.5 + 1.4 d m/s: 1.2 at 0.5); past 0.5 a growing share of the people do not see
the robot (all of them at 1).

``warehouse_moving``: two or three shelving rows (ending 1.2 m short of the walls, so aisles meet
at both ends as well) with aisles between them,
a cross-aisle through every row, and a few crates off the paths. Forklifts patrol stretches of
the aisles back and forth (``dash`` along their waypoints: they turn round in place at each end);
a driver who sees the robot stops while it stands within a metre ahead in the forklift's lane;
people walk stretches of the cross-aisle back and forth (social force, or ORCA). Difficulty sets
the forklifts (1 + 2 d, one per aisle at most, at 0.4 to 0.4 + 1.2 d m/s) and the people (2 + 4 d,
at 0.5 to 0.5 + 1.4 d m/s); past 0.5 a growing share of drivers and people are blind to the
robot (all of them at 1), as in crowds. The robot's start and goal lie off the aisles' centre lines; the shelves, the
cross-aisle and the crates' gaps leave the goal reachable by construction (a test checks it).
In a 10 m world three rows leave the start and goal almost no room off the paths (the far
ends of the rows only), so most three-row draws are redrawn: 3% of the scenarios have three
rows. The suites keep that mix, as their figures were measured on it.

Options (a suite's variants): ``reacting`` (True or False: every person and driver sees the robot, or none)
and ``behavior`` (``orca`` or ``sfm`` for the whole crowd). Movers pass through each other
(collision mode ``unobstructed_obstacles``, IR-SIM's); the robot stops on any contact. People
slide along walls, shelves and crates rather than walk into them (``static_contact: slide``,
:mod:`common.motion.slide`): pushed sideways by the crowd, IR-SIM's would cross a corridor's wall
or walk into a shelf's end.
Each kind draws from its own seeded stream, so the static kinds' scenarios are untouched. The
placements are compiled loops on the caller's generator: a new scenario costs well under a
millisecond (``curriculum bench``'s ``reset_ms_*``).
"""

from __future__ import annotations

import functools
import math
from typing import Callable

import numpy as np

from common.kernel_cache import compiled_for, kernel
from common.motion.spec import Dash, Motion, Orca, Sfm
from common.scenario import BoxObstacle, CircleObstacle, Obstacle, Scenario, SegmentObstacle

PERSON_RADIUS = (0.2, 0.3)  # m: shoulders of 0.4 to 0.6 m
FORKLIFT = (1.0, 0.6)  # m: a pallet truck's footprint, length x width
FORKLIFT_SPEED = (0.4, 1.2)  # m/s: from 0.4 to 0.4 + 1.2 d (1 at difficulty 0.5)
MARGIN = 0.5  # m: people and patrols keep this far inside the world's walls
CLEAR_OF_ROBOT = 1.0  # m: between a mover's start (or a crate) and the robot's start and goal
FORKLIFT_YIELD = 1.0  # m: a driver who sees the robot in the lane ahead, this close, stops until it leaves
OFF_PATHS = 0.9  # m: from a warehouse's start and goal to the lines forklifts and people move along
# The social force among generated people. IR-SIM's defaults let people walk into a robot standing
# still (65% of 40 crowds within 30 s) and into each other (1.6 overlapping pairs a step); a
# stronger push (10, not 2.1) that saturates at a personal space of 0.3 m, weighing distance over
# closing speed (lambda 1, not 2), leaves neither, at the same pace; and walls felt within a metre
# or two (2 and 0.5 m, as IR-SIM's own head-on example; its defaults, 10 and 0.8 m, reach 4 m and
# squeeze people between a wall and the robot). tests/test_moving_kinds.py measures both. Beyond
# 3 m (IR-SIM: 10) people leave each other alone.
CROWD_SFM = {"force_factor_social": 10.0, "safety_radius": 0.3, "lambda_importance": 1.0, "neighbor_threshold": 3.0,
             "force_factor_obstacle": 2.0, "sigma_obstacle": 0.5}
ORCA_CROWD = Orca(neighbor_dist=4.0, max_neighbors=8, time_horizon=2.0, time_horizon_obst=2.0, safe_radius=0.05)


def crowd_size(difficulty: float) -> tuple[int, float]:
    """The number of people and the fastest walker's speed (m/s) at a difficulty."""
    return int(round(4 + 16 * difficulty)), 0.5 + 1.4 * difficulty


@kernel
def _spaced_points(rng, regions: np.ndarray, count: int, keep: np.ndarray, clearance: float, spacing: float,
                   tries: int) -> np.ndarray:
    """``count`` points, the i-th drawn in region ``i % len(regions)`` (x0, y0, x1, y1), each
    ``clearance`` from the points of ``keep`` and ``spacing`` from the others; fewer rows if one
    found no place in ``tries`` draws."""
    points = np.zeros((count, 2))
    for i in range(count):
        r = regions[i % regions.shape[0]]
        placed = False
        for _ in range(tries):
            x = r[0] + (r[2] - r[0]) * rng.random()
            y = r[1] + (r[3] - r[1]) * rng.random()
            fits = True
            for k in range(keep.shape[0]):
                if math.hypot(x - keep[k, 0], y - keep[k, 1]) < clearance:
                    fits = False
                    break
            for j in range(i):
                if fits and math.hypot(x - points[j, 0], y - points[j, 1]) < spacing:
                    fits = False
            if fits:
                points[i, 0], points[i, 1] = x, y
                placed = True
                break
        if not placed:
            return points[:i]
    return points


def _person(x: float, y: float, radius: float, speed: float, behavior: str, reacting: bool,
            goals: list[tuple[float, float]], route: str, region: tuple | None, group: str) -> CircleObstacle:
    kind = ORCA_CROWD if behavior == "orca" else Sfm(vmax=speed, **CROWD_SFM)
    # ORCA plans a group with the robot in it or without: who sees the robot is part of the group.
    motion = Motion(behavior=kind, goals=goals, route=route, wander=region, vel_max=(speed, speed), goal_threshold=0.3,
                    group=group if reacting else f"{group}-unaware", reacts_to_robot=reacting, label="person",
                    static_contact="slide")
    return CircleObstacle(x=x, y=y, radius=radius, height=1.7, motion=motion)


def crowd(template: Scenario, rng: np.random.Generator, difficulty: float, reacting: bool | None = None,
          behavior: str | None = None) -> tuple | None:
    """People in a hall or two crossing corridors (see the module); (start, goal, obstacles) or None."""
    world = template.world
    x0, y0 = world.offset
    x1, y1 = x0 + world.width, y0 + world.height
    inner = np.array([x0 + MARGIN, y0 + MARGIN, x1 - MARGIN, y1 - MARGIN])
    walls: list[Obstacle] = []
    if rng.random() < 0.5:  # an open hall
        regions = inner[None]
        ends = _spaced_points(rng, regions, 2, np.zeros((0, 2)), 0.0, min(6.0, 0.6 * world.diagonal), 100)
        if len(ends) < 2:
            return None
    else:  # two corridors crossing at (cx, cy)
        half = 0.5 * float(rng.uniform(2.4, 3.4))
        cx = float(rng.uniform(x0 + 0.35 * world.width, x1 - 0.35 * world.width))
        cy = float(rng.uniform(y0 + 0.35 * world.height, y1 - 0.35 * world.height))
        walls = [SegmentObstacle(points=[(x, cy + sy * half), (cx + sx * half, cy + sy * half), (cx + sx * half, y)])
                 for sx, x in ((-1, x0), (1, x1)) for sy, y in ((-1, y0), (1, y1))]
        lane = half - 0.4
        regions = np.array([(inner[0], cy - lane, inner[2], cy + lane), (cx - lane, inner[1], cx + lane, inner[3])])
        arms = np.array([(inner[0] + 0.3, cy), (inner[2] - 0.3, cy), (cx, inner[1] + 0.3), (cx, inner[3] - 0.3)])
        ends = arms[rng.choice(4, size=2, replace=False)]
    count, fastest = crowd_size(difficulty)
    starts = _spaced_points(rng, regions, count, ends, CLEAR_OF_ROBOT, 2 * PERSON_RADIUS[1] + 0.1, 100)
    if len(starts) < count:
        return None
    goals = _spaced_points(rng, regions, count, np.zeros((0, 2)), 0.0, 0.0, 1)
    kind = behavior or ("orca" if rng.random() < 0.5 else "sfm")
    draws = rng.random((count, 3))  # radius, speed, whether it sees the robot
    radii = PERSON_RADIUS[0] + (PERSON_RADIUS[1] - PERSON_RADIUS[0]) * draws[:, 0]
    speeds = 0.5 + (max(fastest, 0.5) - 0.5) * draws[:, 1]
    unaware = max(0.0, 2.0 * difficulty - 1.0)  # the share of people who do not see the robot
    sees = draws[:, 2] >= unaware if reacting is None else np.full(count, reacting)
    people = [_person(float(starts[i, 0]), float(starts[i, 1]), float(radii[i]), float(speeds[i]), kind, bool(sees[i]),
                      [(float(goals[i, 0]), float(goals[i, 1]))], "once", tuple(map(float, regions[i % len(regions)])),
                      "crowd")
              for i in range(count)]
    heading = float(rng.uniform(-math.pi, math.pi))
    return (float(ends[0, 0]), float(ends[0, 1]), heading), (float(ends[1, 0]), float(ends[1, 1])), [*walls, *people]


@kernel(inline="always")
def _gap(x: float, y: float, half_x: float, half_y: float, bx: float, by: float, bhalf_x: float,
         bhalf_y: float) -> float:
    """The gap between two axis-aligned boxes (centre and half sides)."""
    return math.hypot(max(abs(x - bx) - half_x - bhalf_x, 0.0), max(abs(y - by) - half_y - bhalf_y, 0.0))


# The ends keep more than OFF_PATHS off the paths (a crate at least its reach): the next float up
# makes _off_paths's "at least" that "more than", exactly as the ends were always drawn.
_BEYOND_OFF_PATHS = math.nextafter(OFF_PATHS, math.inf)


@kernel(inline="always")
def _off_paths(x: float, y: float, reach: float, aisles: np.ndarray, walk_x: float) -> bool:
    """Whether (x, y) is at least ``reach`` off every aisle's centre line and the cross-aisle's."""
    if abs(x - walk_x) < reach:
        return False
    for k in range(aisles.shape[0]):
        if abs(y - aisles[k]) < reach:
            return False
    return True


@kernel(inline="always")
def _clear_of_boxes(x: float, y: float, half: float, boxes: np.ndarray, gap: float) -> bool:
    """Whether a square of half side ``half`` at (x, y) keeps ``gap`` from every box (a point for 0)."""
    for k in range(boxes.shape[0]):
        if _gap(x, y, half, half, boxes[k, 0], boxes[k, 1], boxes[k, 2], boxes[k, 3]) < gap:
            return False
    return True


@kernel
def _ends(rng, inner: np.ndarray, boxes: np.ndarray, aisles: np.ndarray, walk_x: float, min_distance: float,
          clearance: float) -> np.ndarray:
    """A start and a goal (rows) ``min_distance`` apart, ``clearance`` from every box and
    ``OFF_PATHS`` off every aisle's centre line (y = aisles[k]) and the cross-aisle's (x =
    ``walk_x``), so nothing that moves there runs into a robot waiting at either; empty if 200
    draws found none. The cheap tests come first: in most layouts almost every draw fails them."""
    ends = np.empty((2, 2))  # one array for all the draws: allocating one per draw took a third of a failing call
    for _ in range(200):
        for e in range(2):
            ends[e, 0] = inner[0] + (inner[2] - inner[0]) * rng.random()
            ends[e, 1] = inner[1] + (inner[3] - inner[1]) * rng.random()
        if math.hypot(ends[1, 0] - ends[0, 0], ends[1, 1] - ends[0, 1]) < min_distance:
            continue
        if (_off_paths(ends[0, 0], ends[0, 1], _BEYOND_OFF_PATHS, aisles, walk_x)
                and _off_paths(ends[1, 0], ends[1, 1], _BEYOND_OFF_PATHS, aisles, walk_x)
                and _clear_of_boxes(ends[0, 0], ends[0, 1], 0.0, boxes, clearance)
                and _clear_of_boxes(ends[1, 0], ends[1, 1], 0.0, boxes, clearance)):
            return ends
    return np.empty((0, 2))


@kernel
def _crates(rng, inner: np.ndarray, count: int, boxes: np.ndarray, aisles: np.ndarray, walk_x: float,
            ends: np.ndarray, gap: float) -> np.ndarray:
    """Up to ``count`` square crates as boxes are given (x, y, half side, half side), off the aisles'
    centre lines and the cross-aisle (x = ``walk_x``), ``CLEAR_OF_ROBOT`` from the start and goal,
    ``gap`` from every box and crate."""
    crates = np.zeros((count, 4))
    placed = 0
    for _ in range(20 * count):
        if placed == count:
            break
        x = inner[0] + (inner[2] - inner[0]) * rng.random()
        y = inner[1] + (inner[3] - inner[1]) * rng.random()
        side = 0.4 + 0.3 * rng.random()
        half = 0.5 * side
        corner = half * math.sqrt(2.0)  # from the centre
        if (not _off_paths(x, y, corner + 0.7, aisles, walk_x)
                or math.hypot(x - ends[0, 0], y - ends[0, 1]) - corner < CLEAR_OF_ROBOT
                or math.hypot(x - ends[1, 0], y - ends[1, 1]) - corner < CLEAR_OF_ROBOT
                or not _clear_of_boxes(x, y, half, boxes, gap)
                or not _clear_of_boxes(x, y, half, crates[:placed], gap)):
            continue
        crates[placed, 0], crates[placed, 1], crates[placed, 2], crates[placed, 3] = x, y, half, half
        placed += 1
    return crates[:placed]


@functools.cache
def _placement_codes() -> tuple[Callable, Callable]:
    """:func:`_ends`'s and :func:`_crates`'s machine code for the arrays :func:`warehouse_moving`
    hands them (float64, C-contiguous) and a Generator: called directly, a draw skips the
    dispatcher's typing of its arguments (the Generator's is slow), about 4 redrawn layouts a scenario."""
    rng, row, table = np.random.default_rng(0), np.empty(4), np.empty((0, 4))
    return (compiled_for(_ends, rng, row, table, row, 0.0, 0.0, 0.0),
            compiled_for(_crates, rng, row, 0, table, row, 0.0, np.empty((2, 2)), 0.0))


def warehouse_moving(template: Scenario, rng: np.random.Generator, difficulty: float, reacting: bool | None = None,
                     behavior: str | None = None) -> tuple | None:
    """Shelving rows with aisles between them and a cross-aisle through them, forklifts patrolling
    the aisles and people walking the cross-aisle (see the module); (start, goal, obstacles) or None."""
    world = template.world
    flip = rng.random() < 0.5  # rows along x, or along y: drawn along x, then mirrored onto the world
    width, height = (world.height, world.width) if flip else (world.width, world.height)
    rows = 2 if rng.random() < 0.5 else 3
    spacing = height / (rows + 1)
    row_ys = [spacing * (k + 1) for k in range(rows)]
    aisles = np.array([0.5 * (a + b) for a, b in zip([0.0, *row_ys], [*row_ys, height])])
    gap = float(rng.uniform(1.4, 2.0))
    cross = float(rng.uniform(width / 3, 2 * width / 3))
    boxes = []  # (x, y, half x, half y, height) in the drawing frame
    for y in row_ys:
        for a, b in ((1.2, cross - 0.5 * gap), (cross + 0.5 * gap, width - 1.2)):
            if b - a > 0.6:
                boxes.append((0.5 * (a + b), y, 0.5 * (b - a), 0.3, 1.8))
    # (0, 4) without rows: the placement code is compiled for two-dimensional tables only.
    table = np.array([box[:4] for box in boxes], dtype=float).reshape(-1, 4)
    inner = np.array([MARGIN, MARGIN, width - MARGIN, height - MARGIN])
    placing_ends, placing_crates = _placement_codes()
    ends = placing_ends(rng, inner, table, aisles, cross, 5.0, template.robot.bounding_radius + 0.3)
    if len(ends) < 2:
        return None
    crates = placing_crates(rng, inner, int(rng.integers(3, 7)), table, aisles, cross, ends,
                            2.0 * template.robot.bounding_radius + 0.05)
    frame = _Frame(world, flip)
    statics = [frame.box(x, y, 2 * hx, 2 * hy, h) for x, y, hx, hy, h in boxes]
    statics += [frame.box(x, y, 2 * hx, 2 * hy, 0.6) for x, y, hx, hy in crates]
    movers: list[Obstacle] = []
    unaware = max(0.0, 2.0 * difficulty - 1.0)  # the share of drivers and people blind to the robot, as in crowds
    for k in rng.permutation(len(aisles))[:1 + int(round(2 * difficulty))]:
        stretch = _stretch(rng, 1.0, width - 1.0, 2.0, ends, lambda u, y=float(aisles[k]): (u, y))
        if stretch is None:
            return None
        a, b = frame.point(stretch[0], float(aisles[k])), frame.point(stretch[1], float(aisles[k]))
        speed = float(rng.uniform(FORKLIFT_SPEED[0], FORKLIFT_SPEED[0] + FORKLIFT_SPEED[1] * difficulty))
        sees = _sees(rng, unaware) if reacting is None else reacting
        motion = Motion(behavior=Dash(angle_tolerance=0.05, yield_distance=FORKLIFT_YIELD), goals=[b],
                        route="back_and_forth", kinematics="diff", vel_max=(speed, 1.5), vel_min=(0.0, -1.5),
                        goal_threshold=0.2, reacts_to_robot=sees, label="forklift")
        movers.append(BoxObstacle(x=a[0], y=a[1], length=FORKLIFT[0], width=FORKLIFT[1],
                                  yaw=math.atan2(b[1] - a[1], b[0] - a[0]), height=2.0, motion=motion))
    kind = behavior or "sfm"
    fastest = crowd_size(difficulty)[1]
    for _ in range(2 + int(round(4 * difficulty))):
        stretch = _stretch(rng, 0.8, height - 0.8, 1.0, ends, lambda v: (cross, v))
        if stretch is None:
            return None
        a, b = frame.point(cross, stretch[0]), frame.point(cross, stretch[1])
        radius, speed = float(rng.uniform(*PERSON_RADIUS)), float(rng.uniform(0.5, max(fastest, 0.5)))
        sees = _sees(rng, unaware) if reacting is None else reacting
        movers.append(_person(a[0], a[1], radius, speed, kind, sees,
                              [b], "back_and_forth", None, "people"))
    start, goal = frame.point(*ends[0]), frame.point(*ends[1])
    return (*start, float(rng.uniform(-math.pi, math.pi))), goal, [*statics, *movers]


def _sees(rng: np.random.Generator, unaware: float) -> bool:
    """Whether a mover sees the robot, ``unaware`` the share that do not. Drawn only where someone
    may be blind, so the layouts of difficulty 0.5 and below keep their draws."""
    return unaware == 0.0 or rng.random() >= unaware


def _stretch(rng: np.random.Generator, low: float, high: float, shortest: float, ends: np.ndarray,
             at) -> tuple[float, float] | None:
    """A stretch [a, b] of a path (``at(t)``: its point at t in [low, high]), at least ``shortest``
    long, whose start is ``CLEAR_OF_ROBOT`` from the robot's start and goal; None if 20 draws miss."""
    points = ends.tolist()
    for _ in range(20):
        a = float(rng.uniform(low, high - shortest))
        b = float(rng.uniform(a + shortest, high))
        x, y = at(a)
        # Plain floats: NumPy's arithmetic on two points took a tenth of a scenario's draw.
        if min(math.hypot(px - x, py - y) for px, py in points) >= CLEAR_OF_ROBOT:
            return a, b
    return None


class _Frame:
    """The drawing frame (rows along x, from the world's corner) onto the world's, mirrored if ``flip``."""

    def __init__(self, world, flip: bool) -> None:
        self.x0, self.y0 = world.offset
        self.flip = flip

    def point(self, u: float, v: float) -> tuple[float, float]:
        return (self.x0 + float(v), self.y0 + float(u)) if self.flip else (self.x0 + float(u), self.y0 + float(v))

    def box(self, u: float, v: float, length: float, width: float, height: float) -> BoxObstacle:
        x, y = self.point(u, v)
        return BoxObstacle(x=x, y=y, length=float(length), width=float(width), yaw=0.5 * math.pi if self.flip else 0.0,
                           height=height)
