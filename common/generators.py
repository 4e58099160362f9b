"""Seeded scenario generators by kind and difficulty, and the named evaluation suites.

Every generator draws from ``numpy.random.default_rng([seed, kind, split])``, so a (kind, seed,
split) triple always gives the same scenario and the training and evaluation splits never share
a scenario. Obstacles keep a gap of at least the robot's diameter between them (so the robot
can always squeeze through a gap the generator leaves), clear the start and goal, and the goal is
checked reachable by the robot's footprint on a 0.1 m grid; a layout that fails is redrawn.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Iterator, Literal, NamedTuple

import numpy as np

from common import placement
from common.errors import ConfigError, quote
from common.occupancy import goal_reachable
from common.scenario import BoxObstacle, CircleObstacle, Obstacle, Scenario

Split = Literal["train", "eval"]
KINDS = ("open", "sparse", "cluttered", "warehouse", "trap")
_SPLIT_IDS = {"train": 0, "eval": 1}
_MAX_ATTEMPTS = 200


class _Shape(NamedTuple):
    """A proposed obstacle as raw numbers; it becomes a validated obstacle only once it fits."""

    kind: int  # placement.CIRCLE or placement.BOX
    x: float
    y: float
    size: tuple[float, ...]  # (radius,) or (length, width, yaw)
    height: float

    @property
    def params(self) -> np.ndarray:
        return np.array([self.x, self.y, *self.size, *(0.0,) * (3 - len(self.size))])

    def build(self) -> Obstacle:
        if self.kind == placement.CIRCLE:
            return CircleObstacle(x=self.x, y=self.y, radius=self.size[0], height=self.height)
        length, width, yaw = self.size
        return BoxObstacle(x=self.x, y=self.y, length=length, width=width, yaw=yaw, height=self.height)


class _Layout:
    """Obstacles placed one by one, each rejected if it crowds another, the start, the goal or a wall."""

    def __init__(self, template: Scenario, rng: np.random.Generator, start, goal, capacity: int = 32) -> None:
        self.template = template
        self.rng = rng
        self.start, self.goal = start, goal
        self.clearance = 2.0 * template.robot.bounding_radius + 0.05
        world, margin = template.world, self.clearance
        self._low = np.array(world.offset) + margin
        self._high = np.array(world.offset) + (world.width - margin, world.height - margin)
        self._ends = np.array([start[:2], goal])
        self.obstacles: list[Obstacle] = []
        # What the compiled check reads of the placed shapes, in arrays grown as needed.
        self._kinds = np.zeros(capacity, dtype=np.int64)
        self._params = np.zeros((capacity, 5))
        self._outlines = np.zeros((capacity, placement.OUTLINE_POINTS, 2))

    def _place(self, shape: _Shape) -> bool:
        """Place the shape if it crowds nothing; whether it was placed."""
        count = len(self.obstacles)
        if count == len(self._kinds):
            for name in ("_kinds", "_params", "_outlines"):
                grown = getattr(self, name)
                setattr(self, name, np.concatenate([grown, np.zeros_like(grown)]))
        if not placement.place(shape.kind, shape.params, self._low, self._high, self._ends,
                               self.template.robot.bounding_radius + 0.3, self.clearance, self._kinds, self._params,
                               self._outlines, count):
            return False
        self.obstacles.append(shape.build())
        return True

    def add(self, propose: Callable[[], _Shape], count: int, tries: int = 60) -> bool:
        """Place ``count`` shapes from ``propose``; False if one found no free place in ``tries``."""
        for _ in range(count):
            if not any(self._place(propose()) for _ in range(tries)):
                return False
        return True

    def uniform(self, low: float, high: float) -> float:
        """``rng.uniform(low, high)`` bit for bit (NumPy computes low + (high - low) * random()), at
        a third of its call cost: the layouts draw thousands of these per scenario."""
        return low + (high - low) * self.rng.random()

    def near_route(self, spread: float) -> tuple[float, float]:
        """A point on the start-goal segment's middle stretch, jittered sideways."""
        t = self.uniform(0.25, 0.75)
        sx, sy = self.start[:2]
        gx, gy = self.goal
        heading = math.atan2(gy - sy, gx - sx)
        side = self.uniform(-spread, spread)
        return sx + t * (gx - sx) - side * math.sin(heading), sy + t * (gy - sy) + side * math.cos(heading)

    def anywhere(self) -> tuple[float, float]:
        x0, y0 = self.template.world.offset
        return self.uniform(x0, x0 + self.template.world.width), self.uniform(y0, y0 + self.template.world.height)

    def circle(self, where: tuple[float, float], r_min: float, r_max: float) -> _Shape:
        return _Shape(placement.CIRCLE, float(where[0]), float(where[1]), (self.uniform(r_min, r_max),), 0.5)

    def box(self, where: tuple[float, float], side_min: float, side_max: float, height: float = 0.5) -> _Shape:
        length, width = self.uniform(side_min, side_max), self.uniform(side_min, side_max)
        yaw = self.uniform(-math.pi, math.pi)
        return _Shape(placement.BOX, float(where[0]), float(where[1]), (length, width, yaw), height)


def _start_goal(template: Scenario, rng: np.random.Generator, min_distance: float, margin: float = 1.0):
    """A start pose (random yaw) and a goal at least ``min_distance`` apart, ``margin`` inside the world."""
    world = template.world
    x0, y0 = world.offset
    min_distance = min(min_distance, 0.9 * math.hypot(world.width - 2 * margin, world.height - 2 * margin))
    while True:
        sx, gx = rng.uniform(x0 + margin, x0 + world.width - margin, 2)
        sy, gy = rng.uniform(y0 + margin, y0 + world.height - margin, 2)
        if math.hypot(gx - sx, gy - sy) >= min_distance:
            return (float(sx), float(sy), float(rng.uniform(-math.pi, math.pi))), (float(gx), float(gy))


def _open(template: Scenario, rng: np.random.Generator, difficulty: float) -> tuple:
    start, goal = _start_goal(template, rng, 2.0 + 4.0 * difficulty)
    return start, goal, []


def _sparse(template: Scenario, rng: np.random.Generator, difficulty: float) -> tuple:
    start, goal = _start_goal(template, rng, 4.0 + 2.0 * difficulty)
    layout = _Layout(template, rng, start, goal)
    count = int(round(3 + 5 * difficulty))
    on_route = max(1, count // 3)
    placed = layout.add(lambda: layout.circle(layout.near_route(0.6), 0.25, 0.5), on_route) and layout.add(
        lambda: layout.circle(layout.anywhere(), 0.25, 0.5), count - on_route)
    return (start, goal, layout.obstacles) if placed else None


def _cluttered(template: Scenario, rng: np.random.Generator, difficulty: float) -> tuple:
    start, goal = _start_goal(template, rng, 5.0 + 2.0 * difficulty)
    layout = _Layout(template, rng, start, goal)
    count = int(round(10 + 10 * difficulty))
    shape = lambda where: (layout.circle(where, 0.2, 0.5) if rng.random() < 0.5 else layout.box(where, 0.3, 1.0))
    placed = layout.add(lambda: shape(layout.near_route(1.0)), count // 3) and layout.add(
        lambda: shape(layout.anywhere()), count - count // 3)
    return (start, goal, layout.obstacles) if placed else None


def _warehouse(template: Scenario, rng: np.random.Generator, difficulty: float) -> tuple:
    """Shelving rows, pillars and scattered crates: 31 obstacles, as in the 3D tutorial's warehouse."""
    start, goal = _start_goal(template, rng, 3.0 + 3.0 * difficulty)
    layout = _Layout(template, rng, start, goal)
    def shelf() -> _Shape:
        # x and y from two draws of anywhere(), as when the suites were first measured.
        x, y = layout.anywhere()[0], layout.anywhere()[1]
        length = layout.uniform(1.5, 2.5)
        return _Shape(placement.BOX, float(x), float(y), (length, 0.4, float(rng.choice([0.0, math.pi / 2]))), 1.8)

    def pillar() -> _Shape:
        x, y = layout.anywhere()[0], layout.anywhere()[1]
        return _Shape(placement.CIRCLE, float(x), float(y), (0.15,), 3.0)

    crate = lambda: layout.box(layout.anywhere(), 0.3, 0.7, height=0.6)
    placed = layout.add(shelf, 6) and layout.add(pillar, 5) and layout.add(crate, 20, tries=200)
    return (start, goal, layout.obstacles) if placed else None


def _trap(template: Scenario, rng: np.random.Generator, difficulty: float) -> tuple:
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
    return (float(start[0]), float(start[1]), float(start[2])), goal, obstacles


_GENERATORS: dict[str, Callable[[Scenario, np.random.Generator, float], tuple | None]] = {
    "open": _open, "sparse": _sparse, "cluttered": _cluttered, "warehouse": _warehouse, "trap": _trap,
}


def generate(kind: str, seed: int, difficulty: float = 0.5, split: Split = "train",
             template: Scenario | None = None) -> Scenario:
    """The scenario of ``kind`` for this seed, difficulty (0 to 1) and split.

    ``template`` supplies the robot, lidar, world size and goal threshold (defaults: a 10 m × 10 m
    walled world, a 0.2 m circular robot with v_max 1 m/s, w_max 1 rad/s, a 36-beam 5 m lidar).
    """
    if kind not in _GENERATORS:
        raise ConfigError(None, "kind", f"unknown scenario kind {quote(kind)}; allowed: {', '.join(KINDS)}")
    if not 0.0 <= difficulty <= 1.0:
        raise ConfigError(None, "difficulty", f"{difficulty} is outside [0, 1]")
    template = template or Scenario()
    rng = np.random.default_rng([seed, KINDS.index(kind), _SPLIT_IDS[split]])
    for _ in range(_MAX_ATTEMPTS):
        layout = _GENERATORS[kind](template, rng, difficulty)
        if layout is None:
            continue
        start, goal, obstacles = layout
        scenario = template.model_copy(update=dict(
            name=f"{kind}-{split}-{seed}", kind=kind, difficulty=difficulty, seed=seed,
            start=tuple(float(v) for v in start), goal=(float(goal[0]), float(goal[1])), obstacles=obstacles))
        if _valid(scenario) and goal_reachable(scenario):
            return scenario
    raise RuntimeError(f"no reachable {kind} layout in {_MAX_ATTEMPTS} attempts (seed {seed})")


def _valid(scenario: Scenario) -> bool:
    try:
        scenario.check()
    except ConfigError:
        return False
    return True


@dataclass(frozen=True)
class Suite:
    """A named, reproducible list of evaluation scenarios: (generator kind, count, base seed)."""

    name: str
    kind: str
    count: int = 100
    base_seed: int = 0
    difficulty: float = 0.5

    def scenarios(self, count: int | None = None, seed: int = 0, template: Scenario | None = None) -> Iterator[Scenario]:
        """Yield the suite's scenarios; ``seed`` shifts the base seed, ``count`` overrides its length."""
        for i in range(self.count if count is None else count):
            yield generate(self.kind, self.base_seed + seed + i, self.difficulty, "eval", template)


SUITES: dict[str, Suite] = {
    kind: Suite(name=kind, kind=kind, difficulty=1.0 if kind == "warehouse" else 0.5) for kind in KINDS
}


def get_suite(name: str) -> Suite:
    """The named suite, or a one-line :class:`ConfigError` listing the names."""
    try:
        return SUITES[name]
    except KeyError:
        raise ConfigError(None, "suite", f"unknown suite {quote(name)}; allowed: {', '.join(SUITES)}") from None
