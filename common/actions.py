"""The policy's action space: [-1, 1]² mapped to forward-only (v, w) within a robot's limits.

Forward-only is deliberate: both tutorials found that a robot allowed to reverse learns to back
away from obstacles instead of going round them.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from common.scenario import RobotProfile

ACTION_SPACE = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)


class ActionMapping:
    """a[0] in [-1, 1] -> v in [0, v_max]; a[1] in [-1, 1] -> w in [-w_max, w_max]."""

    def __init__(self, robot: RobotProfile) -> None:
        self.v_max = robot.v_max
        self.w_max = robot.w_max

    def to_velocity(self, action) -> tuple[float, float]:
        """Velocities for an action (clipped into [-1, 1] first)."""
        a0 = min(max(float(action[0]), -1.0), 1.0)
        a1 = min(max(float(action[1]), -1.0), 1.0)
        return 0.5 * (a0 + 1.0) * self.v_max, a1 * self.w_max

    def to_action(self, v: float, w: float) -> np.ndarray:
        """The action that commands (v, w), clipped to what the mapping can express."""
        return np.clip(np.array([2.0 * v / self.v_max - 1.0, w / self.w_max], dtype=np.float32), -1.0, 1.0)
