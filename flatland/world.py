"""The flatland world: a pymunk space of static obstacles and a kinematic diff-drive robot.

The robot moves by the unicycle update (IR-SIM's Euler step by default), not by forces: the 2D
tier is a kinematic simulator, and pymunk supplies the collision geometry (circles, convex boxes
and polygons, segments). Collisions follow IR-SIM's ``stop`` mode: the robot halts at a pose that
touches something and stays there, velocity zero, until reset. Every move is also swept, so no
obstacle can be jumped over or grazed unseen at any speed.
"""

from __future__ import annotations

import math

import numpy as np
import pymunk

from common.kinematics import INTEGRATORS, Pose2D, WheelOdometry, wheel_speeds, wrap_angle
from common.polygons import convex_pieces
from common.readings import Imu, Odometry, Readings, frozen
from common.scenario import BoxObstacle, CircleObstacle, PolygonObstacle, Scenario, SegmentObstacle
from flatland.lidar import Lidar

GRAVITY = 9.81
_ROBOT_CATEGORY = 0b10
_BOX_SEARCH_STEP = 0.01  # m: path resolution when a box footprint's swept bound touches something


def _edges(points: np.ndarray, closed: bool) -> np.ndarray:
    """Rows x1, y1, x2, y2 of a polyline's (or closed ring's) edges."""
    ends = np.roll(points, -1, axis=0) if closed else points[1:]
    starts = points if closed else points[:-1]
    return np.hstack([starts, ends])


class World:
    """A 2D world built from a :class:`Scenario`.

    ``reset(seed)`` puts the robot at the scenario's start; ``step(v, w)`` applies raw velocities
    (clipped to the robot's limits and acceleration window) for one ``step_time`` and returns a
    :class:`Readings` snapshot.
    """

    def __init__(self, scenario: Scenario, seed: int | None = None) -> None:
        self.scenario = scenario
        self.rng = np.random.default_rng(seed)
        self.space = pymunk.Space()
        self.lidar = Lidar(scenario.lidar, *self._add_obstacles(scenario), rng=self.rng)
        self._build_robot(scenario)
        robot = scenario.robot
        self._integrate = INTEGRATORS[scenario.world.integrator]
        self.odometry = WheelOdometry(robot.wheel_radius, robot.wheel_base, robot.encoder_noise, self.rng, self._integrate)
        self._dt = scenario.world.step_time
        self._limits = (robot.v_min, robot.v_max, robot.w_low, robot.w_max)
        self._accel = (robot.accel_v * self._dt, robot.accel_w * self._dt)
        self._has_accel = math.isfinite(robot.accel_v) or math.isfinite(robot.accel_w)
        self.pose = scenario.start_pose
        self.velocity = (0.0, 0.0)
        self.stopped = False
        self.steps = 0
        self.readings: Readings | None = None

    def _add_obstacles(self, scenario: Scenario) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Add static shapes to the space; return the lidar's circles, boxes and segments."""
        static = self.space.static_body
        circles: list[tuple[float, float, float]] = []
        boxes: list[tuple[float, ...]] = []
        segments: list[np.ndarray] = []
        for obstacle in scenario.obstacles:
            if obstacle.unobstructed:
                continue
            if isinstance(obstacle, CircleObstacle):
                circles.append((obstacle.x, obstacle.y, obstacle.radius))
                self.space.add(pymunk.Circle(static, obstacle.radius, (obstacle.x, obstacle.y)))
                continue
            if isinstance(obstacle, BoxObstacle):
                c, s = math.cos(obstacle.yaw), math.sin(obstacle.yaw)
                boxes.append((obstacle.x, obstacle.y, c, s, 0.5 * obstacle.length, 0.5 * obstacle.width))
                self.space.add(pymunk.Poly(static, [tuple(p) for p in obstacle.corners()]))
                continue
            if isinstance(obstacle, PolygonObstacle):
                ring, closed = np.asarray(obstacle.vertices, dtype=float), True
            else:
                assert isinstance(obstacle, SegmentObstacle)
                ring, closed = np.asarray(obstacle.points, dtype=float), False
            segments.append(_edges(ring, closed))
            if closed:
                # pymunk collides convex shapes only.
                self.space.add(*(pymunk.Poly(static, [tuple(v) for v in piece]) for piece in convex_pieces(ring)))
            else:
                self.space.add(*(pymunk.Segment(static, tuple(a), tuple(b), 0.0) for a, b in zip(ring[:-1], ring[1:])))
        if scenario.world.walls:
            x0, y0 = scenario.world.offset
            x1, y1 = x0 + scenario.world.width, y0 + scenario.world.height
            corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
            segments.append(_edges(corners, closed=True))
            self.space.add(*(pymunk.Segment(static, tuple(a), tuple(b), 0.0) for a, b in _edges(corners, True).reshape(-1, 2, 2)))
        return (np.array(circles).reshape(-1, 3), np.array(boxes).reshape(-1, 6),
                np.vstack(segments) if segments else np.zeros((0, 4)))

    def _build_robot(self, scenario: Scenario) -> None:
        robot = scenario.robot
        self.body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        if robot.shape == "circle":
            self.footprint: pymunk.Shape = pymunk.Circle(self.body, robot.radius)
        else:
            self.footprint = pymunk.Poly.create_box(self.body, (robot.length, robot.width))
        self._sweep_radius = robot.bounding_radius
        self.footprint.filter = pymunk.ShapeFilter(categories=_ROBOT_CATEGORY)
        self._not_robot = pymunk.ShapeFilter(mask=pymunk.ShapeFilter.ALL_MASKS() ^ _ROBOT_CATEGORY)
        self.space.add(self.body, self.footprint)

    def overlaps(self, pose: Pose2D) -> bool:
        """Whether the robot's footprint at ``pose`` touches any obstacle or wall."""
        self.body.position = (pose[0], pose[1])
        self.body.angle = pose[2]
        self.space.reindex_shapes_for_body(self.body)
        return bool(self.space.shape_query(self.footprint))

    def reset(self, seed: int | None = None) -> Readings:
        """Put the robot at the start, at rest; reseed the noise if ``seed`` is given."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
            self.lidar.rng = self.odometry.rng = self.rng
        self.pose = self.scenario.start_pose
        self.velocity = (0.0, 0.0)
        self.steps = 0
        self.odometry.reset(self.pose)
        # As in IR-SIM, contact is judged after a move: a start that overlaps may still drive out.
        self.stopped = False
        self.readings = self._read(0.0)
        return self.readings

    def step(self, v: float, w: float) -> Readings:
        """Drive with (v m/s, w rad/s) for one step and return the new readings."""
        if self.stopped:
            v = w = 0.0
        else:
            v, w = self._clip(float(v), float(w))
            self.pose, self.stopped = self._sweep(self.pose, self._integrate(self.pose, v, w, self._dt))
        previous_v = self.velocity[0]
        self.velocity = (v, w)
        self.steps += 1
        left, right = wheel_speeds(v, w, self.odometry.wheel_radius, self.odometry.wheel_base)
        self.odometry.update(left, right, self._dt)
        self.readings = self._read((v - previous_v) / self._dt)
        return self.readings

    def _clip(self, v: float, w: float) -> tuple[float, float]:
        v_lo, v_hi, w_lo, w_hi = self._limits
        if self._has_accel:
            # IR-SIM's acceleration window around the velocity applied last step.
            v_lo, v_hi = max(v_lo, self.velocity[0] - self._accel[0]), min(v_hi, self.velocity[0] + self._accel[0])
            w_lo, w_hi = max(w_lo, self.velocity[1] - self._accel[1]), min(w_hi, self.velocity[1] + self._accel[1])
        return min(max(v, v_lo), v_hi), min(max(w, w_lo), w_hi)

    def _sweep(self, start: Pose2D, end: Pose2D) -> tuple[Pose2D, bool]:
        """Where the robot ends a move from ``start`` to ``end``, and whether it collided.

        As in IR-SIM's stop mode, a move whose end pose overlaps something halts there. A contact
        that end-pose check would miss (a thin or small obstacle passed between the two poses)
        halts the robot at its first touching pose instead: the swept footprint is checked too.
        """
        # The box around the swept bounding circle holds both poses: nothing in it, nothing touched.
        # (Space.segment_query with a radius is no substitute: chipmunk walks its tree with the bare
        # segment and misses shapes that only the radius reaches.)
        r = self._sweep_radius
        box = pymunk.BB(min(start[0], end[0]) - r, min(start[1], end[1]) - r,
                        max(start[0], end[0]) + r, max(start[1], end[1]) + r)
        candidates = self.space.bb_query(box, self._not_robot)
        if not candidates:
            return end, False
        if self.overlaps(end):
            return end, True
        turn = wrap_angle(end[2] - start[2])
        along = lambda f: Pose2D(start[0] + f * (end[0] - start[0]), start[1] + f * (end[1] - start[1]),
                                 wrap_angle(start[2] + f * turn))
        if self.scenario.robot.shape == "circle":
            # The swept circle is the footprint: the earliest alpha is the first contact. A contact at
            # alpha 0 is an overlap the robot started in and is leaving (the end pose is clear).
            hits = [hit.alpha for hit in (shape.segment_query(start[:2], end[:2], r) for shape in candidates)
                    if hit and hit.alpha > 0.0]
            return (along(min(hits)), True) if hits else (end, False)
        if self.overlaps(start):
            return end, False  # leaving an overlap: judge by the end pose alone, as IR-SIM does
        # The swept bounding circle only says a box footprint may touch: search the path finely.
        substeps = max(1, math.ceil(math.hypot(end[0] - start[0], end[1] - start[1]) / _BOX_SEARCH_STEP))
        for k in range(1, substeps):
            pose = along(k / substeps)
            if self.overlaps(pose):
                return pose, True
        return end, False

    def _read(self, acceleration: float) -> Readings:
        x, y, yaw = self.pose
        v, w = self.velocity
        odometry = self.odometry
        return Readings(
            pose=self.pose,
            velocity=self.velocity,
            odometry=Odometry(odometry.pose, odometry.v, odometry.w),
            lidar=frozen(self.lidar.scan(x, y, yaw)),
            imu=Imu((acceleration, v * w, GRAVITY), (0.0, 0.0, w)),
            collided=self.stopped,
            time=self.steps * self._dt,
        )
