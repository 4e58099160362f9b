"""What the local controllers (``dwa``, ``orca``) share: movers tracked from the scan, a guide
path round the static returns, and the control period."""

from __future__ import annotations

import numpy as np

from common.controllers.base import Controller
from common.controllers.tracking import Scene, ScanTracker
from common.controllers.waypoint import Guide, Path
from common.readings import Readings
from common.scenario import LidarSpec, RobotProfile


class LocalController(Controller):
    """A controller that sees movers through a :class:`ScanTracker` (with ``track_movers`` False,
    every return counts as static) and steers along a :class:`~common.controllers.waypoint.Guide`'s
    path (with ``guide`` False, straight for the goal), both started afresh every episode; it knows its
    control period."""

    track_movers: bool
    guide: bool
    margin: float
    step_time: float | None
    first_period = 0.1  # s: the control period assumed before two steps have shown it
    guide_slack = 0.1  # m: the guide's path keeps this much more than ``margin`` from static returns

    def bind(self, robot: RobotProfile, lidar: LidarSpec, goal_threshold: float = 0.3) -> None:
        super().bind(robot, lidar, goal_threshold)
        self.tracker = ScanTracker(self.lidar)
        self.planner = Guide(self.lidar, robot.bounding_radius, self.margin + self.guide_slack)

    def reset(self) -> None:
        self.tracker.reset()
        self.planner.reset()
        self._previous_time: float | None = None

    def scene(self, readings: Readings) -> Scene:
        """What this step's scan shows, at the odometry pose."""
        if self.track_movers:
            return self.tracker.update(readings.lidar, readings.odometry.pose, readings.time)
        static = self.lidar.returns_world_frame(readings.lidar, readings.odometry.pose)
        return Scene(static, np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0))

    def path(self, readings: Readings, scene: Scene, goal: tuple[float, float]) -> Path:
        """The path to steer along: round the static returns, or straight to the goal."""
        if not self.guide:
            return Path(np.array([readings.odometry.pose[:2], goal], float))
        return self.planner.path(readings.lidar, readings.odometry.pose, scene.static, np.asarray(goal, float))

    def period(self, time: float) -> float:
        """The control period: ``step_time`` if given, else the time since the last call."""
        if self.step_time is not None:
            return self.step_time
        known = self._previous_time is not None and time > self._previous_time
        dt = time - self._previous_time if known else self.first_period
        self._previous_time = time
        return dt
