"""Named robot profiles, so a curriculum or a command line can ask for a robot by name,
families of robots drawn per episode (the ``robot_family`` condition), and how far each lidar
beam runs inside the robot before it reaches the world (:func:`footprint_reach`).

``physics3d`` is the 3D tier's URDF robot (``physics3d/assets/diff_drive.urdf``) as a profile:
its footprint (body and wheels, 0.3 × 0.24 m), wheels and the 3D tutorial's limits. It lives here,
free of simulator imports, so a 2D stage can train on the 3D robot's profile.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, Strict, model_validator

from common.errors import ConfigError, quote
from common.scenario import LidarSpec, RobotProfile

WHEEL_RADIUS = 0.05  # m, as in the URDF (tests/test_physics3d.py checks the two agree)
WHEEL_BASE = 0.22  # m, between the wheels' mid-planes

PROFILES: dict[str, RobotProfile] = {
    "default": RobotProfile(),
    "physics3d": RobotProfile(shape="box", length=0.3, width=0.24, wheel_radius=WHEEL_RADIUS, wheel_base=WHEEL_BASE,
                              v_max=0.5, w_max=1.5),
}


def robot_profile(value: str | dict[str, Any] | RobotProfile, field: str = "robot") -> RobotProfile:
    """A profile by name (``default``, ``physics3d``), from a mapping of its fields, or as given."""
    if isinstance(value, RobotProfile):
        return value
    if isinstance(value, str):
        if value not in PROFILES:
            raise ConfigError(None, field, f"unknown robot {quote(value)}; allowed: {', '.join(PROFILES)} or a mapping of profile fields")
        return PROFILES[value]
    if isinstance(value, dict):
        from pydantic import ValidationError

        from common.scenario import pydantic_error, refuse_misread

        refuse_misread(value, RobotProfile, None, field)
        try:
            return RobotProfile.model_validate(value)
        except ValidationError as exc:
            error = pydantic_error(None, exc, RobotProfile)
            raise ConfigError(None, f"{field}.{error.field}" if error.field else field, error.problem) from None
    raise ConfigError(None, field, f"got {quote(value)}; allowed: a robot name ({', '.join(PROFILES)}) or a mapping")


Size = Annotated[float, Field(gt=0.0, le=2.0), Strict()]  # m: a robot this project's worlds have room for
Rate = Annotated[float, Field(gt=0.0, le=10.0), Strict()]  # m/s, rad/s


class RobotFamily(BaseModel):
    """Robots drawn per episode: a shape from ``shapes``, then its size (a circle's ``radius``, or
    a box's ``length`` along the heading and ``width`` across it), ``v_max`` and ``w_max``, each
    uniform in its [low, high] range, in that order, from the env's seeded generator. The defaults
    span the robots users bring: circles of 0.1-0.3 m radius, boxes up to 0.55 x 0.45 m, 0.5-2 m/s,
    1-3 rad/s."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    shapes: Annotated[tuple[Literal["circle", "box"], ...], Field(min_length=1, max_length=2)] = ("circle", "box")
    radius: tuple[Size, Size] = (0.1, 0.3)
    length: tuple[Size, Size] = (0.2, 0.55)
    width: tuple[Size, Size] = (0.2, 0.45)
    v_max: tuple[Rate, Rate] = (0.5, 2.0)
    w_max: tuple[Rate, Rate] = (1.0, 3.0)

    @model_validator(mode="after")
    def _ordered(self) -> "RobotFamily":
        for name in ("radius", "length", "width", "v_max", "w_max"):
            low, high = getattr(self, name)
            if low > high:
                raise ValueError(f"{name}: [{low:g}, {high:g}]; allowed: [low, high] with low <= high")
        return self

    def draw(self, rng: np.random.Generator, base: RobotProfile | None = None) -> RobotProfile:
        """One robot of the family (``base``'s other fields: wheels, accelerations, noise)."""
        shape = self.shapes[int(rng.integers(len(self.shapes)))]
        size = ({"radius": float(rng.uniform(*self.radius))} if shape == "circle"
                else {"length": float(rng.uniform(*self.length)), "width": float(rng.uniform(*self.width))})
        limits = {"v_max": float(rng.uniform(*self.v_max)), "w_max": float(rng.uniform(*self.w_max))}
        return (base or RobotProfile()).model_copy(update={"shape": shape, **size, **limits})


def footprint_reach(robot: RobotProfile, lidar: LidarSpec) -> np.ndarray:
    """Per beam, in scan order: how far the beam runs from the sensor to the footprint's edge, m
    (0 where the sensor sits outside every part that beam crosses). A return at range r is
    r minus this from the robot: what a robot of any shape needs to judge a gap by."""
    x, y, yaw = lidar.offset
    angles = yaw + lidar.beam_angles()
    directions = np.column_stack([np.cos(angles), np.sin(angles)])
    reach = np.zeros(len(angles))
    for part in robot.outline:
        if part.radius is not None:
            # |o + t d - c| = R: the larger root is where the beam leaves the circle.
            offset = np.array([x, y]) - np.asarray(part.center, dtype=float)
            along = directions @ offset
            disc = along**2 - (offset @ offset - part.radius**2)
            exits = np.where(disc >= 0.0, -along + np.sqrt(np.maximum(disc, 0.0)), 0.0)
        else:
            starts = np.asarray(part.vertices, dtype=float)
            edges = np.roll(starts, -1, axis=0) - starts
            rel = starts - np.array([x, y])
            # Beam o + t d meets edge s + u e: solve t d - u e = s - o for each beam and edge.
            cross = directions[:, None, 0] * edges[None, :, 1] - directions[:, None, 1] * edges[None, :, 0]
            safe = np.where(np.abs(cross) > 1e-12, cross, np.inf)
            t = (rel[None, :, 0] * edges[None, :, 1] - rel[None, :, 1] * edges[None, :, 0]) / safe
            u = (rel[None, :, 0] * directions[:, None, 1] - rel[None, :, 1] * directions[:, None, 0]) / safe
            exits = np.where((u >= 0.0) & (u <= 1.0) & (t >= 0.0), t, 0.0).max(axis=1)
        reach = np.maximum(reach, np.maximum(exits, 0.0))
    return reach
