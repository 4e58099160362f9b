"""The validated field types scenarios and motions are built from, and their caps.

Every number a shared file holds is range-checked before anything uses it (a radius of 1e300
must be a one-line error, not a crash deep in a physics engine). Lengths in metres, angles in
radians, speeds in m/s and rad/s.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field

MAX_LENGTH = 1000.0  # m: world sides, obstacle and robot sizes, lidar range
MAX_COORDINATE = 10_000.0  # m: any position
MAX_SPEED = 100.0  # m/s and rad/s
MAX_MOVER_SPEED = 10.0  # m/s and rad/s: people, forklifts and IR-SIM's agents move slower than this


def _not_a_boolean(value: object) -> object:
    # pydantic reads true as 1.0: `width: true` made a 1 m world without a word.
    if isinstance(value, bool):
        raise ValueError(f"got {str(value).lower()}; allowed: a number")
    return value


Number = Annotated[float, BeforeValidator(_not_a_boolean)]
Whole = Annotated[int, BeforeValidator(_not_a_boolean)]  # beams: true was one beam
Coordinate = Annotated[Number, Field(ge=-MAX_COORDINATE, le=MAX_COORDINATE)]
Point = tuple[Coordinate, Coordinate]
Length = Annotated[Number, Field(gt=0.0, le=MAX_LENGTH)]
# A robot's own size: below a millimetre its outline's polygon had no area to check, and the env failed building it.
BodyLength = Annotated[Number, Field(ge=0.001, le=MAX_LENGTH)]
NonNegativeLength = Annotated[Number, Field(ge=0.0, le=MAX_LENGTH)]
Angle = Annotated[Number, Field(ge=-1000.0, le=1000.0)]  # rad: any finite heading a person would write
Speed = Annotated[Number, Field(ge=-MAX_SPEED, le=MAX_SPEED)]
# Not built on Number: allow_inf_nan does not apply through a validator's wrapper.
Acceleration = Annotated[float, Field(gt=0.0, allow_inf_nan=True), BeforeValidator(_not_a_boolean)]  # inf: no limit, IR-SIM's default
Fraction = Annotated[Number, Field(ge=0.0, le=1.0)]
MoverSpeed = Annotated[Number, Field(ge=-MAX_MOVER_SPEED, le=MAX_MOVER_SPEED)]
Positive = Annotated[Number, Field(gt=0.0, le=1e6)]  # a gain, a time or a length scale
NonNegative = Annotated[Number, Field(ge=0.0, le=1e6)]


class Frozen(BaseModel):
    """An immutable model that refuses unknown keys and non-finite numbers."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)
