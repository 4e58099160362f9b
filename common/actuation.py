"""What happens to a velocity command between the controller and the wheels, in either tier.

Real robots do not do exactly what they are told: the command arrives late, the motors are a
little stronger or weaker than their data sheet, and the wheels take time to reach a new speed.
:class:`Actuator` models the first two for both tiers (the 3D tier's physics supplies the third
itself) and, for flatland, :class:`WheelDynamics` rehearses the third.
"""

from __future__ import annotations

import collections
import math

import numpy as np

from common.kinematics import wheel_speeds


class WheelDynamics:
    """Each wheel's speed follows its target with a first-order lag ``tau`` and an angular
    acceleration limit ``accel``, as the 3D robot's velocity-controlled, torque-limited wheels do.

    Defaults fitted to the 3D robot (``physics3d``: 0.15 N·m per wheel, 2 kg): from rest, 0.5 m/s
    is reached in two 0.1 s steps (0.254, then 0.5 m/s measured), braking from 1 m/s takes 0.19 m,
    and a turn started together with a forward run lags two steps (0, 0.76, 1.5 rad/s measured)
    because the outer wheel's acceleration limit binds; a turn on the spot follows at once.
    """

    def __init__(self, wheel_radius: float, wheel_base: float, tau: float = 0.02, accel: float = 50.0) -> None:
        self.radius, self.base = wheel_radius, wheel_base
        self.tau, self.accel = tau, accel
        self.speeds = np.zeros(2)

    def reset(self) -> None:
        self.speeds = np.zeros(2)

    def __call__(self, v: float, w: float, dt: float) -> tuple[float, float]:
        target = np.array(wheel_speeds(v, w, self.radius, self.base))
        change = (1.0 - math.exp(-dt / self.tau)) * (target - self.speeds)
        limit = self.accel * dt
        self.speeds = self.speeds + np.clip(change, -limit, limit)
        left, right = self.speeds * self.radius
        return 0.5 * (left + right), (right - left) / self.base


class Actuator:
    """A command's way to the wheels: ``delay`` whole control steps late (the robot keeps the last
    command it got; at the start, standing still), scaled by a motor ``gain``, then through
    ``dynamics`` if any. The delay and the gain are the episode's (:meth:`reset`; drawn by
    :meth:`common.conditions.Conditions.draw`).
    """

    def __init__(self, dynamics: WheelDynamics | None = None) -> None:
        self.dynamics = dynamics
        self.delay, self.gain = 0, 1.0
        self._queue: collections.deque[tuple[float, float]] = collections.deque()
        #: Whether commands pass through unchanged (the cheap path); an attribute, as it is read every step.
        self.idle = dynamics is None

    def reset(self, delay: int = 0, gain: float = 1.0) -> None:
        """Start an episode with this delay (steps) and motor gain: an empty pipeline, wheels at rest."""
        self.delay, self.gain = delay, gain
        self._queue = collections.deque([(0.0, 0.0)] * delay)
        self.idle = delay == 0 and gain == 1.0 and self.dynamics is None
        if self.dynamics is not None:
            self.dynamics.reset()

    def __call__(self, v: float, w: float, dt: float) -> tuple[float, float]:
        """The (v, w) the wheels deliver this step for the command (v, w)."""
        if self.delay:
            self._queue.append((v, w))
            v, w = self._queue.popleft()
        v, w = v * self.gain, w * self.gain
        return self.dynamics(v, w, dt) if self.dynamics is not None else (v, w)
