"""Go-to-goal: the 2D tutorial's proportional controller, blind to obstacles."""

from __future__ import annotations

import math

from common.controllers.base import Controller
from common.kinematics import wrap_angle
from common.readings import Readings


def goal_polar(readings: Readings, goal: tuple[float, float]) -> tuple[float, float, float]:
    """(distance m, bearing rad in the world frame, heading error rad) of the goal from the odometry pose."""
    x, y, yaw = readings.odometry.pose
    dx, dy = goal[0] - x, goal[1] - y
    bearing = math.atan2(dy, dx)
    return math.hypot(dx, dy), bearing, wrap_angle(bearing - yaw)


class GoToGoal(Controller):
    """P control on distance and heading error: v = k_linear·d, w = k_angular·e.

    Args:
        k_linear: forward gain, 1/s (0.5, the tutorial's).
        k_angular: turning gain, 1/s (2.0, the tutorial's).
        stop_distance: within this many metres of the goal (by odometry), stand still; None (default):
            half the scenario's goal threshold, so the robot drives into any goal radius.
        turn_in_place: scale v by max(0, cos e) (True). A forward-only robot with the bare law
            drives away from a goal behind it while it turns; with the factor it turns on the spot
            and the law is unchanged when the goal is straight ahead. False gives the tutorial's
            bare law.
    """

    name = "go_to_goal"

    def __init__(self, k_linear: float = 0.5, k_angular: float = 2.0, stop_distance: float | None = None,
                 turn_in_place: bool = True) -> None:
        self.k_linear = k_linear
        self.k_angular = k_angular
        self.stop_distance = stop_distance
        self.turn_in_place = turn_in_place

    def act(self, readings: Readings, goal: tuple[float, float]) -> tuple[float, float]:
        distance, _, error = goal_polar(readings, goal)
        if self.arrived(distance, self.stop_distance):
            return 0.0, 0.0
        return self.clip(*self.goal_command(distance, error))

    def goal_command(self, distance: float, error: float) -> tuple[float, float]:
        """The unclipped (v, w) toward the goal, for subclasses that fall back to it."""
        v = self.k_linear * distance
        if self.turn_in_place:
            v *= max(0.0, math.cos(error))
        return v, self.k_angular * error
