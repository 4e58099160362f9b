"""How a command moves the controlled robot when it is not a differential drive (IR-SIM's
``omni``, ``omni_angular`` and ``acker`` kinematics, with their limits) or moves with IR-SIM's
motion noise.

A command has one number per channel (:data:`CHANNELS`): ``omni`` (forward, lateral: m/s in the
body frame; the heading stays), ``omni_angular`` (forward, lateral, w) and ``acker`` (v and the
steering angle in rad, or the steering rate in rad/s with ``steer_mode: angular``). Each channel
is clipped to the robot's limits, narrowed to what its acceleration reaches from the last
command, as IR-SIM's ``get_vel_range`` does. Every model then moves by IR-SIM's Euler step: the
position advances by the body-frame velocity turned by the heading at the step's start, the
heading by the turn rate, so a step's path is a straight segment. A car turns at
v tan(steer) / axle_distance with the steering angle the step began with, as IR-SIM's
``ackermann_kinematics`` has it. The differential drive keeps its own path (:mod:`common.kinematics`
and flatland's compiled step) unless it has motion noise.

Motion noise (``RobotProfile.motion_noise``, IR-SIM's ``alpha``) perturbs the clipped command
before it moves the robot, drawn as IR-SIM draws it, so a seeded world moves alike in both:
a differential drive or a car gets N(0, α0 c0² + α1 c1²) on its first channel and N(0, α2 c0² +
α3 c1²) on its second (c: the clipped command), an omnidirectional robot N(0, αi) on channel i.
The acceleration window and the readings keep the command as given; the odometry integrates it,
so the noise is what dead reckoning does not see.
"""

from __future__ import annotations

import math

import numpy as np

from common.errors import ConfigError, quote
from common.kinematics import Pose2D, wrap_angle
from common.scenario import RobotProfile

CHANNELS: dict[str, tuple[str, ...]] = {
    "diff": ("v", "w"),
    "omni": ("v", "lateral"),
    "omni_angular": ("v", "lateral", "w"),
    "acker": ("v", "steer"),
}
DEFAULT_NOISE = {"diff": (0.03, 0.0, 0.0, 0.03), "omni": (0.03, 0.03), "omni_angular": (0.03, 0.03, 0.03),
                 "acker": (0.03, 0.0, 0.0, 0.03)}  # IR-SIM's alpha when noise is on and alpha is not given


def refuse_other_drives(robot: RobotProfile, who: str) -> None:
    """A one-line error if ``robot`` is not a differential drive, which ``who`` needs."""
    if robot.kinematics != "diff":
        raise ConfigError(None, "robot.kinematics", f"{who} drives a differential drive (v, w), not "
                          f"{quote(robot.kinematics)}; allowed: diff")


def channel_limits(robot: RobotProfile) -> list[tuple[float, float, float]]:
    """Each command channel's (low, high, acceleration) for ``robot``, in :data:`CHANNELS` order."""
    limits = {"v": (robot.v_min, robot.v_max, robot.accel_v), "w": (robot.w_low, robot.w_max, robot.accel_w),
              "lateral": (robot.lateral_low, robot.lateral_max, robot.accel_lateral),
              "steer": (robot.steer_low, robot.steer_max, robot.accel_steer)}
    return [limits[name] for name in CHANNELS[robot.kinematics]]


def body_euler(pose: Pose2D, forward: float, lateral: float, w: float, dt: float) -> Pose2D:
    """IR-SIM's Euler step of a body-frame velocity (forward, lateral) and turn rate ``w``."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    return Pose2D(x + (forward * c - lateral * s) * dt, y + (forward * s + lateral * c) * dt,
                  wrap_angle(yaw + w * dt))


class Drive:
    """The command state of a robot that is not a noise-free differential drive: the last command
    (for the acceleration window) and a car's steering angle."""

    def __init__(self, robot: RobotProfile, dt: float) -> None:
        self.kinematics = robot.kinematics
        self.channels = CHANNELS[robot.kinematics]
        limits = channel_limits(robot)
        self._low = [low for low, _, _ in limits]
        self._high = [high for _, high, _ in limits]
        self._window = [acceleration * dt for _, _, acceleration in limits]
        self._dt = dt
        self._steers = robot.steer_mode == "steer"
        self._axle = robot.axle_distance
        self._alpha = robot.motion_noise
        self.reset()

    def reset(self, steer: float = 0.0) -> None:
        """At rest, the wheels at ``steer`` (a car's)."""
        self.last = [0.0] * len(self.channels)
        self.steer = steer

    def halt(self) -> None:
        """A halted robot's command is zero (the steering stays where it is)."""
        self.last = [0.0] * len(self.channels)

    def clip(self, command: tuple[float, ...]) -> list[float]:
        """``command`` within the limits and the acceleration window around the last one."""
        if len(command) != len(self.channels):
            raise ValueError(f"a {self.kinematics} robot takes {len(self.channels)} numbers "
                             f"({', '.join(self.channels)}), got {len(command)}")
        clipped = []
        for value, low, high, window, last in zip(command, self._low, self._high, self._window, self.last):
            low, high = max(low, last - window), min(high, last + window)
            # Raised to the low end, then lowered to the high end (NumPy's clip, which IR-SIM uses):
            # a window above the limit leaves the limit.
            value = max(float(value), low)
            clipped.append(min(value, high))
        return clipped

    def move(self, command: tuple[float, ...], rng: np.random.Generator | None = None
             ) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """Clip ``command`` and take it as the last one; the body velocity (forward, lateral,
        turn rate) it commands, and the one it moves the robot with this step (with the motion
        noise, drawn from ``rng``, if the robot has any)."""
        clipped = self.last = self.clip(command)
        real = clipped if self._alpha is None else self._noisy(clipped, rng)
        commanded = self._body(clipped, self.steer)
        moved = commanded if real is clipped else self._body(real, self.steer)
        if self.kinematics == "acker":
            steer = real[1]
            self.steer = steer if self._steers else self.steer + steer * self._dt
        return commanded, moved

    def _body(self, channels: list[float], steer: float) -> tuple[float, float, float]:
        if self.kinematics == "diff":
            return channels[0], 0.0, channels[1]
        if self.kinematics == "omni":
            return channels[0], channels[1], 0.0
        if self.kinematics == "omni_angular":
            return channels[0], channels[1], channels[2]
        v = channels[0]
        return v, 0.0, math.tan(steer) / self._axle * v

    def _noisy(self, clipped: list[float], rng: np.random.Generator) -> list[float]:
        """IR-SIM's draw: one normal per channel, in one call of its shape (a column)."""
        alpha = self._alpha
        size = len(clipped)
        if self.kinematics in ("diff", "acker"):
            first, second = clipped
            scale = [[np.sqrt(alpha[0] * first ** 2 + alpha[1] * second ** 2)],
                     [np.sqrt(alpha[2] * first ** 2 + alpha[3] * second ** 2)]]
        else:
            scale = [[np.sqrt(a)] for a in alpha[:size]]
        drawn = rng.normal([[0]] * size, scale=scale)
        return [value + float(drawn[k, 0]) for k, value in enumerate(clipped)]
