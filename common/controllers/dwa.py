"""The dynamic window approach (Fox, Burgard and Thrun 1997; ROS's base_local_planner), among movers.

Each step: the (v, w) the robot can reach within one control period (its acceleration limits
about its odometry velocity, within v in [0, v_max] and w in [-w_max, w_max]) are sampled on a
grid; each is rolled out as an arc for ``horizon`` seconds and checked against the static
returns and against the tracked movers (:mod:`common.controllers.tracking`), each moved at its
constant velocity to the rollout's time. Among the admissible arcs the best-scoring one is
driven: progress along the guide's path (:mod:`common.controllers.waypoint`; as ROS's local
planner follows a global plan), heading along it at the arc's end, clearance and speed, weighted.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from common.controllers.go_to_goal import goal_polar
from common.controllers.local import LocalController
from common.controllers.tracking import Scene
from common.controllers.waypoint import Path
from common.readings import Readings
from common.scenario import LidarSpec, RobotProfile


def wrap(angle: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-pi, pi), elementwise."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def arcs(pose: tuple[float, float, float], v: np.ndarray, w: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Poses (S, T, 3) along the arcs of constant (v[s], w[s]) from ``pose`` at ``times`` (T,)."""
    x, y, yaw = pose
    turn = w[:, None] * times[None]
    chord = v[:, None] * times[None] * np.sinc(turn / (2.0 * math.pi))  # exact arc, straight when w = 0
    along = yaw + 0.5 * turn
    return np.stack([x + chord * np.cos(along), y + chord * np.sin(along), yaw + turn], axis=-1)


def first_contact(gaps: np.ndarray, margin: float, times: np.ndarray) -> np.ndarray:
    """(S,) the first of ``times`` at which each row of ``gaps`` (S, T) falls below ``margin`` (inf if never)."""
    close = gaps < margin
    return np.where(close.any(axis=1), times[close.argmax(axis=1)], np.inf)


def clearances(points: np.ndarray, scene: Scene, times: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """(S, T) gaps between the robot's disc at ``points`` (S, T, 2) and the nearest static return,
    and the nearest mover moved at constant velocity to ``times`` (T,)."""
    static = np.full(points.shape[:2], np.inf)
    movers = np.full(points.shape[:2], np.inf)
    if len(scene.static):
        # The nearest return by a k-d tree, its gap as before: every arc point against every return
        # took a quarter of the controller's time on a 360-beam scan.
        flat = points.reshape(-1, 2)
        offsets = flat - scene.static[cKDTree(scene.static).query(flat)[1]]
        static = np.hypot(offsets[:, 0], offsets[:, 1]).reshape(points.shape[:2])
    if len(scene.centres):
        offsets = points[:, :, None, :] - scene.centres_at(times)[None]
        movers = (np.hypot(offsets[..., 0], offsets[..., 1]) - scene.radii).min(axis=2)
    return static - radius, movers - radius


class DynamicWindow(LocalController):
    """Sample the dynamic window, roll out arcs among predicted movers, drive the best admissible one.

    Score of an arc: progress_weight·(cost to go now − at its end)/(v_max·horizon), the cost to go
    from a point being the path left beyond its projection plus its distance off the path (all
    of it gained by an arc that reaches the goal) + heading_weight·(1 − |e_end|/pi), e_end the
    heading error at its end toward the path ``lookahead`` further on +
    clearance_weight·min(clearance, clearance_cap)/clearance_cap + velocity_weight·cos(e)·v/v_max,
    e that heading error now (so a forward-only robot with its way behind turns on the spot rather
    than driving a wide loop) − mover_weight·(1 − t/horizon), t when it first meets a predicted
    mover (none: no penalty).

    An arc that comes within ``margin`` of a static return is not admissible, nor is one that meets
    a predicted mover within ``mover_horizon``: a later meeting is a risk the score weighs (the
    mover may turn), not a certainty. When no arc is admissible, the one whose first contact comes
    latest is driven among those clear of static returns (a wall will be there, a mover may turn),
    the most clearance breaking ties: braking, turning in place or getting out of a mover's way,
    whichever that is.

    Args:
        horizon: how far ahead each arc is checked, s (2.0).
        rollout_step: seconds between checked poses along an arc (0.1).
        v_samples, w_samples: grid points across the window in v and in w (7, 15).
        accel_v, accel_w: the window's half-widths per second of control period, m/s², rad/s², where
            the robot's profile sets no finite limit (5.0, 10.0: at 0.1 s, half the speed range and
            the whole turn range of the default robot, which can change both at once).
        heading_weight, progress_weight, clearance_weight, velocity_weight: the score's weights
            (0.3, 1.0, 0.5, 0.2).
        clearance_cap: clearance beyond which more is no better, m (1.0).
        margin: the least clearance an admissible arc keeps, m (0.05).
        mover_horizon: an arc meeting a predicted mover sooner than this is not admissible, s (1.5).
        mover_weight: the score's penalty for meeting one at once, falling to 0 at the horizon (1.0).
        lookahead: the heading term aims at the path this far beyond an arc's end, m (1.0).
        track_movers: predict the tracked movers (True); False: every return is static (the bare DWA).
        guide: follow a path round the static returns (True); False: the straight line to the goal.
        stop_distance: within this many metres of the goal (by odometry), stand still; None (default):
            half the scenario's goal threshold.
        step_time: control period, s; None infers it from successive ``readings.time`` (None).
    """

    name = "dwa"

    def __init__(self, horizon: float = 2.0, rollout_step: float = 0.1, v_samples: int = 7, w_samples: int = 15,
                 accel_v: float = 5.0, accel_w: float = 10.0, heading_weight: float = 0.3, progress_weight: float = 1.0,
                 clearance_weight: float = 0.5, velocity_weight: float = 0.2, clearance_cap: float = 1.0,
                 margin: float = 0.05, mover_horizon: float = 1.5, mover_weight: float = 1.0,
                 lookahead: float = 1.0, track_movers: bool = True, guide: bool = True,
                 stop_distance: float | None = None, step_time: float | None = None) -> None:
        self.horizon, self.rollout_step = horizon, rollout_step
        self.v_samples, self.w_samples = v_samples, w_samples
        self.accel_v, self.accel_w = accel_v, accel_w
        self.heading_weight, self.progress_weight = heading_weight, progress_weight
        self.clearance_weight, self.velocity_weight = clearance_weight, velocity_weight
        self.clearance_cap, self.margin, self.lookahead = clearance_cap, margin, lookahead
        self.mover_horizon, self.mover_weight = mover_horizon, mover_weight
        self.track_movers, self.guide = track_movers, guide
        self.stop_distance = stop_distance
        self.step_time = step_time

    def bind(self, robot: RobotProfile, lidar: LidarSpec, goal_threshold: float = 0.3) -> None:
        super().bind(robot, lidar, goal_threshold)
        self.times = self.rollout_step * np.arange(1, max(1, round(self.horizon / self.rollout_step)) + 1)

    def act(self, readings: Readings, goal: tuple[float, float]) -> tuple[float, float]:
        distance, _, _ = goal_polar(readings, goal)
        if self.arrived(distance, self.stop_distance):
            return 0.0, 0.0
        scene = self.scene(readings)
        pose = readings.odometry.pose
        path = self.path(readings, scene, goal)
        v, w = self.window(readings)
        poses = arcs(pose, v, w, self.times)
        static, movers = clearances(poses[..., :2], scene, self.times, self.robot.bounding_radius)
        gap = np.minimum(static, movers)
        meets_static = first_contact(static, self.margin, self.times)
        meets_mover = first_contact(movers, self.margin, self.times)
        score = self.score(pose, poses, gap, v, np.asarray(goal, float), path)
        score -= self.mover_weight * np.clip(1.0 - meets_mover / self.times[-1], 0.0, 1.0)
        admissible = np.isinf(meets_static) & (meets_mover > self.mover_horizon)
        if admissible.any():
            best = int(np.argmax(np.where(admissible, score, -np.inf)))
        else:  # clear of static returns (a wall is certain, a mover's course not), the latest contact, the most clearance
            best = int(np.lexsort((gap.min(axis=1), np.minimum(meets_static, meets_mover), np.isinf(meets_static)))[-1])
        return self.clip(float(v[best]), float(w[best]))

    def window(self, readings: Readings) -> tuple[np.ndarray, np.ndarray]:
        """The sampled (v, w) pairs, flat: a grid over what one control period's acceleration reaches."""
        dt = self.period(readings.time)
        robot = self.robot
        reach_v = (robot.accel_v if math.isfinite(robot.accel_v) else self.accel_v) * dt
        reach_w = (robot.accel_w if math.isfinite(robot.accel_w) else self.accel_w) * dt
        v0, w0 = readings.odometry.v, readings.odometry.w
        slowest, turn_low = max(0.0, robot.v_min), robot.w_low  # forward only, within the robot's own limits
        v_low, v_high = max(slowest, min(v0 - reach_v, robot.v_max)), min(robot.v_max, max(v0 + reach_v, slowest))
        w_low, w_high = max(turn_low, min(w0 - reach_w, robot.w_max)), min(robot.w_max, max(w0 + reach_w, turn_low))
        ws = np.linspace(w_low, w_high, self.w_samples)
        if w_low < 0.0 < w_high:  # driving straight is always among the choices
            ws = np.union1d(ws, [0.0])
        v, w = np.meshgrid(np.linspace(v_low, v_high, self.v_samples), ws, indexing="ij")
        return v.ravel(), w.ravel()

    def score(self, pose: tuple[float, float, float], poses: np.ndarray, gap: np.ndarray, v: np.ndarray,
              goal: np.ndarray, path: Path) -> np.ndarray:
        """(S,) the weighted score of each arc along ``path`` (see the class)."""
        # Cost to go from a point: the path left beyond its projection, plus its distance off the path.
        along, off = path.locate(np.vstack([pose[:2], poses[:, -1, :2]]))
        cost = path.length - along + off
        # An arc that reaches the goal would stop there: it has done all it must, whatever follows.
        reaches = self.arrived(np.hypot(*(goal - poses[..., :2]).transpose(2, 0, 1)), self.stop_distance).any(axis=1)
        progress = (cost[0] - np.where(reaches, 0.0, cost[1:])) / (self.robot.v_max * self.times[-1])
        carrot = path.ahead(along, self.lookahead) - np.vstack([pose[:2], poses[:, -1, :2]])
        error = wrap(np.arctan2(carrot[:, 1], carrot[:, 0]) - np.r_[pose[2], poses[:, -1, 2]])
        heading = np.where(reaches, 1.0, 1.0 - np.abs(error[1:]) / math.pi)
        clearance = np.minimum(gap.min(axis=1), self.clearance_cap) / self.clearance_cap
        toward = math.cos(error[0])
        return (self.heading_weight * heading + self.progress_weight * progress
                + self.clearance_weight * clearance + self.velocity_weight * toward * v / self.robot.v_max)
