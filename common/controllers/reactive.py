"""Reactive avoidance: go-to-goal that turns away from whatever is close in front."""

from __future__ import annotations

import math

import numpy as np

from common.controllers.go_to_goal import GoToGoal, goal_polar
from common.readings import Readings


class ReactiveAvoidance(GoToGoal):
    """Go-to-goal, except when the nearest lidar return within ``front_half_angle`` of straight
    ahead is closer than ``clearance`` beyond the robot's bounding radius: then creep forward at
    ``avoid_v`` and turn at ``avoid_w`` away from the side that return is on (the 2D tutorial's rule).

    Args:
        k_linear, k_angular, stop_distance, turn_in_place: as :class:`GoToGoal` (0.5, 2.0, None, True).
        clearance: metres beyond the robot's radius that trigger avoidance (0.5, the tutorial's).
        front_half_angle: half-width of the watched sector, radians (pi/3, the tutorial's ±60°).
        avoid_v: forward speed while avoiding, m/s (0.1, the tutorial's).
        avoid_w: turn rate while avoiding, rad/s (0.8, the tutorial's), capped at the robot's w_max.
    """

    name = "reactive"

    def __init__(self, k_linear: float = 0.5, k_angular: float = 2.0, stop_distance: float | None = None,
                 turn_in_place: bool = True, clearance: float = 0.5, front_half_angle: float = math.pi / 3,
                 avoid_v: float = 0.1, avoid_w: float = 0.8) -> None:
        super().__init__(k_linear, k_angular, stop_distance, turn_in_place)
        self.clearance = clearance
        self.front_half_angle = front_half_angle
        self.avoid_v = avoid_v
        self.avoid_w = avoid_w

    def act(self, readings: Readings, goal: tuple[float, float]) -> tuple[float, float]:
        distance, _, error = goal_polar(readings, goal)
        if self.arrived(distance, self.stop_distance):
            return 0.0, 0.0
        nearest = self.nearest_front(readings.lidar)
        if nearest is not None and nearest[0] < self.robot.bounding_radius + self.clearance:
            # A return on the left (positive angle) means turn right, and vice versa; clip brings
            # the tutorial's 0.8 rad/s down to a slower robot's limit.
            return self.clip(self.avoid_v, -self.avoid_w if nearest[1] > 0.0 else self.avoid_w)
        return self.clip(*self.goal_command(distance, error))

    def nearest_front(self, ranges: np.ndarray) -> tuple[float, float] | None:
        """(range m, robot-frame angle rad) of the nearest return in the front sector, None if none."""
        angles = (self.lidar.relative_angles + math.pi) % (2.0 * math.pi) - math.pi
        front = np.flatnonzero(np.abs(angles) <= self.front_half_angle)
        if front.size == 0:
            return None
        i = front[np.argmin(ranges[front])]
        return float(ranges[i]), float(angles[i])
