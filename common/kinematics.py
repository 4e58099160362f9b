"""Differential-drive kinematics: unicycle updates, wheel speeds, angle wrapping, wheel odometry.

Pure functions of floats (``math``, not numpy, because they run once per env step and numpy
scalars are an order of magnitude slower there). Frame: x right, y up, yaw counter-clockwise.
The pose updates are also compiled into flatland's step kernel (``register_jitable``: from Python
they stay plain functions), so both paths compute the same bits.
"""

from __future__ import annotations

import math
from typing import Callable, NamedTuple

import numpy as np
from numba.extending import register_jitable


record = tuple.__new__
"""``record(Cls, (field, ...))``: a NamedTuple from every one of its fields, built in C. Calling
the class runs a Python-level ``__new__`` (0.31 µs against 0.14 for a pose), and each env step
builds six records: the hot paths use this."""


class Pose2D(NamedTuple):
    """A planar pose: position in metres, yaw in radians (counter-clockwise from +x)."""

    x: float
    y: float
    yaw: float


def nan_command(command: tuple) -> ValueError:
    """The error for a command holding NaN: every comparison with NaN is false, so it passes the
    limits' clips and corrupts the pose (in PyBullet, the robot's body for good)."""
    return ValueError(f"command {command!r}: NaN is not a velocity; allowed: finite numbers, clipped to the "
                      "robot's limits")


@register_jitable
def wrap_angle(angle: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    shifted = angle + math.pi
    # x % 2 pi is x itself for x in [0, 2 pi): the same bits without the modulo's fmod, which cost
    # a mover's step a tenth of its time.
    wrapped = (shifted if 0.0 <= shifted < 2.0 * math.pi else shifted % (2.0 * math.pi)) - math.pi
    # Just below -pi, the modulo rounds up to 2 pi and the formula alone would give +pi.
    return wrapped if wrapped < math.pi else -math.pi


@register_jitable
def unicycle_euler(pose: Pose2D, v: float, w: float, dt: float) -> Pose2D:
    """One forward-Euler step, heading taken at the start of the step (IR-SIM's ``diff`` update)."""
    x, y, yaw = pose
    return Pose2D(x + v * math.cos(yaw) * dt, y + v * math.sin(yaw) * dt, wrap_angle(yaw + w * dt))


@register_jitable
def unicycle_exact(pose: Pose2D, v: float, w: float, dt: float) -> Pose2D:
    """The exact update for constant (v, w) over ``dt``: a circular arc, a straight line when w = 0."""
    x, y, yaw = pose
    dyaw = w * dt
    if abs(dyaw) < 1e-9:
        # The arc formula divides by w; its limit is the straight line (second-order term kept).
        mid = yaw + 0.5 * dyaw
        return Pose2D(x + v * dt * math.cos(mid), y + v * dt * math.sin(mid), wrap_angle(yaw + dyaw))
    radius = v / w
    new_yaw = yaw + dyaw
    return Pose2D(
        x + radius * (math.sin(new_yaw) - math.sin(yaw)),
        y - radius * (math.cos(new_yaw) - math.cos(yaw)),
        wrap_angle(new_yaw),
    )


Integrator = Callable[[Pose2D, float, float, float], Pose2D]
INTEGRATORS: dict[str, Integrator] = {"euler": unicycle_euler, "exact": unicycle_exact}


@register_jitable
def wheel_speeds(v: float, w: float, wheel_radius: float, wheel_base: float) -> tuple[float, float]:
    """Body velocity (v m/s, w rad/s) to wheel angular speeds (left, right) in rad/s."""
    half = 0.5 * wheel_base * w
    return (v - half) / wheel_radius, (v + half) / wheel_radius


@register_jitable
def body_velocity(
    left: float, right: float, wheel_radius: float, wheel_base: float
) -> tuple[float, float]:
    """Wheel angular speeds (left, right) in rad/s to body velocity (v m/s, w rad/s)."""
    return 0.5 * wheel_radius * (left + right), wheel_radius * (right - left) / wheel_base


class WheelOdometry:
    """Dead reckoning from wheel encoders, with multiplicative Gaussian encoder noise; the heading
    may come from a gyroscope instead (``update(..., turned=...)``).

    Each step the true wheel rotations are scaled by ``1 + N(0, noise)`` (a slip-like error, so the
    drift grows with the distance travelled) and integrated.

    Args:
        wheel_radius: metres.
        wheel_base: distance between the wheels, metres.
        noise: relative standard deviation of each wheel's measured rotation (0 = perfect encoders).
        rng: the generator the noise is drawn from.
        integrate: the pose update, the same one the world uses, so perfect encoders track exactly.
    """

    def __init__(
        self,
        wheel_radius: float,
        wheel_base: float,
        noise: float,
        rng: np.random.Generator,
        integrate: Integrator = unicycle_exact,
    ) -> None:
        self.wheel_radius = wheel_radius
        self.wheel_base = wheel_base
        self.noise = noise
        self.rng = rng
        self.integrate = integrate
        self.pose = Pose2D(0.0, 0.0, 0.0)
        self.v = 0.0
        self.w = 0.0

    def reset(self, pose: Pose2D) -> None:
        """Start dead reckoning from a known pose, at rest."""
        self.pose = Pose2D(*pose)
        self.v = 0.0
        self.w = 0.0

    def update(self, left: float, right: float, dt: float, turned: float | None = None) -> Pose2D:
        """Integrate one period of true wheel speeds (rad/s); return the estimated pose.

        ``turned``: the heading change over the period as another sensor measured it (a gyroscope);
        given, it replaces the wheels' turn and the wheels supply only the speed. Heading is where
        dead reckoning drifts most: a wheel's error turns the estimate, and the turn carries every
        later metre off course.
        """
        if self.noise > 0.0:
            slip = self.rng.normal(0.0, self.noise, 2).tolist()  # floats: NumPy scalars slow the arithmetic after
            left *= 1.0 + slip[0]
            right *= 1.0 + slip[1]
        self.v, self.w = body_velocity(left, right, self.wheel_radius, self.wheel_base)
        if turned is not None:
            self.w = turned / dt if dt > 0.0 else 0.0
        self.pose = self.integrate(self.pose, self.v, self.w, dt)
        return self.pose
