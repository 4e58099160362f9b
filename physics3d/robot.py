"""The 3D tutorial's differential-drive robot: URDF loading, wheel velocity control, joint readings.

The robot is ``assets/diff_drive.urdf`` (0.3 × 0.2 × 0.1 m body of 2 kg, wheels of radius 0.05 m
on continuous joints 0.22 m apart, a rear caster, lidar and camera mounts). Its base pose is the
body's centre, above the middle of the wheel axle, so it is the unicycle pose of
:mod:`common.kinematics`.
"""

from __future__ import annotations

import math
from pathlib import Path

import pybullet as p

from common.kinematics import Pose2D, wheel_speeds
from common.robots import PROFILES, WHEEL_BASE, WHEEL_RADIUS
from common.scenario import LidarSpec, Scenario, WorldSpec

URDF_PATH = Path(__file__).parent / "assets" / "diff_drive.urdf"
SPAWN_HEIGHT = 0.08  # m: the base link's height when the wheels and the caster rest on the floor
# N·m per wheel, below the tyres' grip (μ N r ≈ 1.0 × 6 N × 0.05 m = 0.3 N·m): a motor that can
# out-torque its tyres spins them at every start and turn reversal, and wheel odometry drifts by
# metres over a warehouse crossing (measured: 0.3 N·m and up); 0.15 N·m still accelerates the
# robot at 2.5 m/s² and holds its odometry within a few centimetres.
MOTOR_FORCE = 0.15
# The robot's links are in this collision group so the lidar's rays can leave them out.
ROBOT_COLLISION_GROUP = 0b100
_WHEEL_JOINTS = ("left_wheel_joint", "right_wheel_joint")
# Inertia as written (PyBullet would recompute it from the collision shapes) and smooth wheels
# (PyBullet would otherwise tessellate URDF cylinders into faceted hulls, which bump as they roll).
_URDF_FLAGS = p.URDF_USE_INERTIA_FROM_FILE | p.URDF_USE_IMPLICIT_CYLINDER

ROBOT_PROFILE = PROFILES["physics3d"]
"""The URDF robot as a profile: its footprint (body plus wheels) and the 3D tutorial's limits."""

TEMPLATE = Scenario(name="physics3d", robot=ROBOT_PROFILE, lidar=LidarSpec(beams=36, range_max=5.0),
                    world=WorldSpec(width=10.0, height=10.0, step_time=0.1, walls=True))
"""What the 3D env's generator kinds draw scenarios around: this robot, a 36-beam 360° 5 m lidar,
a walled 10 m × 10 m world and a 0.1 s step."""


def yaw_of(quaternion: tuple[float, float, float, float]) -> float:
    """The yaw (rotation about z) of an (x, y, z, w) quaternion."""
    x, y, z, w = quaternion
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


class Robot:
    """The URDF robot in one physics client.

    PyBullet reports and resets a base by its centre of mass, which the URDF puts 4 cm behind the
    body's centre; :meth:`link_pose` converts back to the body's frame.
    """

    def __init__(self, client: int, start: Pose2D) -> None:
        self.client = client
        orientation = p.getQuaternionFromEuler((0.0, 0.0, start[2]))
        self.id = p.loadURDF(str(URDF_PATH), (start[0], start[1], SPAWN_HEIGHT), orientation, flags=_URDF_FLAGS,
                             physicsClientId=client)
        count = p.getNumJoints(self.id, physicsClientId=client)
        infos = [p.getJointInfo(self.id, j, physicsClientId=client) for j in range(count)]
        joints = {info[1].decode(): info[0] for info in infos}
        links = {info[12].decode(): info[0] for info in infos}  # a child link's index is its joint's
        self.wheels = [joints[name] for name in _WHEEL_JOINTS]
        self.camera_link = links["camera_link"]
        self.lidar_height = p.getLinkState(self.id, links["lidar_link"], computeForwardKinematics=True,
                                        physicsClientId=client)[4][2] - SPAWN_HEIGHT
        for link in [-1, *links.values()]:
            p.setCollisionFilterGroupMask(self.id, link, ROBOT_COLLISION_GROUP, 0xFFFF, physicsClientId=client)
        info = p.getDynamicsInfo(self.id, -1, physicsClientId=client)
        self._base_mass = info[0]
        local = info[3:5]
        self._com_to_link = p.invertTransform(*local)
        self.drive(0.0, 0.0)

    def drive(self, v: float, w: float) -> None:
        """Set the wheels' velocity targets for body velocity (v m/s, w rad/s)."""
        p.setJointMotorControlArray(self.id, self.wheels, p.VELOCITY_CONTROL,
                                    targetVelocities=wheel_speeds(v, w, WHEEL_RADIUS, WHEEL_BASE),
                                    forces=(MOTOR_FORCE, MOTOR_FORCE), physicsClientId=self.client)

    def set_friction(self, mu: float) -> None:
        """Set the wheels' friction coefficient with the floor (the tyres' grip)."""
        for wheel in self.wheels:
            p.changeDynamics(self.id, wheel, lateralFriction=mu, physicsClientId=self.client)

    def set_mass_scale(self, scale: float) -> None:
        """Scale the body's mass (a payload) from the URDF's."""
        p.changeDynamics(self.id, -1, mass=self._base_mass * scale, physicsClientId=self.client)

    def link_pose(self) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
        """World position and orientation of the body's frame (not its centre of mass)."""
        com = p.getBasePositionAndOrientation(self.id, physicsClientId=self.client)
        return p.multiplyTransforms(*com, *self._com_to_link)

    def velocity(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """World linear velocity of the centre of mass and angular velocity of the base."""
        return p.getBaseVelocity(self.id, physicsClientId=self.client)

    def wheel_angles(self) -> tuple[float, float]:
        """The wheels' joint angles (left, right) in radians, unwrapped (continuous joints)."""
        left, right = p.getJointStates(self.id, self.wheels, physicsClientId=self.client)
        return left[0], right[0]

    def camera_pose(self) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
        """World position and orientation of the camera mount."""
        state = p.getLinkState(self.id, self.camera_link, computeForwardKinematics=True, physicsClientId=self.client)
        return state[4], state[5]
