"""Named robot profiles, so a curriculum or a command line can ask for a robot by name.

``physics3d`` is the 3D tier's URDF robot (``physics3d/assets/diff_drive.urdf``) as a profile:
its footprint (body and wheels, 0.3 × 0.24 m), wheels and the 3D tutorial's limits. It lives here,
free of simulator imports, so a 2D stage can train on the 3D robot's profile.
"""

from __future__ import annotations

from typing import Any

from common.errors import ConfigError, quote
from common.scenario import RobotProfile

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

        from common.scenario import pydantic_error

        try:
            return RobotProfile.model_validate(value)
        except ValidationError as exc:
            error = pydantic_error(None, exc)
            raise ConfigError(None, f"{field}.{error.field}" if error.field else field, error.problem) from None
    raise ConfigError(None, field, f"got {quote(value)}; allowed: a robot name ({', '.join(PROFILES)}) or a mapping")
