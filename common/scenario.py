"""Scenarios: the robot profile, sensors, world, start, goal and obstacles, defined once for both tiers.

A :class:`Scenario` is an immutable, validated pydantic model, so the same class is the runtime
object, the YAML schema and the source of one-line error messages. Lengths in metres, angles in
radians, world frame x right, y up, yaw counter-clockwise.

Every number is range-checked before anything uses it (files are shared between people, and a
radius of 1e300 must be a one-line error, not a crash deep in a physics engine): finite values,
coordinates within :data:`MAX_COORDINATE` m, lengths up to :data:`MAX_LENGTH` m (a 1 km world),
speeds up to :data:`MAX_SPEED`, at most :data:`MAX_OBSTACLES` obstacles of at most
:data:`MAX_VERTICES` vertices (:data:`MAX_TOTAL_VERTICES` in all), and no obstacle or robot wider
than the world's diagonal.
"""

from __future__ import annotations

import functools
import math
import re
import typing
from pathlib import Path
from typing import Annotated, Any, Literal, Sequence, Union

import numpy as np
import yaml
from pydantic import BaseModel, Field, ValidationError, model_validator

from common import geometry
from common.errors import ConfigError, did_you_mean, quote
from common.fields import (  # noqa: F401  (re-exported: the scenario's caps and types)
    MAX_COORDINATE,
    MAX_LENGTH,
    MAX_SPEED,
    Acceleration,
    Angle,
    BodyLength,
    Coordinate,
    Fraction,
    Frozen,
    Length,
    NonNegativeLength,
    Point,
    Speed,
)
from common.grid_maps import GridMap, occupied_boxes
from common.kinematics import Pose2D
from common.motion.spec import Motion
from common.params import numeral
from common.polygons import is_simple_polygon
from common.yaml_io import read_yaml_mapping

MAX_OBSTACLES = 2000
MAX_VERTICES = 1000  # of one polygon or polyline
MAX_TOTAL_VERTICES = 10_000  # of all of a scenario's: what loading, building and scanning it costs
MAX_MOVERS = 500  # moving obstacles: each is stepped, and stepped among the others, every step


def _group_traits(motion: Motion) -> tuple:
    """What the movers of one group share: a group plans with one behaviour for one kinematics,
    and ORCA counts the robot among its agents or not (their parameters may differ)."""
    name = motion.behavior.name
    return name, motion.kinematics, motion.reacts_to_robot if name == "orca" else None


def _absent(value: Any) -> bool:
    return value is None


# Fields added after scenarios were first written (and hashed: tests/test_scenario.py) are left out
# of a dump while they hold their defaults, so a scenario without them is written as before.
OMITTED_WHEN_ABSENT = Field(default=None, exclude_if=_absent)


def omitted_at_default(default: Any) -> Any:
    """A field left out of a dump while it holds ``default`` (as :data:`OMITTED_WHEN_ABSENT`)."""
    return Field(default=default, exclude_if=lambda value: value == default)


class CircleObstacle(Frozen):
    """A cylinder in 3D: centre (x, y), radius; a person, if it carries a ``motion``."""

    type: Literal["circle"] = "circle"
    x: Coordinate
    y: Coordinate
    radius: Length
    height: Length = 0.5
    unobstructed: bool = False  # IR-SIM: drawn, but neither seen by lidar nor collided with
    # A mover's heading at the start; and IR-SIM's polygon of a circle turns with it (common.irsim_geometry).
    yaw: Angle = Field(default=0.0, exclude_if=lambda yaw: yaw == 0.0)
    motion: Motion | None = OMITTED_WHEN_ABSENT  # where it goes and how (common.motion.spec); the pose above is its start

    def sdf(self, points: np.ndarray) -> np.ndarray:
        """Signed distance from points (N, 2) to this obstacle."""
        return geometry.circle_sdf(points, self.x, self.y, self.radius)

    def bounds(self) -> tuple[float, float, float, float]:
        """The axis-aligned box (x_min, y_min, x_max, y_max) holding the obstacle."""
        return self.x - self.radius, self.y - self.radius, self.x + self.radius, self.y + self.radius


class BoxObstacle(Frozen):
    """A box: centre (x, y), ``length`` along its local x, ``width`` along local y, rotated by ``yaw``;
    a forklift or a cart, if it carries a ``motion`` (its yaw is then its heading)."""

    type: Literal["box"] = "box"
    x: Coordinate
    y: Coordinate
    length: Length
    width: Length
    yaw: Angle = 0.0
    height: Length = 0.5
    unobstructed: bool = False
    motion: Motion | None = OMITTED_WHEN_ABSENT

    def sdf(self, points: np.ndarray) -> np.ndarray:
        """Signed distance from points (N, 2) to this obstacle."""
        return geometry.box_sdf(points, self.x, self.y, self.length, self.width, self.yaw)

    def corners(self) -> np.ndarray:
        """The four corners (4, 2), counter-clockwise."""
        return geometry.box_corners(self.x, self.y, self.length, self.width, self.yaw)

    def bounds(self) -> tuple[float, float, float, float]:
        """The axis-aligned box (x_min, y_min, x_max, y_max) holding the obstacle."""
        return _bounds(self.corners())


class PolygonObstacle(Frozen):
    """A simple polygon given by its vertices in world coordinates."""

    type: Literal["polygon"] = "polygon"
    vertices: Annotated[list[Point], Field(min_length=3, max_length=MAX_VERTICES)]
    height: Length = 0.5
    unobstructed: bool = False

    @model_validator(mode="after")
    def _simple(self) -> "PolygonObstacle":
        if not is_simple_polygon(np.asarray(self.vertices, dtype=float)):
            raise ValueError("the polygon crosses itself or has no area; allowed: a simple polygon, vertices in order")
        return self

    def sdf(self, points: np.ndarray) -> np.ndarray:
        """Signed distance from points (N, 2) to this obstacle."""
        return geometry.polygon_sdf(points, np.asarray(self.vertices, dtype=float))

    def bounds(self) -> tuple[float, float, float, float]:
        """The axis-aligned box (x_min, y_min, x_max, y_max) holding the obstacle."""
        return _bounds(np.asarray(self.vertices, dtype=float))


class SegmentObstacle(Frozen):
    """A polyline of zero thickness (a wall or an IR-SIM ``linestring``)."""

    type: Literal["segment"] = "segment"
    points: Annotated[list[Point], Field(min_length=2, max_length=MAX_VERTICES)]
    height: Length = 0.5
    unobstructed: bool = False

    def sdf(self, points: np.ndarray) -> np.ndarray:
        """Distance from points (N, 2) to the polyline (never negative: it has no inside)."""
        p = np.asarray(self.points, dtype=float)
        return geometry.segments_distance(points, p[:-1], p[1:])

    def bounds(self) -> tuple[float, float, float, float]:
        """The axis-aligned box (x_min, y_min, x_max, y_max) holding the obstacle."""
        return _bounds(np.asarray(self.points, dtype=float))


def _bounds(points: np.ndarray) -> tuple[float, float, float, float]:
    (x_min, y_min), (x_max, y_max) = points.min(axis=0), points.max(axis=0)
    return float(x_min), float(y_min), float(x_max), float(y_max)


Obstacle = Annotated[
    Union[CircleObstacle, BoxObstacle, PolygonObstacle, SegmentObstacle], Field(discriminator="type")
]


PositiveSpeed = Annotated[float, Field(gt=0.0, le=MAX_SPEED)]
MAX_PARTS = 32  # of a compound footprint: each is a collision shape the robot carries every step
FootprintVertices = Annotated[tuple[tuple[Coordinate, Coordinate], ...], Field(min_length=3, max_length=MAX_VERTICES)]


class FootprintPart(Frozen):
    """One part of a compound footprint, in the robot frame: a simple polygon (``vertices``) or a
    circle (``radius`` about ``center``), as IR-SIM's compound shape's parts."""

    vertices: FootprintVertices | None = OMITTED_WHEN_ABSENT
    center: tuple[Coordinate, Coordinate] = omitted_at_default((0.0, 0.0))
    radius: Length | None = OMITTED_WHEN_ABSENT

    @model_validator(mode="after")
    def _one_outline(self) -> "FootprintPart":
        if (self.vertices is None) == (self.radius is None):
            raise ValueError("a part is a polygon (vertices) or a circle (radius, center), not both or neither")
        if self.vertices is not None and not is_simple_polygon(np.asarray(self.vertices, dtype=float)):
            raise ValueError("the part crosses itself or has no area; allowed: a simple polygon, vertices in order")
        return self

    @property
    def reach(self) -> float:
        """How far the part's farthest point lies from the robot's reference point."""
        if self.vertices is not None:
            return max(math.hypot(x, y) for x, y in self.vertices)
        return math.hypot(*self.center) + self.radius


NOISE_SIZES = {"diff": 4, "omni": 2, "omni_angular": 3, "acker": 4}  # how many values IR-SIM's alpha takes


class RobotProfile(Frozen):
    """The robot's footprint, drive and velocity limits.

    ``kinematics`` is how a command moves the robot, as IR-SIM's models do (:mod:`common.drive`):
    ``diff`` (v, w), ``omni`` (forward, lateral speed in the body frame; the heading stays),
    ``omni_angular`` (forward, lateral, w) and ``acker`` (v and the steering angle, or its rate
    with ``steer_mode: angular``; wheels ``axle_distance`` apart). Each channel has its limits:
    ``v_*`` forward, ``w_*`` turn rate, ``lateral_*`` sideways, ``steer_*`` steering; a ``*_min``
    left out is minus the ``*_max``, except ``v_min`` (0: forward only). The policy's actions map to
    v in [0, v_max] and w in [-w_max, w_max] (other kinematics: :mod:`common.actions`); the minima
    and the acceleration limits (m/s², rad/s²) constrain raw ``World.step`` commands, as IR-SIM's
    ``vel_min`` and ``acce`` do. ``footprint_offset``: how far ahead of the robot's reference point
    (its pose, a car's rear axle) the footprint's centre sits; a ``polygon`` footprint is its
    ``vertices`` in the robot frame, a ``compound`` one the union of its ``parts`` (IR-SIM's
    compound shape; both flatland only). ``motion_noise``: IR-SIM's ``alpha``
    of its kinematics' motion noise (:mod:`common.drive`; None: none). ``static``: the robot never
    moves, whatever it is commanded (IR-SIM's static robot, a sensor on a post).
    """

    shape: Literal["circle", "box", "polygon", "compound"] = "circle"
    radius: BodyLength = 0.2
    length: BodyLength = 0.3
    width: BodyLength = 0.2
    vertices: FootprintVertices | None = OMITTED_WHEN_ABSENT
    parts: Annotated[tuple[FootprintPart, ...], Field(min_length=1, max_length=MAX_PARTS)] | None = OMITTED_WHEN_ABSENT
    footprint_offset: Annotated[float, Field(ge=-MAX_LENGTH, le=MAX_LENGTH)] = omitted_at_default(0.0)
    kinematics: Literal["diff", "omni", "omni_angular", "acker"] = omitted_at_default("diff")
    wheel_radius: Length = 0.05
    wheel_base: Length = 0.22
    v_min: Speed = 0.0
    v_max: PositiveSpeed = 1.0
    w_max: PositiveSpeed = 1.0
    w_min: Speed | None = None  # default -w_max
    lateral_max: PositiveSpeed = omitted_at_default(1.0)
    lateral_min: Speed | None = OMITTED_WHEN_ABSENT  # default -lateral_max
    steer_max: PositiveSpeed = omitted_at_default(1.0)
    steer_min: Speed | None = OMITTED_WHEN_ABSENT  # default -steer_max
    steer_mode: Literal["steer", "angular"] = omitted_at_default("steer")
    axle_distance: Length = omitted_at_default(1.0)
    accel_v: Acceleration = math.inf
    accel_w: Acceleration = math.inf
    accel_lateral: Acceleration = omitted_at_default(math.inf)
    accel_steer: Acceleration = omitted_at_default(math.inf)
    encoder_noise: Fraction = 0.0
    motion_noise: tuple[Annotated[float, Field(ge=0.0, le=100.0)], ...] | None = OMITTED_WHEN_ABSENT
    static: bool = omitted_at_default(False)

    @model_validator(mode="after")
    def _limits_ordered(self) -> "RobotProfile":
        if self.v_min > self.v_max:
            raise ValueError(f"v_min {self.v_min} must not exceed v_max {self.v_max}")
        for name in ("w", "lateral", "steer"):
            low, high = getattr(self, f"{name}_min"), getattr(self, f"{name}_max")
            if low is not None and low > high:
                raise ValueError(f"{name}_min {low} must not exceed {name}_max {high}")
        if self.kinematics == "acker" and self.steer_mode == "steer" and max(self.steer_max, -self.steer_low) >= 1.5:
            raise ValueError(f"a steering angle limit of {max(self.steer_max, -self.steer_low):g} rad turns the "
                             "car on the spot; allowed: below 1.5 rad")
        if (self.shape == "polygon") != (self.vertices is not None):
            raise ValueError("a polygon footprint takes its vertices (x, y in the robot frame), and only it; "
                             "allowed: shape: polygon with vertices, or no vertices")
        if self.vertices is not None and not is_simple_polygon(np.asarray(self.vertices, dtype=float)):
            raise ValueError("the footprint crosses itself or has no area; allowed: a simple polygon, vertices in order")
        if (self.shape == "compound") != (self.parts is not None):
            raise ValueError("a compound footprint takes its parts (polygons and circles in the robot frame), and "
                             "only it; allowed: shape: compound with parts, or no parts")
        if self.parts is not None and sum(len(part.vertices or ()) for part in self.parts) > MAX_VERTICES:
            raise ValueError(f"the parts hold more than {MAX_VERTICES} vertices in all; allowed: at most {MAX_VERTICES}")
        if (self.vertices is not None or self.parts is not None) and self.footprint_offset:
            raise ValueError(f"a {self.shape} footprint's vertices place it; allowed: footprint_offset 0")
        if self.kinematics != "diff" and self.encoder_noise > 0:
            raise ValueError(f"encoder_noise models a differential drive's wheels; allowed: 0 for {self.kinematics}")
        if self.motion_noise is not None and len(self.motion_noise) < NOISE_SIZES[self.kinematics]:
            raise ValueError(f"motion_noise of a {self.kinematics} robot takes {NOISE_SIZES[self.kinematics]} values "
                             f"(IR-SIM's alpha), got {len(self.motion_noise)}")
        return self

    @property
    def lateral_low(self) -> float:
        """The lowest sideways velocity a raw command may reach (omni kinematics)."""
        return -self.lateral_max if self.lateral_min is None else self.lateral_min

    @property
    def steer_low(self) -> float:
        """The lowest steering angle (or rate) a raw command may reach (acker)."""
        return -self.steer_max if self.steer_min is None else self.steer_min

    @property
    def w_low(self) -> float:
        """The lowest angular velocity a raw command may reach."""
        return -self.w_max if self.w_min is None else self.w_min

    @property
    def outline(self) -> tuple[FootprintPart, ...]:
        """The footprint as parts in the robot frame: one for a circle, box or polygon (a box's
        corners counter-clockwise), a compound's own. Built on each call: a cached one would
        outlive ``model_copy(update=...)``, which copies the instance's dict."""
        if self.parts is not None:
            return self.parts
        if self.vertices is not None:
            return (FootprintPart(vertices=self.vertices),)
        if self.shape == "circle":
            return (FootprintPart(center=(self.footprint_offset, 0.0), radius=self.radius),)
        half_length, half_width = 0.5 * self.length, 0.5 * self.width
        return (FootprintPart(vertices=tuple((self.footprint_offset + sx * half_length, sy * half_width)
                                             for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1)))),)

    def _span(self, axis: int) -> float:
        """The footprint's extent along the robot frame's x (0) or y (1) axis."""
        ends = []
        for part in self.outline:
            if part.radius is not None:
                ends += [part.center[axis] - part.radius, part.center[axis] + part.radius]
            else:
                ends += [vertex[axis] for vertex in part.vertices]
        return max(ends) - min(ends)

    @property
    def width_across(self) -> float:
        """How wide the footprint is across the heading: what a gap it drives through head-on must exceed."""
        return self._span(1)

    @property
    def length_along(self) -> float:
        """How long the footprint is along the heading."""
        return self._span(0)

    @property
    def bounding_radius(self) -> float:
        """Radius of the smallest circle about the reference point around the footprint (the
        conservative clearance)."""
        if self.vertices is not None:
            return max(math.hypot(x, y) for x, y in self.vertices)
        if self.parts is not None:
            return max(part.reach for part in self.parts)
        half = self.radius if self.shape == "circle" else 0.5 * math.hypot(self.length, self.width)
        return half + abs(self.footprint_offset)


class LidarSpec(Frozen):
    """A 2D lidar: beams spread over ``angle_range`` centred on the sensor's heading.

    ``offset`` is the mount (x, y, yaw) in the robot frame. Ranges are clipped to
    [range_min, range_max]; a beam that hits nothing reads ``range_max``.

    Beams run from -angle_range/2 to +angle_range/2 with both ends included, except on a full
    circle, where n beams are spaced 2π/n, centred on the heading (at ±π/n, ±3π/n, ...), so no
    direction is read twice. ``repeat_end_beam`` keeps IR-SIM's layout on a full circle too (both
    ends, so its ±π beam is read twice): IR-SIM world files set it, for parity with IR-SIM.
    """

    beams: Annotated[int, Field(ge=1, le=4096)] = 36
    range_min: NonNegativeLength = 0.0
    range_max: Length = 5.0
    angle_range: Annotated[float, Field(gt=0.0, le=2.0 * math.pi + 1e-9)] = 2.0 * math.pi
    offset: tuple[Annotated[float, Field(ge=-MAX_LENGTH, le=MAX_LENGTH)], Annotated[float, Field(ge=-MAX_LENGTH, le=MAX_LENGTH)], Angle] = (0.0, 0.0, 0.0)
    noise_std: NonNegativeLength = 0.0
    repeat_end_beam: bool = False

    @model_validator(mode="after")
    def _range_ordered(self) -> "LidarSpec":
        if self.range_min >= self.range_max:
            raise ValueError(f"range_min {self.range_min} must be below range_max {self.range_max}")
        return self

    @property
    def full_circle(self) -> bool:
        """Whether the beams cover every direction (and are spaced evenly all round)."""
        return self.angle_range >= 2.0 * math.pi - 1e-9 and not self.repeat_end_beam

    @property
    def beam_spacing(self) -> float:
        """Radians between neighbouring beams."""
        if self.full_circle:
            return 2.0 * math.pi / self.beams
        return self.angle_range / max(self.beams - 1, 1)

    def beam_angles(self) -> np.ndarray:
        """Beam directions relative to the sensor heading, in scan order (a single beam looks
        straight ahead)."""
        if self.beams == 1:
            return np.zeros(1)
        if self.full_circle:
            return -math.pi + (np.arange(self.beams) + 0.5) * (2.0 * math.pi / self.beams)
        return np.linspace(-0.5 * self.angle_range, 0.5 * self.angle_range, self.beams)


class WorldSpec(Frozen):
    """The world rectangle [x0, x0 + width] × [y0, y0 + height], its step time and boundary walls.

    ``integrator`` is how a step moves the robot: ``euler`` (heading from the step's start, IR-SIM's
    update) or ``exact`` (the arc of constant v and w). ``collision_mode`` is what a contact does,
    as IR-SIM's: ``stop`` halts the robot and any mover that touches something; ``unobstructed``
    halts nothing (contacts are still reported); ``unobstructed_obstacles`` halts the robot and
    movers whose role is ``robot``, while moving obstacles pass on.
    """

    width: Length = 10.0
    height: Length = 10.0
    offset: Point = (0.0, 0.0)
    step_time: Annotated[float, Field(gt=0.0, le=10.0)] = 0.1
    walls: bool = True
    integrator: Literal["euler", "exact"] = "euler"
    collision_mode: Literal["stop", "unobstructed", "unobstructed_obstacles"] = Field(
        default="stop", exclude_if=lambda mode: mode == "stop")

    def contains(self, x: float, y: float, margin: float = 0.0) -> bool:
        """Whether (x, y) lies inside the rectangle, at least ``margin`` from its edges."""
        x0, y0 = self.offset
        return x0 + margin <= x <= x0 + self.width - margin and y0 + margin <= y <= y0 + self.height - margin

    @property
    def diagonal(self) -> float:
        """Length of the world's diagonal: the largest possible goal distance."""
        return math.hypot(self.width, self.height)


class Scenario(Frozen):
    """Everything a tier needs to build a world: robot, sensors, world, start, goal, obstacles.

    Obstacles with a ``motion`` move (:mod:`common.motion`); their pose is where they start.
    ``robot_motion`` is the controlled robot's own IR-SIM behaviour, read from an IR-SIM file: the
    robot follows its commands, but IR-SIM still counts it in its group's plan and draws its
    wandering goals, so flatland keeps both to stay IR-SIM's. ``grid_map`` is an occupancy grid
    over the world (:mod:`common.grid_maps`, IR-SIM's ``obstacle_map``; flatland only), an
    obstacle besides the others.
    """

    name: str = "scenario"
    world: WorldSpec = WorldSpec()
    robot: RobotProfile = RobotProfile()
    lidar: LidarSpec = LidarSpec()
    start: tuple[Coordinate, Coordinate, Angle] = (1.0, 1.0, 0.0)
    goal: Point = (9.0, 9.0)
    goal_threshold: Length = 0.3
    obstacles: Annotated[list[Obstacle], Field(max_length=MAX_OBSTACLES)] = []
    kind: str = "custom"
    difficulty: Fraction = 0.0
    seed: int | None = None
    robot_motion: Motion | None = OMITTED_WHEN_ABSENT
    grid_map: GridMap | None = OMITTED_WHEN_ABSENT

    @model_validator(mode="after")
    def _movers_fit_the_world(self) -> "Scenario":
        movers = [(i, o.motion) for i, o in enumerate(self.obstacles) if getattr(o, "motion", None) is not None]
        if len(movers) > MAX_MOVERS:
            raise ValueError(f"{len(movers):,} moving obstacles; allowed: at most {MAX_MOVERS}")
        groups: dict[str, Motion] = {}
        for index, motion in movers + ([(-1, self.robot_motion)] if self.robot_motion is not None else []):
            where = "robot_motion" if index < 0 else f"obstacles.{index}.motion"
            if motion.static_contact == "slide":
                self._check_slide(where, motion, None if index < 0 else self.obstacles[index])
            if self.world.walls:  # a walled world cannot be left: every goal must lie inside it
                for k, (x, y) in enumerate(motion.goals):
                    if not self.world.contains(x, y):
                        raise ValueError(f"{where}.goals.{k}: ({x:g}, {y:g}) lies outside the world {self._extent()}; "
                                         "allowed: inside it")
                if motion.wander is not None and not (self.world.contains(*motion.wander[:2])
                                                      and self.world.contains(*motion.wander[2:])):
                    raise ValueError(f"{where}.wander: {list(motion.wander)} reaches outside the world "
                                     f"{self._extent()}; allowed: a region inside it")
            if motion.group is not None:
                first = groups.setdefault(motion.group, motion)
                if _group_traits(first) != _group_traits(motion):
                    raise ValueError(f"{where}.group: the movers of group {motion.group!r} differ in behaviour, "
                                     "kinematics or (ORCA) whether they see the robot; allowed: one of each per group")
        return self

    def _check_slide(self, where: str, motion: Motion, body) -> None:
        """A sliding mover is a circle whose step is shorter than its radius: slid out from where a
        step ends, a longer one could end past a thin wall's middle and leave on its far side."""
        if not isinstance(body, CircleObstacle):
            raise ValueError(f"{where}.static_contact: slide keeps circle obstacles out of static geometry; "
                             "allowed: pass")
        step = motion.speed * self.world.step_time
        if step >= body.radius:
            raise ValueError(f"{where}.static_contact: slide needs a step shorter than the radius {body.radius:g} m "
                             f"(here {motion.speed:g} m/s x {self.world.step_time:g} s = {step:g} m); allowed: pass, "
                             "or a slower mover")

    @property
    def movers(self) -> list[Obstacle]:
        """The obstacles that move."""
        return [o for o in self.obstacles if getattr(o, "motion", None) is not None]

    @property
    def static_obstacles(self) -> list[Obstacle]:
        """The obstacles that stay where they are."""
        return [o for o in self.obstacles if getattr(o, "motion", None) is None]

    @model_validator(mode="after")
    def _sizes_fit_the_world(self) -> "Scenario":
        diagonal = self.world.diagonal
        if self.robot.bounding_radius >= diagonal:
            raise ValueError(f"the robot ({self.robot.bounding_radius:g} m across) is wider than the world; "
                             f"allowed: below its diagonal, {diagonal:g} m")
        vertices = 0
        for index, obstacle in enumerate(self.obstacles):
            if isinstance(obstacle, CircleObstacle):
                size = obstacle.radius
            elif isinstance(obstacle, BoxObstacle):
                size = max(obstacle.length, obstacle.width)
            else:
                size = 0.0
                vertices += len(obstacle.vertices if isinstance(obstacle, PolygonObstacle) else obstacle.points)
            if size > diagonal:
                raise ValueError(f"obstacle {index} ({size:g} m) is larger than the world; allowed: up to its diagonal, {diagonal:g} m")
        if vertices > MAX_TOTAL_VERTICES:
            raise ValueError(f"the polygons and polylines hold {vertices:,} vertices in all; allowed: at most "
                             f"{MAX_TOTAL_VERTICES:,}")
        return self

    @property
    def start_pose(self) -> Pose2D:
        """The start as a :class:`Pose2D`."""
        return Pose2D(*self.start)

    def signed_distance(self, points: np.ndarray, include_unobstructed: bool = False) -> np.ndarray:
        """Signed distance from points (N, 2) to the nearest obstacle (+inf with none)."""
        points = np.atleast_2d(np.asarray(points, dtype=float))
        out = np.full(len(points), np.inf)
        for obstacle in self.obstacles:
            if include_unobstructed or not obstacle.unobstructed:
                out = np.minimum(out, obstacle.sdf(points))
        if self.grid_map is not None:
            # The map's occupied cells, merged into axis-aligned boxes.
            cells = occupied_boxes(self.grid_map, self.world.width, self.world.height, self.world.offset)
            if len(cells):
                beyond = np.abs(points[:, None, :] - cells[None, :, :2]) - 0.5 * cells[None, :, 2:]
                sdf = np.linalg.norm(np.maximum(beyond, 0.0), axis=2) + np.minimum(beyond.max(axis=2), 0.0)
                out = np.minimum(out, sdf.min(axis=1))
        return out

    def outside_problems(self, source: str | Path | None = None) -> list[ConfigError]:
        """Where the start or the goal lies outside the world, as one-line errors."""
        return [ConfigError(source, field, f"({x:g}, {y:g}) lies outside the world {self._extent()}")
                for field, (x, y) in (("start", self.start[:2]), ("goal", self.goal)) if not self.world.contains(x, y)]

    def placement_problems(self, source: str | Path | None = None) -> list[ConfigError]:
        """Where the start or the goal is outside the world or inside (or, for the start, within
        the robot's radius of) an obstacle, as one-line errors."""
        problems = self.outside_problems(source)
        clearance = self.robot.bounding_radius
        for field, (x, y) in (("start", self.start[:2]), ("goal", self.goal)):
            if not self.world.contains(x, y):
                continue
            d = float(self.signed_distance(np.array([[x, y]]))[0])
            if d < (clearance if field == "start" else 0.0):
                where = "inside an obstacle" if d < 0 else f"{d:.2f} m from an obstacle"
                need = f"at least {clearance:g} m (the robot's radius)" if field == "start" else "outside"
                problems.append(ConfigError(source, field, f"({x:g}, {y:g}) is {where}; allowed: {need}"))
        return problems

    def check(self, source: str | Path | None = None) -> "Scenario":
        """Raise the first of :meth:`placement_problems`, if any, or a start within the robot's
        radius of the world's boundary walls. (Only here, for scenarios a user writes: the
        generators keep their own acceptance rule, so every suite stays the same.)"""
        problems = self.placement_problems(source)
        if problems:
            raise problems[0]
        x, y = self.start[:2]
        x0, y0 = self.world.offset
        gap = min(x - x0, x0 + self.world.width - x, y - y0, y0 + self.world.height - y)
        if self.world.walls and gap < self.robot.bounding_radius - 1e-9:  # 10 - 9.8 is a hair under 0.2
            # It collided on the first step, and the episode ended before it began.
            raise ConfigError(source, "start", f"({x:g}, {y:g}) is {gap:.2f} m from the world's boundary wall; allowed: "
                              f"at least {self.robot.bounding_radius:g} m (the robot's radius), or world.walls: false")
        for index, obstacle in enumerate(self.obstacles):
            left, bottom, right, top = obstacle.bounds()
            outside = right < x0 or left > x0 + self.world.width or top < y0 or bottom > y0 + self.world.height
            if self.world.walls and outside and getattr(obstacle, "motion", None) is None:
                # Behind the walls no beam and no robot meets it: a sign of a wrong coordinate, not a design.
                raise ConfigError(source, f"obstacles.{index}", f"lies entirely outside the world {self._extent()}; "
                                  "allowed: an obstacle that overlaps the world, or world.walls: false")
        if math.dist((x, y), self.goal) < self.goal_threshold:
            # The episode was a success before the robot moved (common.task's test: nearer than the radius).
            raise ConfigError(source, "goal", f"{tuple(self.goal)} is within goal_threshold ({self.goal_threshold:g} m) "
                              f"of the start; allowed: farther from the start")
        return self

    def _extent(self) -> str:
        x0, y0 = self.world.offset
        return f"[{x0:g}, {x0 + self.world.width:g}] x [{y0:g}, {y0 + self.world.height:g}]"

    def to_yaml(self) -> str:
        """YAML text that :func:`load_scenario` reads back to an equal scenario."""
        return yaml.safe_dump(self.model_dump(mode="json"), sort_keys=False)


def _models_in(annotation: Any) -> list[type[BaseModel]]:
    """The models an annotation holds: itself, an Optional's, a union's members, a list's items."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return [model for arg in typing.get_args(annotation) for model in _models_in(arg)]


def allowed_keys(model: type[BaseModel], loc: Sequence[Any]) -> list[str] | None:
    """The keys allowed beside the unknown key at ``loc`` (a pydantic error's path from ``model``);
    None where the path leaves the models (a union member pydantic names by its tag, say)."""
    models = _walk(model, loc[:-1])[0]
    return sorted({key for m in models for key in m.model_fields}) if len(models) == 1 else None


def _walk(model: type[BaseModel], path: Sequence[Any]) -> tuple[list[type[BaseModel]], list[Any]]:
    """The models a value at ``path`` from ``model`` may be (a union's members, or none), and
    ``path`` without the tagged unions' member tags pydantic puts in it
    (``obstacles.0.circle.radius``: no one wrote a key ``circle``). A tag stands right after the
    field holding the union (or its list index); a key spelt like a tag anywhere else is a key."""
    models, tag, written, union = [model], "type", [], False
    for part in path:
        if isinstance(part, int):
            written.append(part)
            continue  # a list's item: its models are already the field's
        members = [m for m in models if tag in m.model_fields and m.model_fields[tag].default == part] if union else []
        union = False
        if members:  # a tagged union's member: the one whose tag field holds that tag
            models = members
            continue
        held = [m.model_fields[part] for m in models if part in m.model_fields]
        if held:
            models = [inner for info in held for inner in _models_in(info.annotation)]
            tag = next((info.discriminator for info in held if isinstance(info.discriminator, str)), "type")
            union = len(models) > 1
        else:
            models = []  # a key no model has (an unknown one), or one inside a plain value
        written.append(part)
    return models, written


_UNION_TAG = re.compile(r"constrained-\w+|int|float|str|bool|none|function-\w+|lax-or-strict|json-or-python")


def pydantic_error(source: str | Path | None, error: ValidationError, model: type[BaseModel] | None = None) -> ConfigError:
    """The first problem of a pydantic error as a one-line :class:`ConfigError`; an unknown key of
    ``model`` (the model validated) also lists the keys allowed there."""
    first = error.errors()[0]
    # Union members add tags such as "list[constrained-int]" or "constrained-int" to the path: they name no field.
    path = [part for part in first["loc"] if "[" not in str(part) and not _UNION_TAG.fullmatch(str(part))]
    raw, path = path, (_walk(model, path)[1] if model is not None else path)  # raw: the walk's, with the tags
    field = ".".join(str(part) for part in path) or None
    message = first["msg"]
    if first["type"] == "extra_forbidden":
        allowed = allowed_keys(model, raw) if model else None
        message = "unknown key"
        if allowed:
            message += did_you_mean(path[-1] if path else "", allowed) + f"; allowed: {', '.join(allowed)}"
    elif first["type"] in ("union_tag_not_found", "union_tag_invalid"):
        # pydantic's wording ("Unable to extract tag using discriminator") named no key a person wrote.
        key = first["ctx"]["discriminator"].strip("'")
        tags = [m.model_fields[key].default for m in _walk(model, raw)[0] if key in m.model_fields] if model else []
        given = first["input"].get(key) if isinstance(first["input"], dict) else first["ctx"].get("tag")
        field = f"{field}.{key}" if field else key
        message = "missing" if given is None else quote(given) + did_you_mean(given, tags)
        message += f"; allowed: {', '.join(tags)}" if tags else ""
    elif first["type"] == "missing" and path and isinstance(path[-1], int):
        # An item missing from a fixed-length list: goal: [9.0] said "goal.1: Field required".
        field = ".".join(str(part) for part in path[:-1]) or None
        message = f"too few values (got {quote(first['input'])}); item {path[-1]} is missing"
    elif first["type"] == "model_type":
        # pydantic names its class ("a valid dictionary or instance of RobotFamily"); a person writes keys.
        keys = allowed_keys(model, [*raw, None]) if model else None
        message = f"expected a mapping{' of ' + ', '.join(keys) if keys else ''} (got {quote(first['input'])})"
    elif first["type"] == "value_error":
        message = message.removeprefix("Value error, ")  # our validators' messages say what they got
    elif "input" in first:
        message = f"{message} (got {quote(first['input'])})"
    return ConfigError(source, field, message)


def _kinds_of(annotation: Any) -> set[str]:
    """What a value of ``annotation`` may be, as a person writes it: "flag", "number", "text" or
    "other" (a mapping or anything else)."""
    if annotation is bool:
        return {"flag"}
    if annotation in (int, float):
        return {"number"}
    if annotation is str:
        return {"text"}
    if annotation is type(None):
        return set()
    if typing.get_origin(annotation) is Annotated:
        return _kinds_of(typing.get_args(annotation)[0])
    if typing.get_origin(annotation) is Literal:
        return {"flag" if isinstance(v, bool) else "number" if isinstance(v, (int, float)) else "text"
                for v in typing.get_args(annotation)}
    args = typing.get_args(annotation)
    if typing.get_origin(annotation) is dict or not args:
        return {"other"}
    return set().union(*(_kinds_of(arg) for arg in args))


@functools.cache
def _key_kinds(model: type[BaseModel]) -> dict[str, frozenset[str]]:
    """For each field name of ``model`` and every model its fields hold, what its value may be
    (:func:`_kinds_of`), over every model that has a field of that name."""
    kinds: dict[str, set[str]] = {}
    seen, stack = set(), [model]
    while stack:
        current = stack.pop()
        if current in seen:
            continue
        seen.add(current)
        for name, info in current.model_fields.items():
            kinds.setdefault(name, set()).update(_kinds_of(info.annotation))
            stack.extend(_models_in(info.annotation))
    return {name: frozenset(kind) for name, kind in kinds.items()}


def refuse_misread(data: Any, model: type[BaseModel], source: str | Path | None = None, field: str = "") -> None:
    """A one-line error for a value of ``data`` (a person's mapping for ``model``) that pydantic
    would read as something else: true or false where a number belongs (``width: true`` made a
    1 m world), a quoted number ("0.5"), or anything but true or false where a flag belongs
    (``walls: 0`` read as false). One pass over what a person wrote, not a validator on every
    number: generated scenarios, made at every reset, hold none of these. A grid map generator's
    own parameters are checked by its own rules."""
    kinds, anything = _key_kinds(model), frozenset({"other"})

    def walk(value: Any, path: tuple, allowed: frozenset[str]) -> None:
        # ``allowed``: what the nearest key above ``value`` takes (a list's items take their key's).
        problem = None
        if isinstance(value, bool) and "flag" not in allowed and path:
            problem = f"got {str(value).lower()}; allowed: a number"
        elif isinstance(value, str) and "number" in allowed and "text" not in allowed and numeral(value) is not None:
            problem = f"got {quote(value)} (quoted); allowed: a number"
        elif allowed == {"flag"} and not isinstance(value, bool):
            problem = f"got {quote(value)}; allowed: true or false"
        if problem is not None:
            raise ConfigError(source, ".".join(str(part) for part in (field, *path) if part != ""), problem)
        if isinstance(value, dict):
            for key, item in value.items():
                if key != "generator":
                    walk(item, (*path, key), kinds.get(key, anything))
        elif isinstance(value, (list, tuple)):
            for index, item in enumerate(value):
                walk(item, (*path, index), allowed)

    walk(data, (), anything)


def scenario_from_mapping(data: dict, source: str | Path | None = None) -> Scenario:
    """Validate a mapping as a scenario (schema and geometry)."""
    refuse_misread(data, Scenario, source)
    try:
        scenario = Scenario.model_validate(data)
    except ValidationError as exc:
        raise pydantic_error(source, exc, Scenario) from None
    grid = scenario.grid_map
    if grid is not None:
        if grid.image is not None and source is not None and not Path(grid.image).is_absolute():
            # A map image beside the scenario file, wherever it is read from.
            grid = grid.model_copy(update={"image": str(Path(source).resolve().parent / grid.image)})
            scenario = scenario.model_copy(update={"grid_map": grid})
        try:
            occupied_boxes(grid, scenario.world.width, scenario.world.height, scenario.world.offset)
        except ConfigError as exc:  # the image's own file named, where the error is about it
            if exc.source is None and exc.field and exc.field.startswith("generator."):
                raise ConfigError(source, f"grid_map.{exc.field}", exc.problem) from None
            raise ConfigError(source, "grid_map", f"{exc.source}: {exc.problem}" if exc.source else exc.problem) from None
    return scenario.check(source)


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a project scenario YAML file."""
    return scenario_from_mapping(read_yaml_mapping(path), path)


def save_scenario(scenario: Scenario, path: str | Path) -> None:
    """Write a scenario as YAML."""
    Path(path).write_text(scenario.to_yaml())
