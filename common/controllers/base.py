"""What every classical controller shares: the interface and the lidar geometry.

A controller reads only what a real robot has (the odometry pose estimate, the lidar scan, the
goal), so the same object drives the 2D and the 3D robot. ``bind`` tells it the robot's limits,
where its lidar's beams point and the goal's radius; ``reset`` starts an episode; ``act`` returns
raw (v, w).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np

from common.drive import refuse_other_drives
from common.readings import Readings
from common.scenario import LidarSpec, RobotProfile


class LidarGeometry:
    """Beam directions and mount of a lidar, to turn ranges into points."""

    def __init__(self, lidar: LidarSpec) -> None:
        self.spec = lidar
        self.relative_angles = lidar.beam_angles() + lidar.offset[2]  # robot frame
        self.cos = np.cos(self.relative_angles)
        self.sin = np.sin(self.relative_angles)

    def returns_robot_frame(self, ranges: np.ndarray, include_misses: bool = False) -> np.ndarray:
        """(N, 2) points of the returns in the robot frame (beams that hit nothing dropped unless asked)."""
        mx, my, _ = self.spec.offset
        points = np.column_stack([mx + ranges * self.cos, my + ranges * self.sin])
        return points if include_misses else points[ranges < self.spec.range_max]

    def returns_world_frame(self, ranges: np.ndarray, pose: tuple[float, float, float]) -> np.ndarray:
        """(N, 2) world points of the returns, for a robot at ``pose``."""
        local = self.returns_robot_frame(ranges)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        return np.column_stack([pose[0] + c * local[:, 0] - s * local[:, 1], pose[1] + s * local[:, 0] + c * local[:, 1]])

    def sector(self, ranges: np.ndarray, centre: float, half_width: float) -> np.ndarray:
        """The ranges of beams pointing within ``half_width`` of ``centre`` (robot frame, radians)."""
        offset = (self.relative_angles - centre + math.pi) % (2 * math.pi) - math.pi
        return ranges[np.abs(offset) <= half_width]


class Controller(ABC):
    """A classical controller: ``bind`` once per robot, ``reset`` per episode, ``act`` per step."""

    name: str = "controller"

    def bind(self, robot: RobotProfile, lidar: LidarSpec, goal_threshold: float = 0.3) -> None:
        """Learn the robot's limits, the lidar's geometry and how close to the goal counts as
        arrived (call before ``reset``). Every controller here commands (v, w): a robot of other
        kinematics is a one-line error."""
        refuse_other_drives(robot, f"the {self.name} controller")
        self.robot = robot
        self.lidar = LidarGeometry(lidar)
        self.goal_threshold = goal_threshold

    def arrived(self, distance: float, stop_distance: float | None) -> bool:
        """Whether to stand still at ``distance`` from the goal (by odometry).

        ``stop_distance`` None means half the goal threshold: well inside it, so that the small
        error of the odometry estimate does not leave the robot parked just outside.
        """
        return distance < (0.5 * self.goal_threshold if stop_distance is None else stop_distance)

    def reset(self) -> None:
        """Forget everything from the previous episode."""

    @abstractmethod
    def act(self, readings: Readings, goal: tuple[float, float]) -> tuple[float, float]:
        """The (v m/s, w rad/s) command for these readings."""

    def clip(self, v: float, w: float) -> tuple[float, float]:
        """Clip to the robot's limits, forward only as policies drive: v in [max(0, v_min), v_max], w
        in [w_min (default -w_max), w_max]. (Clipped to [0, v_max] x [-w_max, w_max] alone, a robot
        with a v_min above 0 was told to turn on the spot and drove forward into the wall it faced.)"""
        robot = self.robot
        return min(max(v, max(0.0, robot.v_min)), robot.v_max), min(max(w, robot.w_low), robot.w_max)
