"""Seeded scenario generators by kind and difficulty, and the named evaluation suites.

Every generator draws from ``numpy.random.default_rng([seed, kind, split])``, so a (kind, seed,
split) triple always gives the same scenario and the training and evaluation splits never share
a scenario. Obstacles keep a gap of at least the robot's diameter between them (so the robot
can always squeeze through a gap the generator leaves), clear the start and goal, and the goal is
checked reachable by the robot's footprint on a 0.1 m grid; a layout that fails is redrawn.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Iterator, Literal

import numpy as np

from common.errors import ConfigError, quote
from common import moving_kinds
from common.layouts import CIRCLE_ANY, CIRCLE_NEAR, CRATE, MIXED_ANY, MIXED_NEAR, PILLAR, SHELF, Layout, Step, lay_out
from common.grid_maps import GridMap, maze_rooms
from common.occupancy import goal_reachable, path_exists, shapes_grid
from common.passages import passages
from common.placement import CIRCLE
from common.scenario import BoxObstacle, CircleObstacle, Obstacle, RobotProfile, Scenario

Split = Literal["train", "eval"]
KINDS = ("open", "sparse", "cluttered", "warehouse", "trap", "crowd", "warehouse_moving", "maze", "passages")
MOVING_KINDS = ("crowd", "warehouse_moving")
_SPLIT_IDS = {"train": 0, "eval": 1}
_MAX_ATTEMPTS = 200


def _placed(template: Scenario, rng: np.random.Generator, min_distance: float, *steps: Step) -> tuple | None:
    """A start and goal ``min_distance`` apart and the steps' obstacles around them, or None if one
    found no place or the goal cannot be reached.

    The placement keeps every obstacle the robot's radius + 0.3 m from start and goal, more than
    ``Scenario.check`` asks, so only their being inside the world is checked here (checking the
    whole scenario again cost a third of a warehouse's generation)."""
    world = template.world
    robot_radius = template.robot.bounding_radius
    layout = lay_out(rng, (*world.offset, world.width, world.height), min_distance, steps, robot_radius)
    if layout is None or not (world.contains(*layout.start[:2]) and world.contains(*layout.goal)):
        return None
    # Reachability is judged on the layout's arrays, before any obstacle is built.
    if not path_exists(shapes_grid(world, layout.kinds, layout.params, 0.1, robot_radius), layout.start, layout.goal,
                       template.goal_threshold):
        return None
    return layout.start, layout.goal, _obstacles(layout)


def _obstacles(layout: Layout) -> list[Obstacle]:
    obstacles: list[Obstacle] = []
    for kind, (x, y, a, b, yaw), height in zip(layout.kinds.tolist(), layout.params.tolist(), layout.heights.tolist()):
        if kind == CIRCLE:
            obstacles.append(CircleObstacle(x=x, y=y, radius=a, height=height))
        else:
            obstacles.append(BoxObstacle(x=x, y=y, length=a, width=b, yaw=yaw, height=height))
    return obstacles


def _open(template: Scenario, rng: np.random.Generator, difficulty: float) -> tuple | None:
    return _placed(template, rng, 2.0 + 4.0 * difficulty)


def _sparse(template: Scenario, rng: np.random.Generator, difficulty: float) -> tuple | None:
    count = int(round(3 + 5 * difficulty))
    on_route = max(1, count // 3)
    return _placed(template, rng, 4.0 + 2.0 * difficulty,
                   Step(CIRCLE_NEAR, on_route, radius=(0.25, 0.5), spread=0.6),
                   Step(CIRCLE_ANY, count - on_route, radius=(0.25, 0.5)))


def _cluttered(template: Scenario, rng: np.random.Generator, difficulty: float) -> tuple | None:
    count = int(round(10 + 10 * difficulty))
    return _placed(template, rng, 5.0 + 2.0 * difficulty,
                   Step(MIXED_NEAR, count // 3, radius=(0.2, 0.5), side=(0.3, 1.0), spread=1.0),
                   Step(MIXED_ANY, count - count // 3, radius=(0.2, 0.5), side=(0.3, 1.0)))


def _warehouse(template: Scenario, rng: np.random.Generator, difficulty: float) -> tuple | None:
    """Shelving rows, pillars and scattered crates: 31 obstacles, as in the 3D tutorial's warehouse,
    less the crates that find no place with the robot's gap (most seeds for robots wider than
    0.25 m bounding radius; 3 in 1,200 train-split layouts for the default robot)."""
    return _placed(template, rng, 3.0 + 3.0 * difficulty, Step(SHELF, 6, height=1.8), Step(PILLAR, 5, height=3.0),
                   Step(CRATE, 20, tries=200, side=(0.3, 0.7), height=0.6, optional=True))


def _trap(template: Scenario, rng: np.random.Generator, difficulty: float) -> tuple | None:
    """A U whose cavity faces the start with the goal behind its base, or two twin obstacles whose
    repulsions cancel on the start-goal line: both hold a potential field in a local minimum."""
    world = template.world
    cx = world.offset[0] + 0.5 * world.width + rng.uniform(-0.5, 0.5)
    cy = world.offset[1] + 0.5 * world.height + rng.uniform(-0.5, 0.5)
    heading = rng.uniform(-math.pi, math.pi)
    c, s = math.cos(heading), math.sin(heading)
    to_world = lambda u, v: (cx + c * u - s * v, cy + s * u + c * v)
    start_u = -3.0 - rng.uniform(0.0, 0.5)
    start = (*to_world(start_u, rng.uniform(-0.2, 0.2)), float(heading + rng.uniform(-0.3, 0.3)))
    goal = to_world(2.0 + rng.uniform(0.0, 0.5), rng.uniform(-0.2, 0.2))
    half_gap = 0.7 + 0.5 * difficulty
    thickness = 0.3
    if rng.random() < 0.7:
        depth = 1.2 + 1.0 * difficulty
        parts = [(0.0, 0.0, thickness, 2 * half_gap + 2 * thickness)]  # base, between cavity and goal
        for side in (-1.0, 1.0):
            parts.append((-0.5 * depth + 0.5 * thickness, side * (half_gap + 0.5 * thickness), depth, thickness))
        obstacles = [BoxObstacle(x=to_world(u, v)[0], y=to_world(u, v)[1], length=L, width=W, yaw=float(heading))
                     for u, v, L, W in parts]
    else:
        radius = 0.5 + 0.3 * difficulty
        # Twin circles nearly touching across the route: too narrow to pass, so the field must go round.
        offset = radius + 0.5 * template.robot.bounding_radius
        obstacles = [CircleObstacle(x=to_world(0.0, side * offset)[0], y=to_world(0.0, side * offset)[1], radius=radius)
                     for side in (-1.0, 1.0)]
    return _checked(template, (float(start[0]), float(start[1]), float(start[2])), goal, obstacles)


MAZE_RESOLUTION = 0.1  # m per cell of a maze's grid


def _maze(template: Scenario, rng: np.random.Generator, difficulty: float) -> tuple | None:
    """A maze on a grid map (:func:`common.grid_maps.maze_occupancy`): passages four robot radii
    wide (at least 1 m), fewer shortcuts the harder, the start and goal in rooms at least half the
    world's diagonal apart."""
    world = template.world
    passage = max(1.0, 4.0 * template.robot.bounding_radius)
    grid = GridMap(generator=(("loops", round(0.3 * (1.0 - difficulty), 6)), ("name", "maze"), ("passage", passage),
                              ("resolution", MAZE_RESOLUTION), ("seed", int(rng.integers(2**31 - 1)))))
    rooms = maze_rooms(world.width, world.height, MAZE_RESOLUTION, passage, world.offset)
    first, second = rng.choice(len(rooms), 2, replace=False)
    start, goal = rooms[first], rooms[second]
    if math.dist(start, goal) < 0.5 * world.diagonal:
        return None
    start_pose = (float(start[0]), float(start[1]), float(rng.uniform(-math.pi, math.pi)))
    scenario = template.model_copy(update=dict(start=start_pose, goal=(float(goal[0]), float(goal[1])), obstacles=[],
                                               grid_map=grid))
    return (start_pose, tuple(goal), [], {"grid_map": grid}) if goal_reachable(scenario) else None


def _checked(template: Scenario, start: tuple, goal: tuple, obstacles: list[Obstacle]) -> tuple | None:
    """The layout if its start and goal are clear of the obstacles and the goal is reachable, else None."""
    scenario = template.model_copy(update=dict(start=start, goal=goal, obstacles=obstacles))
    return (start, goal, obstacles) if not scenario.placement_problems() and goal_reachable(scenario) else None


# Each returns (start, goal, obstacles) already checked (clear and reachable), and any other field
# of the scenario it sets (a maze's grid map), or None to redraw.
_GENERATORS: dict[str, Callable[..., tuple | None]] = {
    "open": _open, "sparse": _sparse, "cluttered": _cluttered, "warehouse": _warehouse, "trap": _trap,
    "crowd": moving_kinds.crowd, "warehouse_moving": moving_kinds.warehouse_moving, "maze": _maze,
    "passages": passages,
}
OPTIONS = ("reacting", "behavior")  # what a moving kind's variants may set


def generate(kind: str, seed: int, difficulty: float = 0.5, split: Split = "train",
             template: Scenario | None = None, **options: Any) -> Scenario:
    """The scenario of ``kind`` for this seed, difficulty (0 to 1) and split.

    ``template`` supplies the robot, lidar, world size and goal threshold (defaults: a 10 m × 10 m
    walled world, a 0.2 m circular robot with v_max 1 m/s, w_max 1 rad/s, a 36-beam 5 m lidar).
    A template whose robot finds no layout (too wide for the world) is a :class:`ConfigError`
    naming ``robot``. ``options`` are a moving kind's variants (:mod:`common.moving_kinds`:
    ``reacting``, ``behavior``).
    """
    if kind not in _GENERATORS:
        raise ConfigError(None, "kind", f"unknown scenario kind {quote(kind)}; allowed: {', '.join(KINDS)}")
    if not 0.0 <= difficulty <= 1.0:
        raise ConfigError(None, "difficulty", f"{difficulty} is outside [0, 1]")
    for name in options:
        if kind not in MOVING_KINDS or name not in OPTIONS:
            raise ConfigError(None, name, f"not an option of the {kind} kind; allowed: "
                              f"{', '.join(OPTIONS) if kind in MOVING_KINDS else 'none'}")
    template = template or Scenario()
    if kind in MOVING_KINDS:  # movers pass through each other; the robot stops on any contact
        template = template.model_copy(update={"world": template.world.model_copy(
            update={"collision_mode": "unobstructed_obstacles"})})
    rng = np.random.default_rng([seed, KINDS.index(kind), _SPLIT_IDS[split]])
    for _ in range(_MAX_ATTEMPTS):
        layout = _GENERATORS[kind](template, rng, difficulty, **options)
        if layout is None:
            continue
        start, goal, obstacles, *fields = layout
        scenario = template.model_copy(update=dict(
            name=f"{kind}-{split}-{seed}", kind=kind, difficulty=difficulty, seed=seed,
            start=tuple(float(v) for v in start), goal=(float(goal[0]), float(goal[1])), obstacles=obstacles,
            **(fields[0] if fields else {})))
        return scenario
    world = template.world
    raise ConfigError(None, "robot", f"no reachable {kind} layout in {_MAX_ATTEMPTS} attempts (seed {seed}) for a robot "
                      f"of bounding radius {template.robot.bounding_radius:g} m in a {world.width:g} m x "
                      f"{world.height:g} m world; allowed: a smaller robot or a larger world")


@dataclass(frozen=True)
class Suite:
    """A named, reproducible list of evaluation scenarios: (generator kind, count, base seed), and
    the kind's options (a moving kind's variant).

    The scenarios are laid out for the robot that drives them where the template's would not do:
    a robot wider than the template's bounding circle may not fit a gap left for it, and a
    ``for_robot`` suite (``passages``) sizes every gap by the robot's own width. A robot within
    the template's bounding circle fits every layout drawn for it, and drives the suite's one
    draw, so the figures measured on it keep their meaning.
    """

    name: str
    kind: str
    count: int = 100
    base_seed: int = 0
    difficulty: float = 0.5
    options: tuple[tuple[str, Any], ...] = field(default=())
    for_robot: bool = False

    def scenarios(self, count: int | None = None, seed: int = 0, template: Scenario | None = None,
                  robot: RobotProfile | None = None) -> Iterator[Scenario]:
        """Yield the suite's scenarios; ``seed`` shifts the base seed, ``count`` overrides its length;
        ``robot``: the robot that will drive them (see the class)."""
        template = template or Scenario()
        if robot is not None and (self.for_robot or robot.bounding_radius > template.robot.bounding_radius):
            template = template.model_copy(update={"robot": robot})
        for i in range(self.count if count is None else count):
            yield generate(self.kind, self.base_seed + seed + i, self.difficulty, "eval", template, **dict(self.options))


SUITES: dict[str, Suite] = {
    kind: Suite(name=kind, kind=kind, difficulty=1.0 if kind == "warehouse" else 0.5, for_robot=kind == "passages")
    for kind in KINDS
}
# The crowd as the robot's targets are set: 12 people at 0.5-1.2 m/s who all see the robot; and the
# same people blind to it (the hard case).
SUITES["crowd"] = Suite(name="crowd", kind="crowd", options=(("reacting", True),))
SUITES["crowd_unaware"] = Suite(name="crowd_unaware", kind="crowd", options=(("reacting", False),))
# The moving warehouse with every driver and person blind to the robot.
SUITES["warehouse_moving_unaware"] = Suite(name="warehouse_moving_unaware", kind="warehouse_moving",
                                           options=(("reacting", False),))


def get_suite(name: str) -> Suite:
    """The named suite, or a one-line :class:`ConfigError` listing the names."""
    try:
        return SUITES[name]
    except KeyError:
        raise ConfigError(None, "suite", f"unknown suite {quote(name)}; allowed: {', '.join(SUITES)}") from None
