"""A scenario's moving obstacles, advanced step by step the same way in every tier.

A tier builds :class:`Movers` from its scenario, starts each episode with :meth:`Movers.reset`
(where the robot starts; the groups plan from that snapshot) and, each step, moves the robot
itself, then calls :meth:`Movers.finish` with where it went: the movers step after it, as in
IR-SIM, are judged, and the groups plan the next step. (A tier whose robot step is compiled may
make the movers' step inside its own kernel instead: :meth:`Movers.begin`, the compiled
:func:`~common.motion.step.finish_packed` on :attr:`Movers.step_arguments`, then
:meth:`Movers.settled`, as flatland's clear steps do.) The movers' poses then go into the tier's sensors. Everything random
(a wanderer's next goal) is drawn from the generator the tier passes, so a seed fixes the episode.
"""

from __future__ import annotations

import copy
import functools
import math

from typing import Callable, NamedTuple

import numpy as np

from common.errors import ConfigError
from common.irsim_geometry import circle_outline, rectangle_outline
from common.kernel_cache import compiled_for
from common.motion.rvo import rvo_velocity
from common.motion.packing import pack
from common.motion.step import (
    COLLISION_MODES, PACKED_BOX_ROWS, PACKED_BOXES, PACKED_CIRCLE_ROWS, PACKED_CIRCLES, PACKED_F, PACKED_GOALS, PACKED_I,
    PACKED_MEMBERS, PACKED_MOVING, PACKED_NEIGHBORS, PACKED_OBJECTS, PACKED_OUTLINE, PACKED_OUTLINES, PACKED_PARAMS,
    PACKED_RING_INDEX, PACKED_RINGS, PACKED_ROBOT, PACKED_ROUTES, PACKED_SEEN_BOXES, PACKED_SEEN_CIRCLES,
    PACKED_SEGMENTS, PACKED_STATES, PACKED_WALLS, command, desired_velocity, draw_wanderers, finish_packed, gather,
    move, plan_step, prepare, snapshot, sync_robot,
)
from common.motion.steering import world_to_diff, world_to_omni
from common.motion.table import (
    ARRIVED, BEHAVIOR, BOX, DIFF, DRIVEN, EXTEND, GROUP, HEAD, INIT_THETA, INIT_V0, INIT_V1, KINEMATICS, OVX, OVY,
    PLANNED, ROBOTS, ROUTE_LENGTH, ROW, RVO, RVO_MODE, RVO_MODES, SEEN_RADIUS, SHAPE, START_X, START_Y, STOPPED, TAIL,
    TARGET, THETA, UNOBSTRUCTED, V0, V1, WANDER, X, Y, MoverTable, mover_table, static_contacts,
)
from common.scenario import Scenario


_MOVERS_STREAM = 0x6D6F76  # a word of the movers' seed sequence: their draws are a stream of their own


def mover_generator(seed: int | None) -> np.random.Generator:
    """The generator a world's movers draw from (a wanderer's next goals) for an episode ``seed``:
    every tier makes the same one, whatever else it draws from the seed."""
    return np.random.default_rng(None if seed is None else [seed, _MOVERS_STREAM])


@functools.cache
def finish_code() -> Callable:
    """:func:`finish_packed`'s machine code for the arguments :class:`Movers` packs, whose types
    never vary: called directly, a step skips the dispatcher's matching of them to a signature
    (a fifth of the call), and looked up once a process, a new scenario's movers skip it too (a
    quarter of building a crowd's). The pose and command go in as floats and ``stopped`` as a bool
    whatever their Python type (numba's unboxing converts numbers)."""
    layout = np.empty((0, 4), dtype=np.int64)
    return compiled_for(finish_packed, np.empty(0), layout, np.empty(0, dtype=np.int64), layout,
                        np.empty((0, 2), dtype=np.float32), np.empty((0, 0), dtype=np.bool_), False, 0.0, False, 0,
                        0.0, 0.0, 0.0, 0.0, 0.0, 0.0, False)


class MoverStates(NamedTuple):
    """Where the movers are: one row each of x, y, heading, vx, vy (world frame), radius (a box's
    half diagonal), length and width (a box's; 0 for a circle); and what each is (its label)."""

    rows: np.ndarray
    labels: tuple[str, ...]


def refuse_unmodelled(scenario: Scenario) -> None:
    """A one-line error for movers this project's motion code cannot model (IR-SIM itself runs them);
    the robot's own IR-SIM behaviour counts, as flatland tracks it among them."""
    if not scenario.movers and scenario.robot_motion is None:
        return
    robot = scenario.robot
    if robot.shape in ("polygon", "compound"):
        raise ConfigError(None, "robot.shape", f"a {robot.shape} robot among movers is not modelled; allowed: circle, box")
    if scenario.grid_map is not None:
        raise ConfigError(None, "grid_map", "movers on a grid map are not modelled (they would not see it); "
                          "allowed: a grid map without movers, or movers among shapes")


class Movers:
    """The movers of ``scenario`` (its obstacles with a motion, and the robot's own IR-SIM
    behaviour if it has one: tracked for its group and its draws, never driving it)."""

    def __init__(self, scenario: Scenario) -> None:
        refuse_unmodelled(scenario)
        self.scenario = scenario
        self.table: MoverTable = mover_table(scenario)
        t = self.table
        I = t.I  # noqa: E741
        self._moving = np.flatnonzero(I[:, DRIVEN] == 0)
        self.count = len(self._moving)
        self.labels = tuple(t.labels[m] for m in self._moving)
        seen = I[self._moving, UNOBSTRUCTED] == 0
        self._circles = self._moving[(I[self._moving, SHAPE] != BOX) & seen]
        self._boxes = self._moving[(I[self._moving, SHAPE] == BOX) & seen]
        self._contacts = static_contacts(scenario)
        self._dt = scenario.world.step_time
        self._mode = COLLISION_MODES.index(scenario.world.collision_mode)
        self._members, self._inside = _groups(I, len(t.objects))
        self._python = bool((I[:, BEHAVIOR] == RVO).any())  # IR-SIM's rvo is NumPy: a Python loop
        self.draws = bool(I[:, WANDER].any())  # whether an episode draws random numbers
        # Wanderers given a region and no goals: each episode's first goal is drawn at reset, as
        # IR-SIM draws a wanderer's first at its start.
        self._goalless = (I[:, WANDER] == 1) & (I[:, ROUTE_LENGTH] == 0)
        self._draws_first_goals = bool(self._goalless.any())
        self._wanderer_arrived = False
        self._start: tuple[tuple[float, ...], list[np.ndarray]] | None = None  # the last start and its state
        self._neighbors = np.zeros((len(t.objects) + len(t.F), 5))
        self._initial_objects = t.objects.copy()
        self._states = np.empty((self.count, 8))
        self._circle_rows, self._box_rows = np.empty((len(self._circles), 3)), np.empty((len(self._boxes), 6))
        robot = scenario.robot
        # The robot's body for contacts: shape, x, y, heading, radius, length, width, and how far
        # ahead of its pose the footprint's centre is.
        box = robot.shape == "box"
        self._robot = np.array([BOX if box else 0, 0.0, 0.0, 0.0, 0.5 * math.hypot(robot.length, robot.width) if box
                                else robot.radius, robot.length, robot.width, robot.footprint_offset])
        self._outline = np.zeros((0, 2))  # the robot's polygon, for IR-SIM's view of it
        if t.irsim:
            self._outline = (rectangle_outline(robot.length, robot.width) if box else circle_outline(robot.radius)) \
                + (robot.footprint_offset, 0.0)
        self._pack(t)
        self._finish_step = finish_code()

    def _pack(self, t: MoverTable) -> None:
        """Move the arrays the compiled step reads and writes into one float and one integer buffer
        (:mod:`common.motion.packing`, at the ``PACKED_*`` positions of :mod:`common.motion.step`),
        every name here and in the table then a view of them, and gather :func:`finish_packed`'s
        arguments but the robot's pose and command."""
        circles, boxes, walls, rings, ring_index = self._contacts
        floats, float_layout, views = pack(in_packed_order({
            PACKED_F: t.F, PACKED_PARAMS: t.params, PACKED_GOALS: t.goals, PACKED_ROUTES: t.routes,
            PACKED_OBJECTS: t.objects, PACKED_SEGMENTS: t.segments, PACKED_OUTLINES: t.outlines,
            PACKED_NEIGHBORS: self._neighbors, PACKED_OUTLINE: self._outline, PACKED_ROBOT: self._robot,
            PACKED_CIRCLES: circles, PACKED_BOXES: boxes, PACKED_WALLS: walls, PACKED_RINGS: rings,
            PACKED_STATES: self._states, PACKED_CIRCLE_ROWS: self._circle_rows, PACKED_BOX_ROWS: self._box_rows}),
            np.float64)
        (t.F, t.params, t.goals, t.routes, t.objects, t.segments, t.outlines, self._neighbors, self._outline,
         self._robot, circles, boxes, walls, rings, self._states, self._circle_rows, self._box_rows) = views
        ints, int_layout, views = pack(in_packed_order({
            PACKED_I: t.I, PACKED_RING_INDEX: ring_index, PACKED_MOVING: self._moving,
            PACKED_SEEN_CIRCLES: self._circles, PACKED_SEEN_BOXES: self._boxes, PACKED_MEMBERS: self._members}),
            np.int64)
        t.I, ring_index, self._moving, self._circles, self._boxes, self._members = views
        self._contacts = (circles, boxes, walls, rings, ring_index)
        self._packed = (floats, float_layout, ints, int_layout, t.orca_velocity, self._inside, t.irsim, self._dt,
                        self._python, self._mode)

    def __deepcopy__(self, memo: dict) -> "Movers":
        # The arrays the compiled step writes are views of the two packed buffers; a deep copy
        # makes each view an array of its own, which the copy's steps never wrote (its states and
        # lidar rows stood still while its movers moved). The copy packs them again.
        twin = object.__new__(type(self))
        memo[id(self)] = twin
        twin.__dict__.update(copy.deepcopy(self.__dict__, memo))
        twin._pack(twin.table)
        return twin

    def reset(self, pose: tuple[float, float, float], rng: np.random.Generator) -> None:
        """Every mover back at its start with its first goal and its first command; the robot at
        ``pose``, at rest; the groups' plans for the first step. A wanderer without goals draws
        its first from ``rng``."""
        start = tuple(pose)
        if self._draws_first_goals:  # each episode draws other first goals: nothing to copy back
            self._start_afresh(pose, rng)
            return
        if self._start is not None and self._start[0] == start:
            # The same start as the last one computed: the same state, copied back (a reset from
            # scratch costs tens of microseconds, and training resets every few hundred steps).
            for live, saved in zip(self._episode_state(), self._start[1]):
                np.copyto(live, saved)
            self._wanderer_arrived = False
            return
        self._start_afresh(pose, rng)
        self._start = (start, [array.copy() for array in self._episode_state()])

    def _episode_state(self) -> tuple[np.ndarray, ...]:
        """The arrays that hold every value an episode changes: the two packed buffers (the rest
        of them, the scenario's constants and scratch, comes back unchanged) and ORCA's velocities."""
        floats, _, ints = self._packed[:3]
        return floats, ints, self.table.orca_velocity

    def _start_afresh(self, pose: tuple[float, float, float], rng: np.random.Generator) -> None:
        t = self.table
        F, I = t.F, t.I  # noqa: E741
        F[:, X], F[:, Y], F[:, THETA] = F[:, START_X], F[:, START_Y], F[:, INIT_THETA]
        F[:, V0], F[:, V1] = F[:, INIT_V0], F[:, INIT_V1]
        I[:, STOPPED] = I[:, PLANNED] = 0
        # A goalless wanderer starts as if it had arrived, so it draws a goal before anything plans.
        I[:, ARRIVED] = self._goalless
        t.goals[:] = t.routes
        I[:, HEAD], I[:, TAIL] = 0, np.maximum(I[:, ROUTE_LENGTH], 1)
        draw_wanderers(F, I, t.goals, rng)  # the goalless wanderers' first goals, if any
        t.orca_velocity[:] = 0.0
        t.objects[:] = self._initial_objects
        self._wanderer_arrived = False
        m, rows = self._moving, I[self._moving, ROW]
        c, s, v0, v1 = np.cos(F[m, THETA]), np.sin(F[m, THETA]), F[m, V0], F[m, V1]
        diff = I[m, KINEMATICS] == DIFF  # the two cases of step.world_velocity, for every mover at once
        t.objects[rows, OVX] = np.where(diff, v0 * c, v0 * c - v1 * s)
        t.objects[rows, OVY] = np.where(diff, v0 * s, v0 * s + v1 * c)
        snapshot(t.F, t.I, t.objects, self._moving, self._circles, self._boxes, self._states, self._circle_rows,
                 self._box_rows)
        plan_step(t.F, t.I, t.params, t.goals, t.objects, t.segments, t.orca_velocity, self._members, self._inside,
                  self._dt, self._neighbors, self._outline, t.irsim, self._robot, *pose, 0.0, 0.0, False)

    def finish(self, pose: tuple[float, float, float], v: float, w: float, stopped: bool,
               rng: np.random.Generator, lateral: float = 0.0) -> int:
        """End the step: the robot went to ``pose`` with (v, w) and sideways at ``lateral`` (an
        omnidirectional robot; ``stopped``: it was halted when the step began); every mover steps (a wanderer's next goal drawn from ``rng``), is judged, and
        the groups plan the next step. The index (a row of :meth:`states`) of the first mover the
        robot touches, or -1."""
        self.begin(rng)
        if self._python:
            self._advance_in_python(pose, v, w, lateral, stopped)
        x, y, yaw = pose
        return self.settled(*self._finish_step(*self._packed, x, y, yaw, v, w, lateral, stopped))

    @property
    def compiled(self) -> bool:
        """Whether a step is the one compiled call :meth:`step_arguments` feeds (no mover steps
        in Python first, as IR-SIM's rvo does), which a tier may make inside a kernel of its own."""
        return not self._python

    def begin(self, rng: np.random.Generator) -> None:
        """Start a step: every wanderer that arrived last step draws its next goal from ``rng``."""
        if self._wanderer_arrived:
            draw_wanderers(self.table.F, self.table.I, self.table.goals, rng)
            self._wanderer_arrived = False

    @property
    def step_arguments(self) -> tuple:
        """:func:`~common.motion.step.finish_packed`'s arguments before the robot's pose and
        command, for a tier's kernel to pass on (after :meth:`begin`, then :meth:`settled`)."""
        return self._packed

    def settled(self, touched: int, wanders: bool) -> int:
        """End a step with what the compiled step returned: the index (a row of :meth:`states`)
        of the first mover the robot touched, or -1."""
        self._wanderer_arrived = wanders
        return -1 if touched < 0 else int(np.searchsorted(self._moving, touched))

    def _advance_in_python(self, pose: tuple[float, float, float], v: float, w: float, lateral: float,
                           stopped: bool) -> None:
        """Every mover's step, in order, with IR-SIM's rvo (NumPy) where a mover has it."""
        t = self.table
        sync_robot(t.F, t.I, t.objects, self._outline, t.irsim, self._robot, *pose, v, w, lateral, stopped)
        for m in range(len(t.F)):
            if not prepare(t.F, t.I, t.goals, t.routes, t.objects, m):
                continue
            if t.I[m, BEHAVIOR] == RVO and not t.I[m, PLANNED]:
                c0, c1 = self._rvo(m)
            else:
                c0, c1 = command(t.F, t.I, t.params, t.goals, t.objects, t.segments, m, self._dt, self._neighbors)
            move(t.F, t.I, t.objects, t.outlines, t.irsim, m, c0, c1, self._dt, *self._contacts[:3])

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

    @property
    def rows(self) -> np.ndarray:
        """The table rows of the movers that move (the controlled robot's own left out), in the
        order of :meth:`states`."""
        return self._moving

    def states(self) -> MoverStates:
        """The movers' poses, velocities and sizes now (the controlled robot's own row left out)."""
        # A copy (the next step overwrites ours), left writable: marking it read-only cost 0.26 µs,
        # 1% of the crowd env's step, every step (movers_vs_static stands at its 0.5 line).
        return MoverStates(self._states.copy(), self.labels)

    def visible(self) -> tuple[np.ndarray, np.ndarray]:
        """What a lidar sees of the movers now: circles (x, y, r) and boxes (x, y, cos, sin, half
        length, half width), unobstructed ones left out (arrays the next step overwrites)."""
        return self._circle_rows, self._box_rows



def in_packed_order(arrays: dict[int, np.ndarray]) -> list[np.ndarray]:
    """The arrays keyed by their packed positions, in position order (every position once)."""
    if sorted(arrays) != list(range(len(arrays))):
        raise ValueError(f"packed positions {sorted(arrays)} are not 0 to {len(arrays) - 1} once each")
    return [arrays[k] for k in range(len(arrays))]


def _groups(I: np.ndarray, objects: int) -> tuple[np.ndarray, np.ndarray]:  # noqa: E741
    """Each group's movers in order, as rows padded with -1, and whether each object row belongs to it."""
    count = int(I[:, GROUP].max(initial=-1)) + 1
    members = [np.flatnonzero(I[:, GROUP] == g) for g in range(count)]
    table = np.full((count, max((len(m) for m in members), default=0)), -1, dtype=np.int64)
    inside = np.zeros((count, objects), dtype=np.bool_)
    for g, rows in enumerate(members):
        table[g, :len(rows)] = rows
        inside[g, I[rows, ROW]] = True
    return table, inside
