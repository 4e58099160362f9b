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

from common.errors import ConfigError, quote
from common.occupancy import goal_reachable
from common.scenario import BoxObstacle, CircleObstacle, Obstacle, Scenario

Split = Literal["train", "eval"]
KINDS = ("open", "sparse", "cluttered", "warehouse", "trap")
_SPLIT_IDS = {"train": 0, "eval": 1}
_MAX_ATTEMPTS = 200


_CIRCLE_POINTS = 32
_UNIT_CIRCLE = np.column_stack([np.cos(np.linspace(0.0, 2.0 * math.pi, _CIRCLE_POINTS, endpoint=False)),
                                np.sin(np.linspace(0.0, 2.0 * math.pi, _CIRCLE_POINTS, endpoint=False))])
_SIDE_STEPS = np.linspace(0.0, 1.0, 8, endpoint=False)[:, None]


def _outline(obstacle: Obstacle) -> np.ndarray:
    """Points along the obstacle's boundary (enough to measure gaps between convex shapes)."""
    if isinstance(obstacle, CircleObstacle):
        return _UNIT_CIRCLE * obstacle.radius + (obstacle.x, obstacle.y)
    assert isinstance(obstacle, BoxObstacle)
    corners = obstacle.corners()
    ends = np.roll(corners, -1, axis=0)
    # Each side's eight points (its start included), sides in order: as 8 steps along each edge.
    return (corners[:, None, :] + _SIDE_STEPS[None] * (ends - corners)[:, None, :]).reshape(-1, 2)


class _Placed(NamedTuple):
    """An obstacle with what the gap checks need of it."""

    obstacle: Obstacle
    outline: np.ndarray
    centre: np.ndarray
    radius: float


class _Layout:
    """Obstacles placed one by one, each rejected if it crowds another, the start, the goal or a wall."""

    def __init__(self, template: Scenario, rng: np.random.Generator, start, goal) -> None:
        self.template = template
        self.rng = rng
        self.start, self.goal = start, goal
        self.clearance = 2.0 * template.robot.bounding_radius + 0.05
        world, margin = template.world, self.clearance
        self._low = np.array(world.offset) + margin
        self._high = np.array(world.offset) + (world.width - margin, world.height - margin)
        self._ends = np.array([start[:2], goal])
        self.placed: list[_Placed] = []
        self._centres = np.zeros((0, 2))
        self._radii = np.zeros(0)

    @property
    def obstacles(self) -> list[Obstacle]:
        return [p.obstacle for p in self.placed]

    def fits(self, obstacle: Obstacle) -> _Placed | None:
        """The obstacle ready to place, or None if it crowds a wall, the start, the goal or another."""
        outline = _outline(obstacle)
        if (outline < self._low).any() or (outline > self._high).any():
            return None
        if obstacle.sdf(self._ends).min() < self.template.robot.bounding_radius + 0.3:
            return None
        centre = outline.mean(axis=0)
        radius = float(np.hypot(*(outline - centre).T).max())
        # Bounding circles apart by the clearance: no closer look needed. Only the near ones are
        # measured outline to outline (the shapes are convex, so their outlines' gaps are theirs).
        near = np.flatnonzero(np.hypot(*(self._centres - centre).T) < radius + self._radii + self.clearance)
        for index in near:
            other = self.placed[index]
            if other.obstacle.sdf(outline).min() < self.clearance or obstacle.sdf(other.outline).min() < self.clearance:
                return None
        return _Placed(obstacle, outline, centre, radius)

    def add(self, propose: Callable[[], Obstacle], count: int, tries: int = 60) -> bool:
        """Place ``count`` obstacles from ``propose``; False if one found no free place in ``tries``."""
        for _ in range(count):
            for _ in range(tries):
                placed = self.fits(propose())
                if placed is not None:
                    self.placed.append(placed)
                    self._centres = np.vstack([self._centres, placed.centre])
                    self._radii = np.append(self._radii, placed.radius)
                    break
            else:
                return False
        return True

    def near_route(self, spread: float) -> tuple[float, float]:
        """A point on the start-goal segment's middle stretch, jittered sideways."""
        t = self.rng.uniform(0.25, 0.75)
        sx, sy = self.start[:2]
        gx, gy = self.goal
        heading = math.atan2(gy - sy, gx - sx)
        side = self.rng.uniform(-spread, spread)
        return sx + t * (gx - sx) - side * math.sin(heading), sy + t * (gy - sy) + side * math.cos(heading)

    def anywhere(self) -> tuple[float, float]:
        x0, y0 = self.template.world.offset
        return self.rng.uniform(x0, x0 + self.template.world.width), self.rng.uniform(y0, y0 + self.template.world.height)

    def circle(self, where: tuple[float, float], r_min: float, r_max: float) -> CircleObstacle:
        return CircleObstacle(x=where[0], y=where[1], radius=self.rng.uniform(r_min, r_max))

    def box(self, where: tuple[float, float], side_min: float, side_max: float, height: float = 0.5) -> BoxObstacle:
        length, width = self.rng.uniform(side_min, side_max, 2)
        return BoxObstacle(x=where[0], y=where[1], length=length, width=width,
                           yaw=self.rng.uniform(-math.pi, math.pi), height=height)


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
    shelf = lambda: BoxObstacle(x=layout.anywhere()[0], y=layout.anywhere()[1], length=rng.uniform(1.5, 2.5),
                                width=0.4, yaw=float(rng.choice([0.0, math.pi / 2])), height=1.8)
    pillar = lambda: CircleObstacle(x=layout.anywhere()[0], y=layout.anywhere()[1], radius=0.15, height=3.0)
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
