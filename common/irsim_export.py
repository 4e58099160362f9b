"""Write a scenario as an IR-SIM world mapping, so IR-SIM can run the very same world (benchmarks,
parity checks). Boundary walls, which IR-SIM lacks, become a closed ``linestring`` obstacle, last.

Movers become IR-SIM's moving objects: their kinematics, limits, goals and behaviour with IR-SIM's
names (a ``back_and_forth`` route as the goal list a ``loop`` runs through; a wanderer's region as
``range_low``/``range_high``, IR-SIM drawing its first goal itself), a group as one YAML group with
its ``group_behavior``, a mover blind to the robot as ``target_roles: obstacle``. What IR-SIM cannot
say is a one-line :class:`ConfigError`: members of a group whose parameters differ (IR-SIM's groups
share theirs), an ORCA group that sees the robot (IR-SIM's ORCA sees its group only), a
``dash`` mover that yields to the robot (IR-SIM's never does), and a mover that slides along walls
(IR-SIM's pass through them: :func:`passing` is the same world with IR-SIM's movers).
"""

from __future__ import annotations

import math
from typing import Any

from common.drive import channel_limits
from common.errors import ConfigError
from common.motion.spec import Dash, Motion, Orca
from common.scenario import BoxObstacle, CircleObstacle, PolygonObstacle, Scenario

_ORIGIN = [0.0, 0.0, 0.0]
_ORCA_NAMES = {"neighbor_dist": "neighborDist", "max_neighbors": "maxNeighbors", "time_horizon": "timeHorizon",
               "time_horizon_obst": "timeHorizonObst", "safe_radius": "safe_radius", "max_speed": "maxSpeed"}


def _obstacle(obstacle) -> dict[str, Any]:
    if isinstance(obstacle, CircleObstacle):
        shape, state = {"name": "circle", "radius": obstacle.radius}, [obstacle.x, obstacle.y, obstacle.yaw]
    elif isinstance(obstacle, BoxObstacle):
        shape = {"name": "rectangle", "length": obstacle.length, "width": obstacle.width}
        state = [obstacle.x, obstacle.y, obstacle.yaw]
    elif isinstance(obstacle, PolygonObstacle):
        shape, state = {"name": "polygon", "vertices": [list(v) for v in obstacle.vertices]}, _ORIGIN
    else:
        shape, state = {"name": "linestring", "vertices": [list(p) for p in obstacle.points]}, _ORIGIN
    return {"shape": shape, "state": list(state), "unobstructed": obstacle.unobstructed}


def _behavior(motion: Motion) -> dict[str, Any]:
    """IR-SIM's behaviour mapping: the behaviour's parameters, its route and whom it avoids."""
    behavior = motion.behavior
    values = behavior.model_dump(exclude={"name", "yield_distance"}, exclude_none=True)
    if isinstance(behavior, Orca):
        values = {_ORCA_NAMES[key]: value for key, value in values.items()}
    out: dict[str, Any] = {"name": behavior.name, **values}
    if motion.wander is not None:
        x0, y0, x1, y1 = motion.wander
        out.update(wander=True, range_low=[x0, y0, -math.pi], range_high=[x1, y1, math.pi])
    elif motion.route != "once":
        out["loop"] = True
    roles = motion.target_roles if motion.reacts_to_robot else "obstacle"  # blind to the robot: obstacles only
    if roles != "all":
        out["target_roles"] = roles  # "robot" was once dropped: the movers then avoided everyone
    return out


def _mover(obstacle) -> dict[str, Any]:
    """A moving obstacle as IR-SIM's moving object (its behaviour written by the caller)."""
    motion = obstacle.motion
    goals = motion.route_from((obstacle.x, obstacle.y)) if motion.wander is None else list(motion.goals[:1])
    entry = {**_obstacle(obstacle), "kinematics": {"name": motion.kinematics}}
    if goals:  # a wanderer without goals: IR-SIM draws its first in the region, as flatland does
        entry["goal"] = [[x, y, 0.0] for x, y in goals] if len(goals) > 1 else [*goals[0], 0.0]
    entry.update({"goal_threshold": motion.goal_threshold, "vel_max": list(motion.vel_max),
                  "vel_min": list(motion.lower), "velocity": list(motion.velocity), "arrive_mode": "position"})
    if any(math.isfinite(a) for a in motion.acce):
        entry["acce"] = list(motion.acce)
    return entry


def _groups(scenario: Scenario) -> tuple[list[dict], list[dict]]:
    """The robots (after the controlled one) and obstacles: static and per-object movers one by
    one, each group as one YAML group with a per-object list of every key."""
    robots: list[dict] = []
    obstacles: list[dict] = []
    grouped: dict[str, list] = {}
    for index, obstacle in enumerate(scenario.obstacles):
        motion = getattr(obstacle, "motion", None)
        where = f"obstacles.{index}.motion"
        if motion is None:
            obstacles.append(_obstacle(obstacle))
            continue
        if motion.static_contact == "slide":
            raise ConfigError(None, f"{where}.static_contact", "IR-SIM's movers pass through static geometry; "
                                                               "allowed: pass (common.irsim_export.passing)")
        if isinstance(motion.behavior, Dash) and motion.behavior.yield_distance > 0.0 and motion.reacts_to_robot:
            raise ConfigError(None, f"{where}.behavior.yield_distance", "IR-SIM's dash never yields to the robot; "
                                                                        "allowed: 0, or reacts_to_robot: false")
        section = robots if motion.role == "robot" else obstacles
        if motion.group is None and isinstance(motion.behavior, Orca):
            raise ConfigError(None, f"{where}.group", "IR-SIM runs ORCA as a group behaviour only; allowed: a group")
        if motion.group is None:
            section.append({**_mover(obstacle), "behavior": _behavior(motion)})
            continue
        if motion.group not in grouped:
            grouped[motion.group] = []
            section.append({"group": motion.group})  # a placeholder, filled below, keeps the order
        grouped[motion.group].append((obstacle, where))
    for section in (robots, obstacles):
        for k, entry in enumerate(section):
            if set(entry) == {"group"}:
                section[k] = _group(grouped[entry["group"]])
    return robots, obstacles


def _group(members: list) -> dict[str, Any]:
    first, where = members[0]
    behavior = _behavior(first.motion)
    for obstacle, path in members:
        if _behavior(obstacle.motion) != behavior:
            raise ConfigError(None, path, "IR-SIM's group behaviour has one set of parameters; allowed: the same "
                                          "behaviour and route settings for every member of the group")
    if isinstance(first.motion.behavior, Orca) and first.motion.reacts_to_robot:
        raise ConfigError(None, where, "IR-SIM's ORCA group sees only its members; allowed: reacts_to_robot: false")
    entries = [_mover(obstacle) for obstacle, _ in members]
    out: dict[str, Any] = {"number": len(entries), "distribution": {"name": "manual"},
                           "group_behavior": behavior}
    for key in entries[0]:
        values = [entry[key] for entry in entries]
        if all(value == values[0] for value in values):
            out[key] = values[0]
        elif isinstance(values[0], (list, dict)):
            out[key] = values  # one per object (IR-SIM's fan-out)
        else:  # IR-SIM reads a list of numbers or flags as one vector, shared by every member
            raise ConfigError(None, f"{where.rsplit('.motion', 1)[0]}", f"the members of group {first.motion.group!r} "
                              f"differ in {key}; allowed: one value for the group (IR-SIM's)")
    return out


def scenario_to_irsim(scenario: Scenario) -> dict[str, Any]:
    """The IR-SIM world mapping of a scenario (dump it with ``yaml.safe_dump``)."""
    world, robot, lidar = scenario.world, scenario.robot, scenario.lidar
    # What IR-SIM has no model of is refused, not dropped (its poses parted from flatland's by
    # centimetres within 20 steps, without a word).
    if robot.encoder_noise > 0:
        raise ConfigError(None, "robot.encoder_noise", "IR-SIM's robot has no wheel encoders; allowed: 0")
    if world.integrator != "euler":
        raise ConfigError(None, "world.integrator", "IR-SIM moves its robot by Euler steps; allowed: euler")
    if robot.shape == "circle":
        shape = {"name": "circle", "radius": robot.radius, "center": [robot.footprint_offset, 0.0]}
    elif robot.shape == "polygon":
        shape = {"name": "polygon", "vertices": [list(vertex) for vertex in robot.vertices]}
    elif robot.shape == "compound":
        shape = {"name": "compound", "parts": [
            {"name": "circle", "radius": part.radius, "center": list(part.center)} if part.radius is not None
            else {"name": "polygon", "vertices": [list(vertex) for vertex in part.vertices]} for part in robot.parts]}
    else:
        # IR-SIM puts a rectangle half its shape's wheelbase ahead of the pose.
        shape = {"name": "rectangle", "length": robot.length, "width": robot.width,
                 **({"wheelbase": 2.0 * robot.footprint_offset} if robot.footprint_offset else {})}
    kinematics: dict[str, Any] = {"name": robot.kinematics}
    if robot.kinematics == "acker":
        kinematics.update(mode=robot.steer_mode, wheelbase=robot.axle_distance)
    if robot.motion_noise is not None:
        kinematics.update(noise=True, alpha=list(robot.motion_noise))
    limits = channel_limits(robot)
    robot_entry: dict[str, Any] = {
        "kinematics": kinematics,
        "shape": shape,
        "state": list(scenario.start) + ([0.0] if robot.kinematics == "acker" else []),
        "goal": [*scenario.goal, 0.0],
        "goal_threshold": scenario.goal_threshold,
        "vel_min": [low for low, _, _ in limits],
        "vel_max": [high for _, high, _ in limits],
        **({"static": True} if robot.static else {}),
        "sensors": [{
            "name": "lidar2d", "range_min": lidar.range_min, "range_max": lidar.range_max,
            # IR-SIM spreads beams over linspace(-range/2, range/2): a full circle's evenly spaced
            # beams are that over 2π(n - 1)/n, the same directions.
            "angle_range": 2 * math.pi - lidar.beam_spacing if lidar.full_circle else lidar.angle_range,
            "number": lidar.beams, "offset": list(lidar.offset),
            "noise": lidar.noise_std > 0, "std": lidar.noise_std,
        }],
    }
    if any(math.isfinite(acceleration) for _, _, acceleration in limits):
        robot_entry["acce"] = [acceleration for _, _, acceleration in limits]
    robots, obstacles = _groups(scenario)
    if world.walls:
        x0, y0 = world.offset
        x1, y1 = x0 + world.width, y0 + world.height
        ring = [[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]
        obstacles.append({"shape": {"name": "linestring", "vertices": ring}, "state": list(_ORIGIN)})
    grid = scenario.grid_map
    world_entry: dict[str, Any] = {"width": world.width, "height": world.height, "step_time": world.step_time,
                                   "offset": list(world.offset), "collision_mode": world.collision_mode}
    if grid is not None:
        world_entry.update(obstacle_map=grid.image if grid.image is not None else dict(grid.generator),
                           mdownsample=grid.downsample)
    return {
        "world": world_entry,
        "robot": [robot_entry, *robots],
        "obstacle": obstacles,
    }


def passing(scenario: Scenario) -> Scenario:
    """The scenario with every mover passing through static geometry, as IR-SIM's do (a sliding
    one, ``static_contact: slide``, is kept out of it: :mod:`common.motion.slide`)."""
    def passes(obstacle):
        motion = getattr(obstacle, "motion", None)
        if motion is None or motion.static_contact == "pass":
            return obstacle
        return obstacle.model_copy(update={"motion": motion.model_copy(update={"static_contact": "pass"})})
    return scenario.model_copy(update={"obstacles": [passes(obstacle) for obstacle in scenario.obstacles]})


def fixed_routes(scenario: Scenario, count: int | None = None) -> Scenario:
    """The scenario with its people (the first ``count``, default all) each walking back and forth
    to their first goal, planning alone (ORCA's people in their group: IR-SIM runs ORCA for groups
    only) and passing through static geometry: a crowd both simulators move alike (a wanderer's
    next goals are drawn by each simulator from its own generator)."""
    people = []
    for person in scenario.movers[:count]:
        group = person.motion.group if isinstance(person.motion.behavior, Orca) else None
        motion = person.motion.model_copy(update={"group": group, "wander": None, "route": "back_and_forth"})
        people.append(person.model_copy(update={"motion": motion}))
    return passing(scenario.model_copy(update={"obstacles": [*scenario.static_obstacles, *people]}))
