"""Conditions: what varies a world without changing its code, with the same names in both tiers.

A :class:`Conditions` is a set of env keyword arguments (``gym.make(..., lidar_noise=0.02)``, a
stage's ``env_kwargs``, ``--env-kwargs lidar_noise:0.02``). Unset knobs take the tier's default
(:data:`TIER_DEFAULTS`): flatland is ideal unless asked; physics3d is the 3D robot with realistic
imperfections. Ranges are drawn per episode from the world's seeded generator, so a seed still
fixes every episode. The same conditions apply to a stage's training envs and to its evaluations,
and a policy's manifest records them, so a policy is evaluated under the conditions it trained in
unless a user says otherwise.

=================  ======================================================  =========  ===========
knob               meaning                                                  flatland   physics3d
=================  ======================================================  =========  ===========
``robot``          the robot profile: a name (``default``, ``physics3d``)    scenario's ``physics3d``
                   or a mapping of :class:`RobotProfile` fields
``lidar_noise``    σ of the Gaussian noise on each lidar return, m           scenario's 0.01
``lidar_beams``    beams of the lidar, over its angular range               scenario's scenario's
``odometry_noise`` relative σ of each wheel's measured rotation              scenario's 0.01
``action_delay``   control steps a command arrives late, or [lo, hi]: a      0          0
                   whole number of steps drawn per episode
``motor_scale``    [lo, hi]: a per-episode gain on the achieved v and w      none       [0.95, 1.05]
``friction``       [lo, hi]: the wheels' friction coefficient per episode    (3D only)  [0.8, 1.2]
``mass_scale``     [lo, hi]: a per-episode factor on the body's mass         (3D only)  [0.9, 1.1]
``control_period`` seconds per step (default the scenario's step_time)       (3D only)  step_time
``dynamics``       ``kinematic`` or ``first_order`` (wheel lag and           kinematic  (2D only)
                   acceleration limits fitted to the 3D robot)
``heading_source`` where the odometry's heading comes from: ``wheels``       (3D only)  ``gyro``
                   or ``gyro`` (the wheels still give the speed)
``gyro_noise``     σ of each gyroscope reading, rad/s                        (3D only)  0.005
``gyro_bias``      σ of the gyroscope's bias, drawn per episode, rad/s       (3D only)  0.0005
``accel_noise``    σ of each accelerometer reading, m/s²                     (3D only)  0.05
``robot_family``   robots drawn per episode, each scenario generated for     none       (2D only)
                   its robot: ``true`` (circles r 0.1-0.3 m, boxes up to
                   0.55 x 0.45 m, 0.5-2 m/s, 1-3 rad/s) or a mapping of
                   :class:`~common.robots.RobotFamily`'s ranges; a
                   generator kind or mix only
=================  ======================================================  =========  ===========

IR-SIM as a world (``--world irsim``, for evaluation) takes ``robot``, ``lidar_noise`` and
``lidar_beams`` and refuses the rest (:data:`NOT_IN_IRSIM`).

A world takes its conditions whole (``World(scenario, seed, conditions)``), fills the tier's
defaults (:meth:`Conditions.for_tier`) and, at every reset, draws the episode's values with
:meth:`Conditions.draw`, in the order that method fixes. Adding a knob is a field here (with its
bounds, its tier default and a row above) and its use in the tier it applies to.

Why these physics3d defaults: a 2D lidar of the RPLIDAR class measures to about 1 % (1 cm at 1 m);
wheel encoders with tyre slip err by about 1 % per wheel; motors and wheel radii vary by a few
per cent between units and with battery charge; a warehouse floor's friction with rubber tyres
lies around 0.8-1.2; a payload changes the mass by about a tenth. A policy that sees only a
perfect robot learns to rely on perfection (the 3D tutorial's own warning). Small robots with an
IMU take their odometry's heading from its gyroscope, because heading is where dead reckoning
drifts most (a wheel's error turns the estimate, and the turn carries every later metre off
course); a MEMS gyro re-zeroed while the robot stands at its start keeps a bias of a few hundredths
of a degree per second (0.0005 rad/s is about 100°/h, several times the bias instability of
consumer parts), and 0.005 rad/s of noise per reading.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable
from typing import Annotated, Any, Literal, NamedTuple

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, Strict, ValidationError, field_validator, model_validator

from common.errors import ConfigError
from common.fields import Fraction
from common.robots import PROFILES, RobotFamily, robot_profile
from common.scenario import RobotProfile, Scenario

# Strict numbers: true, false and "0.5" are what a person wrote by mistake, not 1, 0 and 0.5.
Scale = Annotated[float, Field(gt=0.0, le=10.0), Strict()]
Range = tuple[Scale, Scale]
Steps = Annotated[int, Field(ge=0, le=20), Strict()]
StrictFraction = Annotated[Fraction, Strict()]
HeadingSource = Literal["wheels", "gyro"]
ONLY_3D = ("friction", "mass_scale", "control_period", "heading_source", "gyro_noise", "gyro_bias", "accel_noise")
ONLY_2D = ("dynamics", "robot_family")
# IR-SIM as a world (``--world irsim``) moves its robot by its own kinematics and senses with its own
# lidar: it takes the robot and the lidar's beams and noise, and nothing that needs wheels or time.
NOT_IN_IRSIM = (*ONLY_3D, *ONLY_2D, "odometry_noise", "action_delay", "motor_scale")

TIER_DEFAULTS: dict[str, dict[str, Any]] = {
    "flatland": {"action_delay": 0, "dynamics": "kinematic"},
    "physics3d": {"robot": "physics3d", "lidar_noise": 0.01, "odometry_noise": 0.01, "action_delay": 0,
                  "motor_scale": (0.95, 1.05), "friction": (0.8, 1.2), "mass_scale": (0.9, 1.1),
                  "heading_source": "gyro", "gyro_noise": 0.005, "gyro_bias": 0.0005, "accel_noise": 0.05},
    "irsim": {},
}
_NOT_IN = {"flatland": ONLY_3D, "physics3d": ONLY_2D, "irsim": NOT_IN_IRSIM}
_NAMED = {"shape", "radius", "length", "width", "v_max", "w_max"}  # a profile's footprint and limits


class EpisodeDraw(NamedTuple):
    """The values a world's conditions take for one episode (:meth:`Conditions.draw`)."""

    action_delay: int
    motor_gain: float
    friction: float | None  # None: the robot's own
    mass_scale: float | None
    gyro_bias: tuple[float, float, float]


class Conditions(BaseModel):
    """The physical conditions of a world (see the module's table); None: the tier's default."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    robot: str | dict[str, Any] | None = None
    lidar_noise: StrictFraction | None = None
    lidar_beams: Annotated[int, Field(ge=1, le=4096), Strict()] | None = None  # LidarSpec.beams's bounds
    odometry_noise: StrictFraction | None = None
    action_delay: Steps | tuple[Steps, Steps] | None = None
    motor_scale: Range | None = None
    friction: Range | None = None
    mass_scale: Range | None = None
    control_period: Scale | None = None
    dynamics: Literal["kinematic", "first_order"] | None = None
    heading_source: HeadingSource | None = None
    gyro_noise: StrictFraction | None = None
    gyro_bias: StrictFraction | None = None
    accel_noise: Annotated[float, Field(ge=0.0, le=10.0), Strict()] | None = None
    robot_family: RobotFamily | None = None

    @field_validator("robot_family", mode="before")
    @classmethod
    def _family(cls, value: Any) -> Any:
        if value is True:
            return RobotFamily()  # the default ranges
        return None if value is False else value

    @model_validator(mode="after")
    def _one_robot(self) -> "Conditions":
        if self.robot is not None and self.robot_family is not None:
            raise ValueError("robot and robot_family both choose the robot; allowed: one of them")
        return self

    @field_validator("robot", mode="before")
    @classmethod
    def _profile_as_data(cls, value: Any) -> Any:
        # A RobotProfile from Python, kept as the mapping a file would give (a manifest stores it),
        # its footprint and limits named even where defaults: a tier's robot fills only what it leaves out.
        if not isinstance(value, RobotProfile):
            return value
        return {**value.model_dump(mode="json", include=_NAMED), **value.model_dump(mode="json", exclude_defaults=True)}

    @field_validator("robot")
    @classmethod
    def _known_robot(cls, value: Any) -> Any:
        if value is not None:
            try:
                robot_profile(value)
            except ConfigError as error:
                inner = error.field.removeprefix("robot").removeprefix(".")
                raise ValueError(f"{inner}: {error.problem}" if inner else error.problem) from None
        return value

    @field_validator("motor_scale", "friction", "mass_scale", mode="before")
    @classmethod
    def _a_range(cls, value: Any) -> Any:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            raise ValueError(f"expected a range [low, high] drawn per episode, got {value!r}; "
                             f"for a fixed value: [{value!r}, {value!r}]")
        return value

    @field_validator("motor_scale", "friction", "mass_scale", "action_delay")
    @classmethod
    def _ordered(cls, value: Any) -> Any:
        if isinstance(value, tuple) and value[0] > value[1]:
            raise ValueError(f"expected [low, high] with low <= high, got {list(value)}")
        return value

    @classmethod
    def parse(cls, values: dict[str, Any], source: str | None = None, field: str = "env_kwargs") -> "Conditions":
        """Validate a mapping of knobs; one-line errors naming the knob."""
        from common.scenario import pydantic_error

        try:
            return cls.model_validate(values)
        except ValidationError as exc:
            error = pydantic_error(None, exc, cls)
            raise ConfigError(source, f"{field}.{error.field}" if error.field else field, error.problem) from None

    def for_tier(self, tier: str, strict: bool = True) -> "Conditions":
        """These conditions with the tier's defaults filled in. A knob of the other tier is an error,
        or with ``strict=False`` dropped (a 2D policy's wheel dynamics mean nothing in 3D, where
        physics supplies them)."""
        given = self.model_dump(exclude_none=True)
        if strict:
            refuse_other_knobs(given, tier)
        for knob in _NOT_IN[tier]:
            given.pop(knob, None)
        base = TIER_DEFAULTS[tier].get("robot")
        if isinstance(base, str) and isinstance(given.get("robot"), dict):
            # A mapping changes the tier's robot (in 3D the URDF robot: ``{v_max: 0.3}`` is that box,
            # slower), not the 2D default's circle, which no 3D body is.
            given["robot"] = {**PROFILES[base].model_dump(mode="json", exclude_defaults=True), **given["robot"]}
        return Conditions.model_validate({**TIER_DEFAULTS[tier], **given})

    def given(self) -> dict[str, Any]:
        """The knobs set (not left to a default), as plain data for a manifest."""
        return self.model_dump(mode="json", exclude_none=True)

    @functools.cached_property
    def profile(self) -> RobotProfile | None:
        """The robot profile asked for, if any (built once: a world asks at every scenario it loads)."""
        return robot_profile(self.robot) if self.robot is not None else None

    def scenario(self, scenario: Scenario) -> Scenario:
        """``scenario`` with this robot and these sensors (the knobs a scenario holds)."""
        update: dict[str, Any] = {}
        robot = self.profile or scenario.robot
        if self.odometry_noise is not None and self.odometry_noise != robot.encoder_noise:
            robot = robot.model_copy(update={"encoder_noise": self.odometry_noise})
        if robot is not scenario.robot and robot != scenario.robot:
            world = scenario.world
            if 2.0 * robot.bounding_radius >= min(world.width, world.height):
                raise ConfigError(None, "robot", f"{2 * robot.bounding_radius:g} m across, it does not fit in the "
                                  f"{world.width:g} x {world.height:g} m world of {scenario.name}; allowed: a robot "
                                  "narrower than its world")
            update["robot"] = robot
        lidar = {}
        if self.lidar_noise is not None and self.lidar_noise != scenario.lidar.noise_std:
            lidar["noise_std"] = self.lidar_noise
        if self.lidar_beams is not None and self.lidar_beams != scenario.lidar.beams:
            lidar["beams"] = self.lidar_beams
        if lidar:
            update["lidar"] = scenario.lidar.model_copy(update=lidar)
        return scenario.model_copy(update=update) if update else scenario

    @property
    def delay_range(self) -> tuple[int, int]:
        """``action_delay`` as (low, high) steps."""
        delay = self.action_delay or 0
        return (delay, delay) if isinstance(delay, int) else delay

    def draws(self, scenario: Scenario) -> bool:
        """Whether an episode of ``scenario`` (as conditioned) under these conditions draws random
        numbers: sensor or motion noise, or a knob given as a range. A world that draws nothing
        need not reseed its generator per episode."""
        ranges = (self.motor_scale, self.friction, self.mass_scale)
        robot = scenario.robot
        return (scenario.lidar.noise_std > 0.0 or robot.encoder_noise > 0.0 or robot.motion_noise is not None
                or bool(self.gyro_noise) or bool(self.gyro_bias) or bool(self.accel_noise) or _varies(self.delay_range)
                or any(_varies(r) for r in ranges if r is not None))

    def draw(self, rng: np.random.Generator) -> EpisodeDraw:
        """This episode's values, drawn from ``rng`` in a fixed order (delay, motor gain, friction,
        mass, gyro bias). A fixed value (a knob unset, a number, or a range whose ends agree) draws
        nothing, so adding a fixed knob leaves every other draw, and so every episode, as it was."""
        delay = _uniform_int(rng, self.delay_range)
        gain = _uniform(rng, self.motor_scale) if self.motor_scale is not None else 1.0
        friction = _uniform(rng, self.friction) if self.friction is not None else None
        mass = _uniform(rng, self.mass_scale) if self.mass_scale is not None else None
        bias = tuple(rng.normal(0.0, self.gyro_bias, 3).tolist()) if self.gyro_bias else (0.0, 0.0, 0.0)
        return EpisodeDraw(delay, gain, friction, mass, bias)


def _varies(limits: tuple[float, float]) -> bool:
    return limits[1] > limits[0]


def _uniform(rng: np.random.Generator, limits: tuple[float, float]) -> float:
    return float(rng.uniform(*limits)) if _varies(limits) else float(limits[0])


def _uniform_int(rng: np.random.Generator, limits: tuple[int, int]) -> int:
    return int(rng.integers(limits[0], limits[1] + 1)) if _varies(limits) else int(limits[0])


CONDITION_KEYS = tuple(Conditions.model_fields)


def conditions_of(env_kwargs: dict[str, Any], source: str | None = None, field: str = "env_kwargs") -> Conditions:
    """The conditions among a stage's or a manifest's env kwargs (the rest are task options such as
    ``goal_threshold``, which shape training, not the world)."""
    return Conditions.parse({k: v for k, v in env_kwargs.items() if k in CONDITION_KEYS}, source, field)


def refuse_other_knobs(knobs: Iterable[str], tier: str) -> None:
    """A one-line error for a knob among ``knobs`` (names) that ``tier`` does not model: checked
    before the knobs' values, whose advice would be for a knob the tier then refuses."""
    wrong = _NOT_IN[tier]
    for knob in knobs:
        if knob in wrong:
            allowed = ", ".join(k for k in Conditions.model_fields if k not in wrong)
            raise ConfigError(None, knob, f"not {'an' if tier == 'irsim' else 'a'} {tier} knob; allowed: {allowed}")
