"""The 3D robot's sensors: a planar lidar (one ``rayTestBatch`` per scan), an RGB / depth /
segmentation camera, and an IMU. Every noise draw comes from the world's seeded generator.
"""

from __future__ import annotations

import math
import operator
from typing import Sequence

import numpy as np
import pybullet as p

from common.geometry import sensor_origin
from common.readings import Imu as ImuReading, sensed_ranges
from common.scenario import LidarSpec

GRAVITY = 9.81

Vector = Sequence[float]
Quaternion = Sequence[float]


_HIT_FRACTION = operator.itemgetter(2)  # of a rayTestBatch result: the hit's fraction of the ray


class Lidar:
    """A 2D lidar ``height`` metres above the robot's base frame, its beams level with the floor.

    The beams are :meth:`LidarSpec.beam_angles` turned by the mount's yaw, in that order, from the
    mount's (x, y) offset in the robot's frame, as in flatland. Rays skip the collision group
    ``exclude_group`` (the robot's own links). The scan stays level when the body pitches a fraction
    of a degree on its suspensionless wheels: a tilted plane would read the floor at long range.
    """

    def __init__(self, spec: LidarSpec, client: int, height: float, rng: np.random.Generator,
                 exclude_group: int) -> None:
        self.spec = spec
        self.client = client
        self.height = height
        self.rng = rng
        angles = spec.beam_angles() + spec.offset[2]
        # Each beam's reach in the base frame, (N, 3): one product with the yaw's rotation places them.
        self._reach = spec.range_max * np.column_stack((np.cos(angles), np.sin(angles), np.zeros_like(angles)))
        self._from = np.empty((spec.beams, 3))
        self._to = np.empty((spec.beams, 3))
        # Filled in place each scan: built from tuples, the rotation and origin cost a fifth of the rays' placing.
        self._rotation = np.eye(3)
        self._origin = np.empty(3)
        self._mask = 0xFFFF & ~exclude_group

    def rays(self, x: float, y: float, z: float, yaw: float) -> tuple[np.ndarray, np.ndarray]:
        """Start and end points (N, 3) of the beams for a robot base frame at (x, y, z, yaw), in
        buffers the next call overwrites."""
        origin, rotation = self._origin, self._rotation
        origin[0], origin[1] = sensor_origin(x, y, yaw, self.spec.offset[0], self.spec.offset[1])
        origin[2] = z + self.height
        rotation[0, 0] = rotation[1, 1] = math.cos(yaw)
        rotation[0, 1] = s = math.sin(yaw)
        rotation[1, 0] = -s
        self._from[:] = origin
        np.matmul(self._reach, rotation, out=self._to)
        self._to += origin
        return self._from, self._to

    def scan(self, x: float, y: float, z: float, yaw: float) -> np.ndarray:
        """Ranges in beam order (a new array each call), clipped to [range_min, range_max]."""
        hits = p.rayTestBatch(*self.rays(x, y, z, yaw), collisionFilterMask=self._mask, physicsClientId=self.client)
        ranges = np.fromiter(map(_HIT_FRACTION, hits), float, self.spec.beams)
        ranges *= self.spec.range_max  # a hit's fraction is at most 1: a miss reads range_max
        return sensed_ranges(ranges, self.spec, self.rng)


class Camera:
    """A pinhole camera: RGB (uint8), depth in metres and a segmentation image of body ids.

    ``fov`` is the vertical field of view in degrees. Pixels that see nothing read depth ``far``
    and segmentation -1.
    """

    def __init__(self, client: int, width: int = 320, height: int = 240, fov: float = 60.0, near: float = 0.05,
                 far: float = 20.0, renderer: int = p.ER_TINY_RENDERER) -> None:
        self.client = client
        self.width, self.height = width, height
        self.near, self.far = near, far
        self.renderer = renderer
        self.projection = p.computeProjectionMatrixFOV(fov, width / height, near, far)

    def from_mount(self, position: Vector, orientation: Quaternion) -> dict[str, np.ndarray]:
        """An image from a mount looking along its x axis, its z axis up."""
        m = p.getMatrixFromQuaternion(orientation)
        forward, up = (m[0], m[3], m[6]), (m[2], m[5], m[8])
        target = [a + b for a, b in zip(position, forward)]
        return self.capture(p.computeViewMatrix(position, target, up))

    def look_at(self, eye: Vector, target: Vector, segmentation: bool = True) -> dict[str, np.ndarray]:
        """An image from ``eye`` towards ``target``, world z up."""
        return self.capture(p.computeViewMatrix(eye, target, (0.0, 0.0, 1.0)), segmentation)

    def capture(self, view: Sequence[float], segmentation: bool = True) -> dict[str, np.ndarray]:
        """Render one frame for a view matrix: ``rgb`` (H, W, 3), ``depth`` (H, W) and ``segmentation`` (H, W)."""
        flags = 0 if segmentation else p.ER_NO_SEGMENTATION_MASK
        _, _, rgba, zbuffer, mask = p.getCameraImage(self.width, self.height, view, self.projection, flags=flags,
                                                     renderer=self.renderer, physicsClientId=self.client)
        rgb = np.ascontiguousarray(np.reshape(rgba, (self.height, self.width, 4))[..., :3], dtype=np.uint8)
        # The z-buffer holds OpenGL's non-linear depth in [0, 1]; invert the projection for metres.
        z = np.reshape(zbuffer, (self.height, self.width)).astype(np.float32)
        depth = self.far * self.near / (self.far - (self.far - self.near) * z)
        out = {"rgb": rgb, "depth": np.clip(depth, self.near, self.far, out=depth)}  # float32 rounding overshoots far
        if segmentation:
            out["segmentation"] = np.reshape(mask, (self.height, self.width)).astype(np.int32)
        return out


def _rotate_into(q: Quaternion, v: Vector) -> tuple[float, float, float]:
    """Vector ``v`` (world frame) expressed in the frame of orientation ``q`` (x, y, z, w)."""
    x, y, z, w = -q[0], -q[1], -q[2], q[3]  # the inverse rotation
    tx, ty, tz = 2.0 * (y * v[2] - z * v[1]), 2.0 * (z * v[0] - x * v[2]), 2.0 * (x * v[1] - y * v[0])
    return (v[0] + w * tx + y * tz - z * ty, v[1] + w * ty + z * tx - x * tz, v[2] + w * tz + x * ty - y * tx)


class Imu:
    """An IMU at the base's centre of mass: accelerometer (specific force, so gravity reads +9.81
    m/s² up at rest) and gyroscope, in the body frame, each axis with Gaussian noise; the gyroscope
    also carries a bias per axis, the episode's (:meth:`reset`; drawn by the world's conditions).

    The acceleration is the change of the base's velocity over the last control period: what a
    real IMU averaged over that period would report. :meth:`turned` is the gyroscope's yaw rate
    integrated over the period, as IMU drivers integrate their high-rate samples.
    """

    def __init__(self, rng: np.random.Generator, accel_noise: float = 0.0, gyro_noise: float = 0.0) -> None:
        self.rng = rng
        self.accel_noise, self.gyro_noise = accel_noise, gyro_noise
        self.bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._previous: Vector = (0.0, 0.0, 0.0)

    def reset(self, bias: Vector = (0.0, 0.0, 0.0), velocity: Vector = (0.0, 0.0, 0.0)) -> None:
        """Start an episode with this gyroscope bias per axis (rad/s), forgetting the last velocity."""
        self.bias, self._previous = bias, velocity

    def turned(self, yaw_change: float, dt: float) -> float:
        """The yaw change (rad) the gyroscope measured over a period ``dt`` in which the body turned
        by ``yaw_change``: its mean rate carries the bias and one reading's noise."""
        noise = self.rng.normal(0.0, self.gyro_noise) if self.gyro_noise > 0.0 else 0.0
        return yaw_change + (self.bias[2] + noise) * dt

    def read(self, orientation: Quaternion, velocity: Vector, angular_velocity: Vector, dt: float) -> ImuReading:
        """The reading after a period ``dt`` that ended with these base orientation and velocities."""
        inv = 1.0 / dt if dt > 0.0 else 0.0
        (vx, vy, vz), (px, py, pz) = velocity, self._previous
        specific = ((vx - px) * inv, (vy - py) * inv, (vz - pz) * inv + GRAVITY)
        self._previous = velocity
        (ax, ay, az), (gx, gy, gz) = _rotate_into(orientation, specific), _rotate_into(orientation, angular_velocity)
        # Element by element, not by generator: this runs every control period.
        if self.accel_noise > 0.0 or self.gyro_noise > 0.0:
            n = self.rng.normal(0.0, 1.0, 6).tolist()
            a, g = self.accel_noise, self.gyro_noise
            ax, ay, az = ax + a * n[0], ay + a * n[1], az + a * n[2]
            gx, gy, gz = gx + g * n[3], gy + g * n[4], gz + g * n[5]
        bx, by, bz = self.bias
        if bx or by or bz:
            gx, gy, gz = gx + bx, gy + by, gz + bz
        return ImuReading((ax, ay, az), (gx, gy, gz))
