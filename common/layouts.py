"""The generators' obstacle layouts, compiled: proposals drawn and placed in one loop.

A warehouse rejects a couple of hundred proposals before its 31 obstacles fit. In Python each
proposal cost 10-20 µs (its draws, its tuple, its call into the gap check): most of a new
scenario's cost. Here the whole loop runs compiled on the caller's ``numpy.random.Generator``
(numba shares its bit generator and draws as NumPy does, bit for bit), so a seed gives the same
layout as the Python loop it replaced.

A layout is a sequence of :class:`Step`: place ``count`` shapes of a recipe, each from at most
``tries`` proposals; a shape that finds no place fails the layout, unless its step is
``optional`` (a warehouse's crates: a wider robot, which needs wider gaps, gets fewer of them).
Recipes, by integer code:

==================  ==========================================================================
``CIRCLE_NEAR``     a circle (its radius in ``radius``) near the start-goal route
``CIRCLE_ANY``      a circle anywhere in the world
``MIXED_NEAR``      a circle or a box (its sides in ``side``, its yaw any), evenly, near the route
``MIXED_ANY``       the same, anywhere
``SHELF``           a warehouse shelf: 1.5-2.5 m x 0.4 m, along x or y
``PILLAR``          a 0.15 m pillar
``CRATE``           a box anywhere (its sides in ``side``)
==================  ==========================================================================
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from common.kernel_cache import kernel
from common.placement import BOX, CIRCLE, OUTLINE_POINTS, place

CIRCLE_NEAR, CIRCLE_ANY, MIXED_NEAR, MIXED_ANY, SHELF, PILLAR, CRATE = range(7)
END_MARGIN = 1.0  # m: how far inside the world the start and the goal are drawn


class Step(NamedTuple):
    """Place ``count`` shapes of ``recipe``, each from at most ``tries`` proposals."""

    recipe: int
    count: int
    tries: int = 60
    radius: tuple[float, float] = (0.0, 0.0)  # a circle's radius is drawn from this range
    side: tuple[float, float] = (0.0, 0.0)  # and a box's length and width from this one
    spread: float = 0.0  # how far sideways of the route a NEAR recipe may stray
    height: float = 0.5
    optional: bool = False  # a shape that finds no place is left out instead of failing the layout


@kernel
def _uniform(rng, low: float, high: float) -> float:
    # NumPy's uniform(low, high) is low + (high - low) * random(): the same draws, bit for bit.
    return low + (high - low) * rng.random()


@kernel
def _anywhere(rng, world: np.ndarray) -> tuple[float, float]:
    x0, y0, width, height = world[0], world[1], world[2], world[3]
    x = _uniform(rng, x0, x0 + width)
    return x, _uniform(rng, y0, y0 + height)


@kernel
def _near_route(rng, ends: np.ndarray, spread: float) -> tuple[float, float]:
    """A point on the start-goal segment's middle stretch, jittered sideways."""
    t = _uniform(rng, 0.25, 0.75)
    sx, sy, gx, gy = ends[0, 0], ends[0, 1], ends[1, 0], ends[1, 1]
    heading = math.atan2(gy - sy, gx - sx)
    side = _uniform(rng, -spread, spread)
    return sx + t * (gx - sx) - side * math.sin(heading), sy + t * (gy - sy) + side * math.cos(heading)


@kernel
def _circle(rng, x: float, y: float, r_min: float, r_max: float, out: np.ndarray) -> int:
    out[0], out[1], out[2], out[3], out[4] = x, y, _uniform(rng, r_min, r_max), 0.0, 0.0
    return CIRCLE


@kernel
def _box(rng, x: float, y: float, side_min: float, side_max: float, out: np.ndarray) -> int:
    length = _uniform(rng, side_min, side_max)
    width = _uniform(rng, side_min, side_max)
    out[0], out[1], out[2], out[3], out[4] = x, y, length, width, _uniform(rng, -math.pi, math.pi)
    return BOX


@kernel
def _propose(rng, recipe: int, sizes: np.ndarray, spread: float, world: np.ndarray, ends: np.ndarray,
             out: np.ndarray) -> int:
    """Draw one shape of the recipe into ``out`` (x, y and three size parameters); its kind."""
    if recipe == SHELF or recipe == PILLAR:
        # x from one point anywhere and y from another, as when the suites were first measured.
        x = _anywhere(rng, world)[0]
        y = _anywhere(rng, world)[1]
        if recipe == PILLAR:
            out[0], out[1], out[2], out[3], out[4] = x, y, 0.15, 0.0, 0.0
            return CIRCLE
        length = _uniform(rng, 1.5, 2.5)
        out[0], out[1], out[2], out[3] = x, y, length, 0.4
        out[4] = 0.5 * math.pi if rng.integers(0, 2) == 1 else 0.0
        return BOX
    if recipe == CIRCLE_NEAR or recipe == MIXED_NEAR:
        x, y = _near_route(rng, ends, spread)
    else:
        x, y = _anywhere(rng, world)
    if recipe == CRATE or ((recipe == MIXED_NEAR or recipe == MIXED_ANY) and rng.random() >= 0.5):
        return _box(rng, x, y, sizes[2], sizes[3], out)
    return _circle(rng, x, y, sizes[0], sizes[1], out)


@kernel
def _start_goal(rng, world: np.ndarray, min_distance: float, margin: float) -> np.ndarray:
    """A start (x, y, yaw: any) and a goal (x, y) at least ``min_distance`` apart, ``margin`` inside
    the world, as (start x, start y, yaw, goal x, goal y)."""
    x0, y0, width, height = world[0], world[1], world[2], world[3]
    while True:
        # The draws of rng.uniform(low, high, 2) for the xs, then the ys.
        sx, gx = _uniform(rng, x0 + margin, x0 + width - margin), _uniform(rng, x0 + margin, x0 + width - margin)
        sy, gy = _uniform(rng, y0 + margin, y0 + height - margin), _uniform(rng, y0 + margin, y0 + height - margin)
        if math.hypot(gx - sx, gy - sy) >= min_distance:
            return np.array([sx, sy, _uniform(rng, -math.pi, math.pi), gx, gy])


@kernel
def _lay_out(rng, world: np.ndarray, min_distance: float, recipes: np.ndarray, counts: np.ndarray,
             tries: np.ndarray, optional: np.ndarray, sizes: np.ndarray, spreads: np.ndarray, robot_radius: float,
             kinds: np.ndarray, params: np.ndarray, steps: np.ndarray) -> tuple[np.ndarray, int, bool]:
    """Draw the start and goal, then place every step's shapes into ``kinds`` and ``params`` (and
    the step each came from into ``steps``): the start and goal (as ``_start_goal`` gives them),
    how many shapes were placed, and whether every shape of a step that is not optional was."""
    ends_drawn = _start_goal(rng, world, min_distance, END_MARGIN)
    ends = np.array([[ends_drawn[0], ends_drawn[1]], [ends_drawn[3], ends_drawn[4]]])
    clearance = 2.0 * robot_radius + 0.05
    low = np.array([world[0] + clearance, world[1] + clearance])
    high = np.array([world[0] + world[2] - clearance, world[1] + world[3] - clearance])
    outlines = np.zeros((kinds.shape[0], OUTLINE_POINTS, 2))
    proposal = np.empty(5)
    placed = 0
    for step in range(recipes.shape[0]):
        for _ in range(counts[step]):
            for _attempt in range(tries[step]):
                kind = _propose(rng, recipes[step], sizes[step], spreads[step], world, ends, proposal)
                if place(kind, proposal, low, high, ends, robot_radius + 0.3, clearance, kinds, params, outlines,
                         placed):
                    steps[placed] = step
                    placed += 1
                    break
            else:
                if not optional[step]:
                    return ends_drawn, placed, False  # this shape found no free place: the layout fails here
    return ends_drawn, placed, True


class Layout(NamedTuple):
    """A start pose, a goal and the shapes placed around them: ``kinds[i]`` (``CIRCLE`` or ``BOX``),
    ``params[i]`` = (x, y, radius, 0, 0) or (x, y, length, width, yaw), and each one's ``heights[i]``."""

    start: tuple[float, float, float]
    goal: tuple[float, float]
    kinds: np.ndarray
    params: np.ndarray
    heights: np.ndarray


@lru_cache(maxsize=64)
def _step_arrays(steps: tuple[Step, ...]) -> tuple[np.ndarray, ...]:
    """The steps as the kernel reads them (a curriculum asks for the same few lists again and again)."""
    arrays = (np.array([s.recipe for s in steps], dtype=np.int64), np.array([s.count for s in steps], dtype=np.int64),
              np.array([s.tries for s in steps], dtype=np.int64), np.array([s.optional for s in steps], dtype=np.bool_),
              np.array([(*s.radius, *s.side) for s in steps], dtype=float).reshape(-1, 4),
              np.array([s.spread for s in steps], dtype=float), np.array([s.height for s in steps], dtype=float))
    for array in arrays:
        array.flags.writeable = False  # shared by every call with these steps
    return arrays


def lay_out(rng: np.random.Generator, world: tuple[float, float, float, float], min_distance: float,
            steps: tuple[Step, ...], robot_radius: float) -> Layout | None:
    """A start and a goal at least ``min_distance`` apart (or 90% of the world's inner diagonal,
    if less) and every step's shapes placed around them, in the world (x0, y0, width, height);
    None if a shape of a step that is not optional found no place.

    Start and goal are drawn ``END_MARGIN`` inside the world (in a world narrower than twice that,
    they may fall outside it: the caller checks). Shapes keep a robot's diameter (plus 5 cm) from each
    other and from the walls, and the robot's radius plus 0.3 m from the start and the goal.
    """
    width, height = world[2], world[3]
    min_distance = min(min_distance, 0.9 * math.hypot(width - 2.0 * END_MARGIN, height - 2.0 * END_MARGIN))
    recipes, counts, tries, optional, sizes, spreads, heights = _step_arrays(steps)
    total = int(counts.sum())
    kinds, params, owners = np.zeros(total, dtype=np.int64), np.zeros((total, 5)), np.zeros(total, dtype=np.int64)
    ends, placed, complete = _lay_out(rng, np.array(world, dtype=float), min_distance, recipes, counts, tries, optional,
                                      sizes, spreads, robot_radius, kinds, params, owners)
    if not complete:
        return None
    sx, sy, yaw, gx, gy = ends.tolist()
    return Layout((sx, sy, yaw), (gx, gy), kinds[:placed], params[:placed], heights[owners[:placed]])
