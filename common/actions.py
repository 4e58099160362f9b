"""The policy's action space: [-1, 1]² mapped to forward-only (v, w) within a robot's limits.

A robot of other kinematics (:mod:`common.drive`) gets one action per command channel, each in
[-1, 1]: a car (``acker``) maps a[0] to v as below and a[1] to the steering angle (or rate) in
[-steer_max, steer_max]; an omnidirectional robot maps forward onto its [v_min, v_max] (IR-SIM's
files give a negative ``vel_min``: one that cannot turn, ``omni``, backs towards a goal behind
it), lateral to [-lateral_max, lateral_max] and w to [-w_max, w_max]. The whole range of a[0]
spans what the robot can drive: mapped to [-v_max, v_max] and clipped to v_min = 0, its lower
half stood still.

Forward-only is deliberate: both tutorials found that a robot allowed to reverse learns to back
away from obstacles instead of going round them.

Two mappings of a[0] to v:

* ``linear`` (default): v = (a[0] + 1) / 2 · v_max, the whole range spread over [0, v_max].
* ``rectified``: v = max(a[0], 0) · v_max, so the lower half of the range stands still. A Gaussian
  policy then explores turning on the spot as often as driving, which a linear mapping makes rare.
"""

from __future__ import annotations

import math
import numbers

import numpy as np
from gymnasium import spaces

from common.drive import CHANNELS
from common.errors import ConfigError, quote
from common.scenario import RobotProfile

ACTION_SPACE = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
MAPPINGS = ("linear", "rectified")


def action_space(robot: RobotProfile) -> spaces.Box:
    """The action space of a robot: one number in [-1, 1] per command channel."""
    size = len(CHANNELS[robot.kinematics])
    return ACTION_SPACE if size == 2 else spaces.Box(-1.0, 1.0, shape=(size,), dtype=np.float32)


def _is_number(value) -> bool:
    """A real number: not a bool, and not a string such as "0.5" that float() would read."""
    kind = type(value)
    if kind is float or kind is int:  # the common case, without the slower abstract-class check
        return True
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def _components(action, size: int = 2) -> tuple[float, ...]:
    """The ``size`` numbers of an action, refusing a wrong shape, anything but numbers (a string such as
    "05" would otherwise read as two digits) or a non-finite value: a NaN let through would
    silently corrupt the robot's pose and every observation after it."""
    array = isinstance(action, np.ndarray)
    if array and action.dtype.kind == "f" and action.shape == (size,):
        values = action.tolist()
        if all(map(math.isfinite, values)):  # the policies' actions: one check instead of the general path's five
            return tuple(values)
    try:
        shape = action.shape if array else None if isinstance(action, (str, bytes)) else np.shape(action)
    except ValueError:  # numpy refuses a ragged sequence such as [1, [2, 3]]
        shape = None
    if shape != (size,):
        raise ValueError(f"action {quote(action)}: expected shape ({size},) with values in [-1, 1], got "
                         f"{'a ' + type(action).__name__ if shape is None else f'shape {shape}'}")
    values = action.tolist() if array else action  # tolist: the fast path for arrays
    # An array of floats or integers holds numbers; any other dtype, or a sequence, is checked value by value.
    if not (array and action.dtype.kind in "fiu") and not all(_is_number(value) for value in values):
        raise ValueError(f"action {quote(action)}: expected {('two', 'three')[size - 2]} numbers in [-1, 1]")
    try:
        values_ = tuple(float(value) for value in values)
    except OverflowError:  # an integer beyond any float
        values_ = (math.inf,) * size
    if not all(math.isfinite(value) for value in values_):
        raise ValueError(f"action {quote(action)}: expected finite numbers in [-1, 1] (NaN and inf are refused)")
    return values_


class ActionMapping:
    """a[0] in [-1, 1] -> v in [0, v_max] (``linear`` or ``rectified``); a[1] in [-1, 1] -> w in
    [-w_max, w_max]; other kinematics as the module says."""

    def __init__(self, robot: RobotProfile, kind: str = "linear") -> None:
        if kind not in MAPPINGS:
            raise ConfigError(None, "action_mapping", f"unknown mapping {quote(kind)}; allowed: {', '.join(MAPPINGS)}")
        self.kind = kind
        self.kinematics = robot.kinematics
        self.space = action_space(robot)
        self.v_max = robot.v_max
        self.w_max = robot.w_max
        self._rectified = kind == "rectified"
        # The symmetric scale of every channel after the first, and of the first for omni robots.
        scales = {"v": robot.v_max, "w": robot.w_max, "lateral": robot.lateral_max, "steer": robot.steer_max}
        self._scales = tuple(scales[name] for name in CHANNELS[robot.kinematics])
        self._omni = robot.kinematics in ("omni", "omni_angular")
        self._forward = (robot.v_min, robot.v_max)

    def to_velocity(self, action) -> tuple[float, ...]:
        """The command for an action, (v, w) for a differential drive: finite values are clipped
        into [-1, 1]; anything else is a ValueError."""
        if self.kinematics != "diff":
            return self._command(action)
        a0, a1 = _components(action)
        # Comparisons, not min(max()): the builtin calls made the whole mapping twice as slow.
        a0 = -1.0 if a0 < -1.0 else 1.0 if a0 > 1.0 else a0
        a1 = -1.0 if a1 < -1.0 else 1.0 if a1 > 1.0 else a1
        v = max(a0, 0.0) * self.v_max if self._rectified else 0.5 * (a0 + 1.0) * self.v_max
        return v, a1 * self.w_max

    def _command(self, action) -> tuple[float, ...]:
        clipped = [min(max(a, -1.0), 1.0) for a in _components(action, len(self._scales))]
        command = [a * scale for a, scale in zip(clipped, self._scales)]
        a0 = clipped[0]
        if self._omni:
            low, high = self._forward
            command[0] = low + 0.5 * (a0 + 1.0) * (high - low)
        else:  # a car drives forward only, as a differential drive does
            command[0] = max(a0, 0.0) * self.v_max if self._rectified else 0.5 * (a0 + 1.0) * self.v_max
        return tuple(command)

    def to_action(self, *command: float) -> np.ndarray:
        """An action that commands ``command`` ((v, w) for a differential drive), clipped to what
        the mapping can express."""
        action = [value / scale for value, scale in zip(command, self._scales)]
        v = command[0]
        if self._omni:
            low, high = self._forward
            action[0] = 2.0 * (v - low) / (high - low) - 1.0 if high > low else 0.0
        else:
            action[0] = v / self.v_max if self._rectified else 2.0 * v / self.v_max - 1.0
        return np.clip(np.array(action, dtype=np.float32), -1.0, 1.0)
