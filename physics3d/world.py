"""The physics3d world: a scenario's warehouse and the URDF robot in a PyBullet client of its own.

Physics runs at 240 Hz; each control step holds the wheel velocity targets for
``round(control_period × 240)`` sub-steps. The robot drives by its wheels' friction (it can slip,
bump and be pushed), unlike flatland's kinematic robot, and a collision is any contact between the
robot and anything but the floor. ``reset``/``step`` return the same :class:`Readings` as flatland.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import math
import os
import sys
import numpy as np
import pybullet as p

from common.actuation import Actuator
from common.conditions import Conditions
from common.errors import ConfigError, quote
from common.kinematics import Pose2D, WheelOdometry, nan_command, unicycle_exact, wrap_angle
from common.motion.movers import mover_generator
from common.readings import Contact, Odometry, Readings, frozen, mover_fault
from common.scenario import RobotProfile, Scenario
from physics3d.robot import ROBOT_COLLISION_GROUP, WHEEL_BASE, WHEEL_RADIUS, Robot, yaw_of
from physics3d.sensors import GRAVITY, Camera, Imu, Lidar, Quaternion, Vector
from physics3d.movers import MovingBodies
from physics3d.warehouse import Tag, Warehouse, build

PHYSICS_HZ = 240
# Ten solver iterations instead of PyBullet's fifty: the robot still tracks (v, w) within about 1 %
# and a step costs about 30 % less.
SOLVER_ITERATIONS = 10
SETTLE_SUBSTEPS = 24  # at build: let the robot sink into its contacts before the start state is saved
# A contact point nearer than this counts as touching. Bullet keeps manifold points until they
# separate by 2 cm, so a robot that has just slid past a box still lists it for a few sub-steps.
TOUCH_DISTANCE = 1e-3  # m
# The robot's reach from its centre (half its 0.3 x 0.22 m footprint's diagonal, wheels included,
# rounded up), and a margin beyond its travel in a period.
ROBOT_REACH, REACH_MARGIN = 0.25, 0.1  # m
# How near the robot may come to a body before contacts with it are polled: well above the touch
# distance and Bullet's error in a closest distance.
CONTACT_SLACK = 0.02  # m
# The robot's body frame (position, orientation) and its base's (linear, angular) velocity.
BodyState = tuple[tuple[Vector, Quaternion], tuple[Vector, Vector]]


def _speed_along(linear: Vector, yaw: float) -> float:
    """The speed of a body moving at ``linear`` (world frame) along heading ``yaw``."""
    return linear[0] * math.cos(yaw) + linear[1] * math.sin(yaw)


def refuse_unmodelled(scenario: Scenario) -> None:
    """A one-line error for what this tier cannot build: IR-SIM's ``unobstructed`` collision mode
    (here the robot collides with what it touches; a world that loaded and then behaved otherwise
    would be wrong without a word). ``unobstructed_obstacles`` is modelled: the robot stops on a
    contact, as in ``stop``, and the movers pass on as :mod:`common.motion` moves them. The robot
    is the URDF's differential drive: a scenario's car or omnidirectional robot is refused, and so
    are IR-SIM's motion noise and static robot."""
    if scenario.robot.kinematics != "diff":
        raise ConfigError(None, "robot.kinematics", f"the 3D robot is a differential drive, not "
                          f"{quote(scenario.robot.kinematics)}; allowed: diff")
    if scenario.grid_map is not None:
        raise ConfigError(None, "grid_map", "an occupancy grid map is not built in the 3D tier; allowed: null")
    if scenario.robot.shape in ("polygon", "compound"):
        raise ConfigError(None, "robot.shape", "the 3D robot's body is the URDF's box; allowed: circle, box")
    for field, value in (("motion_noise", scenario.robot.motion_noise), ("static", scenario.robot.static or None)):
        if value is not None:
            raise ConfigError(None, f"robot.{field}", "IR-SIM's kinematic stand-in is not modelled in the 3D tier, "
                              "whose robot moves by physics; allowed: null (motion_noise), false (static)")
    if scenario.world.collision_mode == "unobstructed":
        raise ConfigError(None, "world.collision_mode", "'unobstructed' is not modelled in the 3D tier; "
                          "allowed: stop, unobstructed_obstacles")


def refuse_without_display() -> None:
    """A RuntimeError unless the X display PyBullet's GUI would open answers: without DISPLAY the
    GUI waits forever, and with one that does not answer (a stale DISPLAY over ssh) it ends the
    whole process with exit code 1, no exception to catch."""
    name = os.environ.get("DISPLAY")
    if not name:
        raise RuntimeError("the PyBullet GUI needs an X display (DISPLAY is not set); try xvfb-run")
    library = ctypes.util.find_library("X11")
    if library is None:
        raise RuntimeError("the PyBullet GUI needs the X11 library (libX11), which is not installed")
    x11 = ctypes.CDLL(library)
    x11.XOpenDisplay.restype, x11.XOpenDisplay.argtypes = ctypes.c_void_p, [ctypes.c_char_p]
    x11.XCloseDisplay.argtypes = [ctypes.c_void_p]
    display = x11.XOpenDisplay(name.encode())
    if not display:
        raise RuntimeError(f"the PyBullet GUI cannot open the X display {name!r} (DISPLAY); try xvfb-run")
    x11.XCloseDisplay(display)


MAX_SPEED = 2.0  # m/s
MAX_TURN_ACCELERATION = 4.0  # m/s²: v_max * w_max
"""What the URDF robot's wheels hold on the warehouse floor, with a margin. Measured (2026-11-29,
20 steps to settle, then the mean of 10; friction, mass and motor gain at 1): it drives 2.5 m/s
straight and spins out at 3 (0.2 m/s, -8.9 rad/s); it turns 2 m/s at 2 rad/s (4 m/s²) and 1.5 m/s
at 3 rad/s, and spins out at 2 m/s and 2.5 rad/s (5 m/s²) or 1 m/s and 6 rad/s."""


def refuse_untrackable(robot: RobotProfile) -> None:
    """A one-line error for limits the URDF robot cannot follow: past them it slips and spins, and
    a policy's commands would mean nothing."""
    if robot.v_max > MAX_SPEED:
        raise ConfigError(None, "robot.v_max", f"{robot.v_max:g} m/s; allowed in the 3D tier: at most {MAX_SPEED:g} "
                          "(the URDF robot's wheels slip and it spins at 3)")
    if robot.v_max * robot.w_max > MAX_TURN_ACCELERATION:
        raise ConfigError(None, "robot.w_max", f"{robot.w_max:g} rad/s at v_max {robot.v_max:g} m/s; allowed in the 3D "
                          f"tier: v_max x w_max at most {MAX_TURN_ACCELERATION:g} m/s² (past it the robot spins out "
                          "in a full-speed turn)")


class World:
    """A 3D world built from a :class:`Scenario`.

    Args:
        scenario: the world, robot limits and encoder noise, lidar, start and goal.
        seed: seeds the lidar, encoder and IMU noise and the per-episode draws (``reset(seed)`` reseeds).
        conditions: the knobs of :mod:`common.conditions`, physics3d's defaults where unset (the
            3D robot with realistic imperfections): its profile, sensor noise, actuation, wheel
            friction, mass, control period, IMU noise and where the odometry's heading comes from.
            Ranges are drawn at every reset from the world's generator. ``world.scenario`` is the
            scenario as conditioned.
        gui: open PyBullet's GUI instead of the headless DIRECT client (one per process).
        camera: also render the robot's camera into ``Readings.camera`` every step.

    The URDF robot is always the body that drives; the scenario's robot profile supplies the
    velocity limits and the encoder noise (its acceleration limits are IR-SIM's kinematic
    stand-in for inertia, which this tier simulates, so they are not applied).
    """

    def __init__(self, scenario: Scenario, seed: int | None = None, conditions: Conditions | None = None,
                 gui: bool = False, camera: bool = False) -> None:
        refuse_unmodelled(scenario)
        if gui and sys.platform.startswith("linux"):
            refuse_without_display()
        self.client = p.connect(p.GUI if gui else p.DIRECT)
        self.gui = gui
        self.conditions = resolved = (conditions or Conditions()).for_tier("physics3d")
        period = scenario.world.step_time if resolved.control_period is None else resolved.control_period
        self.substeps = max(1, round(period * PHYSICS_HZ))
        self.period = self.substeps / PHYSICS_HZ
        self.rng = np.random.default_rng(seed)
        self.mover_rng = mover_generator(seed)  # flatland's stream: the same seed, the same movers
        self.gyro_heading = resolved.heading_source == "gyro"
        self.actuator = Actuator()
        renderer = p.ER_BULLET_HARDWARE_OPENGL if gui else p.ER_TINY_RENDERER
        self.camera = Camera(self.client, renderer=renderer) if camera else None
        self._state: int | None = None
        self.load(scenario)

    def load(self, scenario: Scenario) -> None:
        """Replace everything with the world of ``scenario``, in the same client (a GUI window stays open)."""
        refuse_unmodelled(scenario)
        c = self.client
        scenario = self.conditions.scenario(scenario)
        refuse_untrackable(scenario.robot)
        if self.gui:
            p.configureDebugVisualizer(p.COV_ENABLE_RENDERING, 0, physicsClientId=c)  # no redraw per body
        if self._state is not None:
            p.removeState(self._state, physicsClientId=c)
        p.resetSimulation(physicsClientId=c)
        p.setGravity(0.0, 0.0, -GRAVITY, physicsClientId=c)
        # Pyramid friction, not PyBullet's default cone: with ten solver iterations the cone lets the
        # tyres creep sideways at every turn reversal (pid_blend's odometry drifted 10-50 cm per
        # warehouse run with it, 1-5 cm without).
        p.setPhysicsEngineParameter(fixedTimeStep=1.0 / PHYSICS_HZ, numSolverIterations=SOLVER_ITERATIONS,
                                    enableConeFriction=0, deterministicOverlappingPairs=1, physicsClientId=c)
        self.scenario = scenario
        self.warehouse: Warehouse = build(scenario, c)
        self.robot = Robot(c, scenario.start_pose)
        self.warehouse.tags[self.robot.id] = Tag("robot")
        self.movers = MovingBodies(scenario, c, self.warehouse) if scenario.movers else None
        self.lidar = Lidar(scenario.lidar, c, self.robot.lidar_height, self.rng, ROBOT_COLLISION_GROUP)
        self.imu = Imu(self.rng, self.conditions.accel_noise, self.conditions.gyro_noise)
        robot = scenario.robot
        self.odometry = WheelOdometry(WHEEL_RADIUS, WHEEL_BASE, robot.encoder_noise, self.rng, unicycle_exact)
        self._limits = (robot.v_min, robot.v_max, robot.w_low, robot.w_max)
        for _ in range(SETTLE_SUBSTEPS):
            p.stepSimulation(physicsClientId=c)
        # restoreState brings back the bodies, the joints and Bullet's contact cache together: after
        # only resetting poses and velocities, the last episode's warm-start impulses linger and
        # the same seed no longer replays the same episode.
        self._state = p.saveState(physicsClientId=c)
        if self.gui:
            p.configureDebugVisualizer(p.COV_ENABLE_RENDERING, 1, physicsClientId=c)
        self.reset()

    def reset(self, seed: int | None = None) -> Readings:
        """Put the robot back at the start, at rest; reseed the noise if ``seed`` is given."""
        self._refuse_if_closed("reset")
        if seed is not None:
            self.rng = np.random.default_rng(seed)
            self.lidar.rng = self.imu.rng = self.odometry.rng = self.rng
            self.mover_rng = mover_generator(seed)
        p.restoreState(self._state, physicsClientId=self.client)
        drawn = self.conditions.draw(self.rng)
        self.actuator.reset(drawn.action_delay, drawn.motor_gain)
        if drawn.friction is not None:
            self.robot.set_friction(drawn.friction)
        if drawn.mass_scale is not None:
            self.robot.set_mass_scale(drawn.mass_scale)
        self.robot.drive(0.0, 0.0)
        self._driving = (0.0, 0.0)  # the (v, w) the wheels are driven at
        self.steps = 0
        self._angles = self.robot.wheel_angles()
        self.odometry.reset(self.pose())
        self.imu.reset(drawn.gyro_bias)
        if self.movers is not None:
            self.movers.reset(self.pose(), self.mover_rng)
            p.performCollisionDetection(physicsClientId=self.client)
        self.readings = self._read(0.0, self.touching(), (self.robot.link_pose(), self.robot.velocity()))
        return self.readings

    def step(self, v: float, w: float) -> Readings:
        """Drive with (v m/s, w rad/s), clipped to the robot's limits, for one control period."""
        self._refuse_if_closed("step")
        v, w = float(v), float(w)
        if v != v or w != w:
            raise nan_command((v, w))
        v_lo, v_hi, w_lo, w_hi = self._limits
        v, w = min(max(v, v_lo), v_hi), min(max(w, w_lo), w_hi)
        if not self.actuator.idle:
            v, w = self.actuator(v, w, self.period)
        self.robot.drive(v, w)
        self._driving = (v, w)
        # A contact at any sub-step counts: a graze that separates again within the control period
        # is a collision too, not only one still touching at its end.
        touched: list[int] = []
        if self.gui:
            # Draw the end of the period, not each sub-step: drawing 24 frames a period is what
            # held the GUI at a third of real time on a software renderer.
            p.configureDebugVisualizer(p.COV_ENABLE_RENDERING, 0, physicsClientId=self.client)
        near, first = self._bodies_near(max(abs(v), self._planar_speed), max(abs(w), abs(self.readings.velocity[1])))
        movers = {} if self.movers is None else self.movers.row_of  # their bodies, as keys
        walls = [body for body in near if body not in movers]
        for substep in range(self.substeps):
            p.stepSimulation(physicsClientId=self.client)
            if substep < first:
                continue
            if not touched:
                touched = self.touching(near)
            elif walls and not set(touched) - movers.keys():
                # Static geometry touched later in the period still comes first, as in flatland.
                touched = self.touching(walls) + touched
        state = self.robot.link_pose(), self.robot.velocity()
        if self.movers is not None:
            # The movers step after the robot, from where it is and how it moves now.
            (position, orientation), (linear, angular) = state
            yaw = yaw_of(orientation)
            self.movers.finish(Pose2D(position[0], position[1], yaw), _speed_along(linear, yaw), angular[2], self.mover_rng)
            touched = touched or self.touching()
        if self.gui:
            p.configureDebugVisualizer(p.COV_ENABLE_RENDERING, 1, physicsClientId=self.client)
        self.steps += 1
        self.readings = self._read(self.period, touched, state)
        return self.readings

    def pose(self) -> Pose2D:
        """The robot's true planar pose (body centre, yaw)."""
        position, orientation = self.robot.link_pose()
        return Pose2D(position[0], position[1], yaw_of(orientation))

    def _bodies_near(self, speed: float, turn_rate: float) -> tuple[list[int], int]:
        """The bodies but the floor that the robot can touch this control period, and the first
        sub-step (counted from 0) at which it can touch any of them (``substeps``: none).

        Within a period nothing moves the robot faster than twice its ``speed`` (the faster of its
        command and its velocity now) plus the sweep of its corners at twice ``turn_rate`` (the
        same for its turn rate), but a collision with one of these bodies. A broadphase query
        (bounding boxes against a square round the robot) names the candidates, one exact
        closest-distance query each keeps those within that travel and 0.1 m, and the nearest of
        them tells how many sub-steps pass before the robot could close the gap but 2 cm. So the
        sub-steps ask Bullet for contacts with these alone, and only from then on: a contact query
        for the whole robot every sub-step (its wheels' on the floor included) took a sixth of the
        step, one per nearby box every sub-step a tenth."""
        x, y, _ = self.readings.pose  # where the robot is: nothing has moved it since it was read
        rate = 2.0 * (speed + turn_rate * ROBOT_REACH)  # m/s
        bound = rate * self.period + REACH_MARGIN
        reach = ROBOT_REACH + bound
        robot, client, skip = self.robot.id, self.client, (self.robot.id, self.warehouse.floor)
        overlapping = p.getOverlappingObjects((x - reach, y - reach, -0.1), (x + reach, y + reach, 2.0),
                                              physicsClientId=client) or ()
        near, gap = [], math.inf
        for body in sorted({body for body, _ in overlapping if body not in skip}):
            points = p.getClosestPoints(robot, body, bound, physicsClientId=client)
            if points:
                near.append(body)
                gap = min(gap, *(point[8] for point in points))
        if not near:
            return near, self.substeps
        closing = rate * self.period / self.substeps  # the most a sub-step can close the gap, m
        return near, 0 if closing <= 0.0 else max(0, math.ceil((gap - CONTACT_SLACK) / closing) - 1)

    def touching(self, bodies: list[int] | None = None) -> list[int]:
        """Ids of the bodies other than the floor that the robot touches now (among ``bodies``, if given)."""
        robot, client = self.robot.id, self.client
        if bodies is not None:
            return [body for body in bodies if any(point[8] < TOUCH_DISTANCE
                                                   for point in p.getContactPoints(robot, body, physicsClientId=client))]
        others = {point[2] if point[1] == robot else point[1]
                  for point in p.getContactPoints(robot, physicsClientId=client) if point[8] < TOUCH_DISTANCE}
        others.discard(self.warehouse.floor)
        return sorted(others)

    def _contact(self, touched: list[int]) -> Contact | None:
        """What the robot touched (``touched``: body ids), as flatland reports it: static geometry
        first, else the first mover; None for nothing."""
        if self.movers is None:
            return None  # as in flatland: a world without movers reports only that it collided
        rows = [self.movers.row_of[b] for b in touched if b in self.movers.row_of]
        if not touched:
            return None
        if len(rows) < len(touched):
            return Contact("static", -1, "robot")
        # Judged by the speed and turn the robot was driven at this period, as flatland judges it:
        # at the contact itself the body has already been stopped, or pushed back, by what it met.
        v, w = self._driving
        return Contact("mover", rows[0], mover_fault(self.pose(), (v, 0.0, w), self.movers.states().rows[rows[0]],
                                                     self.scenario.robot))

    def _read(self, dt: float, touched: list[int], state: BodyState) -> Readings:
        """The readings after a period ``dt`` in which the robot touched ``touched``, ending in
        ``state``: the body frame's pose and the base's velocities, as read from Bullet."""
        contact = self._contact(touched)
        (position, orientation), (linear, angular) = state
        yaw = yaw_of(orientation)
        self._planar_speed = math.hypot(linear[0], linear[1])
        if dt > 0.0:
            left, right = self.robot.wheel_angles()
            # The gyro is read whichever source the heading takes, so switching it changes no other draw.
            turned = self.imu.turned(wrap_angle(yaw - self.readings.pose.yaw), dt)
            self.odometry.update((left - self._angles[0]) / dt, (right - self._angles[1]) / dt, dt,
                                 turned if self.gyro_heading else None)
            self._angles = (left, right)
        camera = None
        if self.camera is not None:
            camera = {key: frozen(image) for key, image in self.camera.from_mount(*self.robot.camera_pose()).items()}
        odometry = self.odometry
        return Readings(
            pose=Pose2D(position[0], position[1], yaw),
            velocity=(_speed_along(linear, yaw), angular[2]),
            odometry=Odometry(odometry.pose, odometry.v, odometry.w),
            lidar=frozen(self.lidar.scan(position[0], position[1], position[2], yaw)),
            imu=self.imu.read(orientation, linear, angular, dt),
            collided=bool(touched),
            time=self.steps * self.period,
            camera=camera,
            movers=None if self.movers is None else self.movers.states(),
            contact=contact,
        )

    def __deepcopy__(self, memo: dict) -> "World":
        # A copy would drive the same PyBullet client: the original's robot moved with it, and
        # closing either closed both.
        raise TypeError("a physics3d World is a PyBullet client, which cannot be copied; make another "
                        "(gym.make, or World(scenario)) instead")

    def __reduce__(self):
        raise TypeError("a physics3d World is a PyBullet client, which cannot be pickled; pass the scenario "
                        "and build the World where it is used")

    def _refuse_if_closed(self, call: str) -> None:
        # A closed world's client is gone: PyBullet's own errors name neither the world nor the cause.
        if self.client is None:
            raise RuntimeError(f"{call}() on a closed physics3d World; make a new one")

    def close(self) -> None:
        """Disconnect the physics client (the GUI window closes)."""
        if self.client is not None and p.isConnected(self.client):
            p.disconnect(self.client)
        self.client = None

    def __del__(self) -> None:
        # At interpreter exit the pybullet module may already be gone.
        if getattr(self, "client", None) is not None and p is not None:
            self.close()
