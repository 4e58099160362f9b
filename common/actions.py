"""The policy's action space: [-1, 1]² mapped to forward-only (v, w) within a robot's limits.

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

from common.errors import ConfigError, quote
from common.scenario import RobotProfile

ACTION_SPACE = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
MAPPINGS = ("linear", "rectified")


def _is_number(value) -> bool:
    """A real number: not a bool, and not a string such as "0.5" that float() would read."""
    kind = type(value)
    if kind is float or kind is int:  # the common case, without the slower abstract-class check
        return True
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def _components(action) -> tuple[float, float]:
    """The two numbers of an action, refusing a wrong shape, anything but numbers (a string such as
    "05" would otherwise read as two digits) or a non-finite value: a NaN let through would
    silently corrupt the robot's pose and every observation after it."""
    array = isinstance(action, np.ndarray)
    try:
        shape = action.shape if array else None if isinstance(action, (str, bytes)) else np.shape(action)
    except ValueError:  # numpy refuses a ragged sequence such as [1, [2, 3]]
        shape = None
    if shape != (2,):
        raise ValueError(f"action {quote(action)}: expected shape (2,) with values in [-1, 1], got "
                         f"{'a ' + type(action).__name__ if shape is None else f'shape {shape}'}")
    first, second = action.tolist() if array else action  # tolist: the fast path for arrays
    # An array of floats or integers holds numbers; any other dtype, or a sequence, is checked value by value.
    if not (array and action.dtype.kind in "fiu") and not (_is_number(first) and _is_number(second)):
        raise ValueError(f"action {quote(action)}: expected two numbers in [-1, 1]")
    try:
        a0, a1 = float(first), float(second)
    except OverflowError:  # an integer beyond any float
        a0 = a1 = math.inf
    if not (math.isfinite(a0) and math.isfinite(a1)):
        raise ValueError(f"action {quote(action)}: expected finite numbers in [-1, 1] (NaN and inf are refused)")
    return a0, a1


class ActionMapping:
    """a[0] in [-1, 1] -> v in [0, v_max] (``linear`` or ``rectified``); a[1] in [-1, 1] -> w in [-w_max, w_max]."""

    def __init__(self, robot: RobotProfile, kind: str = "linear") -> None:
        if kind not in MAPPINGS:
            raise ConfigError(None, "action_mapping", f"unknown mapping {quote(kind)}; allowed: {', '.join(MAPPINGS)}")
        self.kind = kind
        self.v_max = robot.v_max
        self.w_max = robot.w_max
        self._rectified = kind == "rectified"

    def to_velocity(self, action) -> tuple[float, float]:
        """Velocities for an action: finite values are clipped into [-1, 1]; anything else is a ValueError."""
        a0, a1 = _components(action)
        # Comparisons, not min(max()): the builtin calls made the whole mapping twice as slow.
        a0 = -1.0 if a0 < -1.0 else 1.0 if a0 > 1.0 else a0
        a1 = -1.0 if a1 < -1.0 else 1.0 if a1 > 1.0 else a1
        v = max(a0, 0.0) * self.v_max if self._rectified else 0.5 * (a0 + 1.0) * self.v_max
        return v, a1 * self.w_max

    def to_action(self, v: float, w: float) -> np.ndarray:
        """An action that commands (v, w), clipped to what the mapping can express."""
        a0 = v / self.v_max if self._rectified else 2.0 * v / self.v_max - 1.0
        return np.clip(np.array([a0, w / self.w_max], dtype=np.float32), -1.0, 1.0)
