"""Optimal reciprocal collision avoidance (van den Berg, Guy, Lin and Manocha 2011) for one
differential-drive robot among movers it tracks with its lidar.

Each tracked mover (:mod:`common.controllers.tracking`) and each static return gives a velocity
obstacle: the robot velocities that bring the robot's disc (widened by ``margin``) into it within
the time horizon, at the mover's estimated velocity (zero for a return). ORCA replaces each by
the half-plane bounded at the obstacle's nearest edge to the current velocity, shifted by the
``responsibility`` share of the way out. The robot takes all of it by default: it cannot tell a
person who yields from one who does not, nor does a wall yield, and half (RVO2's reciprocal
share, for agents that all run ORCA) leaves it in the way of anyone who does not. The velocity
driven is the sampled one, in the speed disc, that satisfies every half-plane and lies nearest the
preferred one (at full speed, slower within a metre or so of the goal, toward a point ahead on
the guide's path: the goal itself when nothing static stands in the way,
:mod:`common.controllers.waypoint`); when none does, the one that keeps to the static returns'
half-planes and violates the movers' least (RVO2's fallback, which relaxes agents' lines, never
obstacles'). A heading controller turns that holonomic
velocity into (v, w): it turns toward it, driving at its speed times the cosine of the heading
error, and on the spot beyond ``turn_in_place``.
"""

from __future__ import annotations

import math

import numpy as np

from common.controllers.go_to_goal import goal_polar
from common.controllers.local import LocalController
from common.kinematics import wrap_angle
from common.readings import Readings


def orca_half_planes(velocity: np.ndarray, offsets: np.ndarray, velocities: np.ndarray, radii: np.ndarray,
                     horizons: np.ndarray, step: float, responsibility: float) -> tuple[np.ndarray, np.ndarray]:
    """Each obstacle's ORCA half-plane, as RVO2 builds it: (points, directions), both (K, 2); the
    velocities allowed lie left of ``points[k] + t·directions[k]``.

    ``offsets``: obstacle centre minus robot centre; ``radii``: the combined radii; ``horizons``
    (K,): how far ahead a collision counts, s; ``step``: the control period, within which
    overlapping discs must separate.
    """
    relative = velocity - velocities
    distance_sq = np.einsum("ij,ij->i", offsets, offsets)
    radius_sq = radii**2
    apart = distance_sq > radius_sq
    # Apart: the obstacle is a cone cut off by a circle of radius r/horizon; overlapping: of r/step.
    scale = np.where(apart, 1.0 / horizons, 1.0 / step)
    w = relative - scale[:, None] * offsets
    w_length = np.maximum(np.hypot(w[:, 0], w[:, 1]), 1e-12)
    dot = np.einsum("ij,ij->i", w, offsets)
    on_circle = ~apart | ((dot < 0.0) & (dot**2 > radius_sq * w_length**2))
    unit = w / w_length[:, None]
    circle_direction = np.column_stack([unit[:, 1], -unit[:, 0]])
    circle_u = (radii * scale - w_length)[:, None] * unit
    # Nearest a leg of the cone: the left one if the relative velocity passes left of the centre.
    leg = np.sqrt(np.maximum(distance_sq - radius_sq, 0.0))
    x, y = offsets[:, 0], offsets[:, 1]
    left = x * w[:, 1] - y * w[:, 0] > 0.0
    leg_direction = np.where(left[:, None], np.column_stack([x * leg - y * radii, x * radii + y * leg]),
                             -np.column_stack([x * leg + y * radii, -x * radii + y * leg]))
    leg_direction /= np.maximum(distance_sq, 1e-12)[:, None]
    leg_u = np.einsum("ij,ij->i", relative, leg_direction)[:, None] * leg_direction - relative
    directions = np.where(on_circle[:, None], circle_direction, leg_direction)
    u = np.where(on_circle[:, None], circle_u, leg_u)
    return velocity + responsibility * u, directions


def nearest_admissible(preferred: np.ndarray, points: np.ndarray, directions: np.ndarray, hard: np.ndarray,
                       candidates: np.ndarray) -> np.ndarray:
    """The candidate (C, 2) within every half-plane nearest ``preferred``. If none is: of those
    within the ``hard`` (L,) ones, the one whose worst violation of the others is least (RVO2
    never relaxes an obstacle's line either); if none is within those, the least violating them."""
    # How far each candidate lies right of each line (positive: outside the half-plane).
    outside = (directions[None, :, 0] * (points[None, :, 1] - candidates[:, None, 1])
               - directions[None, :, 1] * (points[None, :, 0] - candidates[:, None, 0]))
    worst_hard = outside[:, hard].max(axis=1, initial=0.0)
    worst_soft = outside[:, ~hard].max(axis=1, initial=0.0)
    admissible = (worst_hard <= 0.0) & (worst_soft <= 0.0)
    if admissible.any():
        return candidates[int(np.argmin(np.where(admissible, np.hypot(*(candidates - preferred).T), np.inf)))]
    if (worst_hard <= 0.0).any():
        return candidates[int(np.argmin(np.where(worst_hard <= 0.0, worst_soft, np.inf)))]
    return candidates[int(np.argmin(worst_hard))]


class VelocityObstacle(LocalController):
    """ORCA among tracked movers and static returns, driven by a heading controller (see the module).

    Args:
        time_horizon: how far ahead a mover's collision counts, s (2.0).
        static_horizon: the same for static returns, s (1.0): shorter, so that walls do not keep
            the robot from driving up to a goal beside them.
        responsibility: the share of the avoidance the robot takes (1.0: all; 0.5: RVO2's reciprocal half).
        margin: added to the robot's radius, m (0.1): the heading controller lags the chosen velocity.
        neighbor_distance: returns and movers further than this from the robot's edge are ignored, m (3.0).
        speed_samples, direction_samples: the candidate velocities' polar grid (5, 36), plus the
            preferred velocity and standing still.
        lookahead: the preferred velocity aims at the path this far beyond the robot, m (0.8).
        k_linear: preferred speed per metre of path to the goal, 1/s (1.0), up to v_max.
        k_angular: turning gain on the heading error, 1/s (2.0).
        turn_in_place: heading error beyond which the robot turns on the spot, rad (pi/3).
        track_movers: estimate movers' velocities (True); False: every return is static.
        guide: prefer following a path round the static returns (True); False: the straight line to the goal.
        stop_distance: within this many metres of the goal (by odometry), stand still; None (default):
            half the scenario's goal threshold.
        step_time: control period, s; None infers it from successive ``readings.time`` (None).
    """

    name = "orca"

    def __init__(self, time_horizon: float = 2.0, static_horizon: float = 1.0, responsibility: float = 1.0,
                 margin: float = 0.1, neighbor_distance: float = 3.0, speed_samples: int = 5,
                 direction_samples: int = 36, lookahead: float = 0.8, k_linear: float = 1.0, k_angular: float = 2.0,
                 turn_in_place: float = math.pi / 3, track_movers: bool = True, guide: bool = True,
                 stop_distance: float | None = None, step_time: float | None = None) -> None:
        self.time_horizon, self.static_horizon = time_horizon, static_horizon
        self.responsibility, self.margin, self.neighbor_distance = responsibility, margin, neighbor_distance
        self.speed_samples, self.direction_samples = speed_samples, direction_samples
        self.lookahead, self.k_linear = lookahead, k_linear
        self.k_angular, self.turn_in_place = k_angular, turn_in_place
        self.track_movers, self.guide = track_movers, guide
        self.stop_distance = stop_distance
        self.step_time = step_time

    def act(self, readings: Readings, goal: tuple[float, float]) -> tuple[float, float]:
        distance, _, _ = goal_polar(readings, goal)
        if self.arrived(distance, self.stop_distance):
            return 0.0, 0.0
        scene = self.scene(readings)
        x, y, yaw = readings.odometry.pose
        path = self.path(readings, scene, goal)
        along, off = path.locate(np.array([[x, y]]))
        heading = path.ahead(along, self.lookahead)[0] - np.array([x, y])
        speed = min(self.robot.v_max, self.k_linear * float(path.length - along[0] + off[0]))
        preferred = speed * heading / max(float(np.hypot(*heading)), 1e-9)
        velocity = readings.odometry.v * np.array([math.cos(yaw), math.sin(yaw)])
        # Obstacles: movers at their velocities, then static returns (zero radius, zero velocity).
        centres = np.vstack([scene.centres, scene.static]) - np.array([x, y])
        radii = np.concatenate([scene.radii, np.zeros(len(scene.static))]) + self.robot.bounding_radius + self.margin
        velocities = np.vstack([scene.velocities, np.zeros_like(scene.static)])
        horizons = np.r_[np.full(len(scene.centres), self.time_horizon), np.full(len(scene.static), self.static_horizon)]
        near = np.hypot(centres[:, 0], centres[:, 1]) - radii < self.neighbor_distance
        points, directions = orca_half_planes(velocity, centres[near], velocities[near], radii[near], horizons[near],
                                              self.period(readings.time), self.responsibility)
        static = np.r_[np.zeros(len(scene.centres), bool), np.ones(len(scene.static), bool)][near]
        chosen = nearest_admissible(preferred, points, directions, static, self.candidates(preferred))
        return self.clip(*self.steer(chosen, yaw))

    def candidates(self, preferred: np.ndarray) -> np.ndarray:
        """The preferred velocity, standing still, and a polar grid over the speed disc."""
        speeds = self.robot.v_max * np.arange(1, self.speed_samples + 1) / self.speed_samples
        angles = 2.0 * math.pi * np.arange(self.direction_samples) / self.direction_samples
        grid = (speeds[:, None, None] * np.stack([np.cos(angles), np.sin(angles)], axis=-1)[None]).reshape(-1, 2)
        return np.vstack([preferred, np.zeros(2), grid])

    def steer(self, velocity: np.ndarray, yaw: float) -> tuple[float, float]:
        """(v, w) for a differential drive to follow a holonomic ``velocity``."""
        speed = float(np.hypot(*velocity))
        if speed < 1e-6:
            return 0.0, 0.0
        error = wrap_angle(math.atan2(velocity[1], velocity[0]) - yaw)
        v = speed * math.cos(error) if abs(error) <= self.turn_in_place else 0.0
        return v, self.k_angular * error
