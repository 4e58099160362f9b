"""How an obstacle moves: a route (where it goes) and a behaviour (how it steers there).

A moving obstacle of a scenario carries a :class:`Motion`. Its route is a list of ``goals``
visited in order, then stopped at (``once``), started over (``loop``) or walked back
(``back_and_forth``): a forklift's patrol along an aisle. Or it ``wander``s: on arriving, a new
goal is drawn at random in a region from the world's seeded generator. Its behaviour, IR-SIM's
names and parameters, is how it heads for the current goal:

=========  ====================================================================================
``dash``   straight at the goal, at the speed limit (IR-SIM's ``dash``)
``rvo``    IR-SIM's sampled reciprocal velocity obstacles among everything near (``rvo``)
``orca``   optimal reciprocal collision avoidance among its group (IR-SIM's ``orca``, RVO2's)
``sfm``    the social force model (Moussaïd-Helbing 2009), IR-SIM's ``sfm``
=========  ====================================================================================

Movers of one ``group`` plan together from one snapshot of the world (IR-SIM's
``group_behavior``); a mover without a group plans on its own, seeing the others where they are
at that moment of the step (IR-SIM's ``behavior``). ``orca`` always plans in a group.
``reacts_to_robot`` says whether the controlled robot is among what a mover avoids: real people
do; the hard case is a mover that does not. ``static_contact: slide`` keeps a mover out of walls,
shelves and posts (:mod:`common.motion.slide`), where IR-SIM's walk through them.

Velocity limits, accelerations and the command are in the kinematics' own frame, as IR-SIM has
them: ``omni`` (forward, lateral), ``diff`` (linear, angular).
"""

from __future__ import annotations

import math
from typing import Annotated, Literal, Union

from pydantic import Field, model_validator

from common.fields import (MAX_MOVER_SPEED, Acceleration, Coordinate, Frozen, Length, MoverSpeed, MoverSpeedLimit,
                           NonNegative, Point, Positive)

MAX_GOALS = 1000  # per mover
Pair = tuple[MoverSpeed, MoverSpeed]
LABELS = ("person", "forklift", "cart", "robot", "obstacle")


class Dash(Frozen):
    """Straight at the goal at the speed limit; a ``diff`` mover turns toward it first (IR-SIM's ``dash``)."""

    name: Literal["dash"] = "dash"
    angle_tolerance: Annotated[float, Field(ge=0.0, le=math.pi)] = 0.1  # rad: a heading error it drives with
    # m: a mover that reacts to the robot holds still while the robot stands within this distance
    # ahead of its front, in its lane (a forklift's driver braking); 0: never. IR-SIM's dash never does.
    yield_distance: Annotated[float, Field(ge=0.0, le=10.0)] = 0.0


class Rvo(Frozen):
    """IR-SIM's reciprocal velocity obstacles: the reachable velocity (a 0.05 m/s grid within
    ``acce`` of the current one) nearest the desired one outside every neighbour's cone."""

    name: Literal["rvo"] = "rvo"
    # Capped: the candidates are a 0.05 m/s grid over ±vxmax x ±vymax within acce, so 1e6 asked for
    # a grid of petabytes; at the caps, 400 x 400 candidates a step.
    vxmax: MoverSpeedLimit = 1.5
    vymax: MoverSpeedLimit = 1.5
    acce: Annotated[float, Field(gt=0.0, le=2 * MAX_MOVER_SPEED)] = 1.0  # m/s: how far from the current velocity the candidates reach
    factor: NonNegative = 1.0  # weight of the time to collision when every candidate is inside a cone
    mode: Literal["rvo", "hrvo", "vo"] = "rvo"
    neighbor_threshold: Positive = 3.0  # m


class Orca(Frozen):
    """Optimal reciprocal collision avoidance among the mover's group (RVO2, as IR-SIM runs it)."""

    name: Literal["orca"] = "orca"
    neighbor_dist: Positive = 15.0  # m
    max_neighbors: Annotated[int, Field(ge=0, le=1000)] = 10
    time_horizon: Positive = 20.0  # s
    time_horizon_obst: Positive = 10.0  # s (IR-SIM's groups meet no obstacle lines)
    safe_radius: NonNegative = 0.1  # m added to the body's radius
    max_speed: Positive | None = None  # m/s; default: what the kinematics can hold in every direction


class Sfm(Frozen):
    """The social force model (IR-SIM's ``sfm``): relaxation toward the goal at ``vmax``, anisotropic
    repulsion from neighbours, exponential repulsion from line obstacles."""

    name: Literal["sfm"] = "sfm"
    vmax: Positive = 1.5
    neighbor_threshold: Positive = 10.0
    relaxation_time: Positive = 0.5
    force_factor_desired: NonNegative = 1.0
    force_factor_social: NonNegative = 2.1
    force_factor_obstacle: NonNegative = 10.0
    sigma_obstacle: Positive = 0.8
    lambda_importance: NonNegative = 2.0
    gamma: Positive = 0.35
    n_angular: NonNegative = 2.0
    n_velocity: NonNegative = 3.0
    safety_radius: NonNegative = 0.0


Behavior = Annotated[Union[Dash, Rvo, Orca, Sfm], Field(discriminator="name")]


class Motion(Frozen):
    """A moving obstacle's route, behaviour, kinematics and limits (see the module)."""

    behavior: Behavior = Dash()
    goals: Annotated[list[Point], Field(max_length=MAX_GOALS)] = []
    route: Literal["once", "loop", "back_and_forth"] = "once"
    wander: tuple[Coordinate, Coordinate, Coordinate, Coordinate] | None = None  # x_min, y_min, x_max, y_max
    kinematics: Literal["omni", "diff"] = "omni"
    velocity: Pair = (0.0, 0.0)  # the command it starts with
    vel_max: Pair = (1.0, 1.0)
    vel_min: Pair | None = None  # default -vel_max
    acce: tuple[Acceleration, Acceleration] = (math.inf, math.inf)
    goal_threshold: Length = 0.1
    group: Annotated[str, Field(min_length=1, max_length=64)] | None = None
    reacts_to_robot: bool = True
    target_roles: Literal["all", "robot", "obstacle"] = "all"  # IR-SIM's: whose roles it avoids
    role: Literal["obstacle", "robot"] = "obstacle"  # IR-SIM's: which collision rule stops it
    label: Literal[LABELS] = "person"  # what it is: the social figures count people
    # What static geometry (walls, shelves, posts) does to it: "pass" as IR-SIM (the world's
    # collision mode decides: stop halts it, the unobstructed modes let it through); "slide": it
    # never enters it, keeping the part of a step along the surface (common.motion.slide; circles only).
    static_contact: Literal["pass", "slide"] = "pass"

    @model_validator(mode="before")
    @classmethod
    def _orca_plans_in_a_group(cls, data):
        if isinstance(data, dict) and data.get("group") is None:
            behavior = data.get("behavior")
            name = behavior.get("name") if isinstance(behavior, dict) else getattr(behavior, "name", None)
            if name == "orca":
                data = {**data, "group": "orca"}
        return data

    @model_validator(mode="after")
    def _consistent(self) -> "Motion":
        if not self.goals and self.wander is None:
            raise ValueError("a motion needs goals or a wander region; allowed: goals: [[x, y], ...] or "
                             "wander: [x_min, y_min, x_max, y_max]")
        if self.wander is not None:
            x0, y0, x1, y1 = self.wander
            if not (x0 <= x1 and y0 <= y1):
                raise ValueError(f"wander region {list(self.wander)} is empty; allowed: x_min <= x_max, y_min <= y_max")
        low = self.lower
        for axis in (0, 1):
            if low[axis] > self.vel_max[axis]:
                raise ValueError(f"vel_min {list(low)} exceeds vel_max {list(self.vel_max)}; allowed: vel_min <= vel_max")
        return self

    def route_from(self, start: tuple[float, float]) -> list[tuple[float, float]]:
        """The goals a mover starting at ``start`` runs through before its route starts over
        (IR-SIM's goal list): ``back_and_forth`` goes through the goals and back to the start."""
        goals = [tuple(goal) for goal in self.goals]
        if self.route == "back_and_forth" and len(goals) > 1:
            goals = goals + goals[-2::-1] + [tuple(start)]
        return goals

    @property
    def lower(self) -> tuple[float, float]:
        """The lower velocity limits (``vel_min``, or ``-vel_max``)."""
        return self.vel_min if self.vel_min is not None else (-self.vel_max[0], -self.vel_max[1])

    @property
    def speed(self) -> float:
        """The fastest it can go in a straight line (m/s)."""
        if self.kinematics == "diff":
            return max(abs(self.vel_max[0]), abs(self.lower[0]))
        return math.hypot(max(abs(self.vel_max[0]), abs(self.lower[0])), max(abs(self.vel_max[1]), abs(self.lower[1])))
