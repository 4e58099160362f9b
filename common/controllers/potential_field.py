"""Artificial potential field: the goal attracts, every nearby lidar return repels."""

from __future__ import annotations

import math

import numpy as np

from common.controllers.base import Controller
from common.kinematics import wrap_angle
from common.readings import Readings
from common.scenario import LidarSpec, RobotProfile

# The gains are tuned for the default scan, 36 beams spaced 10° (before 360° scans stopped repeating
# their ±180° beam, 360°/35: the same 36 returns each weighing 1).
_REFERENCE_SPACING = 2.0 * math.pi / 36


class PotentialField(Controller):
    """Drive along the total force of an attractive and a repulsive field (the 2D tutorial's).

    F_att = k_att·(goal − p). Each return at clearance d < d0 (metres from the robot's bounding
    circle to the return) pushes away from itself with k_rep·(1/d − 1/d0)/d², Khatib's gradient of
    ½·k_rep·(1/d − 1/d0)². The extra 1/d² stays gentle at a distance and stiffens sharply near
    contact. The tutorial's bare (1/d − 1/d0) must be strong everywhere to stop a far goal's pull
    pressing the robot into obstacles, and then stalls it in open gaps: its best gain reached 26/30
    sparse and 17/30 cluttered scenarios, this form 28/30 and 25/30 (seeds 0–29). Each return is weighted by its beam spacing relative to 36
    beams over 360°, so a denser scan does not repel harder. The robot turns toward the force
    (w = k_w·e) and drives at v = k_v·(the force's component along its heading), forward only.

    It halts wherever the forces cancel or point backward (a U-shaped obstacle, twin obstacles or a
    gap barely wider than the robot across the route): the local minimum the tutorial shows.
    Nothing here tries to escape it.

    Args:
        k_att: attraction per metre of goal offset (1.0).
        k_rep: repulsion gain, m³ per return (0.002).
        influence: d0, the clearance in metres beyond which returns do not repel (0.5).
        k_w: turning gain, 1/s (2.0).
        k_v: speed per unit of force along the heading, 1/s (0.5).
        stop_distance: within this many metres of the goal (by odometry), stand still; None (default):
            half the scenario's goal threshold, so the robot drives into any goal radius.
    """

    name = "potential_field"

    def __init__(self, k_att: float = 1.0, k_rep: float = 0.002, influence: float = 0.5, k_w: float = 2.0,
                 k_v: float = 0.5, stop_distance: float | None = None) -> None:
        self.k_att = k_att
        self.k_rep = k_rep
        self.influence = influence
        self.k_w = k_w
        self.k_v = k_v
        self.stop_distance = stop_distance

    def bind(self, robot: RobotProfile, lidar: LidarSpec, goal_threshold: float = 0.3) -> None:
        super().bind(robot, lidar, goal_threshold)
        self._beam_weight = lidar.beam_spacing / _REFERENCE_SPACING

    def force(self, readings: Readings, goal: tuple[float, float]) -> np.ndarray:
        """The total force (world frame) on the robot at its odometry pose."""
        pose = readings.odometry.pose
        position = np.array(pose[:2])
        total = self.k_att * (np.asarray(goal, dtype=float) - position)
        away = position - self.lidar.returns_world_frame(readings.lidar, pose)
        centre_distance = np.hypot(away[:, 0], away[:, 1])
        # Clearance from the robot's outline; floored so a grazing return gives a large, finite push.
        d = np.maximum(centre_distance - self.robot.bounding_radius, 0.01)
        near = d < self.influence
        if np.any(near):
            magnitude = self.k_rep * self._beam_weight * (1.0 / d[near] - 1.0 / self.influence) / d[near] ** 2
            total += (magnitude / np.maximum(centre_distance[near], 1e-9)) @ away[near]
        return total

    def act(self, readings: Readings, goal: tuple[float, float]) -> tuple[float, float]:
        x, y, yaw = readings.odometry.pose
        if self.arrived(math.hypot(goal[0] - x, goal[1] - y), self.stop_distance):
            return 0.0, 0.0
        fx, fy = (float(f) for f in self.force(readings, goal))
        error = wrap_angle(math.atan2(fy, fx) - yaw)
        along = fx * math.cos(yaw) + fy * math.sin(yaw)  # negative when the force points behind
        return self.clip(self.k_v * along, self.k_w * error)
