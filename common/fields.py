"""The validated field types scenarios and motions are built from, and their caps.

Every number a shared file holds is range-checked before anything uses it (a radius of 1e300
must be a one-line error, not a crash deep in a physics engine). Lengths in metres, angles in
radians, speeds in m/s and rad/s.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field

MAX_LENGTH = 1000.0  # m: world sides, obstacle and robot sizes, lidar range
MAX_COORDINATE = 10_000.0  # m: any position
MAX_SPEED = 100.0  # m/s and rad/s
MAX_MOVER_SPEED = 10.0  # m/s and rad/s: people, forklifts and IR-SIM's agents move slower than this

Coordinate = Annotated[float, Field(ge=-MAX_COORDINATE, le=MAX_COORDINATE)]
Point = tuple[Coordinate, Coordinate]
Length = Annotated[float, Field(gt=0.0, le=MAX_LENGTH)]
# A robot's own size: below a millimetre its outline's polygon had no area to check, and the env failed building it.
BodyLength = Annotated[float, Field(ge=0.001, le=MAX_LENGTH)]
NonNegativeLength = Annotated[float, Field(ge=0.0, le=MAX_LENGTH)]
Angle = Annotated[float, Field(ge=-1000.0, le=1000.0)]  # rad: any finite heading a person would write
Speed = Annotated[float, Field(ge=-MAX_SPEED, le=MAX_SPEED)]
Acceleration = Annotated[float, Field(gt=0.0, allow_inf_nan=True)]  # inf: no limit, IR-SIM's default
Fraction = Annotated[float, Field(ge=0.0, le=1.0)]
MoverSpeed = Annotated[float, Field(ge=-MAX_MOVER_SPEED, le=MAX_MOVER_SPEED)]
MoverSpeedLimit = Annotated[float, Field(gt=0.0, le=MAX_MOVER_SPEED)]
Positive = Annotated[float, Field(gt=0.0, le=1e6)]  # a gain, a time or a length scale
NonNegative = Annotated[float, Field(ge=0.0, le=1e6)]


class Frozen(BaseModel):
    """An immutable model that refuses unknown keys and non-finite numbers."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)
