"""The ``passages`` generator kind: bands of thin posts and shelving across the world, every gap
1.2 to 2 times the robot's width, the goal beyond the last band.

Reachable by construction, for the robot's footprint and not its bounding circle: each band spans
the world wall to wall as a sequence of gaps and obstacles, and every gap (between two obstacles,
or an obstacle and a wall) is at least 1.2 robot widths across, measured along the band, while
the obstacles beside it stand within the band's depth; so a robot driving straight across a band
through any gap clears it by a tenth of its width each side. Between two bands, and before the
first and after the last, lies a free strip as deep as the robot's bounding circle is wide plus
a margin, where it can turn to the next gap. The generator still checks the layout: the goal
must be reachable on a fine grid inflated by half the robot's width (what a robot crossing a gap
head-on needs), the start and goal clear of every obstacle.

Difficulty sets the bands (2 to 4, fewer where the world has no room for them), their share of
shelving (30 % to 60 %) and how far posts stray from their band's centre line (a field, not a
fence). The bands run across the route in one of the four axis directions, drawn per seed.
"""

from __future__ import annotations

import math

import numpy as np

from common.occupancy import path_exists, shapes_grid
from common.placement import BOX, CIRCLE
from common.scenario import BoxObstacle, CircleObstacle, Scenario

POST_RADIUS = 0.075  # m: a 0.15 m post
SHELF_DEPTH = 0.4  # m
SHELF_LENGTH = (0.8, 2.0)  # m, along the band
GAP = (1.2, 2.0)  # robot widths
TURN_MARGIN = 0.3  # m beyond the bounding circle's diameter, between bands
END_DEPTH = 1.0  # m: the start and the goal lie this far inside the world
CHECK_RESOLUTION = 0.025  # m: a tenth of a robot width of 0.25 m, so a gap 1.2 widths across stays open


def _band(rng: np.random.Generator, length: float, width: float, shelf_share: float, stray: float) -> list[tuple]:
    """One band's obstacles as (kind, v, u offset, size along v): gaps of 1.2-2 widths between
    them and the walls at 0 and ``length``."""
    items, v = [], float(rng.uniform(*GAP)) * width
    while True:
        shelf = rng.random() < shelf_share
        size = float(rng.uniform(*SHELF_LENGTH)) if shelf else 2.0 * POST_RADIUS
        left = length - v - size  # to the far wall, past this obstacle
        if left < GAP[0] * width:
            # A shelf reaches the wall instead: no gap narrower than 1.2 widths is left there.
            items.append((BOX, v, 0.0, length - v))
            return items
        items.append((BOX if shelf else CIRCLE, v, 0.0 if shelf else float(rng.uniform(-stray, stray)), size))
        if left <= GAP[1] * width:
            return items  # the gap to the wall is one of the band's
        v += size + float(rng.uniform(*GAP)) * width


def passages(template: Scenario, rng: np.random.Generator, difficulty: float) -> tuple | None:
    """A passages layout (see the module's docstring), or None to redraw."""
    world, robot = template.world, template.robot
    width, reach = robot.width_across, 2.0 * robot.bounding_radius
    turn = reach + TURN_MARGIN
    stray = 0.1 + 0.2 * difficulty
    band_depth = max(SHELF_DEPTH, 2.0 * (stray + POST_RADIUS))
    quarter = int(rng.integers(4))  # the direction of travel: +x, +y, -x, -y
    along, across = (world.width, world.height) if quarter % 2 == 0 else (world.height, world.width)
    span = along - 2.0 * END_DEPTH
    fits = int(span // (band_depth + turn)) - 1  # the bands' pitch leaves a turning strip between them
    bands = min(2 + int(round(2 * difficulty)), fits)
    if bands < 1:
        return None
    shelf_share = 0.3 + 0.3 * difficulty
    pitch = span / (bands + 1)
    local: list[tuple[int, float, float, float, float]] = []  # kind, u, v, size along u, size along v
    for k in range(bands):
        u = END_DEPTH + pitch * (k + 1)
        for kind, v, offset, size in _band(rng, across, width, shelf_share, stray):
            depth = SHELF_DEPTH if kind == BOX else size
            local.append((kind, u + offset, v + 0.5 * size, depth, size))
    start_local = (END_DEPTH, float(rng.uniform(END_DEPTH, across - END_DEPTH)))
    goal_local = (along - END_DEPTH, float(rng.uniform(END_DEPTH, across - END_DEPTH)))
    # Local (u along the route, v across it) to world: a quarter turn about the world's centre.
    heading = 0.5 * math.pi * quarter
    c, s = round(math.cos(heading)), round(math.sin(heading))
    cx, cy = world.offset[0] + 0.5 * world.width, world.offset[1] + 0.5 * world.height

    def to_world(u: float, v: float) -> tuple[float, float]:
        du, dv = u - 0.5 * along, v - 0.5 * across
        return cx + c * du - s * dv, cy + s * du + c * dv

    obstacles, kinds, params = [], [], []
    for kind, u, v, depth, size in local:
        x, y = to_world(u, v)
        if kind == CIRCLE:
            obstacles.append(CircleObstacle(x=x, y=y, radius=POST_RADIUS, height=1.0))
            params.append((x, y, POST_RADIUS, 0.0, 0.0))
        else:
            obstacles.append(BoxObstacle(x=x, y=y, length=depth, width=size, yaw=heading, height=1.8))
            params.append((x, y, depth, size, heading))
        kinds.append(kind)
    start, goal = to_world(*start_local), to_world(*goal_local)
    start_pose = (start[0], start[1], float(heading + rng.uniform(-0.5, 0.5)))
    scenario = template.model_copy(update=dict(start=start_pose, goal=goal, obstacles=obstacles))
    grid = shapes_grid(world, np.array(kinds, dtype=np.int64), np.array(params, dtype=float).reshape(-1, 5),
                       CHECK_RESOLUTION, 0.5 * width)
    if scenario.placement_problems() or not path_exists(grid, start, goal, template.goal_threshold):
        return None
    return start_pose, goal, obstacles
