"""The flatland world: a pymunk space of static obstacles and a kinematic diff-drive robot.

The robot moves by the unicycle update (IR-SIM's Euler step by default), not by forces: the 2D
tier is a kinematic simulator, and pymunk supplies the collision geometry (circles, convex boxes
and polygons, segments). Collisions follow IR-SIM's ``stop`` mode: the robot halts at a pose that
touches something and stays there, velocity zero, until reset. Every move is also swept along the
integrator's own path, and the earliest contact on it wins, so no obstacle is jumped over at any
speed or turn rate: a circular footprint is swept exactly; a box is checked at poses no corner of
which is more than :data:`SWEEP_STEP` from the last one checked, so a graze shallower than that
may go unseen. A move with nothing near its path (most moves) is decided, made, and scanned
from in one compiled call (:mod:`flatland.free_step`), with the same arithmetic.
"""

from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np
import pymunk

from common.actuation import Actuator, WheelDynamics
from common.conditions import Conditions
from common.drive import Drive, body_euler
from common.kinematics import INTEGRATORS, Pose2D, WheelOdometry, nan_command, record, wheel_speeds, wrap_angle
from common.motion.movers import Movers, mover_generator
from flatland.polygons import convex_pieces
from common.readings import Contact, Imu, Odometry, Readings, frozen, mover_fault
from common.geometry import box_corner_table
from common.grid_maps import occupied_boxes, occupancy
from common.scenario import BoxObstacle, CircleObstacle, PolygonObstacle, Scenario, SegmentObstacle, WorldSpec
from flatland.clearance import path_clear, swept_capsule
from flatland.free_step import free_step_among_code, free_step_code, step_constants
from flatland.lidar import Lidar

GRAVITY = 9.81
_ROBOT_CATEGORY = 0b10
SWEEP_STEP = 0.01  # m: the most any point of a box footprint moves between two checked poses
_ARC_STEP = 0.1  # rad: a circle's arc is swept as chords of this turn (sagitta under 0.13 % of the radius)


def _between(a: Pose2D, b: Pose2D, fraction: float) -> Pose2D:
    """The pose a ``fraction`` of the way from ``a`` to ``b`` (straight, the shorter turn)."""
    return Pose2D(a[0] + fraction * (b[0] - a[0]), a[1] + fraction * (b[1] - a[1]),
                  wrap_angle(a[2] + fraction * wrap_angle(b[2] - a[2])))


def _reshape_circle(circle: pymunk.Circle, row: tuple[float, float, float]) -> None:
    circle.unsafe_set_radius(row[2])
    circle.unsafe_set_offset(row[:2])


def _edges(points: np.ndarray, closed: bool) -> np.ndarray:
    """Rows x1, y1, x2, y2 of a polyline's (or closed ring's) edges."""
    ends = np.roll(points, -1, axis=0) if closed else points[1:]
    starts = points if closed else points[:-1]
    return np.hstack([starts, ends])


class World:
    """A 2D world built from a :class:`Scenario`.

    ``reset(seed)`` puts the robot at the scenario's start; ``step(v, w)`` applies raw velocities
    (clipped to the robot's limits and acceleration window) for one ``step_time`` and returns a
    :class:`Readings` snapshot. A robot of other kinematics takes its own command
    (:mod:`common.drive`: ``step(forward, lateral)`` for ``omni``, and so on); its readings'
    velocity is (forward speed, turn rate) as commanded, and its odometry integrates the command
    (exact unless motion noise or a contact moved it otherwise). ``conditions``
    (:mod:`common.conditions`; flatland's defaults: an ideal robot) may change the robot, its
    sensors' noise and its actuation; ``world.scenario`` is the scenario as conditioned.

    The scenario's movers (:mod:`common.motion`) step after the robot, as in IR-SIM, and the lidar
    sees them where they end the step. The robot's contact with one is judged where both end the
    step (as IR-SIM judges every contact), and in ``stop`` mode it lasts only while they touch: a
    mover that walks away frees the robot. ``rng``: the generator to draw from (default one seeded
    with ``seed``; an IR-SIM file's, to keep drawing where IR-SIM's parse left off).
    """

    def __init__(self, scenario: Scenario, seed: int | None = None, conditions: Conditions | None = None,
                 rng: np.random.Generator | None = None) -> None:
        self.conditions = (conditions or Conditions()).for_tier("flatland")
        scenario = self.scenario = self.conditions.scenario(scenario)
        self.rng = np.random.default_rng(seed) if rng is None else rng
        # The movers draw from a stream of their own, so that a seed moves them alike in every tier
        # whatever else a tier draws (the 3D tier's sensor noise); an IR-SIM file's movers draw from
        # the generator its parse drew from, in IR-SIM's order.
        self._one_stream = rng is not None and scenario.kind == "irsim"
        self.mover_rng = self.rng if self._one_stream else mover_generator(seed)
        robot = scenario.robot
        first_order = self.conditions.dynamics == "first_order"
        self.actuator = Actuator(WheelDynamics(robot.wheel_radius, robot.wheel_base) if first_order else None)
        self.space = pymunk.Space()
        # Circles and boxes are kept from one scenario to the next and reshaped in place (a new
        # pymunk shape costs ten times more); polygon pieces and segments are rebuilt.
        self._circles: list[pymunk.Circle] = []
        self._boxes: list[pymunk.Poly] = []
        self._pieces: list[pymunk.Shape] = []
        self._wall_edges = self._add_walls(scenario.world)
        self.lidar = Lidar(scenario.lidar, *self._add_obstacles(scenario), rng=self.rng)
        self.lidar.grid = self._grid
        self._build_robot(scenario)
        self._integrate = INTEGRATORS[scenario.world.integrator]
        self.odometry = WheelOdometry(robot.wheel_radius, robot.wheel_base, robot.encoder_noise, self.rng, self._integrate)
        self.drive = None if robot.kinematics == "diff" and robot.motion_noise is None else \
            Drive(robot, scenario.world.step_time)
        # Encoder noise is drawn before the scan's: with it, the whole step stays in Python to keep
        # that order. The compiled step moves a differential drive only, among shapes (not a map).
        self._compilable = robot.encoder_noise == 0.0 and self.drive is None
        self._compiled = self._compilable and self._grid is None
        # A step's path is an arc only under the exact integrator; the other models step by Euler.
        self._curved = scenario.world.integrator == "exact" and self.drive is None
        self._constants = step_constants(
            step_time=scenario.world.step_time, exact=scenario.world.integrator == "exact",
            sweep_radius=robot.bounding_radius, wheel_radius=robot.wheel_radius, wheel_base=robot.wheel_base,
            mount_x=scenario.lidar.offset[0], mount_y=scenario.lidar.offset[1], first_beam=self.lidar.first_beam,
            beam_step=self.lidar.beam_step, range_max=scenario.lidar.range_max)
        self._moved = np.empty(8)
        self._free_step_code = free_step_code() if self._compilable else None
        self._halts = scenario.world.collision_mode != "unobstructed"
        self._kept_movers: dict[int, tuple[Scenario, Movers]] = {}
        self._use_movers(scenario)
        self.period = scenario.world.step_time  # s: one step
        self._limits = (robot.v_min, robot.v_max, robot.w_low, robot.w_max)
        self._accel = (robot.accel_v * self.period, robot.accel_w * self.period)
        self._has_accel = math.isfinite(robot.accel_v) or math.isfinite(robot.accel_w)
        self.pose = scenario.start_pose
        self.velocity = (0.0, 0.0)
        self.stopped = False
        self._static = robot.static
        self._touching_static = False
        self.steps = 0
        self.readings: Readings | None = None

    def _use_movers(self, scenario: Scenario) -> None:
        """The scenario's movers (None without any; the last few scenarios' are kept, as an env
        drawing from a list comes back to them), and whether an episode draws."""
        self.movers = None
        if scenario.robot_motion is not None or any(getattr(o, "motion", None) is not None for o in scenario.obstacles):
            kept = self._kept_movers.get(id(scenario))
            if kept is None or kept[0] is not scenario:
                if len(self._kept_movers) >= 64:
                    self._kept_movers.clear()
                kept = self._kept_movers[id(scenario)] = (scenario, Movers(scenario))
            self.movers = kept[1]
        # Seeding a Generator costs more than a noise-free episode's reset: skipped where nothing draws.
        self._draws = self.conditions.draws(scenario) or (self.movers is not None and self.movers.draws)

    def load(self, scenario: Scenario) -> bool:
        """Swap in another scenario's obstacles, start and goal, keeping the space, the robot and
        its conditions (much cheaper than a new World), if the scenario has the same robot, lidar
        and world rectangle (under this world's conditions); whether it had. :meth:`reset` starts
        its first episode."""
        scenario = self.conditions.scenario(scenario)
        current = self.scenario
        if not (scenario.robot == current.robot and scenario.lidar == current.lidar and scenario.world == current.world):
            return False
        self.scenario = scenario
        self.lidar.place(*self._add_obstacles(scenario))
        self.lidar.grid = self._grid
        self._compiled = self._compilable and self._grid is None
        self._use_movers(scenario)
        self.pose = scenario.start_pose
        return True

    def _add_walls(self, world: WorldSpec) -> np.ndarray:
        """Add the boundary walls (if the world has them) to the space; their edges for the lidar."""
        if not world.walls:
            return np.zeros((0, 4))
        x0, y0 = world.offset
        x1, y1 = x0 + world.width, y0 + world.height
        edges = _edges(np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]), closed=True)
        static = self.space.static_body
        self.space.add(*(pymunk.Segment(static, tuple(a), tuple(b), 0.0) for a, b in edges.reshape(-1, 2, 2)))
        return edges

    def _add_obstacles(self, scenario: Scenario) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Put the scenario's obstacles in the space; return the lidar's circles, boxes and segments."""
        static = self.space.static_body
        circles: list[tuple[float, float, float]] = []
        boxes: list[tuple[float, ...]] = []  # the lidar's rows: x, y, cos yaw, sin yaw, half length, half width
        segments: list[np.ndarray] = [self._wall_edges]
        solids: list[np.ndarray] = []  # the bounds of polygons, whose outline alone leaves their inside unseen
        if self._pieces:
            self.space.remove(*self._pieces)
            for piece in self._pieces:  # removed from the space, a shape stays in its body's set: ~3 kB a reset
                piece.body = None
        self._pieces = []
        for obstacle in scenario.static_obstacles:
            if obstacle.unobstructed:
                continue
            if isinstance(obstacle, CircleObstacle):
                circles.append((obstacle.x, obstacle.y, obstacle.radius))
                continue
            if isinstance(obstacle, BoxObstacle):
                boxes.append((obstacle.x, obstacle.y, math.cos(obstacle.yaw), math.sin(obstacle.yaw),
                              0.5 * obstacle.length, 0.5 * obstacle.width))
                continue
            if isinstance(obstacle, PolygonObstacle):
                ring, closed = np.asarray(obstacle.vertices, dtype=float), True
            else:
                assert isinstance(obstacle, SegmentObstacle)
                ring, closed = np.asarray(obstacle.points, dtype=float), False
            segments.append(_edges(ring, closed))
            if closed:
                solids.append(np.concatenate([ring.min(axis=0), ring.max(axis=0)]))
                # pymunk collides convex shapes only.
                self._pieces.extend(pymunk.Poly(static, [tuple(v) for v in piece]) for piece in convex_pieces(ring))
            else:
                self._pieces.extend(pymunk.Segment(static, tuple(a), tuple(b), 0.0) for a, b in zip(ring[:-1], ring[1:]))
        circle_table, box_table = np.array(circles).reshape(-1, 3), np.array(boxes).reshape(-1, 6)
        self._grid, self._clear_boxes = None, box_table  # what path_clear tests a move against
        solid_boxes = box_table
        if scenario.grid_map is not None:
            # The lidar walks the map's cells (flatland.lidar.cast_grid); contacts meet its occupied
            # cells merged into boxes (a maze's wall is one box, not a box per cell).
            world = scenario.world
            occupied = occupancy(scenario.grid_map, world.width, world.height)
            self._grid = (occupied, *world.offset, world.width / occupied.shape[0], world.height / occupied.shape[1])
            cells = occupied_boxes(scenario.grid_map, world.width, world.height, world.offset)
            cell_boxes = np.column_stack([cells[:, :2], np.ones(len(cells)), np.zeros(len(cells)), 0.5 * cells[:, 2:]])
            solid_boxes = self._clear_boxes = np.vstack([box_table, cell_boxes])
        self._use(self._circles, circles, _reshape_circle, lambda row: pymunk.Circle(static, row[2], row[:2]))
        # All corners in one compiled call: per box in Python they cost more than the reshape.
        self._use(self._boxes, box_corner_table(solid_boxes).tolist(), pymunk.Poly.unsafe_set_vertices,
                  lambda corners: pymunk.Poly(static, corners))
        if self._pieces:
            self.space.add(*self._pieces)
        # Reshaped static shapes keep their old place in the space's index until reindexed.
        self.space.reindex_static()
        self._solids = np.array(solids, dtype=np.float64).reshape(-1, 4)
        return circle_table, box_table, np.vstack(segments)

    def _use(self, pool: list, rows: list, reshape: Callable[[Any, Any], None], make: Callable[[Any], Any]) -> None:
        """Have exactly ``len(rows)`` shapes of ``pool`` in the space, each shaped by its row: the
        pool's shapes are reshaped in place, new ones made only when it runs short."""
        for index, row in enumerate(rows):
            if index < len(pool):
                reshape(pool[index], row)
            else:
                pool.append(make(row))
        for index, shape in enumerate(pool):
            if index < len(rows) and shape.space is None:
                self.space.add(shape)
            elif index >= len(rows) and shape.space is not None:
                self.space.remove(shape)

    def _build_robot(self, scenario: Scenario) -> None:
        robot = scenario.robot
        self.body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        pieces: list[pymunk.Shape] = []
        for part in robot.outline:
            if part.radius is not None:
                pieces.append(pymunk.Circle(self.body, part.radius, part.center))
            else:  # pymunk collides convex shapes only
                pieces.extend(pymunk.Poly(self.body, [tuple(v) for v in piece])
                              for piece in convex_pieces(np.asarray(part.vertices, dtype=float)))
        self.footprint = pieces
        # A circle about the reference point is swept exactly; anything else pose by pose.
        self._swept_circle = robot.shape == "circle" and robot.footprint_offset == 0.0
        self._sweep_radius = robot.bounding_radius
        for piece in pieces:
            # One group: a concave footprint's convex pieces, which share edges, never touch each other.
            piece.filter = pymunk.ShapeFilter(group=1, categories=_ROBOT_CATEGORY)
        self._not_robot = pymunk.ShapeFilter(mask=pymunk.ShapeFilter.ALL_MASKS() ^ _ROBOT_CATEGORY)
        self.space.add(self.body, *pieces)

    def overlaps(self, pose: Pose2D) -> bool:
        """Whether the robot's footprint at ``pose`` touches any obstacle or wall."""
        return bool(self._touching(pose))

    def _touching(self, pose: Pose2D) -> set[pymunk.Shape]:
        self.body.position = (pose[0], pose[1])
        self.body.angle = pose[2]
        self.space.reindex_shapes_for_body(self.body)
        return {info.shape for piece in self.footprint for info in self.space.shape_query(piece)}

    def reset(self, seed: int | None = None) -> Readings:
        """Put the robot at the start, at rest, and the movers at theirs; reseed what draws if
        ``seed`` is given."""
        if seed is not None and self._draws:
            self.rng = np.random.default_rng(seed)
            self.lidar.rng = self.odometry.rng = self.rng
            self.mover_rng = self.rng if self._one_stream else mover_generator(seed)
        self.pose = self.scenario.start_pose
        self.velocity = (0.0, 0.0)
        if self.drive is not None:
            self.drive.reset()
        self.steps = 0
        drawn = self.conditions.draw(self.rng)
        self.actuator.reset(drawn.action_delay, drawn.motor_gain)
        self.odometry.reset(self.pose)
        # As in IR-SIM, contact is judged after a move: a start that overlaps may still drive out.
        self.stopped = self._touching_static = False
        if self.movers is None:
            self.readings = self._read(0.0, self.lidar.scan(*self.pose))
            return self.readings
        self.movers.reset(self.pose, self.mover_rng)
        self.readings = self._read(0.0, self.lidar.scan(*self.pose, *self.movers.visible()), None)
        return self.readings

    def step(self, *command: float) -> Readings:
        """Drive with ``command`` for one step, (v m/s, w rad/s) for a differential drive (others:
        :mod:`common.drive`), and return the new readings."""
        ranges = touched = None  # the scan, and the mover touched, once the compiled step gives them
        movers = self.movers
        lateral = 0.0
        if self.stopped or self._static:
            v = w = 0.0
            if self.drive is not None:
                self.drive.halt()
        elif self.drive is not None:
            if any(value != value for value in command):
                raise nan_command(command)
            (v, lateral, w), moved = self.drive.move(command, self.rng)
            self.pose, self._touching_static = self._move(self.pose, moved[0], moved[2], lateral=moved[1])
        else:
            v, w = command
            v, w = float(v), float(w)
            if v != v or w != w:
                raise nan_command(command)
            v, w = self._clip(v, w)
            if not self.actuator.idle:
                v, w = self.actuator(v, w, self.period)
            if self._compiled:
                among = movers if movers is not None and movers.compiled else None
                if (free := self._free_step(v, w, movers is None or among is not None, among)) is not None:
                    ranges, touched = free
            if ranges is None:
                self.pose, self._touching_static = self._move(self.pose, v, w, test_clear=not self._compiled)
            else:
                self._touching_static = False
        if self.drive is not None:
            # The command, integrated as the robot would have moved without motion noise.
            odometry = self.odometry
            odometry.pose, odometry.v, odometry.w = body_euler(odometry.pose, v, lateral, w, self.period), v, w
        elif ranges is None:
            left, right = wheel_speeds(v, w, self.odometry.wheel_radius, self.odometry.wheel_base)
            self.odometry.update(left, right, self.period)
        previous_v = self.velocity[0]
        self.velocity = (v, w)
        self.steps += 1
        acceleration = (v - previous_v) / self.period
        if movers is None:
            self.stopped = self._touching_static and self._halts
            self.readings = self._read(acceleration, self.lidar.scan(*self.pose) if ranges is None else ranges)
            return self.readings
        if touched is None:
            touched = movers.finish(self.pose, v, w, self.stopped, self.mover_rng, lateral)
            ranges = self.lidar.scan(*self.pose, *movers.visible())
        contact = None
        if self._touching_static:
            contact = Contact("static", -1, "robot")
        elif touched >= 0:
            contact = Contact("mover", touched, mover_fault(self.pose, (v, lateral, w), movers.states().rows[touched],
                                                              self.scenario.robot))
        self.stopped = contact is not None and self._halts
        self.readings = self._read(acceleration, ranges, contact)
        return self.readings

    def _free_step(self, v: float, w: float, scan: bool = True,
                   movers: Movers | None = None) -> tuple[np.ndarray, int | None] | None:
        """The compiled step (:mod:`flatland.free_step`) if the move touches nothing: pose and
        odometry advanced; the new scan (empty without ``scan``) and, with ``movers`` (whose step
        is compiled), the first of them the robot touched (a row of their states, or -1) after
        their step, made in the same call and scanned among. None, with nothing changed, if the
        move may touch."""
        lidar, odometry, moved = self.lidar, self.odometry, self._moved
        ranges = np.empty(lidar.spec.beams if scan else 0)
        arguments = (*self.pose, *odometry.pose, v, w, self._constants, lidar.circles, lidar.boxes, lidar.segments,
                     self._solids, ranges, moved)
        touched = None
        if movers is None:
            if not self._free_step_code(*arguments):
                return None
        else:
            movers.begin(self.mover_rng)
            # Looked up here (cached), not when the world is built: a world without movers never loads it.
            clear, row, wanders = free_step_among_code()(*arguments, *movers.step_arguments, self.stopped)
            if not clear:
                return None
            touched = movers.settled(row, wanders)
        values = moved.tolist()  # x, y, yaw, then the odometry's x, y, yaw, v, w
        self.pose = record(Pose2D, values[:3])
        odometry.pose = record(Pose2D, values[3:6])
        odometry.v, odometry.w = values[6], values[7]
        return (lidar.finish(ranges) if scan else ranges), touched

    def _clip(self, v: float, w: float) -> tuple[float, float]:
        v_lo, v_hi, w_lo, w_hi = self._limits
        if self._has_accel:
            # IR-SIM's acceleration window around the velocity applied last step.
            v_lo, v_hi = max(v_lo, self.velocity[0] - self._accel[0]), min(v_hi, self.velocity[0] + self._accel[0])
            w_lo, w_hi = max(w_lo, self.velocity[1] - self._accel[1]), min(w_hi, self.velocity[1] + self._accel[1])
        # min(max()) as comparisons (four builtin calls took four times as long, once a step), in the
        # same order: a gain above 1 can leave the window's low end above the limit, and the limit wins.
        v = v_lo if v < v_lo else v
        w = w_lo if w < w_lo else w
        return (v_hi if v > v_hi else v), (w_hi if w > w_hi else w)

    def _move(self, start: Pose2D, v: float, w: float, test_clear: bool = True,
              lateral: float | None = None) -> tuple[Pose2D, bool]:
        """Where the robot ends a step of (v, w) from ``start``, and whether it collided; with
        ``lateral``, a step of body velocity (v, lateral) and turn rate w by Euler (other
        kinematics than diff).

        The move is swept along the integrator's path and the earliest contact decides. If the end
        pose still touches what was touched first, the robot halts at the end pose, as IR-SIM's
        stop mode does (so poses match IR-SIM's). If the first thing touched is behind the end pose
        (a thin wall jumped in one step, a wall a spinning box's corner swung through), it halts
        where it first touched it: IR-SIM, which checks end poses only, would let it through.
        ``test_clear=False``: the compiled step has already found something near the path. In
        ``unobstructed`` mode nothing halts the robot: it ends at the end pose, touching or not.
        """
        if lateral is None:
            def at(seconds: float) -> Pose2D:
                return self._integrate(start, v, w, seconds)
            speed = abs(v)
        else:
            def at(seconds: float) -> Pose2D:
                return body_euler(start, v, lateral, w, seconds)
            speed = math.hypot(v, lateral)
        end = at(self.period)
        if not self._halts:
            return end, self.overlaps(end)
        # Nothing within the swept capsule, nothing touched: decided without pymunk's Python layer,
        # which costs more than the rest of a move.
        lidar = self.lidar
        capsule = swept_capsule(self._sweep_radius, speed, w, self.period)
        if test_clear and path_clear(start[0], start[1], end[0], end[1], capsule, lidar.circles, self._clear_boxes,
                                     lidar.segments, self._solids):
            return end, False
        # Something is near the path. (Space.segment_query with a radius is no substitute for what
        # follows: chipmunk walks its tree with the bare segment and misses shapes that only the
        # radius reaches; the bounding-box query rarely comes back empty now, for a path near a
        # polygon's bounds or within the margin.)
        reach = speed * self.period + self._sweep_radius
        box = pymunk.BB(start[0] - reach, start[1] - reach, start[0] + reach, start[1] + reach)
        candidates = self.space.bb_query(box, self._not_robot)
        if not candidates:
            return end, False
        if self.overlaps(start):
            return end, self.overlaps(end)  # leaving an overlap: judge by the end pose alone, as IR-SIM does
        first = self._first_contact(start, at, speed, w, end, candidates)
        if first is None:
            return end, False
        pose, touched = first
        return (end if touched & self._touching(end) else pose), True

    def _first_contact(self, start: Pose2D, at: Callable[[float], Pose2D], speed: float, w: float, end: Pose2D,
                       candidates: list[pymunk.Shape]) -> tuple[Pose2D, set[pymunk.Shape]] | None:
        """The earliest touching pose on the way from ``start`` to ``end`` (``at(t)``: the pose
        ``t`` seconds in, at ``speed``, turning at ``w``), and what it touches."""
        turn = abs(w) * self.period
        circle = self._swept_circle
        if circle:
            # The swept circle is the footprint: exact along a straight move, chords along an arc.
            count = max(1, math.ceil(turn / _ARC_STEP)) if turn > 0 and self._curved else 1
        else:
            # A footprint's farthest point travels the translation plus its arc about the reference point.
            count = max(1, math.ceil((speed * self.period + turn * self._sweep_radius) / SWEEP_STEP))
        previous = start
        for k in range(1, count + 1):
            pose = end if k == count else at(self.period * k / count)
            if circle:
                hits = [(hit.alpha, shape) for shape in candidates
                        if (hit := shape.segment_query(previous[:2], pose[:2], self._sweep_radius))]
                if hits:
                    # Every shape touched at the earliest point, so a tie does not depend on the
                    # order shapes entered the space (a reused world adds them in another order).
                    alpha = min(hit[0] for hit in hits)
                    return _between(previous, pose, alpha), {shape for at, shape in hits if at == alpha}
            elif touched := self._touching(pose):
                return pose, touched
            previous = pose
        return None

    def _read(self, acceleration: float, ranges: np.ndarray, contact: Contact | None = None) -> Readings:
        v, w = self.velocity
        odometry = self.odometry
        estimate = record(Odometry, (odometry.pose, odometry.v, odometry.w))
        imu = record(Imu, ((acceleration, v * w, GRAVITY), (0.0, 0.0, w)))
        movers, collided = (None, self._touching_static) if self.movers is None else \
            (self.movers.states(), contact is not None)
        # Every field, in order: pose, velocity, odometry, lidar, imu, collided, time, camera, movers, contact.
        return record(Readings, (self.pose, self.velocity, estimate, frozen(ranges), imu, collided,
                                 self.steps * self.period, None, movers, contact))
