"""What a world reports after each step: the same record for both tiers."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from common.kernel_cache import kernel
from common.kinematics import Pose2D

if TYPE_CHECKING:
    from common.motion.movers import MoverStates
    from common.scenario import LidarSpec, RobotProfile


class Odometry(NamedTuple):
    """Odometry estimate: dead-reckoned pose and body velocity (v m/s, w rad/s). The speed comes
    from the wheels; the heading and w from the wheels too, or from a gyroscope where the world
    takes them from one (physics3d's ``heading_source="gyro"``)."""

    pose: Pose2D
    v: float
    w: float


class Imu(NamedTuple):
    """Inertial readings in the body frame: linear acceleration (m/s², x y z) and angular velocity (rad/s, x y z)."""

    linear_acceleration: tuple[float, float, float]
    angular_velocity: tuple[float, float, float]


class Contact(NamedTuple):
    """What the robot touched in a step: ``"static"`` geometry or a ``"mover"`` (``mover``: its row
    in ``Readings.movers``), and who moved into whom (``by``: ``"robot"`` if the robot's outline
    closed on the mover, at least as fast as the mover closed on it, else ``"mover"``; always
    ``"robot"`` for static)."""

    kind: str
    mover: int
    by: str


def mover_fault(pose: tuple[float, float, float], motion: tuple[float, float, float], mover: np.ndarray,
                robot: RobotProfile) -> str:
    """Who moved into whom (:attr:`Contact.by`) when ``robot`` (a circle or a box) at ``pose``,
    moving at ``motion`` (forward m/s, sideways m/s, turn rad/s), touched ``mover`` (a row of
    ``Readings.movers``): the robot, if the point of its outline nearest the mover's centre closed
    on it, turning included (a box's corners sweep as it turns), at least as fast as the mover's
    centre closed on the robot; else the mover. A mover's own turn is not known (a forklift
    turning in place sweeps its ends with its centre standing still), so a robot that did not
    close on it is never at fault."""
    x, y, yaw = pose
    v, lateral, w = motion
    c, s = math.cos(yaw), math.sin(yaw)
    px, py = x + robot.footprint_offset * c, y + robot.footprint_offset * s  # the footprint's centre
    # A box is judged at its point nearest the mover's centre (where that lies outside it); a circle
    # at its centre, as turning moves no point of a circle's outline towards or away from anything.
    half_length, half_width = 0.5 * robot.length, 0.5 * robot.width
    du, dv = c * (mover[0] - px) + s * (mover[1] - py), -s * (mover[0] - px) + c * (mover[1] - py)  # robot frame
    if robot.shape == "box" and (abs(du) > half_length or abs(dv) > half_width):
        du, dv = min(max(du, -half_length), half_length), min(max(dv, -half_width), half_width)
        px, py = px + c * du - s * dv, py + s * du + c * dv
    dx, dy = mover[0] - px, mover[1] - py
    distance = math.hypot(dx, dy)
    if distance < 1e-9:  # the two centres together: no direction between them
        return "robot" if math.hypot(v, lateral) >= math.hypot(mover[3], mover[4]) else "mover"
    vx = v * c - lateral * s - w * (py - y)  # the point's velocity: the robot's, turning about its pose
    vy = v * s + lateral * c + w * (px - x)
    robot_closing = (vx * dx + vy * dy) / distance
    mover_closing = -(mover[3] * dx + mover[4] * dy) / distance
    return "robot" if robot_closing > 0.0 and robot_closing >= mover_closing else "mover"


class Readings(NamedTuple):
    """One snapshot of a world: later steps never change it (immutable fields, read-only arrays;
    a NamedTuple because one is built every env step and it is the cheapest immutable record).

    Attributes:
        pose: the true pose (ground truth, for metrics and rewards; controllers use ``odometry``).
        velocity: the true body velocity (v, w) during the last step.
        odometry: the odometry estimate (wheels, and in 3D the gyroscope's heading by default).
        lidar: ranges in metres, in the sensor's beam order.
        imu: inertial readings.
        collided: whether the robot touched an obstacle or a wall in the last step.
        time: simulated seconds since reset.
        camera: RGB, depth and segmentation images where a tier has a camera, else None.
        movers: where the moving obstacles are (ground truth, for metrics and drawing; a
            controller sees them only through the lidar), or None in a world without any.
        contact: what the robot touched this step, in a world with movers (else None).
    """

    pose: Pose2D
    velocity: tuple[float, float]
    odometry: Odometry
    lidar: np.ndarray
    imu: Imu
    collided: bool
    time: float
    camera: dict[str, np.ndarray] | None = None
    movers: "MoverStates | None" = None
    contact: Contact | None = None


def sensed_ranges(ranges: np.ndarray, spec: LidarSpec, rng: np.random.Generator) -> np.ndarray:
    """What a lidar of ``spec`` makes of exact ranges (at most ``range_max``, a miss reading
    ``range_max``), in place, alike in every tier: Gaussian noise on the returns only (a beam that
    hit nothing keeps reading range_max, as IR-SIM's does), one draw per return in beam order,
    then the range limits."""
    if spec.noise_std > 0.0:
        noise = rng.normal(0.0, spec.noise_std, _returns(ranges, spec.range_max))
        _add_to_returns(ranges, noise, spec.range_max, spec.range_min)
    elif spec.range_min > 0.0:
        np.maximum(ranges, spec.range_min, out=ranges)
    return ranges


@kernel
def _returns(ranges: np.ndarray, range_max: float) -> int:
    """How many beams returned (read less than ``range_max``)."""
    count = 0
    for value in ranges:
        count += value < range_max
    return count


@kernel
def _add_to_returns(ranges: np.ndarray, noise: np.ndarray, range_max: float, range_min: float) -> None:
    """Add ``noise`` to the returns in beam order, then keep every range within [range_min,
    range_max] (noise may push a return past either). One call: NumPy's mask, scatter and two
    clips took a fiftieth of the 3D env's step."""
    k = 0
    for i in range(ranges.shape[0]):
        if ranges[i] < range_max:
            ranges[i] += noise[k]
            k += 1
        ranges[i] = max(min(ranges[i], range_max), range_min)


def frozen(array: np.ndarray) -> np.ndarray:
    """Mark an array the caller owns as read-only, so a Readings holding it stays a snapshot."""
    array.setflags(write=False)  # 0.2 µs where ``flags.writeable`` took 0.4: once a step in every tier
    return array


@kernel
def nearest_clearance(ranges: np.ndarray, reach: np.ndarray) -> float:
    """The robot's clearance: the smallest range less how far its beam runs inside the footprint
    (:func:`common.robots.footprint_reach`)."""
    nearest = math.inf
    for i in range(ranges.shape[0]):
        nearest = min(nearest, ranges[i] - reach[i])
    return nearest


@kernel
def nearest_return(ranges: np.ndarray) -> float:
    """The smallest range of a scan (inf for none): ``ranges.min()`` costs five times more per step."""
    nearest = math.inf
    for value in ranges:
        nearest = min(nearest, value)
    return nearest
