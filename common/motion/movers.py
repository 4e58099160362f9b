"""A scenario's moving obstacles, advanced step by step the same way in every tier.

A tier builds :class:`Movers` from its scenario and, each step: tells it where the robot is and
how it moves (:meth:`Movers.sync_robot`), lets the groups plan (:meth:`Movers.plan`), moves the
robot itself, tells it again, advances the movers (:meth:`Movers.advance`) and judges them
(:meth:`Movers.settle`): IR-SIM's order, the robot first. The movers' poses then go into the
tier's sensors. Everything random (a wanderer's next goal) is drawn from the generator the tier
passes, so a seed fixes the episode.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from common.motion.rvo import rvo_velocity
from common.irsim_geometry import circle_outline, rectangle_outline
from common.motion.step import (
    COLLISION_MODES, advance, command, desired_velocity, gather, move, place_disc, plan_groups, prepare, settle,
    world_velocity,
)
from common.motion.steering import world_to_diff, world_to_omni
from common.motion.table import (
    ARRIVED, BEHAVIOR, BOX, DIFF, DRIVEN, EXTEND, GROUP, HEAD, INIT_THETA, INIT_V0, INIT_V1, KINEMATICS, LENGTH, OVX,
    OVY, PLANNED, RADIUS, ROBOTS, SEEN_RADIUS, ROUTE_LENGTH, ROW, RVO, RVO_MODE, RVO_MODES, SHAPE, START_X, START_Y, STOPPED,
    TAIL, TARGET, THETA, UNOBSTRUCTED, V0, V1, WANDER, WIDTH, X, Y, MoverTable, mover_table, static_contacts,
)
from common.scenario import Scenario


class MoverStates(NamedTuple):
    """Where the movers are: one row each of x, y, heading, vx, vy (world frame), radius (a box's
    half diagonal), length and width (a box's; 0 for a circle); and what each is (its label)."""

    rows: np.ndarray
    labels: tuple[str, ...]


class Movers:
    """The movers of ``scenario`` (its obstacles with a motion, and the robot's own IR-SIM
    behaviour if it has one: tracked for its group and its draws, never driving it)."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        self.table: MoverTable = mover_table(scenario)
        I = self.table.I  # noqa: E741
        self._moving = np.flatnonzero(I[:, DRIVEN] == 0)
        self.count = len(self._moving)
        self.labels = tuple(self.table.labels[m] for m in self._moving)
        self._circles = self._moving[(I[self._moving, SHAPE] != BOX) & (I[self._moving, UNOBSTRUCTED] == 0)]
        self._boxes = self._moving[(I[self._moving, SHAPE] == BOX) & (I[self._moving, UNOBSTRUCTED] == 0)]
        self._contacts = static_contacts(scenario)
        self._dt = scenario.world.step_time
        self._mode = COLLISION_MODES.index(scenario.world.collision_mode)
        self._groups = int(I[:, GROUP].max(initial=-1)) + 1
        self._python = bool((I[:, BEHAVIOR] == RVO).any())  # IR-SIM's rvo is NumPy: a Python loop
        self.draws = bool(I[:, WANDER].any())  # whether an episode draws random numbers
        self._neighbors = np.zeros((len(self.table.objects) + len(self.table.F), 5))
        self._initial_objects = self.table.objects.copy()
        robot = scenario.robot
        # The robot's body for contacts: shape, x, y, heading, radius, length, width.
        self._robot = np.array([BOX if robot.shape == "box" else 0, 0.0, 0.0, 0.0, robot.bounding_radius, robot.length,
                                robot.width])
        self._robot_outline = (rectangle_outline(robot.length, robot.width) if robot.shape == "box"
                               else circle_outline(robot.radius))
        self.reset()

    def reset(self) -> None:
        """Every mover back at its start with its first goal and its first command."""
        t = self.table
        F, I = t.F, t.I  # noqa: E741
        F[:, X], F[:, Y], F[:, THETA] = F[:, START_X], F[:, START_Y], F[:, INIT_THETA]
        F[:, V0], F[:, V1] = F[:, INIT_V0], F[:, INIT_V1]
        I[:, STOPPED] = I[:, ARRIVED] = I[:, PLANNED] = 0
        t.goals[:] = t.routes
        I[:, HEAD], I[:, TAIL] = 0, np.maximum(I[:, ROUTE_LENGTH], 1)
        t.orca_velocity[:] = 0.0
        t.objects[:] = self._initial_objects
        for m in self._moving:
            row = I[m, ROW]
            t.objects[row, OVX], t.objects[row, OVY] = world_velocity(I[m, KINEMATICS], F[m, THETA], F[m, V0], F[m, V1])

    def sync_robot(self, pose: tuple[float, float, float], v: float, w: float, stopped: bool) -> None:
        """Tell the movers where the controlled robot is and the command it moves with."""
        t = self.table
        x, y, yaw = pose
        place_disc(t.objects, self._robot_outline, t.irsim, 0, len(self._robot_outline), x, y, yaw)
        t.objects[0, OVX], t.objects[0, OVY] = v * math.cos(yaw), v * math.sin(yaw)
        self._robot[1:4] = x, y, yaw
        if len(self._moving) < len(t.F):  # the robot's own row (it comes first)
            t.F[0, X], t.F[0, Y], t.F[0, THETA], t.F[0, V0], t.F[0, V1] = x, y, yaw, v, w
            t.I[0, STOPPED] = int(stopped)

    def plan(self) -> None:
        """The groups' commands for this step, from where everything is now."""
        if self._groups:
            t = self.table
            plan_groups(t.F, t.I, t.params, t.goals, t.objects, t.segments, t.orca_velocity, self._groups, self._dt,
                        self._neighbors)

    def advance(self, rng: np.random.Generator) -> None:
        """Each mover's step, in order; a wanderer's next goal drawn from ``rng``."""
        t = self.table
        if not self._python:
            advance(t.F, t.I, t.params, t.goals, t.routes, t.objects, t.segments, t.outlines, t.irsim, self._dt, rng,
                    self._neighbors)
            return
        for m in range(len(t.F)):
            if not prepare(t.F, t.I, t.goals, t.routes, t.objects, m, rng):
                continue
            if t.I[m, BEHAVIOR] == RVO and not t.I[m, PLANNED]:
                c0, c1 = self._rvo(m)
            else:
                c0, c1 = command(t.F, t.I, t.params, t.goals, t.objects, t.segments, m, self._dt, self._neighbors)
            move(t.F, t.I, t.objects, t.outlines, t.irsim, m, c0, c1, self._dt)

    def _rvo(self, m: int) -> tuple[float, float]:
        """IR-SIM's rvo command of mover ``m`` among the others where they are now."""
        t = self.table
        F, I, p = t.F, t.I, t.params[m]  # noqa: E741
        row = I[m, ROW]
        count = gather(I, t.objects, m, self._neighbors)
        desired = desired_velocity(F, I, t.goals, m)
        state = [F[m, X], F[m, Y], t.objects[row, OVX], t.objects[row, OVY], F[m, SEEN_RADIUS] + EXTEND, *desired,
                 F[m, THETA]]
        segments = t.segments if I[m, TARGET] != ROBOTS else t.segments[:0]
        vx, vy, considered = rvo_velocity(state, self._neighbors[:count], segments, p[0], p[1], p[2], p[3],
                                          RVO_MODES[I[m, RVO_MODE]], p[4])
        if I[m, KINEMATICS] != DIFF:
            return world_to_omni(F[m, THETA], vx, vy)
        v, w = world_to_diff(F[m, THETA], vx, vy, 1.5, 0.2, 0.1, 0.02)  # IR-SIM's defaults, as its DiffRVO
        if v == 0.0 and w == 0.0 and not considered:
            # Alone with its goal behind it: IR-SIM turns it in place instead of leaving it frozen.
            w = world_to_diff(F[m, THETA], desired[0], desired[1], 1.5, 0.2, 0.1, 0.02)[1]
        return v, w

    def settle(self) -> int:
        """Judge the step: arrivals, contacts and stops; the index (a row of :meth:`states`) of
        the first mover the robot touches, or -1."""
        t = self.table
        touched = settle(t.F, t.I, t.goals, self._robot, self._mode, *self._contacts)
        return -1 if touched < 0 else int(np.searchsorted(self._moving, touched))

    def states(self) -> MoverStates:
        """The movers' poses, velocities and sizes now (the controlled robot's own row left out)."""
        t, m = self.table, self._moving
        F, rows = t.F, t.I[self._moving, ROW]
        boxes = t.I[m, SHAPE] == BOX
        table = np.column_stack([F[m, X], F[m, Y], F[m, THETA], t.objects[rows, OVX], t.objects[rows, OVY],
                                 F[m, RADIUS], np.where(boxes, F[m, LENGTH], 0.0), np.where(boxes, F[m, WIDTH], 0.0)])
        table.flags.writeable = False
        return MoverStates(table, self.labels)

    def visible(self) -> tuple[np.ndarray, np.ndarray]:
        """What a lidar sees of the movers: circles (x, y, r) and boxes (x, y, cos, sin, half
        length, half width), unobstructed ones left out."""
        F, c, b = self.table.F, self._circles, self._boxes
        circles = np.column_stack([F[c, X], F[c, Y], F[c, RADIUS]])
        boxes = np.column_stack([F[b, X], F[b, Y], np.cos(F[b, THETA]), np.sin(F[b, THETA]), 0.5 * F[b, LENGTH],
                                 0.5 * F[b, WIDTH]])
        return circles, boxes
